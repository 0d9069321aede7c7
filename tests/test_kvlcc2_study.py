"""Hold-out validation on the measured MARIN KVLCC2 runs (issue 3, point 5).

Fit on tc+-35 and zz+-10, predict zz+-20 with each model's closed-loop zigzag.
Goals: first overshoot within 2 deg and second within 3 deg on the held-out
zigzags, tactical diameter within 5 % on the training turns.  The tests assert
what each model achieves (measured here) and show where a goal is missed; the
numbers are in docs/validation.md and the issue notes.
"""
from __future__ import annotations

import numpy as np
import pytest

from shipid.studies import kvlcc2 as ks


@pytest.fixture(scope="module")
def runs(request):
    from conftest import MARIN_DIR

    if not MARIN_DIR.is_dir():
        pytest.skip(f"measured KVLCC2 data not found at {MARIN_DIR} (../shared/data/kvlcc2_marin beside the repo)")
    return ks.load_runs(MARIN_DIR), ks.load_runs(MARIN_DIR, decimate=4)


@pytest.fixture(scope="module")
def fitted(runs):
    """Fits shared by the tests of this module (the kcs-response fit is also response-nl's start)."""
    _, dec = runs
    cache = {}

    def get(name):
        if name not in cache:
            start = None
            if name == "response-nl":
                seed = get("kcs-response").coef_
                start = {k: float(seed.get(k, 0.0)) for k in ks.DEFAULT_SETUPS[name]()[0].param_names}
            if name == "mmg-ekf":  # the EKF stage alone (fit_model(..., refine=None); the default before)
                cache[name] = ks.fit_model("mmg", dec, refine=None)
            elif name == "mmg":  # = fit_model("mmg", dec): the EKF stage, then the default refinement
                cache[name] = ks.refine_fit(get("mmg-ekf"), dec, **ks.DEFAULT_REFINE["mmg"])
            else:
                cache[name] = ks.fit_model(name, dec, start=start)
        return cache[name]

    return get


def _evaluated(fit, full):
    """The fit's hold-out table (printed for the test log) and its tactical-diameter errors [%] by run."""
    assert fit.success_, fit.message_
    tab = ks.evaluate(fit.result(), full)
    print(tab.round(3).to_string())
    return tab, tab[(tab.metric == "tactical_diameter_L")].set_index("run")["rel_error_%"]


def _err(table, run, metric):
    row = table[(table.run == run) & (table.metric == metric)]
    return float(row["error"].iloc[0]) if row["error"].notna().all() else np.nan


def test_symmetric_models_cannot_meet_5_percent_on_both_turns(runs):
    """The measured tactical diameters differ by 8.5 % between sides: a port/starboard symmetric
    model misses one of them by at least (3.33 - 3.07) / 2 / 3.2 = 4.1 %."""
    full, _ = runs
    from shipid.manoeuvres import metrics

    td = {k: metrics(full[k]).to_dict()["tactical_diameter_L"] for k in ("tc_35", "tc_-35")}
    spread = abs(td["tc_35"] - td["tc_-35"]) / np.mean(list(td.values()))
    assert 0.07 < spread < 0.10


def test_neutral_rudder_angle_of_the_approach_phases(runs):
    """The rudder that holds the ship straight before each execute: +0.92 deg (models' sign) pooled over
    the four training runs, on the side that makes the turn with negative rudder (MARIN tc_35) the
    tighter one -- as measured (3.07 L vs 3.33 L)."""
    full, dec = runs
    d0 = np.degrees(ks.neutral_rudder_angle(full))
    assert 0.85 < d0 < 1.0, d0
    assert abs(np.degrees(ks.neutral_rudder_angle(dec)) - d0) < 0.05
    assert abs(full["tc_35"]["delta"].min() - np.radians(-35.0)) < np.radians(0.3)  # tc_35 is the negative-rudder turn
    with pytest.raises(ValueError, match="no approach phase"):
        ks.neutral_rudder_angle({"x": type(full["tc_35"]).from_arrays(np.arange(10.0), name="x", delta=np.linspace(0, 0.5, 10))},
                                names=("x",))


