"""shipid.validation and `shipid validate`: replay of logged inputs against known truths.

* The bundled synthetic logs were made by ``kcs-response`` / ``synthetic-truth`` with known sensor
  noise (data/README.md): replaying the TRUE model must reproduce them to noise level -- RMSE at
  the noise standard deviation, manoeuvre metrics within what the noise allows -- and a wrong
  model must be caught.
* The measured MARIN KVLCC2 runs (skipped when ../shared/data/kvlcc2_marin is absent) with the
  published MMG KVLCC2 set: .dat logs, Froude scaling from the 7 m model to the 320 m ship, and the
  files' opposite rudder sign.
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from shipid.cli import main
from shipid.datasets import bundled_kcs_logs
from shipid.identify import FitResult
from shipid.identify.result import software_versions
from shipid.logs import LogError, TrialLog, read_log
from shipid.manoeuvres import metrics
from shipid.models import get_model
from shipid.simulate import replay, replay_errors
from shipid.validation import resolve_model, validate, validate_logs

MARIN = Path(__file__).parents[1] / ".." / "shared" / "data" / "kvlcc2_marin"
PATHS = {p.stem: p for p in bundled_kcs_logs()}
# sensor noise of the bundled logs (data/README.md): x, y 0.02 m; psi 0.2 deg; u 0.01 m/s; v 0.005 m/s; r 0.1 deg/s
NOISE = {"u": 0.01, "v": 0.005, "r": math.radians(0.1), "psi": math.radians(0.2)}
EST = ["b1", "b2", "b3", "b4", "c1", "c2", "c3"]


def truth_result(scale: dict | None = None) -> FitResult:
    """A FitResult holding the synthetic truth (optionally with coefficients scaled) and 1 % sigmas."""
    m = get_model("kcs-response", "synthetic-truth")
    coef = {k: float(v) for k, v in zip(m.param_names, m.params)}
    for k, f in (scale or {}).items():
        coef[k] *= f
    std = {k: (0.01 * abs(coef[k]) if k in EST else 0.0) for k in coef}
    cov = pd.DataFrame(np.diag([std[k] ** 2 for k in EST]), index=EST, columns=EST)
    diag = {"condition_number": 1.0, "correlation": {"names": EST, "matrix": np.eye(len(EST)).tolist()},
            "warnings": [], "poorly_determined": [], "unidentified_combinations": []}
    return FitResult(model="kcs-response", coef=coef, coef_std=std, cov=cov, diagnostics=diag,
                     method="synthetic truth", versions=software_versions())


@pytest.fixture(scope="module")
def truth_validation():
    return {v["name"]: v for v in validate(truth_result(), list(PATHS.values()))}


def test_truth_replay_rmse_is_the_sensor_noise(truth_validation):
    assert set(truth_validation) == set(PATHS)
    for name, v in truth_validation.items():
        assert v["manoeuvre"] == ("turning" if "_tc_" in name else "zigzag"), name
        assert v["success"] and v["replay"]["success"], name
        for ch, sd in NOISE.items():
            # white noise of std sd: RMSE ~ sd (+ a little from the initial-state estimate)
            assert 0.8 * sd < v["rmse"][ch] < 1.3 * sd, (name, ch, v["rmse"][ch], sd)
            assert v["nrmse"][ch] == pytest.approx(v["rmse"][ch] / np.ptp(read_log(PATHS[name])[ch]), rel=1e-9)
        # the track drifts from the noisy initial speed only: well under a tenth of a ship length
        assert v["track_rmse_m"] < 0.1 * 4.36, (name, v["track_rmse_m"])


def test_truth_predicted_metrics_agree_with_measured(truth_validation):
    for name, v in truth_validation.items():
        d = v["difference"]
        print(name, {k: round(x, 4) for k, x in d.items() if x is not None})
        if v["manoeuvre"] == "turning":
            for k in ("advance_L", "transfer_L", "tactical_diameter_L"):
                assert abs(d[k]) < 0.03, (name, k, d[k])  # 0.13 m: position noise 0.02 m + initial-state drift
            assert abs(d["steady_diameter_L"]) < 0.01, name  # circle fit over hundreds of samples
            assert abs(d["speed_loss"]) < 0.01, name
        else:
            # measured overshoots are maxima of a heading with 0.2 deg noise: within 3 sigma of the truth's
            for k in ("overshoot1_deg", "overshoot2_deg"):
                assert abs(d[k]) < 0.6, (name, k, d[k])
            assert abs(d["time_second_execute"]) < 0.2, name
        # the same IMO verdicts as the measurement
        assert v["measured"]["imo"] == pytest.approx(v["predicted"]["imo"], rel=0.02), name


def test_truth_closed_loop_manoeuvre_agrees(truth_validation):
    """The model's own closed-loop manoeuvre (approach speed, rudder, switch angle and side of the log)."""
    v = truth_validation["kcs_tc_p35"]  # constant rpm: the closed loop is the same trial
    s = v["standard_difference"]
    print("tc_p35 closed loop - measured", {k: round(s[k], 4) for k in ("advance_L", "tactical_diameter_L",
                                                                         "steady_diameter_L", "speed_loss")})
    assert v["standard"]["settings"]["side"] == v["measured"]["side"] == "starboard"
    for k in ("advance_L", "transfer_L", "tactical_diameter_L", "steady_diameter_L"):
        # the execute is where the (continuous) rudder left its approach angle, interpolated between
        # samples; taking the first sample past 0.5 deg put it 0.1 s (0.039 L of advance) late
        assert abs(s[k]) < 0.03, (k, s[k])
    assert abs(s["speed_loss"]) < 0.01
    for name in ("kcs_zz_m10", "kcs_zz_p20_rpm"):  # the rpm change of zz_p20 comes after the overshoots
        v = truth_validation[name]
        s = v["standard_difference"]
        print(name, "closed loop - measured", {k: round(s[k], 3) for k in ("overshoot1_deg", "overshoot2_deg")})
        assert v["standard"]["first_side"] == v["measured"]["first_side"]
        for k in ("overshoot1_deg", "overshoot2_deg"):
            # 0.6 deg heading-noise allowance + up to 0.26 deg switch lag of the simulated rudder law
            assert abs(s[k]) < 0.9, (name, k, s[k])


