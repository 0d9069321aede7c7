"""Leg speed/power models: the USV curves of Li et al. and the shipid-model plug-in."""
import numpy as np
import pytest

from shipid.models import get_model
from shipid.routing.energy import ModelSpeedPower, PaperUSVModel, steady_surge_speed


def test_paper_usv_equilibrium_holds_everywhere():
    m = PaperUSVModel()
    rng = np.random.default_rng(0)
    c = rng.uniform(-1.5, 1.5, 500)
    a = rng.uniform(-12.0, 12.0, 500)  # includes tail winds faster than the boat
    us, P, w = m.leg(c, a)
    v = w + c + a
    Ft = 0.0076 * w**2 - 2.654 * w + 17.024
    resid = Ft - 3.9 * w * np.abs(w) - 0.02 * v * np.abs(v)
    np.testing.assert_allclose(resid, 0.0, atol=1e-10)
    np.testing.assert_allclose(us, w + c)
    np.testing.assert_allclose(P, -39.5 * w + 850.0)
    assert np.all(w > 0)


def test_paper_usv_still_water_speed():
    us, P, w = PaperUSVModel().leg(0.0, 0.0)
    # 3.92 w^2 + 2.654 w - 17.024 + ... = 0 with Fw = 0.02 w^2: (3.9 + 0.02 - 0.0076) w^2 + 2.654 w - 17.024 = 0
    A, B, C = 3.9 + 0.02 - 0.0076, 2.654, -17.024
    assert w == pytest.approx((-B + np.sqrt(B * B - 4 * A * C)) / (2 * A), rel=1e-12)
    assert us == pytest.approx(1.7742, abs=1e-4)
    assert P == pytest.approx(850 - 39.5 * 1.77419, abs=1e-3)


def test_steady_surge_speed_of_kcs_response_is_analytic():
    model = get_model("kcs-response")  # synthetic-truth set
    p = dict(zip(model.param_names, model.params))
    for n in (6.0, 10.0, 14.0):
        expected = -p["a9"] * n**2 / (p["a1"] + p["a8"] * n)
        assert steady_surge_speed(model, n) == pytest.approx(expected, rel=1e-10)
    assert steady_surge_speed(model, 10.0) == pytest.approx(1.7, rel=1e-9)


def test_model_speed_power_plug_in_and_calibration():
    model = get_model("kcs-response")
    sp = ModelSpeedPower.calibrated(model, 12.0, n_ref=10.0, power_ref=40.0)
    assert sp.power == pytest.approx(40.0 * 1.2**3)
    us, P, w = sp.leg(np.array([-0.5, 0.0, 0.5]), np.array([3.0, 0.0, -3.0]))
    np.testing.assert_allclose(w, sp.speed)
    np.testing.assert_allclose(us, sp.speed + np.array([-0.5, 0.0, 0.5]))
    np.testing.assert_allclose(P, sp.power)
    sp2 = ModelSpeedPower(model, 10.0, lambda n, u: 5.0 * u**3)
    assert sp2.power == pytest.approx(5.0 * 1.7**3)


def test_plug_in_errors_name_the_problem():
    model = get_model("kcs-response")
    with pytest.raises(ValueError, match="has no input 'rpm'"):
        steady_surge_speed(model, 10.0, rate="rpm")
    with pytest.raises(ValueError, match="does not change sign"):
        steady_surge_speed(model, 10.0, bracket=(2.0, 5.0))
    with pytest.raises(ValueError, match="n_ref > 0"):
        ModelSpeedPower.calibrated(model, 10.0, n_ref=0.0, power_ref=1.0)
