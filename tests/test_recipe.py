"""The fit recipe and what travels with a fit (shipid.identify.recipe, FitResult particulars):
every ship model in the prime system, particulars carried from the logs, the check angle, the recipe's steps."""
from __future__ import annotations

import json
import warnings

import numpy as np
import pytest

from shipid.identify.result import FitResult, load_result
from shipid.logs import TrialLog
from shipid.manoeuvres import zigzag
from shipid.models import get_model

#: Every ship-manoeuvring model, at its shipped length (kcs-response and response-nl: the 4.36 m KCS
#: model; mmg: the KCS set).
SHIP_MODELS = {"kcs-response": (None, {}), "response-nl": (None, {}), "mmg": ("kcs", {})}


def _as_fit_result(model) -> FitResult:
    """The model as a fit would hand it over (coefficients + model_options), through its JSON."""
    import pandas as pd

    res = FitResult(model=model.name, coef=model.params_series().to_dict(),
                    coef_std={k: 0.0 for k in model.param_names}, cov=pd.DataFrame(),
                    model_options=model.options())
    return FitResult.from_dict(json.loads(json.dumps(res.to_dict())))


@pytest.mark.parametrize("name", sorted(SHIP_MODELS))
def test_every_ship_model_predicts_froude_scaled_manoeuvres(name):
    """A fitted model (its result JSON) scaled from its length L1 to L2 = 320 m predicts the Froude-scaled
    manoeuvre: a 20/20 zigzag at U sqrt(lam) gives the same overshoots, times x sqrt(lam), positions x lam,
    to 1e-9; the prime coefficients are unchanged (mmg: prime by construction)."""
    pset, opts = SHIP_MODELS[name]
    small = _as_fit_result(get_model(name, pset, **opts)).to_model()
    L1 = small.lpp
    assert L1 is not None and L1 < 10, f"{name}: the shipped set must know its length"
    big = small.scaled(320.0)
    lam = 320.0 / L1
    assert big.lpp == pytest.approx(320.0)
    assert big.rudder_rate == pytest.approx(small.rudder_rate / np.sqrt(lam), rel=1e-12)
    if hasattr(small, "to_prime"):
        p1, p2 = small.to_prime(), big.to_prime()
        for k in small.param_names:
            assert p2[k] == pytest.approx(p1[k], rel=1e-12, abs=1e-300), k
    U1 = 1.7 if name != "mmg" else small.design_speed
    a = zigzag(small, 20.0, speed=U1, first="starboard")
    b = zigzag(big, 20.0, speed=U1 * np.sqrt(lam), first="starboard")
    ma, mb = a.metrics[0], b.metrics[0]
    assert ma.success and mb.success
    assert abs(ma.overshoot1_deg) > 1.0  # a real manoeuvre
    for k in ("overshoot1_deg", "overshoot2_deg"):
        assert getattr(mb, k) == pytest.approx(getattr(ma, k), abs=1e-9), k
    for k in ("overshoot1_time", "time_second_execute", "time_third_execute"):
        assert getattr(mb, k) == pytest.approx(getattr(ma, k) * np.sqrt(lam), rel=1e-9), k
    assert mb.initial_turning == pytest.approx(ma.initial_turning * lam, rel=1e-9)
    n = min(a.simulation.t.size, b.simulation.t.size)
    np.testing.assert_allclose(b.simulation.t[:n], a.simulation.t[:n] * np.sqrt(lam), rtol=1e-12)
    xa, xb = a.simulation.x[0, :n], b.simulation.x[0, :n]
    np.testing.assert_allclose(xb[:, :2] / lam, xa[:, :2], rtol=1e-9, atol=1e-9 * L1)
    np.testing.assert_allclose(xb[:, 2], xa[:, 2], rtol=0, atol=1e-9)



def test_refinement_from_a_diverging_model_reports_failure():
    """An output-error refinement whose replay diverges (yaw damping of the wrong sign) ends with capped
    residuals: it reports failure and says why, never 'success' (the KVLCC2 kcs-response fit did)."""
    from shipid.datasets import bundled_kcs_logs
    from shipid.identify.batch import OutputErrorRefiner
    from shipid.logs import read_log

    log = read_log(bundled_kcs_logs()[0])
    bad = get_model("kcs-response").with_params({"c2": 50.0})
    ref = OutputErrorRefiner(bad, estimate=["c2"], max_nfev=3).fit([log])
    assert not ref.success_ and "diverges" in ref.message_
    assert not ref.result().success


