"""Every public result class answers the same contract: ``success``, ``message``, ``summary()`` -> DataFrame,
``to_pandas()`` -> DataFrame, ``plot(ax=None)`` -> axes (Agg), and a compact ``_repr_html_``."""
from __future__ import annotations

import warnings

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
import pytest  # noqa: E402

import shipid  # noqa: E402
from shipid.models import get_model  # noqa: E402

HTML_LIMIT = 20_000  # characters: a notebook card, not a dump of the arrays
X0 = np.array([0, 0, 0, 1.0, 0, 0])  # the synthetic log's initial state


# ----------------------------------------------------------------------------- cheap instances
def _turn_log(n: int = 121, dt: float = 0.5):
    """A short synthetic turning log of the KCS model (truth parameters), as a TrialLog."""
    from shipid.logs import TrialLog

    m = get_model("kcs-response", "synthetic-truth")
    t = np.arange(n) * dt
    delta = np.where(t > 5, np.radians(20.0), 0.0)
    U = np.column_stack([delta, np.full(n, 10.0)])
    sim = shipid.simulate(m, np.array([0, 0, 0, 1.0, 0, 0]), t, U)
    cols = {k: sim.state(k) for k in m.state_names}
    return TrialLog.from_arrays(t, name="turn", ship={"lpp": 4.36}, delta=delta, n=np.full(n, 10.0), **cols)


def _fit_result():
    from shipid.identify.result import FitResult

    m = get_model("kcs-response", "synthetic-truth")
    est = list(m.param_names[:4])
    coef = dict(zip(m.param_names, map(float, m.params)))
    std = {k: (0.05 * abs(v) if k in est else 0.0) for k, v in coef.items()}
    cov = pd.DataFrame(np.diag([std[k] ** 2 for k in est]), index=est, columns=est)
    return FitResult(model=m.name, coef=coef, coef_std=std, cov=cov, inputs=[{"name": "turn"}],
                     diagnostics={"warnings": []}, model_options=m.options(), ship={"lpp": 4.36})


@pytest.fixture(scope="module")
def log():
    return _turn_log()


@pytest.fixture(scope="module")
def ekf(log):
    from shipid.identify import EKFIdentifier

    m = get_model("kcs-response", "synthetic-truth")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return EKFIdentifier(m, estimate=list(m.param_names[:3]), n_passes=1, init="model").fit([log])


