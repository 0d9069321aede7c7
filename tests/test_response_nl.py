"""response-nl: analytic Jacobians, reduction to kcs-response, exact recovery by the equation-error fit,
and the default parameter set against the MMG KCS manoeuvres it was fitted to."""
from __future__ import annotations

import json

import numpy as np
import pytest

from shipid.manoeuvres import turning_circle, zigzag
from shipid.models import get_model
from shipid.models.base import Model
from shipid.identify.from_model import fit_to_model
from shipid.models.response_nl import ASYM_NAMES, EXTRA_NAMES, SEED_NAMES, ResponseNLModel


def _point(rng, batch=()):
    x = rng.normal(size=batch + (6,)) * 0.3
    x[..., 3] = 1.5 + 0.1 * rng.normal(size=batch)
    u = np.stack([0.3 * rng.normal(size=batch), 10 + rng.normal(size=batch)], axis=-1)
    return x, u


def test_jacobians_with_every_term_active():
    rng = np.random.default_rng(7)
    m = ResponseNLModel(rng.normal(size=29) * 0.3)
    for _ in range(5):
        x, u = _point(rng, (3,))
        for which in ("x", "u", "p"):
            J = getattr(m, f"jac_{which}")(0.0, x, u)
            fd = Model._fd(m, 0.0, x, u, np.broadcast_to(m.params, (3, 29)).copy(), which)
            np.testing.assert_allclose(J, fd, rtol=1e-6, atol=1e-8, err_msg=which)


def test_reduces_to_kcs_response_when_the_new_terms_are_zero():
    seed = get_model("kcs-response")
    nl = ResponseNLModel({**dict(zip(SEED_NAMES, seed.params)), **{k: 0.0 for k in EXTRA_NAMES + ASYM_NAMES}})
    rng = np.random.default_rng(8)
    x, u = _point(rng, (10,))
    np.testing.assert_allclose(nl.rhs(0.0, x, u), seed.rhs(0.0, x, u), rtol=1e-14, atol=1e-15)
    assert list(nl.param_names[:16]) == list(seed.param_names)


def test_equation_error_fit_recovers_its_own_coefficients():
    """Synthetic truth: manoeuvres of response-nl itself; the linear equation-error fit must return the
    truth exactly (to rounding), which checks regressors, sample assembly and the solve."""
    truth = get_model("response-nl")
    fitted, info = fit_to_model(truth, speeds=(1.5, 1.9), turning_rudders=(15.0, 35.0), zigzags=(20.0,),
                                output_error=False, heading_change_deg=200.0)
    np.testing.assert_allclose(fitted.params, truth.params, rtol=1e-6, atol=1e-9)
    assert info["n_samples"] > 1000 and info["settings"]["free"] == list(truth.param_names)


@pytest.fixture(scope="module")
def kcs_truth_and_default():
    return get_model("mmg", "kcs"), get_model("response-nl")


def test_default_set_documents_its_recipe(kcs_truth_and_default):
    _, nl = kcs_truth_and_default
    ps = nl.parameter_set("mmg-kcs-fit")
    assert "fit_to_model" in ps.source and ps.extra["operating_point"]["lpp_m"] == pytest.approx(4.36)
    assert ps.extra["fit"]["settings"]["truth"].startswith("mmg")
    json.dumps(ps.extra)  # plain JSON


def test_default_set_reproduces_mmg_kcs_turns(kcs_truth_and_default):
    """35 and 20 deg turns at 1.7 m/s: tactical diameter within the recorded accuracy of the fit
    (the MMG KCS set is port/starboard asymmetric, response-nl is symmetric: compared with the mean)."""
    truth, nl = kcs_truth_and_default
    acc = nl.parameter_set("mmg-kcs-fit").extra["fit"]["accuracy"]
    for rud in (20.0, 35.0):
        t = turning_circle(truth, rud, speed=1.7, side="both")
        f = turning_circle(nl, rud, speed=1.7, side="starboard")
        td_t = np.mean([m.tactical_diameter_L for m in t.metrics])
        td_f = f.metrics[0].tactical_diameter_L
        rel = abs(td_f / td_t - 1)
        assert rel <= acc["tactical_diameter_rel_max"] + 1e-3, (rud, td_f, td_t)


def test_default_set_reproduces_mmg_kcs_zigzags(kcs_truth_and_default):
    truth, nl = kcs_truth_and_default
    acc = nl.parameter_set("mmg-kcs-fit").extra["fit"]["accuracy"]
    for z in (10.0, 20.0):
        t = zigzag(truth, z, speed=1.7, first="both")
        f = zigzag(nl, z, speed=1.7, first="starboard")
        o1 = np.mean([m.overshoot1_deg for m in t.metrics])
        assert abs(f.metrics[0].overshoot1_deg - o1) <= acc["overshoot1_abs_deg_max"] + 0.05, (z, f.metrics[0].overshoot1_deg, o1)



