"""Nothing silent for long: a stage line as each long stage starts (output not a terminal), progress bars on
request, and ``--quiet`` leaves the results alone on stdout."""
from __future__ import annotations

import json

import numpy as np
import pytest

from shipid import _jit
from shipid.cli import main
from shipid.datasets import bundled_kcs_logs

SRC = {p.stem: p for p in bundled_kcs_logs()}
FIT = ["fit", str(SRC["kcs_tc_p35"]), str(SRC["kcs_zz_m10"]), "--model", "kcs-response", "--lpp", "4.36",
       "--passes", "1", "--refine", "none"]


def test_fit_says_each_stage_as_it_starts(tmp_path, capsys):
    out = tmp_path / "r.json"
    assert main([*FIT, "-o", str(out)]) == 0
    cap = capsys.readouterr()
    lines = cap.out.splitlines()
    start = next(i for i, ln in enumerate(lines) if ln.startswith("recipe: running the EKF: 1 pass(es) over 2 log(s)"))
    done = next(i for i, ln in enumerate(lines) if ln.startswith("recipe: EKF: "))
    assert start < done  # said before the filter runs, not only after
    assert "\r" not in cap.err and "EKF passes" not in cap.err  # stderr is not a terminal: no bars


def test_fit_quiet_prints_only_the_results(tmp_path, capsys):
    out = tmp_path / "r.json"
    assert main([*FIT, "-o", str(out), "--quiet"]) == 0
    cap = capsys.readouterr()
    assert not [ln for ln in cap.out.splitlines() if ln.startswith("recipe:")]
    assert cap.out.startswith("model kcs-response (ekf): ")  # the coefficient table comes first
    assert f"wrote {out}" in cap.out.splitlines()  # results: the table, what was written, the verdict
    assert "compiling" not in cap.err and "\r" not in cap.err
    assert json.loads(out.read_text())["model"] == "kcs-response"


def test_fit_progress_bars_on_request(tmp_path, capsys):
    out = tmp_path / "r.json"
    assert main([*FIT, "-o", str(out), "--progress"]) == 0
    assert "EKF passes" in capsys.readouterr().err


def test_validate_says_its_stages(tmp_path, capsys):
    res = tmp_path / "r.json"
    assert main([*FIT, "-o", str(res), "--quiet"]) == 0
    capsys.readouterr()
    v = tmp_path / "v.json"
    assert main(["validate", str(res), str(SRC["kcs_zz_m10"]), "-o", str(v), "--horizon", "10"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert "replaying logs (1) ..." in lines
    assert "open-loop predictions over 10 s, logs (1) ..." in lines
    assert main(["validate", str(res), str(SRC["kcs_zz_m10"]), "-o", str(v), "--horizon", "10", "--force",
                 "--quiet"]) == 0
    assert not [ln for ln in capsys.readouterr().out.splitlines() if ln.endswith("...")]


def test_refinement_bar_counts_replays(capsys):
    from shipid.identify.batch import OutputErrorRefiner
    from shipid.logs import read_log
    from shipid.models import get_model

    lg = read_log(SRC["kcs_zz_m10"], lpp=4.36)
    ref = OutputErrorRefiner(get_model("kcs-response", "synthetic-truth"), estimate=["c2", "c3"], max_nfev=2,
                             progress=True).fit([lg])
    assert np.isfinite(ref.cost_)
    assert "output-error refinement" in capsys.readouterr().err


def test_compile_notice_once_and_only_when_compiling(monkeypatch):
    said = []
    monkeypatch.setattr(_jit, "_said", set())
    _jit.set_notices(said.append)
    try:
        class Compiled:  # already compiled in this process: nothing to say
            signatures = [("float64",)]
        assert _jit.compile_notice(Compiled(), "x") is False

        class Fresh:  # not compiled, no disk cache (numba's layout): said once
            signatures = []

            class _cache:
                class _cache_file:
                    _index_path = "/nonexistent/shipid-test.nbi"
        assert _jit.compile_notice(Fresh(), "the test filter", seconds=12) is True
        assert _jit.compile_notice(Fresh(), "the test filter") is False
        assert said == ["compiling the test filter (first run only, about 12 s; cached for later runs)"]
    finally:
        _jit.set_notices(None)


def test_version_names_the_active_path(capsys):
    with pytest.raises(SystemExit):
        main(["--version"])
    out = capsys.readouterr().out.strip()
    assert out.startswith("shipid ") and ("(compiled path: numba " in out or "(numpy path: " in out)
    assert ("compiled path" in out) == _jit.enabled()
