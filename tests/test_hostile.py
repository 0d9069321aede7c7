"""Hostile input corpus (issue 16): every file the CLI reads is treated as hostile.

Each case builds its files in a fresh folder and runs ``shipid ...`` in-process.
The contract, checked for every case by :func:`_check`: exit code 2, exactly one
line on stderr (<= 300 characters) naming the file or option, no traceback, every
input byte-for-byte unchanged, and no output written (an existing output keeps
its bytes).  The other tests cover the write side (exclusive create, file sets,
strict JSON, signal clean-up)."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from shipid import _io
from shipid.cli import main
from shipid.datasets import bundled_kcs_logs
from shipid.models import get_model

REPO = Path(__file__).resolve().parents[1]
LOG = {p.stem: p for p in bundled_kcs_logs()}["kcs_zz_m10"]
DEEP = "[" * 100_000 + "]" * 100_000


def _good_result() -> dict:
    m = get_model("kcs-response", "synthetic-truth")
    coef = {k: float(v) for k, v in m.params_series().items()}
    names = ["c1", "c2"]
    return {"model": "kcs-response", "method": "ekf", "success": True, "message": "ok", "coef": coef,
            "coef_std": {k: 0.01 for k in coef}, "cov": {"names": names, "matrix": [[1e-4, 0.0], [0.0, 1e-4]]},
            "diagnostics": {"warnings": ["a1 and a8 are correlated"], "condition_number": 3.0},
            "loglik": -10.0, "settings": {}, "inputs": [], "versions": {}, "created": "", "extra": {},
            "model_options": {}}


def _write_json(folder: Path, name: str, doc) -> Path:
    p = folder / name
    p.write_text(doc if isinstance(doc, str) else json.dumps(doc))
    return p


def _write_bytes(p: Path, data: bytes) -> Path:
    p.write_bytes(data)
    return p


def _result_case(**changes):
    def build(tmp):
        doc = _good_result()
        for k, v in changes.items():
            if v is _DROP:
                doc.pop(k)
            else:
                doc[k] = v
        return _write_json(tmp, "r.json", doc)
    return build


_DROP = object()

#: (id, build(tmp) -> path of the hostile result file, words the error must contain)
RESULT_CASES = [
    ("coef-list", _result_case(coef=[1, 2]), ["r.json", "coef", "object"]),
    ("coef-int", _result_case(coef=5), ["r.json", "coef"]),
    ("coef-true", _result_case(coef={"a1": True}), ["r.json", "coef.'a1'", "number"]),
    ("coef-unknown-name", lambda tmp: _write_json(tmp, "r.json", {**_good_result(), "coef": {
        **_good_result()["coef"], "zz": 1.0}}), ["r.json", "zz"]),
    ("cov-string", _result_case(cov="abc"), ["r.json", "cov"]),
    ("cov-names-int", _result_case(cov={"names": 3, "matrix": []}), ["r.json", "cov.names"]),
    ("cov-matrix-shape", _result_case(cov={"names": ["c1", "c2"], "matrix": [[1.0]]}), ["r.json", "cov.matrix", "2x2"]),
    ("cov-names-not-coef", _result_case(cov={"names": ["q9"], "matrix": [[1.0]]}), ["r.json", "q9", "coef"]),
    ("model-options-list", _result_case(model_options=[1]), ["r.json", "model_options"]),
    ("model-options-bad", _result_case(model_options={"warp": 9}), ["r.json", "warp"]),
    ("inputs-string", _result_case(inputs="x"), ["r.json", "inputs"]),
    ("settings-list", _result_case(settings=[1]), ["r.json", "settings"]),
    ("coef-std-abc", _result_case(coef_std={"a1": "abc"}), ["r.json", "coef_std.'a1'", "number"]),
    ("warnings-string", _result_case(diagnostics={"warnings": "oops"}), ["r.json", "diagnostics.warnings", "list"]),
    ("success-no", _result_case(success="no"), ["r.json", "success", "true or false"]),
    ("model-list", _result_case(model=["mmg"]), ["r.json", "model", "string"]),
    ("model-missing", _result_case(model=_DROP), ["r.json", "model"]),
    ("loglik-string", _result_case(loglik="high"), ["r.json", "loglik"]),
    ("deep", lambda tmp: _write_json(tmp, "r.json", DEEP), ["r.json", "nested"]),
    ("not-json", lambda tmp: _write_json(tmp, "r.json", "{model: x"), ["r.json", "not valid JSON", "line 1"]),
    ("top-list", lambda tmp: _write_json(tmp, "r.json", "[1, 2]"), ["r.json", "top level"]),
    ("binary", lambda tmp: _write_bytes(tmp / "r.json", bytes(range(256)) * 4), ["r.json", "UTF-8"]),
]


def _snapshot(folder: Path) -> dict:
    return {p: p.read_bytes() for p in folder.rglob("*") if p.is_file()}


def _check(argv, folder: Path, needles, capsys, rc_expected: int = 2) -> str:
    """Run ``shipid argv`` and assert the hostile-input contract; returns the error line."""
    before = _snapshot(folder)
    rc = main([str(a) for a in argv])
    err = capsys.readouterr().err.strip()
    assert rc == rc_expected, err
    lines = err.splitlines()
    assert len(lines) == 1, err
    assert "Traceback" not in err and len(err) <= 300, err
    for n in needles:
        assert n in err, f"{n!r} not in: {err}"
    after = _snapshot(folder)
    assert after == before, f"files changed: {sorted(set(after) ^ set(before)) or 'contents'}"
    return err


@pytest.mark.parametrize("build,needles", [(b, n) for _, b, n in RESULT_CASES], ids=[c[0] for c in RESULT_CASES])
@pytest.mark.parametrize("command", ["simulate", "validate", "fit-params"])
def test_hostile_result_file(build, needles, command, tmp_path, capsys):
    r = build(tmp_path)
    argv = {"simulate": ["simulate", r, "--turning", "35", "-o", tmp_path / "t.csv"],
            "validate": ["validate", r, LOG, "-o", tmp_path / "v.json"],
            "fit-params": ["fit", LOG, "--params", r, "-o", tmp_path / "f.json", "--no-progress"]}[command]
    _check(argv, tmp_path, needles, capsys)