def build(name, log, ekf):
    """One instance of the result class ``name``, from small synthetic inputs."""
    m = get_model("kcs-response", "synthetic-truth")
    if name == "SimulationResult":
        t = np.linspace(0, 10, 21)
        return shipid.simulate(m, np.array([0, 0, 0, 1.0, 0, 0]), t, np.tile([0.1, 10.0], (21, 1)))
    if name == "replay":
        return shipid.simulate.replay(m, log)
    if name == "TrialLog":
        return log
    if name == "ConsistencyResult":
        from shipid.logs.consistency import ConsistencyResult, Finding

        return ConsistencyResult("turn", [Finding("warning", "rudder_turn", ("delta", "r"), "a warning")])
    if name == "turning":
        from shipid.manoeuvres import turning_circle

        return turning_circle(m, 35.0, side="starboard", heading_change_deg=200.0)
    if name == "zigzag":
        from shipid.manoeuvres import zigzag

        return zigzag(m, 10.0, first="starboard", n_executes=2)
    if name == "LogValidation":
        from shipid.validation import validate_logs

        return validate_logs(m, [log], closed_loop=False)[0]
    if name == "HorizonResult":
        from shipid.validation import dead_reckoning, horizon_prediction

        return horizon_prediction(dead_reckoning(), log, horizons=(5.0, 10.0))
    if name == "FitResult":
        return _fit_result()
    if name == "EKFIdentifier":
        return ekf
    if name == "RecipeFit":
        from shipid.identify.recipe import RecipeFit

        return RecipeFit(ekf=ekf, steps=[{"step": "sampling", "value": 1, "reason": "every sample"}], logs=[log],
                         lpp=4.36)
    if name == "PosteriorSamples":
        from shipid.uncertainty import PosteriorSamples

        rng = np.random.default_rng(0)
        names = ["a", "b", "c"]
        diag = {k: dict.fromkeys(names, 1.0) for k in ("tau", "ess", "rhat")}
        return PosteriorSamples("kcs-response", names, rng.normal(size=(200, 3)), diag, True, "converged")
    if name == "ManoeuvrePrediction":
        from shipid.uncertainty import predict_manoeuvres

        return predict_manoeuvres(_fit_result(), ["turning:35"], draws=3, seed=1)
    if name == "ControlResult":  # full throttle on a coarse grid: evaluated, not optimised (cheap)
        from shipid.control import ControlResult, paper_problem

        pr = paper_problem(1, n_intervals=6, substeps=2)
        u = np.tile(pr.u_hi, (pr.n_intervals, 1))
        return ControlResult(pr, "direct-slsqp", u, 30.0, nit=0, nfev=1, optimizer_success=True,
                             optimizer_message="evaluated", wall_time=0.0)
    if name == "ZermeloResult":
        from shipid.routing import ZermeloResult

        t = np.linspace(0.0, 2.0, 9)
        xy = np.column_stack([t, 0.5 * t])
        return ZermeloResult(t, xy, np.full(9, 0.4), 2.0, True, 0.0, True, 0, "reached", "pmp")
    if name in ("PSOResult", "PlanResult", "Voyage"):
        from shipid.routing import paper_scenario, plan_eopso, sail

        p = plan_eopso(paper_scenario(), n_particles=6, max_iter=4, rng=0)
        return {"PSOResult": p.opt, "PlanResult": p, "Voyage": sail(paper_scenario(), p.points)}[name]
    if name == "OCPSOResult":
        from shipid.routing import paper_scenario, plan_ocpso

        return plan_ocpso(paper_scenario(), n_particles=6, max_iter=4, rng=0)
    if name == "LaunchResult":
        from shipid.glider import launch

        return launch([4.0, 5.0], 30.0, 5.0, 0.0)
    if name == "GliderOptimum":
        from shipid.glider.optimise import GliderOptimum

        row = pd.Series({"speed_m_s": 5.0, "angle_deg": 30.0, "fin_deg": 5.0, "cg_m": 0.0, "max_depth_m": 2.0,
                         "horizontal_m": 6.0, "exit_angle_deg": 40.0, "surfaced": True})
        return GliderOptimum(x={"speed": 5.0}, objective=0.5, launch=row, depth_ref=2.0, horizontal_ref=6.0,
                             grid_best=row, success=True, status=0, message="ok", nfev=10, nit=2)
    if name == "CampaignResult":
        from shipid.campaign import CampaignResult

        return CampaignResult({"n_members": 2, "n_failed": 1, "engine": "serial", "members": [
            {"name": "a", "type": "fit", "ok": True, "success": True, "seconds": 1.0, "error": None, "files": ["a/result.json"]},
            {"name": "b", "type": "sweep", "ok": False, "error": "bad file", "seconds": 0.1, "files": []}]})
    raise KeyError(name)


CLASSES = ["SimulationResult", "replay", "TrialLog", "ConsistencyResult", "turning", "zigzag", "LogValidation",
           "HorizonResult", "FitResult", "EKFIdentifier", "RecipeFit", "PosteriorSamples", "ManoeuvrePrediction",
           "ControlResult", "ZermeloResult", "PSOResult", "PlanResult", "Voyage", "OCPSOResult", "LaunchResult",
           "GliderOptimum", "CampaignResult"]


@pytest.mark.parametrize("name", CLASSES)
def test_result_contract(name, log, ekf):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        r = build(name, log, ekf)
    assert isinstance(r.success, (bool, np.bool_)), name
    assert isinstance(r.message, str), name
    s = r.summary()
    assert isinstance(s, pd.DataFrame) and len(s) > 0, name
    assert isinstance(r.to_pandas(), pd.DataFrame), name
    ax = r.plot()
    first = np.ravel(np.asarray(ax, dtype=object))[0]
    assert isinstance(first, matplotlib.axes.Axes), name
    _, given = plt.subplots()
    out = r.plot(ax=given)
    assert given in list(np.ravel(np.asarray(out, dtype=object))), name  # draws where it is told
    plt.close("all")
    h = r._repr_html_()
    assert isinstance(h, str) and h.startswith("<div") and len(h) < HTML_LIMIT, (name, len(h))
    assert (">success</span>" if r.success else ">not successful</span>") in h, name


