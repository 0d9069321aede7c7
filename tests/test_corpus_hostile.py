"""The hostile corpus (tests/corpus_hostile.py): every case in a child process with bounded time and memory.

Each case must end in a clear one-line error, a flag, or its correct result: no traceback, no hang, no write
outside its output folder, no device replaced, no input modified, nothing lost that had finished (a killed
campaign resumed with every member, those finished before the kill unchanged).  The default suite runs a
sample; the slow suite every case."""
from __future__ import annotations

import pytest

from corpus_hostile import cases, run_all

ALL = cases()


def _check(rec):
    assert rec["outcome"] in ("clear", "ok"), (rec["name"], rec["outcome"], rec["rc"], rec["stderr"][-600:],
                                                rec["stdout"][-300:])
    assert not rec["input_modified"] and not rec["escaped"] and not rec["device_replaced"], rec
    assert rec["lost"] == 0, rec
    if rec.get("resume"):
        assert rec["resume"]["complete"] and rec["resume"]["kept"], rec["resume"]


@pytest.mark.parametrize("case", [c for c in ALL if c.fast], ids=lambda c: c.name)
def test_corpus_sample(case):
    [rec] = run_all([case], verbose=False)
    _check(rec)


@pytest.mark.slow
@pytest.mark.parametrize("case", [c for c in ALL if not c.fast], ids=lambda c: c.name)
def test_corpus_every_case(case):
    [rec] = run_all([case], verbose=False)
    _check(rec)
