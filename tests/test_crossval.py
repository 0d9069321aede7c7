"""Cross-validation over runs and model choice (shipid.crossval, shipid crossval, shipid fit --model auto)."""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

import shipid
from shipid import crossval as cvm
from shipid.logs import TrialLog, read_log

REPO = Path(__file__).resolve().parents[1]
KCS = sorted(str(p) for p in (REPO / "data").glob("kcs_*.csv"))
ESSO_DIR = REPO.parent / "shared" / "data" / "esso_osaka_frt"
MARIN_DIR = REPO.parent / "shared" / "data" / "kvlcc2_marin"
#: The cheap setting of the default-suite cross-validations: the EKF stage only.
CHEAP = {"refine": None}


def _trimmed(log, start, stop, name):
    return TrialLog(log.data.iloc[start:stop].reset_index(drop=True), name=name, ship=log.ship, path=log.path,
                    sha256=log.sha256, rows=log.rows[start:stop], units_in=log.units_in, fmt=log.fmt)


@pytest.fixture(scope="module")
def kcs_cv():
    """kcs-response (which made the bundled logs) cross-validated on them, 2 folds, EKF stage only.  The logs
    were made by this model, so it holds beyond the small-drift range the recipe keeps for measured runs
    (``max_drift_deg=None``: the turning logs are used whole)."""
    return shipid.cross_validate(KCS, "kcs-response", folds=2, lpp=4.36,
                                 fit_options={**CHEAP, "max_drift_deg": None})