def test_angles_are_plotted_in_degrees(log):
    m = get_model("kcs-response", "synthetic-truth")
    sim = shipid.simulate.replay(m, log)
    axs = sim.plot()
    labels = [a.get_ylabel() for a in axs]
    assert "psi [deg]" in labels and "r [deg/s]" in labels and "delta [deg]" in labels
    psi_ax = axs[labels.index("psi [deg]")]
    measured, simulated = psi_ax.get_lines()[:2]
    assert measured.get_label() == "measured" and simulated.get_label() == "simulated"
    assert np.nanmax(measured.get_ydata()) == pytest.approx(np.degrees(np.nanmax(log["psi"])))
    plt.close("all")


def test_replay_summary_compares_with_the_log(log):
    m = get_model("kcs-response", "synthetic-truth")
    s = shipid.simulate.replay(m, log, x0=X0, input_hold="zoh").summary()  # the log was made by this model, inputs held
    assert s.loc["psi", "unit"] == "deg" and s.loc["psi", "rmse"] < 1e-3
    assert s.loc["track", "unit"] == "m"
    off = shipid.simulate.replay(m.with_params(m.params * 1.2), log, x0=X0, input_hold="zoh").summary()
    assert off.loc["psi", "rmse"] > 0.1  # degrees


def test_repr_html_shows_the_verdict_grade_and_escapes():
    r = _fit_result()
    r.message = "coefficient <a1> poorly determined & correlated"

    class Verdict:
        grade = "model_error"

    r.verdict = Verdict()
    h = r._repr_html_()
    assert "verdict <b>model_error</b>" in h and "&lt;a1&gt;" in h and "<a1>" not in h
    assert r.summary().attrs["verdict"] == "model_error"


def test_recipe_fit_success_is_one_truth(ekf):
    from shipid.identify.recipe import RecipeFit

    class FailedRefiner:
        success_ = False
        message_ = "refinement failed: cost did not decrease"
        coef_ = ekf.coef_
        coef_std_ = ekf.coef_std_
        estimated_ = ekf.estimated_

    fit = RecipeFit(ekf=ekf, refiner=FailedRefiner())
    assert fit.success is False and fit.success_ is False and "refinement failed" in fit.message
    ekf_ok = RecipeFit(ekf=ekf)
    assert ekf_ok.success == ekf_ok.success_ == bool(ekf.success_)


def test_simulate_is_the_module_and_callable():
    import importlib

    mod = importlib.import_module("shipid.simulate")
    assert shipid.simulate is mod and callable(shipid.simulate)
    assert shipid.simulate.replay is mod.replay and shipid.simulate.simulate is mod.simulate
    m = get_model("kcs-response", "synthetic-truth")
    t = np.linspace(0, 2, 5)
    a = shipid.simulate(m, np.array([0, 0, 0, 1.0, 0, 0]), t, np.tile([0.1, 10.0], (5, 1)))
    b = shipid.simulate.simulate(m, np.array([0, 0, 0, 1.0, 0, 0]), t, np.tile([0.1, 10.0], (5, 1)))
    np.testing.assert_array_equal(a.x, b.x)


def test_fit_cards_carry_the_grade_and_an_unfitted_identifier_says_so(ekf):
    from shipid.identify import EKFIdentifier
    from shipid.identify.recipe import RecipeFit

    from shipid.results import verdict_grade

    for r in (ekf, ekf.result(), RecipeFit(ekf=ekf)):  # each its own grade (a recipe judges its logs too)
        grade = verdict_grade(r)
        assert grade in ("consistent", "model_error", "defect", "diverged")
        assert f"verdict <b>{grade}</b>" in r._repr_html_() and r.summary().attrs["verdict"] == grade
    bare = EKFIdentifier(get_model("kcs-response"))
    h = bare._repr_html_()
    assert bare.success is False and "not fitted" in h and len(h) < HTML_LIMIT
