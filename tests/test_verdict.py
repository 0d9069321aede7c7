"""The graded verdict: grades, exit statuses, physics plausibility, one short line, and where it travels."""
from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import pytest

from shipid.identify import EKFIdentifier
from shipid.identify.verdict import (EXIT_STATUS, GRADES, RANGE_FACTOR, Verdict, assess, exit_status,
                                     physics_findings, plain_message, prime_value, verdict_of, warning_line)
from shipid.models import get_model

DATA = Path(__file__).parents[1] / "data"


# ------------------------------------------------------------------ the grades and the exit status
def test_exit_status_of_each_grade_and_the_json_round_trip():
    assert EXIT_STATUS == {"consistent": 0, "model_error": 0, "defect": 3, "diverged": 4}
    for g in GRADES:
        v = Verdict(g, [f"reason of {g}"] if g != "consistent" else [])
        back = Verdict.from_dict(json.loads(json.dumps(v.to_dict())))
        assert back.grade == g and back.reasons == v.reasons and exit_status(back) == EXIT_STATUS[g]
        assert exit_status({"verdict": v.to_dict()}) == EXIT_STATUS[g]
    with pytest.raises(ValueError, match="verdict grade 'fine': expected one of consistent"):
        Verdict("fine")
    with pytest.raises(ValueError, match="r.json: verdict.reasons must be a list of strings"):
        Verdict.from_dict({"grade": "defect", "reasons": "units"}, "r.json")


def test_a_result_without_a_verdict_is_graded_from_what_it_holds():
    assert verdict_of({"model": "m", "coef": {}, "success": False, "message": "the filter diverged at t = 3 s"}).grade \
        == "diverged"
    assert verdict_of({"diagnostics": {"consistency": {"consistent": False}}}).grade == "model_error"
    assert verdict_of({"diagnostics": {"consistency": {"consistent": True}}}).grade == "consistent"


def _cons(**rows):
    base = {"n": 1000, "nis_band": [0.85, 1.16], "ljung_box_p": 0.5, "rho_max": 0.05, "gated_fraction": 0.0,
            "replay_ratio": 1.0}
    return {"channels": {ch: {**base, **row} for ch, row in rows.items()}, "dynamic_channels": ["u", "v", "r"]}


def test_large_or_coloured_innovations_are_model_error_with_numbers_small_ones_a_defect():
    channels = {"u": {"rmse": 0.031, "unit": "m/s"}, "v": {"rmse": 0.012, "unit": "m/s"},
                "r": {"rmse": 0.21, "unit": "deg/s", "unexplained": 0.08}}
    v = assess(consistency=_cons(x={"nis_mean": 4.2}, r={"nis_mean": 1.0, "ljung_box_p": 1e-9, "rho_max": 0.6}),
               channels=channels, track={"rmse_m": 12.0, "rmse_L": 0.0375}, runs=[{"name": "zz_10", "share": 0.7}])
    assert v.grade == "model_error" and exit_status(v) == 0
    assert v.reasons[0] == ("the model misses the logs by more than their noise: replay RMSE u 0.031 m/s, "
                            "v 0.012 m/s, r 0.21 deg/s; track 12 m (0.037 L); 8 % of the yaw rate's variance "
                            "unexplained; worst run zz_10")
    assert "innovations of x are 4.2-4.2 times the noise model's variance" in v.reasons
    assert any(r.startswith("innovations of r are not white (largest autocorrelation 0.60)") for r in v.reasons)
    line = warning_line(v)
    assert line.startswith("warning: model error -- no data defect found; replay RMSE u 0.031 m/s") and len(line) <= 300
    # innovations smaller than the noise model's (measured logs with conservative noise levels): a note only
    small = assess(consistency=_cons(u={"nis_mean": 0.2}, v={"nis_mean": 0.3}))
    assert small.grade == "consistent" and [f["kind"] for f in small.findings] == ["noise_overstated"]
    coarse = assess(consistency=_cons(u={"nis_mean": 1.0}), sampling={"log_step": 1.0, "time_constant": 0.83})
    assert coarse.grade == "defect" and coarse.reasons == [
        "the logs sample every 1 s, more than half the ship's fastest time constant (0.83 s at the logs' speed): a "
        "decimated log (or time in the wrong unit); fit the logger's full-rate file"]
    assert assess(consistency=_cons(u={"nis_mean": 1.0}), sampling={"log_step": 0.1, "time_constant": 0.83}).grade \
        == "consistent"
    # a divergence that a log's channel error explains is a defect naming the fix
    found = [{"kind": "log_velocity_frame", "channels": ["u", "v"], "option": "--velocity-frame earth",
              "message": "`a.csv`: 'u', 'v' agree with the earth-fixed dx/dt, dy/dt: pass velocity_frame='earth' "
                         "(CLI: --velocity-frame earth)"}]
    dv = assess(consistency={}, diverged=True, message="normalised innovation 1e39", logs_found=found)
    assert dv.grade == "defect" and dv.reasons[0] == found[0]["message"] and exit_status(dv) == 3
    clean = assess(consistency=_cons(u={"nis_mean": 1.02}, r={"nis_mean": 0.97}))
    assert clean.grade == "consistent" and clean.reasons == [] and warning_line(clean) is None
    div = assess(consistency={}, diverged=True, message="the state left the model's range at t = 12.3 s")
    assert div.grade == "diverged" and exit_status(div) == 4
    assert warning_line(div) == "error: diverged -- the filter diverged: the state left the model's range at t = 12.3 s"