def test_recipe_steps_are_reported_and_switchable():
    """fit_logs on two bundled KCS turning logs (4.36 m): every sample (tau 0.83 s at 0.1 s logging), a8
    fixed (the linear range ends both turns within 13 s of the start, before the rpm change of one of them),
    no refinement for turning circles alone ('auto'), and the steps land in the result's settings."""
    from shipid.datasets import bundled_kcs_logs
    from shipid.identify.recipe import fit_logs
    from shipid.logs import read_log

    logs = [read_log(p) for p in bundled_kcs_logs()[:2]]
    lines = []
    fit = fit_logs(logs, "kcs-response", n_passes=1, refine="auto", log=lines.append)
    res = fit.result()
    steps = {s["step"]: s for s in res.settings["recipe"]}
    assert steps["ship"]["value"] == {"lpp": pytest.approx(4.36)}
    assert steps["sampling"]["value"] == 1 and "0.827 s" in steps["sampling"]["reason"]
    done = [ln for ln in lines if not ln.endswith(" ...")]  # one line per recorded step; "... ..." lines start a stage
    assert len(done) == len(res.settings["recipe"]) and lines[0].startswith("recipe: ship:")
    assert any(ln.startswith("recipe: running the EKF: 1 pass(es)") for ln in lines)
    assert steps["a8"]["value"] == 0.0 and "constant" in steps["a8"]["reason"]
    assert steps["refinement"]["value"] == "none"
    assert res.model_options["lpp"] == pytest.approx(4.36) and res.method == "ekf"
    with pytest.raises(ValueError, match="refine='both'"):
        fit_logs(logs, "kcs-response", refine="both")


def test_refine_fit_reuses_one_ekf_stage_and_weighs_the_metrics():
    """refine_fit on one EKF stage (bundled KCS turning circle + zigzag, 4.36 m): the metric residuals at
    weight 0 are the output-error refinement exactly; at weight 1 the training metrics move the fit and its
    tactical-diameter error does not grow; the weight is reported in the steps; a bad weight is refused."""
    from shipid.datasets import bundled_kcs_logs
    from shipid.identify.recipe import fit_logs, metric_residuals, refine_fit
    from shipid.logs import read_log

    logs = [read_log(p) for p in bundled_kcs_logs()[1:3]]  # tc +35, zz -10
    ekf = fit_logs(logs, "kcs-response", n_passes=1, refine=None)
    kw = dict(max_nfev=4)
    oe = refine_fit(ekf, logs, "output-error", **kw)
    m0 = refine_fit(ekf, logs, "metrics", metric_weight=0.0, **kw)
    m1 = refine_fit(ekf, logs, "metrics", metric_weight=1.0, **kw)
    assert ekf.refiner is None and [s["step"] for s in ekf.steps][-1] == "refinement"  # the EKF stage untouched
    np.testing.assert_array_equal(m0.refiner.coef_.to_numpy(), oe.refiner.coef_.to_numpy())
    def reason(fit, name):
        return next(s["reason"] for s in fit.steps if s["step"] == name)

    assert "weight 1" in reason(m1, "metric residuals") and "weight 0" in reason(m0, "metric residuals")
    assert m1.result().settings["metric_weight"] == 1.0 and "metric_weight" not in oe.result().settings
    f, used = metric_residuals(ekf.to_model(), logs)
    assert len(used) == 2
    P = np.stack([oe.to_model().params, m1.to_model().params])
    e = np.abs(f(P))  # (2, 3): TD of the turn, overshoots of the zigzag, over their tolerances
    assert not np.allclose(P[0], P[1])
    assert np.sum(e[1] ** 2) <= np.sum(e[0] ** 2) + 1e-9  # the metrics enter the objective
    with pytest.raises(ValueError, match="metric_weight"):
        refine_fit(ekf, logs, "metrics", metric_weight=-1.0)
    with pytest.raises(ValueError, match="mode="):
        refine_fit(ekf, logs, "both")