def test_wrong_model_is_caught():
    """A rudder 30 % weaker than the truth (c3, b3): the turn widens, RMSE far above noise."""
    bad = {v["name"]: v for v in validate(truth_result({"c3": 0.7, "b3": 0.7}), [PATHS["kcs_tc_p35"]], closed_loop=False)}
    v = bad["kcs_tc_p35"]
    print({k: round(x, 3) for k, x in v["difference"].items() if x is not None}, v["rmse"])
    assert v["difference"]["tactical_diameter_L"] > 0.5
    assert v["rmse"]["r"] > 10 * NOISE["r"]


def test_validate_reuses_replay_and_metrics():
    """validate() is replay + replay_errors + manoeuvres.metrics, nothing else."""
    model = get_model("kcs-response", "synthetic-truth")
    log = read_log(PATHS["kcs_zz_m10"])
    (v,) = validate_logs(model, [log], closed_loop=False)
    sim = replay(model, log)
    np.testing.assert_array_equal(v.simulation.x, sim.x)
    pd.testing.assert_frame_equal(v.errors, replay_errors(sim, log))
    assert v.to_dict()["measured"] == metrics(log).to_dict()
    assert v.to_dict()["file"] == str(PATHS["kcs_zz_m10"])


def test_output_is_strict_json(truth_validation):
    text = json.dumps(list(truth_validation.values()), allow_nan=False)
    back = json.loads(text)
    for d in back:
        for key in ("file", "manoeuvre", "measured", "predicted", "difference", "rmse", "nrmse", "track_rmse_m"):
            assert key in d


def test_rudder_sign_convention():
    """A log written with the opposite rudder sign: flagged by a note; rudder_sign=-1 gives the original replay."""
    model = get_model("kcs-response", "synthetic-truth")
    log = read_log(PATHS["kcs_tc_p35"])
    cols = {c: log.data[c].to_numpy() for c in log.channels}
    cols["delta"] = -cols["delta"]
    with pytest.raises(LogError, match="rudder sign opposite to shipid.s; pass rudder_sign=-1.*pass consistency_checks=False"):  # from_arrays checks too
        TrialLog.from_arrays(log.time, name="flipped", ship=log.ship, **cols)
    flipped = TrialLog.from_arrays(log.time, name="flipped", ship=log.ship, consistency_checks=False, **cols)
    (wrong,) = validate(model, [flipped], closed_loop=False)
    assert any("opposite" in n and "rudder_sign=-1" in n for n in wrong["notes"]), wrong["notes"]
    (right,) = validate(model, [flipped], rudder_sign=-1, closed_loop=False)
    (orig,) = validate(model, [log], closed_loop=False)
    assert right["rmse"] == pytest.approx(orig["rmse"], rel=1e-12)
    assert right["difference"]["tactical_diameter_L"] == pytest.approx(orig["difference"]["tactical_diameter_L"], abs=1e-12)
    with pytest.raises(ValueError, match="rudder_sign"):
        validate(model, [log], rudder_sign=2)