def test_refinement_that_did_not_converge_is_a_defect_unphysical_damping_a_model_error_said_first():
    v = assess(consistency=_cons(u={"nis_mean": 1.0}),
               refinement_failed="The maximum number of function evaluations is exceeded.")
    assert v.grade == "defect"
    assert "the evaluation limit was reached (raise --max-nfev)" in v.reasons[0] and "`" not in v.reasons[0]
    u = assess(consistency=_cons(x={"nis_mean": 4.0}),
               damping={"physical": False, "v": {"fraction_positive": 0.12}, "r": {"fraction_positive": 0.0}})
    assert u.grade == "model_error" and exit_status(u) == 0
    line = warning_line(u)
    assert line.startswith("warning: model error -- no data defect found, but the fitted model is not physical: its "
                           "own sway damping is positive along the logged motions") and len(line) <= 300
    assert plain_message("x: `ftol` termination condition is satisfied.") == "x: the cost stopped decreasing"


# ------------------------------------------------------------------ plausibility from physics
def _linearised(name, pset):
    """c3 L^2/U^2 of a model's straight run at its design speed (the propeller rate that holds it)."""
    from scipy.optimize import brentq

    m = get_model(name, pset)
    o = m.options()
    L = o.get("lpp") or o["particulars"]["lpp"]
    U = o.get("design_speed") or o["particulars"]["design_speed"]
    x = np.zeros(m.nx)
    x[m.state_index("u")] = U
    u = np.zeros(m.nu)
    iu, jn = m.state_index("u"), m.input_index("n")

    def acc(n):
        u[jn] = n
        return m.rhs(0.0, x, u)[iu]

    u[jn] = brentq(acc, 0.1, 100.0)
    J = m.jac_u(0.0, x, u)
    return J[m.state_index("r"), m.input_index("delta")] * (L / U) ** 2, J[m.state_index("v"), m.input_index("delta")] * L / U**2


