"""Propagation of fit uncertainty into standard-manoeuvre predictions (shipid.uncertainty)."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from shipid.cli import main
from shipid.identify import FitResult
from shipid.manoeuvres import turning_circle
from shipid.uncertainty import imo_probability, parameter_draws, parse_manoeuvre, predict_manoeuvres

EST = ["b1", "b2", "b3", "b4", "c1", "c2", "c3"]


@pytest.fixture(scope="module")
def known_result(kcs_truth):
    """A fit result at the truth with a known, correlated covariance of the sway/yaw coefficients."""
    rng = np.random.default_rng(11)
    sd = 0.004 * np.abs(kcs_truth.params_series()[EST].to_numpy())
    A = rng.standard_normal((len(EST), len(EST)))
    corr = np.corrcoef(A @ A.T + 3 * np.eye(len(EST)))
    cov = corr * np.outer(sd, sd)
    coef = kcs_truth.params_series().to_dict()
    std = {k: 0.0 for k in coef}
    std.update(dict(zip(EST, np.sqrt(np.diag(cov)))))
    return FitResult(model="kcs-response", coef=coef, coef_std=std, cov=pd.DataFrame(cov, index=EST, columns=EST))


def test_parse_manoeuvre():
    assert parse_manoeuvre("turning:35").label == "turning_35_starboard"
    z = parse_manoeuvre("zigzag:20/20:port")
    assert (z.kind, z.rudder_deg, z.switch_deg, z.side) == ("zigzag", 20.0, 20.0, "port")
    with pytest.raises(ValueError, match="turning:35"):
        parse_manoeuvre("circle:35")
    with pytest.raises(ValueError, match="one angle"):
        parse_manoeuvre("turning:35/10")


def test_gaussian_draws_have_the_fit_covariance(known_result, kcs_truth):
    P = parameter_draws(known_result, 4000, seed=1)
    idx = [kcs_truth.param_index(n) for n in EST]
    fixed = [i for i in range(kcs_truth.np) if i not in idx]
    np.testing.assert_array_equal(P[:, fixed], np.broadcast_to(kcs_truth.params[fixed], (4000, len(fixed))))
    cov = known_result.cov.to_numpy()
    sd = np.sqrt(np.diag(cov))
    # sample mean within 4 standard errors; sample std within 5 % (its standard error is ~1.1 %)
    err = (P[:, idx].mean(axis=0) - kcs_truth.params[idx]) / (sd / np.sqrt(4000))
    assert np.all(np.abs(err) < 4)
    np.testing.assert_allclose(P[:, idx].std(axis=0), sd, rtol=0.05)
    r_emp = np.corrcoef(P[:, idx], rowvar=False)
    np.testing.assert_allclose(r_emp, cov / np.outer(sd, sd), atol=0.06)
    np.testing.assert_array_equal(P, parameter_draws(known_result, 4000, seed=1))  # same seed, same draws


def test_interval_matches_the_delta_method(known_result, kcs_truth):
    """For a small covariance the 95 % interval of the tactical diameter is +-1.96 sqrt(g' C g) (g: the gradient,
    here by central differences in one batched run)."""
    pred = predict_manoeuvres(known_result, ["turning:35"], draws=800, seed=3)
    row = pred.summary().set_index("metric").loc["tactical_diameter_L"]
    assert pred.success and row["n"] == 800 and row["n_nonfinite"] == 0
    idx = [kcs_truth.param_index(n) for n in EST]
    sd = np.sqrt(np.diag(known_result.cov.to_numpy()))
    P = np.tile(kcs_truth.params, (2 * len(EST), 1))
    for j, i in enumerate(idx):
        P[2 * j, i] += sd[j]
        P[2 * j + 1, i] -= sd[j]
    td = np.array([m.tactical_diameter_L for m in
                   turning_circle(kcs_truth, 35, side="starboard", speed=np.full(len(P), 1.7), params=P).metrics])
    g = (td[0::2] - td[1::2]) / (2 * sd)
    half = 1.96 * np.sqrt(g @ known_result.cov.to_numpy() @ g)
    # Monte-Carlo error of a 2.5/97.5 % quantile with 800 draws is ~6 % of the half width
    assert (row["high"] - row["low"]) / 2 == pytest.approx(half, rel=0.15)
    assert row["median"] == pytest.approx(row["nominal"], abs=0.2 * half)


def test_failed_draws_are_counted(known_result, kcs_truth):
    P = np.tile(kcs_truth.params, (6, 1))
    P[:2, [kcs_truth.param_index("b3"), kcs_truth.param_index("c3")]] = 0.0  # no rudder force: no turn
    pred = predict_manoeuvres(known_result, ["turning:35"], params=P)
    f = pred.failures["turning_35_starboard"]
    assert f["n_failed"] == 2 and pred.status == 1 and not pred.success
    assert "2/6" in pred.message
    row = pred.summary().set_index("metric").loc["tactical_diameter_L"]
    assert (row["n"], row["n_nonfinite"]) == (4, 2)
    imo = pred.imo["turning_35_starboard"]["tactical_diameter"]
    assert imo["n_met"] == 4 and imo["probability"] == pytest.approx(4 / 6) and imo["probability_evaluated"] == 1.0


def test_imo_probability_counts():
    d = [{"overshoot1_pass": True, "overshoot1_limit_deg": 10.0}] * 3 + [{"overshoot1_pass": False}, {"overshoot1_pass": None}]
    p = imo_probability(d)["overshoot1"]
    assert (p["n_met"], p["n_evaluated"], p["n_not_evaluated"], p["limit"]) == (3, 4, 1, 10.0)
    assert p["probability"] == pytest.approx(0.6) and p["probability_evaluated"] == pytest.approx(0.75)
    assert p["mc_std_error"] == pytest.approx(np.sqrt(0.6 * 0.4 / 5))


def test_simulate_and_validate_draws_cli(known_result, tmp_path, capsys):
    rp = known_result.to_json(tmp_path / "res.json")
    mo = tmp_path / "m.json"
    assert main(["simulate", str(rp), "--turning", "35", "--side", "starboard", "--draws", "40",
                 "--metrics-output", str(mo)]) == 0
    doc = json.loads(mo.read_text())
    blk = doc["manoeuvres"]["turning_35_starboard"]
    lo, hi = blk["tactical_diameter_L_ci"]
    assert lo < blk["tactical_diameter_L"] < hi
    assert blk["imo_probability"]["tactical_diameter"]["probability"] == 1.0 and blk["draws"]["n_failed"] == 0
    assert "met with probability" in capsys.readouterr().out
    assert main(["simulate", str(rp), "--turning", "35", "--draws", "-3"]) == 2
    assert "--draws -3" in capsys.readouterr().err
    assert main(["simulate", str(rp), "--turning", "35", "--metrics-output", str(tmp_path / "x.json")]) == 2


def test_validate_draws_inside_predicted(known_result, tmp_path):
    log = Path(__file__).resolve().parents[1] / "data" / "kcs_tc_p35.csv"
    rp = known_result.to_json(tmp_path / "res.json")
    out = tmp_path / "v.json"
    assert main(["validate", str(rp), str(log), "--lpp", "4.36", "-o", str(out), "--draws", "30",
                 "--no-closed-loop"]) == 0
    pred = json.loads(out.read_text())[0]["predicted"]
    lo, hi = pred["tactical_diameter_L_ci"]
    assert lo <= hi and pred["draws"] == {"n": 30, "n_failed": 0, "messages": {}}
    assert pred["imo_probability"]["tactical_diameter"]["n_evaluated"] == 30


def test_report_draws_section(known_result, tmp_path):
    log = Path(__file__).resolve().parents[1] / "data" / "kcs_tc_p35.csv"
    rp = known_result.to_json(tmp_path / "res.json")
    out = tmp_path / "r.html"
    assert main(["report", str(rp), str(log), "--lpp", "4.36", "-o", str(out), "--draws", "12",
                 "--no-closed-loop"]) == 0
    text = out.read_text()
    assert "Prediction uncertainty" in text and "95 % interval" in text and "IMO MSC.137(76) criterion is met" in text