def test_result_sources_and_model_options(tmp_path):
    res = truth_result()
    p = res.to_json(tmp_path / "r.json")
    for src in (res, res.to_dict(), p, str(p)):
        model, fr = resolve_model(src)
        assert model.name == "kcs-response" and fr.coef == res.coef
    doc = {"model": "mmg", "coef": {}, "model_options": {"lpp": 320.0}}
    model, _ = resolve_model(doc)
    assert model.lpp == pytest.approx(320.0)
    with pytest.raises(ValueError, match="not a shipid fit result"):
        resolve_model({"coef": {}})
    with pytest.raises(ValueError, match="unknown model 'nope'"):
        resolve_model({"model": "nope", "coef": {}})


# ------------------------------------------------------------------------------------------ CLI
def test_cli_validate_writes_the_json_list(tmp_path, capsys):
    r = truth_result().to_json(tmp_path / "result.json")
    out = tmp_path / "validation.json"
    logs = [str(PATHS["kcs_zz_m10"]), str(PATHS["kcs_tc_p35"])]
    assert main(["validate", str(r), *logs, "-o", str(out)]) == 0
    doc = json.loads(out.read_text())
    assert [d["file"] for d in doc] == logs
    assert [d["manoeuvre"] for d in doc] == ["zigzag", "turning"]
    assert set(doc[0]["rmse"]) >= {"u", "v", "r", "psi", "x", "y"}
    assert doc[1]["measured"]["tactical_diameter_L"] > 0 and doc[1]["predicted"]["tactical_diameter_L"] > 0
    printed = capsys.readouterr().out
    assert "wrote" in printed
    # each log's line labels the replay's differences and the closed-loop standard manoeuvre's (what the goals
    # judge) apart, with the numbers of the JSON
    turn = next(ln for ln in printed.splitlines() if ln.startswith(doc[1]["name"] + ": turning"))
    for label, key in (("replay", "difference"), ("closed-loop", "standard_difference")):
        assert f"{label}: " in turn
        assert f"dtactical_diameter_L={doc[1][key]['tactical_diameter_L']:+.3f}" in turn.split(f"{label}: ")[1]


def _bad_cases(tmp_path):
    r = truth_result().to_json(tmp_path / "result.json")
    log = str(PATHS["kcs_zz_m10"])
    notjson = tmp_path / "broken.json"
    notjson.write_text("{ not json")
    exists = tmp_path / "exists.json"
    exists.write_text("keep me")
    return {
        "missing result": (["validate", str(tmp_path / "none.json"), log, "-o", str(tmp_path / "o1.json")], "none.json"),
        "broken result": (["validate", str(notjson), log, "-o", str(tmp_path / "o2.json")], "broken.json"),
        "missing log": (["validate", str(r), str(tmp_path / "nolog.csv"), "-o", str(tmp_path / "o3.json")], "nolog.csv"),
        "output exists": (["validate", str(r), log, "-o", str(exists)], "exists.json"),
        "bad lpp": (["validate", str(r), log, "--lpp", "0", "-o", str(tmp_path / "o4.json")], "--lpp"),
    }


@pytest.mark.parametrize("case", ["missing result", "broken result", "missing log", "output exists", "bad lpp"])
def test_cli_validate_bad_input_exits_2_with_one_line(tmp_path, capsys, case):
    argv, needle = _bad_cases(tmp_path)[case]
    before = {p: p.read_bytes() for p in tmp_path.iterdir()}
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and needle in err[0] and "Traceback" not in err[0], err
    assert {p: p.read_bytes() for p in tmp_path.iterdir()} == before  # inputs untouched, nothing written