def test_declared_ranges_and_signs_hold_for_every_published_set():
    """The c3 range of the response models is the span of the published sets' linearisations, and every set has
    the stern-rudder signs (yaw moment positive, sway force negative for positive rudder)."""
    c3 = {}
    for name, pset in (("kcs-response", "synthetic-truth"), ("response-nl", None), ("mmg", "kcs"),
                       ("mmg", "kvlcc2"), ("lowspeed", None)):
        c3[(name, pset)], b3 = _linearised(name, pset)
        assert c3[(name, pset)] > 0 and b3 < 0, (name, pset)
    lo, hi = get_model("kcs-response").physics_ranges["c3"][:2]
    assert lo == pytest.approx(min(c3.values()), abs=0.005) and hi == pytest.approx(max(c3.values()), abs=0.005)
    assert get_model("response-nl").physics_ranges["c3"][:2] == (lo, hi)
    # the window widened by RANGE_FACTOR spans less than 57.3: a degree/radian confusion always leaves it
    assert hi / lo * RANGE_FACTOR**2 < 57.3
    for name in ("mmg", "lowspeed"):
        flo, fhi = get_model(name).physics_ranges["f_alpha"][:2]
        sets = [get_model("mmg", "kcs"), get_model("mmg", "kvlcc2"), get_model("lowspeed")]
        vals = [float(m.params_series()["f_alpha"]) for m in sets]
        assert flo == pytest.approx(min(vals), abs=0.005) and fhi == pytest.approx(max(vals), abs=0.005)
    truth = get_model("kcs-response", "synthetic-truth").params_series()
    for name, (sign, *_rest) in get_model("kcs-response").physics_signs.items():
        assert np.sign(truth[name]) == sign, name


def test_physics_findings_name_the_channel_and_the_option_and_hold_at_any_scale():
    m = get_model("kcs-response", "synthetic-truth")
    coef = m.params_series().to_dict()
    std = {k: 0.01 * abs(v) for k, v in coef.items()}
    prior = {k: abs(v) for k, v in coef.items()}
    assert physics_findings(m, coef, std, prior, speed=1.5) == []
    # the same ship at full scale (Froude-scaled 52.67x): the same prime values, no finding
    big = m.scaled(4.36 * 52.67)
    cb = big.params_series().to_dict()
    assert physics_findings(big, cb, {k: 0.01 * abs(v) for k, v in cb.items()}, {k: abs(v) for k, v in cb.items()},
                            speed=1.5 * 52.67**0.5) == []
    assert prime_value(big, "c3", cb["c3"], 1.5 * 52.67**0.5) == pytest.approx(prime_value(m, "c3", coef["c3"], 1.5))
    flipped = dict(coef, c3=-coef["c3"], b3=-coef["b3"])
    f = physics_findings(m, flipped, std, prior, speed=1.5)
    assert [x["coefficient"] for x in f] == ["b3", "c3"] and all(x["channels"] == ["delta"] for x in f)
    assert f[1]["message"] == ("c3 = -0.14 +- 0.0014 is negative but positive (starboard) rudder must turn the ship "
                               "to starboard: rudder logged positive to port? pass --rudder-sign -1")
    vflip = dict(coef, b3=-coef["b3"])   # the sway term alone: v's sign, not the rudder's
    f = physics_findings(m, vflip, std, prior, speed=1.5)
    assert [x["coefficient"] for x in f] == ["b3"] and f[0]["channels"] == ["v"] and f[0]["grade"] == "model_error"
    assert f[0]["message"].endswith("while c3 has the rudder's sign: the sway equation misses the logs, or v is "
                                    "logged positive to port (--sign v=-1)")
    assert assess(consistency={}, physics=f).grade == "model_error"
    doubt = [{"kind": "log_velocity_frame_doubt", "grade": "note", "channels": ["u", "v"], "option": "",
              "message": "u, v agree with neither the body-axis nor the earth-fixed reading of the track"}]
    assert assess(consistency={}, physics=f, logs_found=doubt).grade == "defect"
    scaled = dict(coef, c3=57.3 * coef["c3"])
    f = physics_findings(m, scaled, std, prior, speed=1.5)
    assert [x["kind"] for x in f] == ["physics_range"] and "--units delta=deg" in f[0]["message"]
    # an undetermined coefficient (posterior std above half the prior's) is not judged
    assert physics_findings(m, flipped, {**std, "c3": 0.6 * prior["c3"], "b3": 0.6 * prior["b3"]}, prior, 1.5) == []


