"""Hostile input corpus: every file the CLI reads is treated as hostile.

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
            "fit-params": ["fit", LOG, "--model", r, "-o", tmp_path / "f.json", "--no-progress"]}[command]
    _check(argv, tmp_path, needles, capsys)


# --------------------------------------------------------------------------- PROBLEM.json (shipid plan)
def _problem(**changes) -> dict:
    doc = json.loads((REPO / "data" / "my_turn.json").read_text())
    for k, v in changes.items():
        if v is _DROP:
            doc.pop(k)
        else:
            doc[k] = v
    return doc


def _problem_case(**changes):
    return lambda tmp: _write_json(tmp, "p.json", _problem(**changes))


PROBLEM_CASES = [
    ("input-bounds-list", _problem_case(input_bounds=[1, 2]), ["p.json", "input_bounds", "object"]),
    ("input-bounds-pair", _problem_case(input_bounds={"delta": [1], "n": [5, 13]}), ["p.json", "input_bounds['delta']", "[lo, hi]"]),
    ("input-bounds-true", _problem_case(input_bounds={"delta": [True, 1], "n": [5, 13]}), ["p.json", "input_bounds['delta']", "number"]),
    ("final-time-soon", _problem_case(final_time="soon"), ["p.json", "final_time", "number"]),
    ("final-time-negative", _problem_case(final_time=-3), ["p.json", "final_time", "> 0"]),
    ("model-list", _problem_case(model=["kcs-response"]), ["p.json", "model", "string"]),
    ("model-unknown", _problem_case(model="boat"), ["p.json", "boat"]),
    ("params-int", _problem_case(params=3), ["p.json", "params"]),
    ("unknown-key", _problem_case(finaltime=3), ["p.json", "unknown key", "finaltime"]),
    ("x0-string", _problem_case(x0="fast"), ["p.json", "x0"]),
    ("x0-unknown-state", _problem_case(x0={"w": 1.0}), ["p.json", "w"]),
    ("terminal-string", _problem_case(terminal={"psi": "north"}), ["p.json", "terminal['psi']", "number"]),
    ("rate-negative", _problem_case(input_rate_bounds={"delta": -1}), ["p.json", "input_rate_bounds['delta']", "> 0"]),
    ("intervals-1e9", _problem_case(n_intervals=1_000_000_000), ["p.json", "n_intervals", "GiB"]),
    ("intervals-ten", _problem_case(n_intervals="ten"), ["p.json", "n_intervals", "number"]),
    ("intervals-half", _problem_case(n_intervals=10.5), ["p.json", "n_intervals", "whole number"]),
    ("substeps-0", _problem_case(substeps=0), ["p.json", "substeps", ">= 1"]),
    ("tf-bounds-string", _problem_case(tf_bounds="wide"), ["p.json", "tf_bounds"]),
    ("tf-bounds-order", _problem_case(tf_bounds=[600, 1]), ["p.json", "tf_bounds"]),
    ("model-options-list", _problem_case(model_options=[1]), ["p.json", "model_options"]),
    ("fit-result-missing", _problem_case(model=_DROP, params=_DROP, fit_result="nothere.json"), ["p.json", "nothere.json"]),
    ("fit-result-bad", lambda tmp: (_write_json(tmp, "fr.json", {"model": "kcs-response", "coef": []}),
                                    _write_json(tmp, "p.json", _problem(model=_DROP, params=_DROP, fit_result="fr.json")))[1],
     ["fr.json", "coef"]),
    ("u-guess-string", _problem_case(u_guess="middle"), ["p.json", "u_guess"]),
    ("deep", lambda tmp: _write_json(tmp, "p.json", DEEP), ["p.json", "nested"]),
    ("not-json", lambda tmp: _write_json(tmp, "p.json", "{"), ["p.json", "not valid JSON"]),
    ("u-guess-shape", _problem_case(u_guess=[1, 2, 3]), ["p.json", "u_guess", "shape"]),
    ("model-options-string", _problem_case(model="mmg", params="kvlcc2", model_options={"lpp": "big"}),
     ["p.json", "model_options", "number"]),
    ("state-bounds-order", _problem_case(state_bounds={"r": [0.2, -0.2]}), ["p.json", "state_bounds['r']", "lo <= hi"]),
    ("fit-result-deep", lambda tmp: (_write_json(tmp, "fr.json", DEEP),
                                     _write_json(tmp, "p.json", _problem(model=_DROP, params=_DROP, fit_result="fr.json")))[1],
     ["fr.json", "nested"]),
]


@pytest.mark.parametrize("build,needles", [(b, n) for _, b, n in PROBLEM_CASES], ids=[c[0] for c in PROBLEM_CASES])
def test_hostile_problem_file(build, needles, tmp_path, capsys):
    p = build(tmp_path)
    _check(["plan", p, "-o", tmp_path / "plan.json"], tmp_path, needles, capsys)


def test_plan_intervals_option_bounded_by_memory(tmp_path, capsys):
    _check(["plan", "paper-2", "--intervals", "1000000000", "-o", tmp_path / "plan.json"], tmp_path,
           ["n_intervals 1000000000", "GiB", "fewer"], capsys)


def test_indirect_at_iteration_limit_is_not_success():
    from shipid.control import paper_problem, solve_indirect

    res = solve_indirect(paper_problem(1, n_intervals=8, substeps=2), max_iter=2, n_penalty=2)
    assert not res.success and res.status in (1, 2)
    assert "iteration limit" in res.message


# --------------------------------------------------------------------------- routing problems (shipid route)
def _pso(**changes) -> dict:
    doc = {"type": "pso", "start": [0, 0], "goal": [0, -300],
           "obstacles": [{"x": 10, "y": -80, "radius": 20}, {"x": -12, "y": -160, "radius": 25}],
           "current": {"type": "uniform", "speed": 0.5, "direction_deg": 90}, "n_particles": 6, "max_iter": 5}
    for k, v in changes.items():
        if v is _DROP:
            doc.pop(k)
        else:
            doc[k] = v
    return doc


def _zermelo(**changes) -> dict:
    doc = {"type": "zermelo", "speed": 1.0, "start": [0, 0], "target": [1000, 500],
           "current": {"type": "uniform", "velocity": [0.2, 0.0]}, "solver": "pmp"}
    doc.update(changes)
    return doc


def _route_case(doc):
    return lambda tmp: _write_json(tmp, "q.json", doc)


ROUTE_CASES = [
    ("unknown-key", _route_case(_pso(replan_time=[10])), ["q.json", "unknown key", "replan_time"]),
    ("max-iter-negative", _route_case(_pso(max_iter=-1)), ["q.json", "max_iter", ">= 1"]),
    ("n-particles-1e8", _route_case(_pso(n_particles=100_000_000)), ["q.json", "n_particles", "GiB"]),
    ("n-particles-true", _route_case(_pso(n_particles=True)), ["q.json", "n_particles", "number"]),
    ("r-min-negative", _route_case(_pso(r_min=-15)), ["q.json", "r_min", ">= 0"]),
    ("obstacles-int", _route_case(_pso(obstacles=5)), ["q.json", "obstacles", "list"]),
    ("obstacle-unknown-key", _route_case(_pso(obstacles=[{"x": 1, "y": -80, "r": 3}])), ["q.json", "obstacles[0]", "'r'"]),
    ("obstacle-radius-negative", _route_case(_pso(obstacles=[{"x": 1, "y": -80, "radius": -3}])), ["q.json", "radius", "> 0"]),
    ("vessel-string", _route_case(_pso(vessel="paper")), ["q.json", "vessel", "object"]),
    ("vessel-unknown-key", _route_case(_pso(vessel={"type": "paper", "power": 3})), ["q.json", "vessel", "power"]),
    ("replan-times-string", _route_case(_pso(replan_times="often")), ["q.json", "replan_times", "list"]),
    ("replan-times-order", _route_case(_pso(replan_times=[50, 10])), ["q.json", "replan_times", "increase"]),
    ("kinematics", _route_case(_pso(kinematics="walk")), ["q.json", "kinematics"]),
    ("start-string", _route_case(_pso(start="here")), ["q.json", "start", "2 numbers"]),
    ("field-unknown-key", _route_case(_pso(current={"type": "uniform", "speed": 1, "direction": 90})), ["q.json", "current", "direction"]),
    ("field-type", _route_case(_pso(current={"type": "tidal"})), ["q.json", "current.type", "tidal"]),
    ("field-speed-string", _route_case(_pso(current={"type": "uniform", "speed": "fast", "direction_deg": 0})), ["q.json", "current.speed", "number"]),
    ("grid-csv-missing", _route_case(_zermelo(current={"type": "grid_csv", "path": "nothere.csv"})), ["q.json", "nothere.csv"]),
    ("grid-csv-columns", lambda tmp: ((tmp / "c.csv").write_text("a,b\n1,2\n"),
                                      _write_json(tmp, "q.json", _zermelo(current={"type": "grid_csv", "path": "c.csv"})))[1],
     ["c.csv", "column"]),
    ("zermelo-solver", _route_case(_zermelo(solver="fast")), ["q.json", "solver"]),
    ("zermelo-n-huge", _route_case(_zermelo(n=10**9)), ["q.json", "n", "<= 100000"]),
    ("zermelo-speed-zero", _route_case(_zermelo(speed=0)), ["q.json", "speed", "> 0"]),
    ("type-missing", _route_case({"speed": 1}), ["q.json", "'type'"]),
    ("deep", lambda tmp: _write_json(tmp, "q.json", DEEP), ["q.json", "nested"]),
]


@pytest.mark.parametrize("build,needles", [(b, n) for _, b, n in ROUTE_CASES], ids=[c[0] for c in ROUTE_CASES])
def test_hostile_route_file(build, needles, tmp_path, capsys):
    q = build(tmp_path)
    _check(["route", q, "-o", tmp_path / "route.json"], tmp_path, needles, capsys)


def test_route_replan_times_are_used(tmp_path, capsys):
    q = _write_json(tmp_path, "q.json", _pso(replan_times=[20.0, 60.0]))
    main(["route", str(q), "-o", str(tmp_path / "r.json")])
    doc = json.loads((tmp_path / "r.json").read_text())
    assert [e["time"] for e in doc["replanning"]] == [20.0, 60.0]


def test_route_pso_paper_says_what_the_default_is():
    from shipid.commands.route import PSO_FRAMING, PSO_PAPER_NOTE

    assert "worst of the 64" in PSO_FRAMING and "10.37" in PSO_FRAMING and PSO_FRAMING[:20].lower() in PSO_PAPER_NOTE.lower()


# --------------------------------------------------------------------------- sizes and options of other commands
OPTION_CASES = [
    ("glider-dt-1e-9", ["glider", "launch", "--speed", "5", "--angle", "45", "--dt", "1e-9", "-o", "{tmp}/g.json"],
     ["dt 1e-09", "GiB", "--dt"]),
    ("glider-speed-nan", ["glider", "launch", "--speed", "nan", "--angle", "45", "-o", "{tmp}/g.json"], ["--speed nan"]),
    ("glider-popsize", ["glider", "optimise", "--popsize", "100000", "-o", "{tmp}/g.json"], ["--popsize 100000"]),
    ("glider-params-bad", ["glider", "launch", "--speed", "5", "--angle", "45", "--model", "{tmp}/r.json", "-o",
                           "{tmp}/g.json"], ["r.json"]),
    ("route-seed-negative", ["route", "paper-pso", "--seed", "-3", "-o", "{tmp}/ps.json"], ["--seed -3"]),
    ("validate-output-is-log", ["validate", "{tmp}/r.json", "{log}", "-o", "{log}", "--force"], ["would replace"]),
    ("plan-output-is-problem", ["plan", "{tmp}/p.json", "-o", "{tmp}/p.json", "--force"], ["would replace"]),
    ("route-output-exists", ["route", "paper-zermelo", "-o", "{tmp}/old.json"], ["old.json", "--force"]),
    ("route-csv-exists", ["route", "paper-zermelo", "-o", "{tmp}/old2.json"], ["old2.csv", "--force"]),
    ("ship-file-deep", ["fit", "{log}", "--ship", "{tmp}/deep.json", "-o", "{tmp}/f.json"], ["deep.json"]),
    ("fit-log-fifo", ["fit", "{tmp}/fifo.csv", "-o", "{tmp}/f.json"], ["fifo.csv"]),
]


@pytest.mark.parametrize("argv,needles", [(a, n) for _, a, n in OPTION_CASES], ids=[c[0] for c in OPTION_CASES])
def test_hostile_options(argv, needles, tmp_path, capsys):
    _write_json(tmp_path, "r.json", {"model": "kcs-response", "coef": []})
    _write_json(tmp_path, "p.json", _problem())
    _write_json(tmp_path, "deep.json", DEEP)
    (tmp_path / "old.json").write_text("{}")
    (tmp_path / "old2.csv").write_text("keep\n")
    log = tmp_path / "log.csv"
    log.write_bytes(LOG.read_bytes())
    if "fifo" in " ".join(argv):
        if not hasattr(os, "mkfifo"):
            pytest.skip("no FIFOs on this platform")
        os.mkfifo(tmp_path / "fifo.csv")
        pytest.skip("reading a FIFO as a log is helper `logs`' item (shipid/logs.py); see the report")
    argv = [a.format(tmp=tmp_path, log=log) for a in argv]
    _check(argv, tmp_path, needles, capsys)


# --------------------------------------------------------------------------- the write side
#: Load shipid/_io.py alone in a child process (it needs only numpy): fast start-up for the process tests.
_LOAD_IO = ("import sys, importlib.util\n"
            f"spec = importlib.util.spec_from_file_location('shipid_io', {str(REPO / 'shipid' / '_io.py')!r})\n"
            "_io = importlib.util.module_from_spec(spec)\nspec.loader.exec_module(_io)\n")


def test_no_clobber_is_atomic_between_racing_writers(tmp_path):
    """Two writers that both passed an 'exists' check: exactly one wins, the other is told."""
    target = tmp_path / "out.json"
    tmp_a, tmp_b = _io._tmp_for(target), _io._tmp_for(target)  # both prepared before either publishes
    _io._fill(tmp_a, b"A")
    _io._fill(tmp_b, b"B")
    _io._publish(tmp_a, target, force=False)
    with pytest.raises(_io.OutputExistsError, match="output exists"):
        _io._publish(tmp_b, target, force=False)
    _io._drop(tmp_b)
    assert target.read_bytes() == b"A" and sorted(p.name for p in tmp_path.iterdir()) == ["out.json"]


def test_racing_processes_lose_no_result_silently(tmp_path):
    code = (_LOAD_IO + "try:\n    _io.atomic_write_text(sys.argv[1], sys.argv[2] * 2_000_000)\n"
            "except _io.OutputExistsError:\n    sys.exit(3)\n")
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    target = tmp_path / "r.txt"
    procs = [subprocess.Popen([sys.executable, "-c", code, str(target), c], env=env) for c in "abcd"]
    codes = [p.wait(60) for p in procs]
    assert sorted(codes) == [0, 3, 3, 3], codes
    text = target.read_text()
    assert len(set(text)) == 1 and len(text) == 2_000_000
    assert [p.name for p in tmp_path.iterdir()] == ["r.txt"]


def test_file_set_is_rolled_back_when_a_member_exists(tmp_path):
    (tmp_path / "b.json").write_text("old")
    with pytest.raises(_io.OutputExistsError):
        _io.atomic_write_set([(tmp_path / "a.csv", "x"), (tmp_path / "b.json", "y")])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["b.json"] and (tmp_path / "b.json").read_text() == "old"
    # the exists check happens first; a member appearing between the links is rolled back too
    orig = _io._publish

    def racing(tmp, path, force):
        if path.name == "d.json":
            path.write_text("someone else")
        return orig(tmp, path, force)

    _io._publish = racing
    try:
        with pytest.raises(_io.OutputExistsError):
            _io.atomic_write_set([(tmp_path / "c.csv", "x"), (tmp_path / "d.json", "y")])
    finally:
        _io._publish = orig
    assert sorted(p.name for p in tmp_path.iterdir()) == ["b.json", "d.json"]
    assert (tmp_path / "d.json").read_text() == "someone else"


def test_strict_json_writer():
    text = _io.dumps_json({"loglik": float("nan"), "a": np.float32(1.5), "b": np.arange(2), "c": [np.inf, True]})
    assert json.loads(text, parse_constant=lambda c: pytest.fail(f"non-strict token {c}")) == \
        {"loglik": None, "a": 1.5, "b": [0, 1], "c": [None, True]}


def test_fit_result_with_nan_loglik_is_strict_json(tmp_path):
    from shipid.identify.result import FitResult, load_result

    doc = {**_good_result(), "loglik": None}
    res = FitResult.from_dict(doc)
    res.loglik = float("nan")
    res.coef_std["a1"] = float("nan")
    res.to_json(tmp_path / "r.json")
    text = (tmp_path / "r.json").read_text()
    assert "NaN" not in text and json.loads(text)["loglik"] is None
    back = load_result(tmp_path / "r.json")
    assert back.loglik is None and np.isnan(back.coef_std["a1"])


def test_sigterm_removes_temporary_files(tmp_path):
    """A run killed by SIGTERM while writing leaves no hidden .tmp file (SIGKILL cannot be caught)."""
    code = (_LOAD_IO + "import time\n_io.install_signal_cleanup()\n"
            "orig = _io._fill\n"
            "def slow(tmp, data):\n    orig(tmp, data)\n    print('written', flush=True)\n    time.sleep(60)\n"
            "_io._fill = slow\n_io.atomic_write_text(sys.argv[1], 'x' * 10_000_000)\n")
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    p = subprocess.Popen([sys.executable, "-c", code, str(tmp_path / "big.csv")], env=env, stdout=subprocess.PIPE, text=True)
    assert p.stdout.readline().strip() == "written"
    assert any(f.name.endswith(".tmp") for f in tmp_path.iterdir())
    p.send_signal(signal.SIGTERM)
    assert p.wait(30) == 128 + signal.SIGTERM
    assert list(tmp_path.iterdir()) == []


def test_output_folder_checked_before_the_computation(tmp_path, capsys, monkeypatch):
    import shipid.control as control

    folder = tmp_path / "ro"
    folder.mkdir()
    real_access = os.access
    monkeypatch.setattr(_io.os, "access", lambda p, mode: False if Path(p) == folder else real_access(p, mode))
    monkeypatch.setattr(control, "solve_direct", lambda *a, **k: pytest.fail("solved before checking the output"))
    _check(["plan", "paper-2", "-o", folder / "plan.json"], tmp_path, ["ro", "not writable"], capsys)


def test_unwritable_folder_is_one_line_without_tmp_name(tmp_path, monkeypatch):
    monkeypatch.setattr(_io.tempfile, "mkstemp", lambda **kw: (_ for _ in ()).throw(PermissionError(13, "Permission denied", ".r.json.x.tmp")))
    with pytest.raises(PermissionError, match="cannot write in folder") as e:
        _io.atomic_write_text(tmp_path / "r.json", "x")
    assert ".tmp" not in str(e.value)


@pytest.mark.parametrize("argv,needles", [
    (["fit", "{log}", "--passes", "9" * 300, "-o", "{tmp}/f.json"], ["--passes 1e+300", "1 to 100"]),
    (["plan", "paper-1", "--intervals", "9" * 300, "-o", "{tmp}/p.json"], ["GiB"]),
], ids=["passes-300-digits", "intervals-300-digits"])
def test_huge_numbers_are_not_echoed(argv, needles, tmp_path, capsys):
    log = tmp_path / "log.csv"
    log.write_bytes(LOG.read_bytes())
    err = _check([a.format(tmp=tmp_path, log=log) for a in argv], tmp_path, needles, capsys)
    assert "9" * 30 not in err


def test_json_integer_with_300_digits_is_not_echoed(tmp_path, capsys):
    p = _write_json(tmp_path, "p.json", json.dumps(_problem()).replace('"n_intervals": 12', '"n_intervals": ' + "9" * 300))
    err = _check(["plan", p, "-o", tmp_path / "plan.json"], tmp_path, ["p.json", "n_intervals"], capsys)
    assert "9" * 30 not in err


def test_deep_yaml_and_json_are_refused_in_one_line():
    pytest.importorskip("yaml")
    for text in ("[" * 100_000 + "]" * 100_000, "a:\n" + "".join("  " * i + f"k{i}:\n" for i in range(1, 200)) + "  " * 200 + "v: 1\n"):
        with pytest.raises(ValueError, match="ship.yaml: nested more than 64 levels") as e:
            _io.loads_yaml(text, "ship.yaml")
        assert len(str(e.value)) < 120
    with pytest.raises(ValueError, match="x.json: nested more than 64 levels"):
        _io.loads_json("[" * 100_000 + "]" * 100_000, "x.json")
    with pytest.raises(ValueError, match="x.json: nested more than 64 levels"):
        _io.loads_json("[" * 70 + "]" * 70, "x.json")
    assert _io.loads_yaml("lpp: 4.36\nname: kcs\n", "ship.yaml") == {"lpp": 4.36, "name": "kcs"}
    with pytest.raises(ValueError, match="ship.yaml: not valid YAML .* line 2"):
        _io.loads_yaml("a: [1, 2\n", "ship.yaml")


def test_cli_restores_the_signal_handlers(tmp_path):
    before = signal.getsignal(signal.SIGTERM)
    main(["models"])
    assert signal.getsignal(signal.SIGTERM) is before


# --------------------------------------------------------------------------- outputs are regular files
def _special(kind: str, p: Path) -> bool:
    """Make ``p`` a FIFO, a character device (a private copy of /dev/null; root only) or a socket."""
    import socket
    import stat

    if kind == "fifo":
        os.mkfifo(p)
    elif kind == "device":
        try:
            os.mknod(p, 0o666 | stat.S_IFCHR, os.makedev(1, 3))
        except (PermissionError, AttributeError):
            return False
    else:
        s = socket.socket(socket.AF_UNIX)
        s.bind(str(p))
        s.close()
    return True


_KIND_WORDS = {"fifo": "a FIFO (named pipe)", "device": "a character device", "socket": "a socket"}


@pytest.mark.parametrize("kind", ["fifo", "device", "socket"])
@pytest.mark.parametrize("command", ["fit", "validate", "report", "simulate", "sample", "log", "metrics", "sweep",
                                     "plan", "route", "glider"])
def test_output_naming_a_device_pipe_or_socket_is_refused_even_with_force(kind, command, tmp_path, capsys):
    import stat

    out = tmp_path / ("X.json" if command in ("plan", "route") else "X")
    if not hasattr(os, "mkfifo") or not _special(kind, out):
        pytest.skip(f"cannot make a {kind} here")
    mode = os.lstat(out).st_mode
    r = tmp_path / "r.json"
    r.write_text(json.dumps(_good_result()))
    argv = {"fit": ["fit", LOG], "validate": ["validate", r, LOG], "report": ["report", r, LOG],
            "simulate": ["simulate", "kcs-response:synthetic-truth", "--turning", "35"],
            "sample": ["sample", r, LOG, "--steps", "10"], "log": ["log", LOG], "metrics": ["metrics", LOG],
            "sweep": ["sweep", "kcs-response:synthetic-truth", "--rudder", "35"],
            "plan": ["plan", "paper-1"], "route": ["route", "paper-zermelo"],
            "glider": ["glider", "launch", "--speed", "1", "--angle", "45"]}[command]
    rc = main([str(a) for a in argv] + ["-o", str(out), "--force"])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and "Traceback" not in err and len(err.splitlines()) == 1, err
    assert f"{out.name}: is {_KIND_WORDS[kind]}; the " in err and "written as a regular file only" in err, err
    assert stat.S_IFMT(os.lstat(out).st_mode) == stat.S_IFMT(mode)


def test_force_replaces_a_links_own_entry_never_its_target(tmp_path):
    target = tmp_path / "target.json"
    target.write_text("keep")
    link = tmp_path / "out.json"
    link.symlink_to(target)
    with pytest.raises(_io.OutputExistsError):
        _io.atomic_write_text(link, "new")
    _io.atomic_write_text(link, "new", force=True)
    assert not link.is_symlink() and link.read_text() == "new" and target.read_text() == "keep"


def test_writers_refuse_a_special_file_appearing_at_the_last_moment(tmp_path):
    p = tmp_path / "late.json"
    os.mkfifo(p)
    with pytest.raises(ValueError, match="late.json: is a FIFO"):
        _io.atomic_write_set([(tmp_path / "a.json", "{}"), (p, "{}")], force=True)
    assert not (tmp_path / "a.json").exists() and not list(tmp_path.glob(".*.tmp"))


# --------------------------------------------------------------------------- bounded structured files
BOMB = "".join(f"{a}: &{a} [" + ", ".join([f"*{p}" if p else "x"] * 9) + "]\n"
               for a, p in zip("abcdefghi", [None, *"abcdefgh"]))


def test_yaml_alias_bomb_is_refused_without_expanding_it():
    with pytest.raises(ValueError) as e:  # counted from the parse events (9 x 9 aliases), never expanded
        _io.loads_yaml(BOMB, "c.yaml", "campaign")
    assert str(e.value) == ("c.yaml: its aliases expand to more than 1e+06 nodes, the limit; write the campaign "
                            "without aliases")


def test_yaml_alias_limits():
    few = "base: &b {passes: 1}\nfits:\n  - {name: a, defaults: *b}\n  - {name: c, defaults: *b}\n"
    assert _io.loads_yaml(few, "c.yaml")["fits"][1]["defaults"] == {"passes": 1}
    many = "a: &a 1\nb: [" + ", ".join(["*a"] * (_io.MAX_ALIASES + 1)) + "]\n"
    with pytest.raises(ValueError, match=rf"c.yaml: more than {_io.MAX_ALIASES} YAML aliases \(\*name\)"):
        _io.loads_yaml(many, "c.yaml")
    deep = "a: &a " + "[" * 40 + "1" + "]" * 40 + "\nb: " + "[" * 40 + "*a" + "]" * 40 + "\n"
    with pytest.raises(ValueError, match="c.yaml: nested more than 64 levels deep"):
        _io.loads_yaml(deep, "c.yaml")  # 41 + 41 levels once the alias is expanded; each part alone is fine
    with pytest.raises(ValueError, match="c.yaml: YAML alias \\*a refers to a node that contains it"):
        _io.loads_yaml("a: &a [1, *a]\n", "c.yaml")


@pytest.mark.parametrize("name, what", [("c.yaml", "campaign"), ("c.json", "campaign"), ("r.json", "result")])
def test_a_huge_sparse_file_is_refused_before_it_is_read(tmp_path, name, what):
    p = tmp_path / name
    with open(p, "wb") as fh:
        fh.truncate(2**30)
    with pytest.raises(ValueError, match=rf"{name}: .* MiB is too large for a {what}"):
        _io.read_structured(p, what)


def test_campaign_yaml_bomb_from_the_cli(tmp_path, capsys):
    p = tmp_path / "c.yaml"
    p.write_text("fits:\n  - name: m1\n    logs: [x.csv]\n    fixed:\n" + "".join("      " + ln + "\n" for ln in BOMB.splitlines()))
    assert main(["campaign", str(p), "-o", str(tmp_path / "out")]) == 2
    assert "its aliases expand to more than 1e+06 nodes, the limit" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


# --------------------------------------------------------------------------- the library's entry points
def test_public_entry_points_check_their_arguments():
    from shipid.identify import EKFIdentifier
    from shipid.simulate import simulate
    from shipid.validation import validate

    m = get_model("kcs-response", "synthetic-truth")
    t = np.arange(0, 10, 0.1)
    U = np.zeros((t.size, 2)) + [0.0, 9.0]
    with pytest.raises(ValueError, match=r"substeps must be a whole number >= 1 .*got 0"):
        validate(m, [str(LOG)], substeps=0)
    with pytest.raises(ValueError, match=r"x0 must be the initial state, shape \(6,\) .*got None"):
        simulate(m, None, t, U)
    with pytest.raises(TypeError, match=r"model must be a model object .*got str 'kcs-response'; build it with "
                                        r"shipid.models.get_model\('kcs-response'\)"):
        EKFIdentifier("kcs-response")
    bad_t = t.copy()
    bad_t[5] = np.nan
    with pytest.raises(ValueError, match=r"t must be finite; t\[5\] = nan"):
        simulate(m, [0, 0, 0, 1.7, 0, 0], bad_t, U)
    with pytest.raises(ValueError, match=r"x0 must be finite; x0\[3\] \('u'\) = inf"):
        simulate(m, [0, 0, 0, np.inf, 0, 0], t, U)


def test_a_batch_member_that_goes_non_finite_is_flagged():
    from shipid.simulate import simulate

    m = get_model("kcs-response", "synthetic-truth")
    t = np.arange(0, 10, 0.1)
    x0 = np.array([[0, 0, 0, 1.7, 0, 0], [0, 0, 0, np.inf, 0, 0]], float)
    with pytest.warns(RuntimeWarning, match="non-finite in 1 of 2 batch member"):
        r = simulate(m, x0, t, np.zeros((t.size, 2)) + [0.0, 9.0])
    assert not r.success and r.meta["failed"] == [1] and np.isfinite(r.x[0]).all()


def test_sample_refuses_a_thinning_that_keeps_too_few_steps_and_a_run_beyond_memory(tmp_path, capsys):
    r = tmp_path / "r.json"
    assert main(["fit", str(LOG), "-o", str(r), "--passes", "1"]) in (0, 3)
    capsys.readouterr()
    rc = main(["sample", str(r), str(LOG), "-o", str(tmp_path / "s.json"), "--thin", "1000", "--steps", "30"])
    err = capsys.readouterr().err
    assert rc == 2 and "thin=1000: keeps 1 of the 20 steps after burn-in" in err and "(--thin)" in err
    rc = main(["sample", str(r), str(LOG), "-o", str(tmp_path / "s.json"), "--walkers", "1000000000", "--steps", "30"])
    err = capsys.readouterr().err
    assert rc == 2 and "sampling with walkers=1000000000 x steps=30 needs about" in err and "--walkers" in err
    assert not (tmp_path / "s.json").exists()


@pytest.mark.slow
def test_ctrl_c_during_sample_is_one_line(tmp_path):
    """SIGINT while the walkers run: 'shipid: interrupted', exit 130, no traceback (emcee prints one for any
    exception inside the likelihood, so the interrupt is taken between steps)."""
    import subprocess
    import sys
    import time

    r = tmp_path / "r.json"
    assert main(["fit", str(LOG), "-o", str(r), "--passes", "1"]) in (0, 3)
    proc = subprocess.Popen([sys.executable, "-m", "shipid", "sample", str(r), str(LOG), "-o", str(tmp_path / "s.json"),
                             "--steps", "100000"], cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    time.sleep(12.0)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130 and "Traceback" not in err and err.strip().endswith("shipid: interrupted"), err[-500:]
    assert not (tmp_path / "s.json").exists() and not list(tmp_path.glob(".*.tmp"))