def test_cli_validate_unknown_model(tmp_path, capsys):
    p = tmp_path / "r.json"
    p.write_text(json.dumps({"model": "no-such-model", "coef": {}}))
    assert main(["validate", str(p), str(PATHS["kcs_zz_m10"]), "-o", str(tmp_path / "o.json")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no-such-model" in err[0]
    assert not (tmp_path / "o.json").exists()


# ------------------------------------------------------------------------------- MARIN KVLCC2
MARIN_README_OVERSHOOT1 = {"zz_10": 9.4, "zz_-20": 12.7}


@pytest.fixture(scope="module")
def mmg_result(tmp_path_factory):
    """The published MMG KVLCC2 set (Yasukawa & Yoshimura 2015) as a result JSON (7 m model)."""
    m = get_model("mmg", "kvlcc2")
    doc = {"model": "mmg", "method": "parameter set kvlcc2", "coef": dict(zip(m.param_names, map(float, m.params)))}
    p = tmp_path_factory.mktemp("mmg") / "mmg_kvlcc2.json"
    p.write_text(json.dumps(doc))
    return p


def _marin(name):
    if not MARIN.is_dir():
        pytest.skip(f"MARIN KVLCC2 data not found at {MARIN.resolve()} (../shared/data/kvlcc2_marin beside the repo)")
    return MARIN / f"MARIN_FREE_KVLCC2_{name}_m.dat"


def test_marin_dat_logs_with_published_mmg(mmg_result, tmp_path):
    paths = [_marin(n) for n in MARIN_README_OVERSHOOT1]
    out = tmp_path / "v.json"
    assert main(["validate", str(mmg_result), *map(str, paths), "--lpp", "320", "--rudder-sign", "-1",
                 "-o", str(out)]) == 0
    res = json.loads(out.read_text())
    for name, d in zip(MARIN_README_OVERSHOOT1, res):
        meas, pred = d["measured"], d["predicted"]
        print(name, "overshoot1 measured", round(meas["overshoot1_deg"], 2), "replay", round(pred["overshoot1_deg"], 2),
              "closed loop", round(d["standard"]["overshoot1_deg"], 2),
              "rmse", {k: round(x, 4) for k, x in d["rmse"].items()}, "track", round(d["track_rmse_m"], 1))
        assert d["manoeuvre"] == "zigzag" and d["replay"]["success"]
        assert any("Froude-scaled from Lpp 7 m" in n for n in d["notes"])
        assert d["replay"]["model_lpp"] == pytest.approx(320.0)
        assert meas["overshoot1_deg"] == pytest.approx(MARIN_README_OVERSHOOT1[name], abs=0.2)  # README value
        assert pred["first_side"] == meas["first_side"]
        # the published (captive-test) set under-predicts the free-running overshoots; replayed open loop
        # with the logged rudder and rpm the gap is 3-7 deg (docs/validation_report.md) -- a bound, not a goal
        assert -8.0 < d["difference"]["overshoot1_deg"] < 0.0
        # closed loop at the measured approach speed (rps solved for it): the 1.5-3 deg gap of the
        # published set seen in tests/test_mmg.py
        assert -3.0 < d["standard_difference"]["overshoot1_deg"] < -1.0
        # the heading follows to within a few degrees, the yaw rate to 0.1 deg/s
        assert d["rmse"]["r"] < math.radians(0.1)


def test_marin_wrong_rudder_sign_is_flagged(mmg_result):
    # the MARIN reader flips the file's port-positive rudder; rudder_sign=1 reads the file's sign as is (which
    # read_log's consistency check refuses: "the first rudder execute ... turned the ship to port")
    log = read_log(_marin("zz_10"), rudder_sign=1, consistency_checks=False)
    (d,) = validate(mmg_result, [log], lpp=320.0, closed_loop=False)
    assert any("opposite" in n for n in d["notes"]), d["notes"]
    assert d["predicted"]["first_side"] != d["measured"]["first_side"]


def test_log_without_manoeuvre_and_diverging_model(tmp_path, capsys):
    """A straight run: replay errors only.  An unstable model: success False, no numbers, CLI exit 1."""
    model = get_model("kcs-response", "synthetic-truth")
    t = np.arange(0.0, 20.0, 0.1)
    straight = TrialLog.from_arrays(t, name="straight", x=1.7 * t, y=0 * t, psi=0 * t, u=1.7 + 0 * t, v=0 * t,
                                    r=0 * t, delta=0 * t, n=10.0 + 0 * t)
    (d,) = validate(model, [straight], closed_loop=False)
    assert d["manoeuvre"] is None and d["measured"] == {} and d["predicted"] == {} and d["success"]
    assert any("never moves" in n for n in d["notes"])
    assert d["rmse"]["u"] < 1e-3  # 10 rps holds 1.70 m/s in the truth
    unstable = truth_result()
    unstable.coef.update(c2=5.0, a1=3.0)
    (d,) = validate(unstable, [PATHS["kcs_zz_m10"]], closed_loop=False)
    assert not d["success"] and not d["replay"]["success"]
    assert d["predicted"] == {} and all(v is None for v in d["rmse"].values())
    assert any("non-finite" in n for n in d["notes"])
    r = unstable.to_json(tmp_path / "unstable.json")
    out = tmp_path / "v.json"
    assert main(["validate", str(r), str(PATHS["kcs_zz_m10"]), "--no-closed-loop", "-o", str(out)]) == 1
    assert json.loads(out.read_text())[0]["replay"]["success"] is False
    assert "diverged" in capsys.readouterr().err