def test_cli_metric_weight_is_checked(tmp_path, capsys):
    """shipid fit --metric-weight -1: exit 2 with a one-line message naming the option (no fit run)."""
    from shipid.cli import main
    from shipid.datasets import bundled_kcs_logs

    out = tmp_path / "r.json"
    assert main(["fit", str(bundled_kcs_logs()[1]), "--metric-weight", "-1", "-o", str(out), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "--metric-weight -1" in err and "Traceback" not in err and not out.exists()


def test_batched_zigzag_members_are_independent_of_each_other():
    """The metric refinement differentiates closed-loop zigzags by forward differences, all parameter sets in
    one batch.  Members whose rudder reversals fall within rounding of each other used to couple: the event
    locator stopped on |g| < 1e-13 with g a hair below zero and fired the second member a whole step late
    (0.33 deg of overshoot on the MARIN response-nl fit, or a missed reversal: a failed manoeuvre), which
    made that refinement follow the BLAS thread count.  Every member of a batch must give its solo run's
    overshoots, for perturbations down to rounding."""
    model = get_model("mmg", "kvlcc2")
    i = model.param_index("Nr")
    base = model.params.copy()
    P = [base]
    for rel in (1e-13, 1e-12, 1e-11, 1e-10, 1e-9, 1e-8, 1e-6):
        p = base.copy()
        p[i] *= 1.0 + rel
        P.append(p)
    P = np.array(P)
    batch = zigzag(model, 10.0, 10.0, params=P, speed=np.full(len(P), 1.2), first="starboard")
    for b, p in enumerate(P):
        solo = zigzag(model, 10.0, 10.0, params=p, speed=1.2, first="starboard").metrics[0]
        got = batch.metrics[b]
        assert got.success and solo.success
        for k in ("overshoot1_deg", "overshoot2_deg", "time_third_execute"):
            assert getattr(got, k) == pytest.approx(getattr(solo, k), abs=1e-7), (b, k)


def test_identifiable_subset_holds_what_the_solver_cannot_resolve():
    """identifiable_subset: a direction of the scaled Jacobian along which a change of the coefficients by
    their own size moves the cost by less than ftol * cost (singular value below sqrt(2 ftol cost)) is held,
    by subset selection (the column that carries it); a well-conditioned Jacobian keeps every column."""
    from shipid.identify.batch import FTOL, identifiable_subset

    rng = np.random.default_rng(0)
    J = rng.normal(size=(200, 4))
    keep, held, info = identifiable_subset(J, cost=1.0)
    assert list(keep) == [0, 1, 2, 3] and held.size == 0
    assert info["threshold"] == pytest.approx(np.sqrt(2 * FTOL * 1.0))
    assert info["condition"] == pytest.approx(info["condition_kept"]) and np.isfinite(info["condition"])
    # column 3 = column 1 + a change far below the threshold: one of the pair is held, the rest kept
    J2 = np.column_stack([J[:, :3], J[:, 1] + 1e-9 * rng.normal(size=200)])
    keep, held, info = identifiable_subset(J2, cost=1.0)
    assert held.size == 1 and held[0] in (1, 3) and 0 in keep and 2 in keep
    assert info["condition"] > 1e15 and info["condition_kept"] < 1e3
    # the same pair, resolvable: its difference moves the cost by more than ftol * cost
    J3 = np.column_stack([J[:, :3], J[:, 1] + 1e-2 * rng.normal(size=200)])
    assert identifiable_subset(J3, cost=1.0)[1].size == 0
    # a column with no effect at all is held
    J4 = np.column_stack([J, np.zeros(200)])
    assert list(identifiable_subset(J4, cost=1.0)[1]) == [4]


def test_refinement_covariance_is_positive_semidefinite_and_its_condition_finite():
    """The refinement's covariance comes from the SVD of J (the pseudo-inverse of J^T J gave rounding-negative
    eigenvalues at condition ~1e13, which the diagnostics reported as a condition number of ~1e291)."""
    from shipid.datasets import bundled_kcs_logs
    from shipid.identify.recipe import fit_logs, refine_fit
    from shipid.logs import read_log

    logs = [read_log(p) for p in bundled_kcs_logs()[1:3]]
    ekf = fit_logs(logs, "kcs-response", n_passes=1, refine=None)
    ref = refine_fit(ekf, logs, "output-error", max_nfev=3).refiner
    cov = ref.cov_.to_numpy() / np.outer(ref.coef_std_[ref.estimated_], ref.coef_std_[ref.estimated_])
    assert np.linalg.eigvalsh(cov).min() > -1e-9
    cond = ref.diagnostics_["condition_number"]
    assert np.isfinite(cond) and cond < 1e20
    assert ref.subset_ is not None and ref.result().settings["hold_rule"]["ftol"] == 1e-8


def test_cli_refine_all_switches_the_identifiable_subset_off(tmp_path):
    """shipid fit --refine-all: the refinement fits every estimated coefficient and says so in the recipe steps.
    By default the step holds what the solver cannot resolve -- on one constant-rpm turning circle the surge
    term a5 (a unit change moves the cost by less than ftol * cost) -- at its EKF-stage value, reports it with
    the threshold and the condition numbers before/after, and the rest is refined."""
    from shipid.cli import main
    from shipid.datasets import bundled_kcs_logs
    from shipid.identify.result import load_result

    log = str(bundled_kcs_logs()[1])
    base = ["fit", log, "--refine", "output-error", "--max-nfev", "2", "--passes", "1", "--no-progress"]
    assert main([*base, "-o", str(tmp_path / "a.json")]) in (0, 1, 3)
    assert main([*base, "--refine-all", "-o", str(tmp_path / "b.json")]) in (0, 1, 3)
    a, b = load_result(tmp_path / "a.json"), load_result(tmp_path / "b.json")
    step_a = next(s for s in a.settings["recipe"] if s["step"] == "identifiable subset")
    step_b = next(s for s in b.settings["recipe"] if s["step"] == "identifiable subset")
    held = a.settings["held"]
    assert held == step_a["value"] == ["a5"] and "sqrt(2 ftol cost)" in step_a["reason"]
    rule = a.settings["hold_rule"]
    assert rule["ftol"] == 1e-8 and rule["threshold"] > 0 and rule["condition_after"] < rule["condition_before"]
    assert a.coef["a5"] == a.settings["ekf_stage"]["coef"]["a5"] and a.coef_std["a5"] == 0.0
    assert "a5" not in a.settings["estimated"] and "a5" in b.settings["estimated"]
    assert step_b["value"] is None and "off (asked)" in step_b["reason"] and "held" not in b.settings
    assert b.coef_std["a5"] > 0  # refined with the rest: it has an uncertainty of its own


def test_refinement_keeps_the_own_damping_negative():
    """Logs made by a ship whose sway is self-excited (a kcs-response with b1 = +0.02 1/s: its own sway
    damping is b1 at every state): the EKF stage finds b1 > 0 and so does the unconstrained refinement, which
    the recipe then solves again with the own damping kept below -DAMPING_MARGIN U/L at the logged states and
    at rest, and reports both solutions in its steps; b1 lands on (or just beyond) the margin.  ``physical_damping=False``
    keeps the unconstrained fit, and the result's diagnostics say it is not physical."""
    from shipid.identify.diagnostics import DAMPING_MARGIN
    from shipid.identify.recipe import fit_logs, refine_fit
    from shipid.manoeuvres import turning_circle, zigzag

    base = get_model("kcs-response")
    bad = base.with_params({"b1": 0.02})
    rng = np.random.default_rng(1)

    def log_of(run, name):
        x, u = run.simulation.x[-1], run.simulation.u[-1]
        cols = {**{s: x[:, j] for j, s in enumerate(base.state_names)},
                **{s: u[:, j] for j, s in enumerate(base.input_names)}}
        for s in ("u", "v", "r"):
            cols[s] = cols[s] + rng.normal(0.0, 1e-3, cols[s].size)
        return TrialLog.from_arrays(run.simulation.t, name=name, **cols)

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        logs = [log_of(zigzag(bad, 10.0, first="starboard", dt=0.1), "zz"),
                log_of(turning_circle(bad, 35.0, side="starboard", dt=0.1, heading_change_deg=360), "tc")]
        ekf = fit_logs(logs, "kcs-response", n_passes=1, refine=None, lpp=4.36)
        assert ekf.ekf.coef_["b1"] == pytest.approx(0.02, abs=0.002)
        on = refine_fit(ekf, logs, "output-error", max_nfev=20)
        off = refine_fit(ekf, logs, "output-error", max_nfev=20, physical_damping=False)
    step = next(s for s in on.steps if s["step"] == "physical damping")
    assert step["value"] is True and "unconstrained: own damping positive at 100.0 % (v)" in step["reason"]
    U0 = 1.7  # the approach speed of the bundled KCS set
    margins = on.refiner.coef_["b1"] * 4.36 / U0 / DAMPING_MARGIN
    assert -2.0 < margins < -0.95, margins   # on or just beyond the margin (a softened hinge)
    assert f"at rest {on.refiner.coef_['b1']:+.3g} 1/s (v)" in step["reason"]
    assert on.result().diagnostics["damping"]["physical"] is True
    assert "physical damping" not in [s["step"] for s in off.steps]
    assert off.refiner.coef_["b1"] > 0.01
    dmp = off.result().diagnostics["damping"]
    assert dmp["physical"] is False and dmp["v"]["fraction_positive"] == 1.0


def test_speed_scale_of_the_damping_margin():
    """The own-damping margin's speed: the approach speed; the median speed when the logs start from rest (the
    approach speed below a tenth of it, e.g. the Esso Osaka runs); none when nothing moves."""
    from shipid.identify.sampling import _speed_scale

    t = np.arange(200.0)
    moving = TrialLog.from_arrays(t, name="m", u=np.full(200, 2.0), v=np.zeros(200), r=np.zeros(200))
    U, why = _speed_scale([moving])
    assert U == pytest.approx(2.0) and why == "the approach speed"
    u = np.concatenate([np.zeros(30), np.full(170, 0.5)])
    from_rest = TrialLog.from_arrays(t, name="r", u=u, v=np.zeros(200), r=np.zeros(200))
    U, why = _speed_scale([from_rest])
    assert U == pytest.approx(0.5) and "start from rest" in why
    still = TrialLog.from_arrays(t, name="s", u=np.zeros(200), v=np.zeros(200), r=np.zeros(200))
    U, why = _speed_scale([still])
    assert np.isnan(U) and why == "no log moves"


def test_a_ship_that_never_gets_under_way_is_refused_with_the_reason(tmp_path, capsys):
    """A log of a ship that barely moves (0.5 mm/s at most: Froude number 8e-5 at 4.36 m) has no manoeuvre to
    identify: fit_logs and `shipid fit` stop before the filter (which diverged, exit 4) with the speed, the
    Froude number and what to check (exit 2)."""
    import pandas as pd

    from shipid.cli import main
    from shipid.identify.recipe import fit_logs

    rng = np.random.default_rng(3)
    t = np.arange(0.0, 60.0, 0.1)
    df = pd.DataFrame({"time": t, "x": 0.01 * rng.normal(size=t.size), "y": 0.01 * rng.normal(size=t.size),
                       "psi": 0.001 * rng.normal(size=t.size), "u": 0.0005 * np.sin(t), "v": 0.0, "r": 0.0,
                       "delta": np.radians(20.0) * (t > 5), "n": 10.0})
    lg = TrialLog(df, name="moored")
    with pytest.raises(ValueError, match=r"the ship is not under way in any log: its largest speed is 0.0005 m/s "
                                         r"\(Froude number 7.6e-05 at Lpp 4.36 m, below 0.01\)"):
        fit_logs([lg], "kcs-response", lpp=4.36)
    p = tmp_path / "moored.csv"
    df.to_csv(p, index=False)
    assert main(["fit", str(p), "--model", "kcs-response", "--lpp", "4.36", "--no-consistency-checks",
                 "--no-progress", "-o", str(tmp_path / "r.json")]) == 2
    assert "not under way" in capsys.readouterr().err and not (tmp_path / "r.json").exists()