def test_common_grid_pads_shorter_runs_with_missing_samples():
    """Two runs of different lengths and time stamps on one grid from each run's start: interpolated
    inside, measured channels NaN past a run's end, inputs held; bad step refused."""
    from shipid.logs import TrialLog

    t1, t2 = 100.0 + np.arange(0.0, 10.01, 0.5), np.arange(0.0, 4.01, 0.25)
    runs = {"a": TrialLog.from_arrays(t1, name="a", u=2.0 + 0.1 * (t1 - 100), delta=0.01 * (t1 - 100), n=np.full(t1.size, 1.5)),
            "b": TrialLog.from_arrays(t2, name="b", u=3.0 - 0.2 * t2, delta=0.02 * t2, n=np.full(t2.size, 1.0))}
    a, b = ks.common_grid(runs, ("a", "b"), dt=1.0)
    np.testing.assert_allclose(a.time, np.arange(11.0))
    np.testing.assert_array_equal(a.time, b.time)
    np.testing.assert_allclose(a["u"], 2.0 + 0.1 * a.time)
    np.testing.assert_allclose(b["u"][:5], 3.0 - 0.2 * np.arange(5.0))
    assert np.isnan(b["u"][5:]).all() and b["delta"][5:] == pytest.approx(0.08) and (b["n"] == 1.0).all()
    with pytest.raises(ValueError, match="dt must be a positive"):
        ks.common_grid(runs, ("a",), dt=0.0)


def test_refine_options_are_checked_before_fitting(runs):
    _, dec = runs
    with pytest.raises(ValueError, match="refine='ekf'"):
        ks.fit_model("mmg", dec, refine="ekf")
    with pytest.raises(ValueError, match="how='both'"):
        ks.refine_fit(None, dec, how="both")
    assert ks.DEFAULT_REFINE["mmg"]["how"] in ks.REFINE_MODES


def test_metric_residuals_match_evaluate_and_batch(runs):
    """The closed-loop metric errors the refinement fits, for the published MMG set: a batch of parameter
    sets gives the single-set rows, and the zigzag errors equal evaluate()'s divided by the goal tolerances."""
    from shipid.models import get_model

    _, dec = runs
    pub = get_model("mmg", "kvlcc2", lpp=320.0)
    f = ks.metric_residuals(pub, dec, names=("tc_35", "zz_10"))
    one = f(pub.params)
    P = np.stack([pub.params, pub.params * np.where(np.array(pub.param_names) == "Nr", 1.05, 1.0)])
    both = f(P)
    assert one.shape == (3,) and both.shape == (2, 3)
    np.testing.assert_allclose(both[0], one, atol=1e-4)  # 1e-4 goal tolerances: the batch ends its chunks elsewhere
    assert np.all(np.abs(both[1] - one) > 1e-3)  # Nr moves every metric
    tab = ks.evaluate(pub, dec, names=("zz_10",)).set_index("metric")["error"]
    np.testing.assert_allclose(one[1:], [tab["overshoot1_deg"] / 2.0, tab["overshoot2_deg"] / 3.0], atol=1e-6)


@pytest.mark.slow
def test_mmg_default_metric_refinement_meets_five_of_six_goals(runs, fitted):
    """The default mmg fit: the EKF stage below, then an output-error refinement on the training runs
    (each run weighing equally) whose objective also holds the training runs' closed-loop metric
    errors (tactical diameters of tc+-35, overshoots of zz+-10) and frees delta0 from its measured
    +0.92 deg (-> +0.30 deg).  Chosen among the measured variants by the training runs' metrics only.
    Both turns within 5 % (+3.5 %, -3.7 %); held-out zz_20 first / second overshoot +2.4 / -0.1 deg,
    zz_-20 +0.2 / +1.8 deg: five of the six goals, zz_20's first overshoot misses 2 deg by 0.4 deg."""
    full, _ = runs
    fit = fitted("mmg")
    assert [m["name"] for m in fit.logs_] == list(ks.TRAIN)  # the held-out runs never enter the fit
    # converged (least_squares' xtol test) after ~35 evaluations; cost 16.4 -> ~2.2
    assert fit.nfev_ < ks.DEFAULT_REFINE["mmg"]["max_nfev"] and fit.cost_ < 0.2 * fit.cost_start_
    assert np.degrees(fit.coef_["delta0"]) == pytest.approx(0.30, abs=0.1)
    tab, rel = _evaluated(fit, full)
    assert abs(rel["tc_35"]) < 5.0 and abs(rel["tc_-35"]) < 5.0, rel          # goal met on both
    assert abs(_err(tab, "zz_20", "overshoot2_deg")) < 3.0                     # goal met
    assert abs(_err(tab, "zz_-20", "overshoot1_deg")) < 2.0                    # goal met
    assert abs(_err(tab, "zz_-20", "overshoot2_deg")) < 3.0                    # goal met
    assert 1.4 < _err(tab, "zz_20", "overshoot1_deg") < 3.4                    # goal missed by ~0.4 deg
    for run in ("zz_10", "zz_-10"):                                            # training zigzags: within 4 deg
        assert abs(_err(tab, run, "overshoot1_deg")) < 3.0 and abs(_err(tab, run, "overshoot2_deg")) < 4.0