# ------------------------------------------------------------------ clean synthetic logs: false defect rate
def _seed_grades(seeds):
    from shipid.logs import TrialLog
    from shipid.synthetic import KCS_RECIPES, make_kcs_logs

    m = get_model("kcs-response", "synthetic-truth")
    rec = [r for r in KCS_RECIPES if r.name in ("kcs_tc_m25_rpm", "kcs_zz_p20_rpm")]
    out = []
    for seed in seeds:
        frames = make_kcs_logs(m, seed=1000 + seed, recipes=rec)
        logs = [TrialLog.from_arrays(f["time"].to_numpy(), name=n, **{c: f[c].to_numpy() for c in f.columns
                                                                        if c != "time"})
                for n, (f, _) in frames.items()]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            fit = EKFIdentifier(m, n_passes=1).fit(logs)
        v = fit.result().verdict
        out.append((seed, v.grade, v.reasons))
    return out


def test_clean_synthetic_logs_are_not_defects_5_seeds():
    grades = _seed_grades(range(5))
    assert all(g != "defect" for _, g, _ in grades), grades


@pytest.mark.slow
def test_false_defect_rate_on_50_seeds_of_clean_logs():
    """50 seeds of two clean bundled-recipe logs (tc_m25_rpm, zz_p20_rpm) with the stern-rudder truth: at most
    1 of 50 (2 %) graded defect (the measured rate is in docs/verdict.md)."""
    grades = _seed_grades(range(50))
    bad = [(s, r) for s, g, r in grades if g == "defect"]
    assert len(bad) <= 1, bad


def test_clean_bundled_cli_fit_exits_0_and_recovers_the_truth(tmp_path, capsys):
    """The acceptance case: the bundled logs of the stern-rudder truth, `shipid fit` with default settings."""
    from shipid.cli import main

    out = tmp_path / "r.json"
    rc = main(["fit", str(DATA / "kcs_zz_p20_rpm.csv"), str(DATA / "kcs_zz_m10.csv"), "--lpp", "4.36", "-o", str(out),
               "--no-progress", "--passes", "1"])
    cap = capsys.readouterr()
    doc = json.loads(out.read_text())
    assert rc == 0 and doc["verdict"]["grade"] in ("consistent", "model_error"), (cap.err, doc["verdict"])
    truth = get_model("kcs-response", "synthetic-truth").params_series()
    z = {k: (doc["coef"][k] - truth[k]) / doc["coef_std"][k] for k in doc["cov"]["names"]}
    assert all(abs(v) < 3 for v in z.values()), z
    assert "verdict: " in cap.out


# ------------------------------------------------------------------ the verdict travels
def test_report_banner_and_validate_report_first_lines(tmp_path, capsys):
    from shipid.cli import main
    from shipid.identify import load_result
    from shipid.report.html import verdict_banner

    log = DATA / "kcs_zz_m10.csv"
    res = tmp_path / "r.json"
    assert main(["fit", str(log), "--lpp", "4.36", "-o", str(res), "--no-progress", "--passes", "1",
                 "--estimate", "c1,c2,c3", "--refine", "none"]) == 0
    r = load_result(res)
    assert r.summary().attrs["verdict"] == r.verdict.grade
    html = verdict_banner(r)
    assert f"Verdict: {r.verdict.grade.replace('_', ' ')}." in html and r.verdict.advice in html
    # a defect: the same result with a flipped-rudder finding
    doc = json.loads(res.read_text())
    doc["verdict"] = Verdict("defect", ["c3 = -0.14 +- 0.002 is negative but positive (starboard) rudder must turn "
                                        "the ship to starboard: rudder logged positive to port? pass --rudder-sign -1"]
                             ).to_dict()
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(doc))
    capsys.readouterr()
    assert main(["report", str(bad), str(log), "-o", str(tmp_path / "rep.html"), "--no-progress"]) in (0, 1)
    first = capsys.readouterr().out.splitlines()[0]
    assert first.startswith("warning: this fit's verdict is defect: c3 = -0.14") and len(first) <= 300
    text = (tmp_path / "rep.html").read_text()
    assert text.index("Verdict: defect.") < text.index("id=\"summary\"")
    assert "fit status" not in text and "--rudder-sign -1" in text
    assert main(["validate", str(res), str(log), "-o", str(tmp_path / "v.json"), "--no-progress"]) in (0, 1)
    assert capsys.readouterr().out.splitlines()[0] == f"fit verdict: {r.verdict.grade.replace('_', ' ')}"
