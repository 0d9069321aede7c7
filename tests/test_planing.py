"""Planing-boat model: parameter file matches its documented derivation, the protocol
Jacobians, symmetry and the straight-line reduction used by scenario 1."""
import json
from importlib import resources

import numpy as np
import pytest

from shipid.models import get_model
from shipid.models.base import Model
from shipid.models.planing import TABLE1_HULL, PlaningBoatModel, slender_body_derivatives


def test_parameter_file_matches_derivation_and_table1():
    doc = json.loads(resources.files("shipid.models.parameters").joinpath("planing_table1.json").read_text())
    p = doc["params"]
    assert (p["m"], p["Ixx"], p["Izz"]) == (3600.0, 1435.0, 11320.0)
    d = slender_body_derivatives(TABLE1_HULL)
    for k, v in d.items():
        if not k.startswith("_"):
            assert p[k] == pytest.approx(v, rel=1e-6, abs=1e-3), k
    # slender-body sanity: sway damping and yaw damping negative, added mass below the hull mass
    assert p["Y_uv"] < 0 and p["N_ur"] < 0 and 0 < -p["Y_vdot"] < p["m"]
    assert "VCG" in doc["caveat"] and "Lewandowski" in doc["caveat"]


def test_analytic_jacobians_at_operating_points():
    m = get_model("planing-boat")
    rng = np.random.default_rng(3)
    for _ in range(5):
        x, u = PlaningBoatModel.sample_point(rng)
        for which in ("x", "u"):
            a = getattr(m, f"jac_{which}")(0.0, x, u)
            fd = Model._fd(m, 0.0, x, u, m.params, which)
            np.testing.assert_allclose(a, fd, rtol=1e-5, atol=1e-6)


def test_batch_and_mirror_symmetry():
    m = get_model("planing-boat")
    rng = np.random.default_rng(4)
    x, u = PlaningBoatModel.sample_point(rng, batch=(5,))
    f = m.rhs(0.0, x, u)
    for i in range(5):
        np.testing.assert_allclose(f[i], m.rhs(0.0, x[i], u[i]), rtol=1e-12)
    # port/starboard mirror: (y, psi, phi, v, p, r, phi_p) -> minus
    S = np.array([1, -1, -1, -1, 1, -1, -1, -1.0])
    fm = m.rhs(0.0, x * S, u * np.array([1, -1.0]))
    np.testing.assert_allclose(fm, f * S, rtol=1e-10, atol=1e-10)


def test_straight_line_reduces_to_surge_equation():
    m = get_model("planing-boat")
    x = np.array([10.0, 0, 0, 0, 7.0, 0, 0, 0])
    f = m.rhs(0.0, x, [5000.0, 0.0])
    M = m.params_series()
    assert f[4] == pytest.approx((5000.0 - m.resistance(7.0)) / (M["m"] - M["X_udot"]), rel=1e-12)
    assert np.all(f[[1, 2, 3, 5, 6, 7]] == 0.0) and f[0] == 7.0


def test_vectored_thrust_turns_and_stays_within_paper_limits():
    from shipid.simulate import simulate

    m = get_model("planing-boat")
    t = np.linspace(0, 40, 801)
    res = simulate(m, np.r_[0, 0, 0, 0, 9.0, 0, 0, 0], t, inputs=np.tile([7500.0, np.radians(-20)], (801, 1)))
    r, phi = res.state("r"), res.state("phi")
    assert res.success and np.all(r[1:] > 0) and res.state("psi")[-1] > 1.5  # phi_p < 0 turns to starboard
    # a steady turn with 20 deg thrust vectoring stays inside |r| <= 15 deg/s and |phi| <= 20 deg
    assert np.degrees(np.abs(r)).max() < 15 and np.degrees(np.abs(phi)).max() < 20


def test_user_resistance_table():
    m = get_model("planing-boat", resistance_table=([2.0, 5.0, 10.0], [1000.0, 5000.0, 6000.0]))
    assert m.resistance(5.0) == pytest.approx(5000.0)