@pytest.mark.slow
def test_mmg_refit_with_neutral_angle_meets_the_turning_goal(runs, fitted):
    """The EKF stage of the default (``fit_model("mmg", runs, refine=None)``, the default before): MMG with the measured neutral angle (delta0 = +0.92 deg from the approach phases, fixed) and the
    hull derivatives and resistance re-identified: the tactical diameters of both training turns are
    within the 5 % goal (+0.4 %, -4.9 %); the held-out first overshoots are +6.7 / +0.2 deg and the
    second +1.5 / +7.7 deg -- the 2 / 3 deg goals are met on one run each (measured, asserted as such).
    With delta0 estimated by the EKF instead it lands at -0.9 deg (wrong side) and the turns miss by
    +5.9 / -5.3 % (docs/validation.md)."""
    full, _ = runs
    fit = fitted("mmg-ekf")
    tab, rel = _evaluated(fit, full)
    assert np.degrees(fit.coef_["delta0"]) == pytest.approx(0.915, abs=0.01)
    assert abs(rel["tc_35"]) < 1.0 and abs(rel["tc_-35"]) < 5.0, rel          # goal met on both
    assert abs(_err(tab, "zz_-20", "overshoot1_deg")) < 2.0                    # goal met
    assert abs(_err(tab, "zz_20", "overshoot2_deg")) < 3.0                     # goal met
    assert 6.0 < _err(tab, "zz_20", "overshoot1_deg") < 7.5                    # goal missed by ~4.7 deg
    assert 7.0 < _err(tab, "zz_-20", "overshoot2_deg") < 8.5                   # goal missed by ~4.7 deg


@pytest.mark.slow
def test_seed_linear_model_cannot_do_both(runs, fitted):
    """kcs-response (the seed's linear sway/yaw) fitted to turns and zigzags together: it follows
    the zigzags (held-out first overshoots within 5 deg; measured +1.0 / +3.9 deg) but turns far
    too tightly (tactical diameter 33 % / 44 % small) -- the issue's warning, on measured data."""
    full, _ = runs
    tab, rel = _evaluated(fitted("kcs-response"), full)
    assert rel["tc_35"] < -25 and rel["tc_-35"] < -25, rel
    for run in ks.TEST:
        assert abs(_err(tab, run, "overshoot1_deg")) < 5.0


@pytest.mark.slow
def test_response_nl_predicts_heldout_zigzags(runs, fitted):
    """response-nl (the seed's terms + non-linear damping, asymmetry terms b0, c0 held at 0), started
    from the kcs-response fit: port/starboard symmetric, so it matches the port turn (TD +1.2 %) and
    misses the 8.5 % wider starboard turn (-7.5 %); held-out first overshoots -3.2 / -0.4 deg, second
    -1.5 / -4.8 deg (the 2 / 3 deg goals are met on one of the two runs each)."""
    full, _ = runs
    tab, rel = _evaluated(fitted("response-nl"), full)
    assert abs(rel["tc_35"]) < 2.0 and -8.5 < rel["tc_-35"] < -6.5, rel
    assert abs(_err(tab, "zz_-20", "overshoot1_deg")) < 2.0                    # goal met
    assert abs(_err(tab, "zz_20", "overshoot2_deg")) < 3.0                     # goal met
    assert -4.0 < _err(tab, "zz_20", "overshoot1_deg") < -2.5                  # goal missed by ~1.2 deg
    assert -5.5 < _err(tab, "zz_-20", "overshoot2_deg") < -4.0                 # goal missed by ~1.8 deg