@pytest.mark.slow
def test_output_error_refinement_recovers_its_own_coefficients():
    """Output-error stage (the identifier's OutputErrorRefiner with exact RK4 tangents) started 3-5 %
    away from the truth on response-nl's own noise-free manoeuvres, asymmetry terms included: it must
    return the truth to rounding.  One speed at constant rps: a8 (u n) is collinear with a1 (u), so it
    is held at its true value; every sample is used (decimate=1) so that the replay with sampled inputs
    reproduces the truth's runs exactly."""
    truth = get_model("response-nl").with_params({"b0": 2.7e-6, "c0": -1.4e-5})  # ~1 deg neutral angle
    rng = np.random.default_rng(3)
    start = truth.params * (1 + rng.uniform(0.03, 0.05, truth.np) * rng.choice([-1, 1], truth.np))
    start[truth.param_index("a8")] = truth.params[truth.param_index("a8")]
    free = [k for k in truth.param_names if k != "a8"]
    fitted, info = fit_to_model(truth, speeds=(1.7,), turning_rudders=(35.0,), zigzags=(20.0,), free=free,
                                heading_change_deg=120.0, decimate=1, p0=start, max_nfev=15)
    assert info["success"] and info["cost"][1] < 1e-20 * info["cost"][0], info
    np.testing.assert_allclose(fitted.params, truth.params, rtol=1e-8, atol=1e-14)


def test_prime_round_trip_and_froude_similarity():
    """A model scaled from the 4.36 m KCS model to 320 m predicts the same manoeuvre: positions x lam,
    times x sqrt(lam), speeds x sqrt(lam), rates and rps / sqrt(lam) (RK4 on the scaled time grid is
    exactly similar, so to rounding); the prime coefficients are unchanged and round-trip."""
    from shipid.scaling import scale_inputs, scale_states, scale_time
    from shipid.simulate import simulate

    small = get_model("response-nl").with_params({"b0": 2.7e-6, "c0": -1.4e-5})
    assert small.lpp == pytest.approx(4.36)
    big = small.scaled(320.0)
    lam = 320.0 / 4.36
    assert big.lpp == 320.0 and big.design_speed == pytest.approx(small.design_speed * np.sqrt(lam))
    assert big.rudder_rate == pytest.approx(small.rudder_rate / np.sqrt(lam))
    pr_s, pr_b = small.to_prime(), big.to_prime()
    for k in small.param_names:
        assert pr_b[k] == pytest.approx(pr_s[k], rel=1e-12, abs=1e-300), k
    np.testing.assert_allclose(ResponseNLModel.from_prime(pr_s, 4.36).params, small.params, rtol=1e-13)
    # the named set scaled on construction equals the scaled model
    np.testing.assert_allclose(ResponseNLModel(lpp=320.0).params, get_model("response-nl").scaled(320.0).params,
                               rtol=1e-13)
    z = zigzag(small, 20.0, speed=1.7, first="starboard").simulation
    t, x0, U = z.t, z.x[0, 0], z.u[0]
    res_s = simulate(small, x0, t, U)
    res_b = simulate(big, scale_states(x0, small.state_names, lam), scale_time(t, lam),
                     scale_inputs(U, small.input_names, lam))
    np.testing.assert_allclose(res_b.x, scale_states(res_s.x, small.state_names, lam), rtol=1e-9, atol=1e-9)
    assert np.ptp(res_s.x[:, 2]) > 0.5  # a real manoeuvre (heading swings of tens of degrees)
    # a different length is not similar
    other = simulate(small.scaled(160.0), scale_states(x0, small.state_names, lam), scale_time(t, lam),
                     scale_inputs(U, small.input_names, lam))
    assert np.abs(other.x[:, 1] - res_b.x[:, 1]).max() > 1.0


def test_refiner_tangent_and_forward_difference_agree_on_several_logs():
    """The identifier's OutputErrorRefiner as fit_to_model uses it, on two logs with one time grid (one
    batch) and their default initial states: the exact-tangent and the forward-difference Jacobians
    take the same steps (same coefficients and covariance after two evaluations)."""
    from shipid.identify.batch import OutputErrorRefiner
    from shipid.simulate import simulate
    from shipid.logs import TrialLog

    truth = get_model("response-nl").with_params({"b0": 2.7e-6, "c0": -1.4e-5})
    sim = zigzag(truth, 20.0, speed=1.7, first="both").simulation
    # logs every 4th sample; states re-simulated with those inputs linear between samples (the
    # refiner's default input model, first-order hold), so the truth reproduces them exactly
    t, U = sim.t[::4], sim.u[:, ::4]
    X = simulate(truth, sim.x[:, 0], t, U, input_hold="foh").x
    logs = [TrialLog.from_arrays(t, name=f"z{b}", **dict(zip(truth.state_names, X[b].T)),
                                 **dict(zip(truth.input_names, U[b].T))) for b in range(2)]
    start = truth.with_params({k: truth.params_series()[k] * 1.05 for k in ("c2", "c3", "c0")})
    out = {}
    for mode in ("fd", "tangent"):
        out[mode] = OutputErrorRefiner(start, estimate=["c2", "c3", "c0"], channels=["r", "psi"],
                                       meas_std={"r": 0.01, "psi": 0.01}, max_nfev=2, jacobian=mode).fit(logs)
    np.testing.assert_allclose(out["tangent"].coef_, out["fd"].coef_, rtol=1e-5)
    np.testing.assert_allclose(out["tangent"].cov_, out["fd"].cov_, rtol=1e-3)
    assert out["tangent"].cost_ < 0.1 * out["tangent"].cost_start_