def test_copies_are_left_out_and_overlapping_runs_share_a_fold():
    logs = [read_log(p) for p in KCS]
    zz = logs[2]
    n = len(zz.data)
    copy = _trimmed(zz, 10, n // 2, "copy_of_zz")
    a, b = _trimmed(logs[0], 0, 700, "seg_a"), _trimmed(logs[0], 500, None, "seg_b")
    groups, copies = cvm.fold_groups([a, logs[1], zz, b, copy])
    assert [c["log"] for c in copies] == ["copy_of_zz"] and copies[0]["in"] == zz.name
    assert groups == [[0, 3], [1], [2]]  # the two overlapping segments of one run stay together
    assert cvm.assign_folds(3) == [0, 1, 2]
    assert cvm.assign_folds(5, 2) == [0, 1, 0, 1, 0]
    with pytest.raises(ValueError, match="folds=7"):
        cvm.assign_folds(3, 7)


def test_score_rule_on_known_numbers():
    """The rule of docs/choosing_a_model.md on hand-computed cases."""
    turn = {"run": "t", "lpp": 100.0, "measured": {"tactical_diameter_pct": 3.0}, "errors": {"tactical_diameter_pct": -7.5},
            "horizons": [{"seconds": 30.0, "n_starts": 4, "position_error_median_m": 5.0}]}
    zz = {"run": "z", "lpp": 100.0, "measured": {"overshoot1_deg": 9.0, "overshoot2_deg": 12.0},
          "errors": {"overshoot1_deg": 1.0, "overshoot2_deg": None}, "horizons": []}
    far = {"run": "f", "lpp": 100.0, "measured": {"overshoot1_deg": 9.0}, "errors": {"overshoot1_deg": 50.0},
           "horizons": [{"seconds": 30.0, "n_starts": 4, "position_error_median_m": None}]}  # > half blew up
    s = cvm.score_runs([turn, zz, far], failed_runs=["g"])
    assert s["runs"]["t"] == pytest.approx((7.5 / 5 + 5.0 / 10.0) / 2)       # 1.5 and 0.5
    assert s["runs"]["z"] == pytest.approx((1.0 / 2 + cvm.CAP) / 2)          # a missing prediction counts CAP
    assert s["runs"]["f"] == pytest.approx(cvm.CAP)                           # capped, and blown-up median
    assert s["runs"]["g"] == cvm.CAP                                          # a failed fold
    assert s["score"] == pytest.approx(np.mean([1.0, 5.25, 10.0, 10.0]))
    assert s["worst"] == cvm.CAP and s["worst_run"] in ("f", "g")


def test_cross_validation_of_the_true_model_is_accurate(kcs_cv):
    """The logs were made by kcs-response (known truth): fitted on the other runs it predicts each left-out
    run's closed-loop metrics to well inside the goals, every run predicted, no blow-up."""
    cv = kcs_cv
    assert cv.success, cv.message
    assert sorted(r["run"] for r in cv.runs) == sorted(Path(p).stem for p in KCS)
    for f in cv.folds:  # a left-out run never enters its fold's fit
        assert not set(f["left_out"]) & set(f["train"])
    s = cv.summary()
    assert s.loc["tactical_diameter_pct", "n"] == 2 and s.loc["overshoot1_deg", "n"] == 2
    assert s.loc["tactical_diameter_pct", "median"] < 2.0          # goal 5 %
    assert s.loc["overshoot1_deg", "median"] < 1.0                 # goal 2 deg
    assert s.loc["blowups", "worst"] == 0 and s.loc["failed_folds", "worst"] == 0
    assert cv.score["score"] < 0.5
    d = json.loads(json.dumps(cv.to_dict()))
    assert d["success"] and len(d["runs"]) == 4 and d["score"]["score"] == pytest.approx(cv.score["score"])


def test_a_failed_fold_is_reported_and_the_others_complete(monkeypatch):
    real = cvm.fit_logs

    def fails_without_tc(logs, *a, **k):
        if not any(lg.name == "kcs_tc_p35" for lg in logs):
            raise ValueError("this fold cannot be fitted")
        return real(logs, *a, **k)

    monkeypatch.setattr(cvm, "fit_logs", fails_without_tc)
    cv = shipid.cross_validate(KCS, "kcs-response", folds=2, lpp=4.36, fit_options=CHEAP)
    assert not cv.success and len(cv.failed) == 1 and "cannot be fitted" in cv.failed[0]["error"]
    assert "kcs_tc_p35" in cv.failed[0]["left_out"]
    done = [r["run"] for r in cv.runs]
    assert len(done) == 2 and "kcs_tc_p35" not in done
    assert cv.score["runs"]["kcs_tc_p35"] == cvm.CAP  # the failed fold's runs count CAP
    assert "1 of 2 folds failed" in cv.message


def test_candidates_rule():
    logs = [read_log(p) for p in KCS]
    cands, why = cvm.candidates_for(logs)
    assert [c.model for c in cands] == ["kcs-response", "response-nl", "mmg"]
    assert not any(c.wind or c.current for c in cands) and any("not every log carries wind" in w for w in why)
    astern = logs[0].data.copy()
    astern.loc[: len(astern) // 10, "n"] = -5.0
    cands, why = cvm.candidates_for([TrialLog(astern, name="astern", ship=logs[0].ship)] + logs[1:])
    assert cands[-1].model == "lowspeed" and "astern" in why[0]
    # with wind and current parts only the models that can carry them stay candidates (a response model's folds
    # would all fail)
    cands, why = cvm.candidates_for(logs, wind="kcs", current="constant")
    assert [c.model for c in cands] == ["mmg"] and cands[0].wind == "kcs"
    assert "kcs-response, response-nl are not candidates" in why[-1]
    with pytest.raises(ValueError, match="kcs-response: cannot take a wind or current part"):
        cvm.candidates_for(logs, current="constant", given=[cvm.Candidate("kcs-response")])
    assert [c.label for c in cvm.parse_candidates("auto:mmg:kvlcc2,response-nl")] == ["mmg:kvlcc2", "response-nl"]
    assert cvm.parse_candidates("auto") is None
    with pytest.raises(ValueError, match="unknown model 'nope'"):
        cvm.parse_candidates("auto:nope")


def test_choose_model_ranks_by_the_rule():
    choice = shipid.choose_model(KCS, [cvm.Candidate("mmg", "kcs"), cvm.Candidate("kcs-response")], folds=2,
                                 lpp=4.36, fit_options=CHEAP)
    assert choice.success and choice.chosen == cvm.Candidate("kcs-response")
    tab = choice.summary()
    assert list(tab.index) == ["kcs-response", "mmg:kcs"] and tab["score"].is_monotonic_increasing
    assert "chose kcs-response" in choice.message


def test_choice_table_shows_a_metric_no_run_measures_as_a_dash(capsys):
    """Runs without standard manoeuvres (outdoor runs from rest): the table's manoeuvre columns are NaN, printed
    as "-" (not None), and null in the JSON."""
    from types import SimpleNamespace

    import pandas as pd

    from shipid.commands.fit import print_choice

    summ = pd.DataFrame({"median": [None, 0.27]}, index=pd.Index(["tactical_diameter_pct", "position_30s_m"]))
    cv = SimpleNamespace(candidate="lowspeed", score={"score": 1.08, "worst_run": "zz", "worst": 3.9}, failed=[],
                         runs=[{"blowups": 0, "missing": []}], summary=lambda: summ, to_dict=lambda starts: {})
    choice = cvm.ModelChoice(results=[cv])
    tab = choice.summary()
    assert np.isnan(tab.loc["lowspeed", "tactical_diameter_pct"]) and np.isnan(tab.loc["lowspeed", "overshoot1_deg"])
    assert tab.loc["lowspeed", "position_30s_m"] == 0.27
    print_choice(choice)
    out = capsys.readouterr().out
    assert "None" not in out and "NaN" not in out and " - " in out
    row = choice.to_dict()["table"][0]
    assert row["tactical_diameter_pct"] is None and row["position_30s_m"] == 0.27


def test_cli_crossval_and_fit_cross_validate(tmp_path, capsys):
    from shipid.cli import main

    out = tmp_path / "cv.json"
    rc = main(["crossval", *KCS, "--model", "kcs-response", "--lpp", "4.36", "--refine", "none", "--folds", "2",
               "--no-progress", "-o", str(out)])
    text = capsys.readouterr().out
    assert rc == 0 and "cross-validation of kcs-response" in text and "median |error|" in text
    d = json.loads(out.read_text())
    assert len(d["runs"]) == 4 and d["settings"]["n_folds"] == 2
    assert main(["crossval", *KCS, "--folds", "x", "-o", str(tmp_path / "b.json")]) == 2
    assert "--folds x" in capsys.readouterr().err
    fit = tmp_path / "fit.json"
    rc = main(["fit", *KCS, "--model", "kcs-response", "--lpp", "4.36", "--refine", "none", "--cross-validate",
               "--folds", "2", "--no-progress", "-o", str(fit)])
    assert rc in (0, 3)
    res = json.loads(fit.read_text())
    assert res["extra"]["crossval"]["candidate"] == "kcs-response" and len(res["extra"]["crossval"]["runs"]) == 4
    html = tmp_path / "r.html"
    assert main(["report", str(fit), KCS[0], "--horizon", "none", "--no-progress", "-o", str(html)]) == 0
    page = html.read_text()
    assert "Expected error on runs not used for fitting" in page and "tactical_diameter_pct" in page


def test_validate_says_why_a_closed_loop_metric_is_missing():
    """A model whose rudder does not turn it never reaches the zigzag's check angle: the closed-loop prediction runs
    to its limit (3 times the measured run, or the simulator's own) and the entry says why."""
    from shipid.validation import DURATION_MULTIPLE, validate_one

    truth = shipid.get_model("kcs-response", "synthetic-truth")
    p = truth.params.copy()
    p[truth.param_index("c3")] = p[truth.param_index("b3")] = 0.0  # the rudder neither yaws nor sways the ship
    weak = truth.with_params(p)
    v = validate_one(weak, read_log(REPO / "data" / "kcs_zz_m10.csv"), lpp=4.36)
    miss = {m["metric"]: m["reason"] for m in v.standard_missing}
    assert set(miss) == {"overshoot1_deg", "overshoot2_deg"}
    assert "never changed by half the check angle 10 deg" in miss["overshoot1_deg"]
    assert f"{DURATION_MULTIPLE:g} times the measured run's" in miss["overshoot1_deg"]
    assert v.to_dict()["standard_missing"] == v.standard_missing
    good = validate_one(truth, read_log(REPO / "data" / "kcs_zz_m10.csv"), lpp=4.36)
    assert good.standard_missing == []


@pytest.mark.slow
def test_folds_on_two_workers_equal_serial():
    pytest.importorskip("distributed")
    a = shipid.cross_validate(KCS, "kcs-response", folds=2, lpp=4.36, fit_options=CHEAP)
    b = shipid.cross_validate(KCS, "kcs-response", folds=2, lpp=4.36, fit_options=CHEAP, workers=2)
    strip = lambda d: json.dumps({k: v for k, v in d.items() if k not in ("folds", "settings")}, sort_keys=True)  # noqa: E731
    assert strip(a.to_dict()) == strip(b.to_dict())  # every number to the bit (timings and engine aside)


@pytest.mark.slow
def test_marin_training_runs_cross_validate(marin_dir):
    """Leave-one-run-out over the four MARIN training runs (tc+-35, zz+-10; the zz+-20 runs are never read)."""
    files = [str(marin_dir / f"MARIN_FREE_KVLCC2_{k}_m.dat") for k in ("tc_35", "tc_-35", "zz_10", "zz_-10")]
    cv = shipid.cross_validate(files, "mmg")
    assert len(cv.runs) == 4 and cv.success, cv.message
    assert all(r["errors"].get("tactical_diameter_pct") is not None for r in cv.runs if r["manoeuvre"] == "turning")
    assert math.isfinite(cv.score["score"])


@pytest.mark.slow
def test_esso_runs_cross_validate_in_folds():
    if not ESSO_DIR.is_dir():
        pytest.skip(f"Esso Osaka data not found at {ESSO_DIR} (../shared/data/esso_osaka_frt beside the repo)")
    files = sorted(str(p) for p in ESSO_DIR.glob("*/*.csv"))
    logs = [read_log(f, schema="esso-frt") for f in files]
    cv = shipid.cross_validate(logs, "lowspeed", wind="esso-osaka-3m", current="constant", folds=4)
    assert cv.copies and len(cv.runs) == len(files) - len(cv.copies)
    assert cv.success, cv.message
    assert cv.summary().loc["position_30s_m", "median"] < 1.0


def test_cross_validation_sits_above_fitting_and_validation():
    """Cross-validation uses fitting and validation, so nothing they are built from imports it (no module of the
    identifier, the models, the simulators, the manoeuvres or the validation imports ``shipid.crossval``)."""
    import ast

    pkg = REPO / "shipid"
    below = [p for p in pkg.rglob("*.py")
             if p.relative_to(pkg).parts[0] in ("identify", "models", "manoeuvres", "logs", "environment", "validation")
             or p.name in ("simulate.py", "integrate.py")]
    assert len(below) > 20
    bad = []
    for p in below:
        for node in ast.walk(ast.parse(p.read_text())):
            names = ([a.name for a in node.names] if isinstance(node, ast.Import) else
                     [node.module or ""] + [a.name for a in node.names] if isinstance(node, ast.ImportFrom) else [])
            if any(n.split(".")[-1] == "crossval" for n in names):
                bad.append(f"{p.relative_to(REPO)}:{node.lineno}")
    assert not bad, bad


def test_results_follow_the_result_contract(kcs_cv):
    import matplotlib

    matplotlib.use("Agg")
    import pandas as pd

    choice = cvm.ModelChoice([kcs_cv], [cvm.Candidate("kcs-response")], [])
    for r in (kcs_cv, choice):
        assert r.success is True and isinstance(r.message, str) and r.message
        assert isinstance(r.summary(), pd.DataFrame) and isinstance(r.to_pandas(), pd.DataFrame)
        assert r.plot() is not None
        card = r._repr_html_()
        assert card.startswith("<") and len(card) < 20000
    assert choice.chosen == cvm.Candidate("kcs-response")
