"""The glider model (shipid.models.glider) against analytic truths: ballistic
flight under net buoyancy, the pitch pendulum about the CG, conservation of
kinetic energy with added mass and CG offsets, and the force decomposition
against the paper's formulas."""
import numpy as np
import pytest

from shipid.models import get_model
from shipid.simulate import simulate

NO_HYDRO = {"a": 0.0, "b": 0.0, "c": 0.0, "CL_alpha": 0.0, "CM_alpha": 0.0, "fin_span": 1e-12}


def test_parameter_set_is_the_papers():
    m = get_model("glider")
    p = m.params_series()
    assert (p["a"], p["b"], p["c"], p["CL_alpha"], p["CM_alpha"]) == (5.25, -0.315, 0.732, 4.79, 0.0974)
    assert (p["m"], p["volume"], p["Iy"], p["diameter"], p["length"], p["fin_chord"]) == (5.355, 0.006, 0.3091, 0.09, 0.88, 0.127)
    assert p["X_udot"] == p["Z_wdot"] == p["M_qdot"] == 0.0       # the paper neglects added mass
    assert "fin" in m.parameter_set("paper").caveat and "1025" in m.parameter_set("paper").caveat
    am = get_model("glider", "paper-added-mass").params_series()
    assert am["Z_wdot"] < 0 and am["X_udot"] < 0 and am["M_qdot"] < 0


def test_ballistic_flight_under_net_buoyancy_is_a_parabola():
    """No hydrodynamic force, CG at CB: constant pitch, upward acceleration (B - W)/m."""
    m = get_model("glider", NO_HYDRO)
    p = m.params_series()
    gnet = (p["rho"] * p["volume"] - p["m"]) * p["g"] / p["m"]
    V, gam = 3.0, np.deg2rad(30.0)
    x0 = [0, 0, -(np.pi / 2 - gam), V, 0, 0]
    t = np.linspace(0, 2.0, 401)
    r = simulate(m, x0, t, inputs=np.zeros((t.size, 1)))
    vx, vz = V * np.sin(gam), V * np.cos(gam)
    np.testing.assert_allclose(r.state("x"), vx * t, atol=1e-9)
    np.testing.assert_allclose(r.state("z"), vz * t - 0.5 * gnet * t**2, atol=1e-9)
    np.testing.assert_allclose(r.state("theta"), x0[2], atol=1e-12)


def test_pitch_pendulum_about_the_cg():
    """Neutral buoyancy, CG z_g below the CB, at rest: omega^2 = z_g W / (Iy - m z_g^2)."""
    zg = 0.02
    m0 = get_model("glider")
    p = m0.params_series()
    m = m0.with_params({**NO_HYDRO, "z_g": zg, "volume": p["m"] / p["rho"]})
    th0 = 1e-3
    t = np.linspace(0, 6.0, 601)
    r = simulate(m, [0, 0, th0, 0, 0, 0], t, inputs=np.zeros((t.size, 1)))
    th = r.state("theta")
    up = np.where((th[:-1] < 0) & (th[1:] >= 0))[0]
    tc = t[up] - th[up] * (t[up + 1] - t[up]) / (th[up + 1] - th[up])   # upward zero crossings
    period = np.mean(np.diff(tc))
    omega = np.sqrt(zg * p["m"] * p["g"] / (p["Iy"] - p["m"] * zg**2))
    assert period == pytest.approx(2 * np.pi / omega, rel=1e-4)
    assert np.max(np.abs(th)) == pytest.approx(th0, rel=1e-3)


@pytest.mark.parametrize("xg,zg", [(0.0, 0.0), (0.03, -0.02)])
def test_kinetic_energy_conserved_with_added_mass_and_cg_offset(xg, zg):
    """No gravity, no viscous forces: T = 1/2 nu' M nu is conserved (Coriolis and Munk terms do no work)."""
    m = get_model("glider", "paper-added-mass").with_params({**NO_HYDRO, "g": 0.0, "x_g": xg, "z_g": zg})
    p = m.params_series()
    M = np.array([[p["m"] - p["X_udot"], 0, p["m"] * zg],
                  [0, p["m"] - p["Z_wdot"], -p["m"] * xg],
                  [p["m"] * zg, -p["m"] * xg, p["Iy"] - p["M_qdot"]]])
    t = np.linspace(0, 5.0, 501)
    r = simulate(m, [0, 0, 0.1, 1.0, 0.3, 0.4], t, inputs=np.zeros((t.size, 1)))
    nu = r.x[:, 3:]
    T = 0.5 * np.einsum("ti,ij,tj->t", nu, M, nu)
    assert np.ptp(T) / T[0] < 1e-7
    assert np.ptp(nu[:, 2]) > 0.05        # the Munk moment does change the motion


def test_hull_forces_follow_the_paper_formulas():
    m = get_model("glider")
    p = m.params_series()
    rho, Af = p["rho"], np.pi * p["diameter"] ** 2 / 4
    for u, w in [(2.0, 0.1), (1.0, 0.3), (3.0, -0.2)]:
        F = m.forces(0.0, [0, 0, 0, u, w, 0], [0.0])
        al = np.arctan2(w, u)
        V2 = u * u + w * w
        cd = p["a"] * al**2 + p["b"] * abs(al) + p["c"]
        drag = np.array([F["X_D"], F["Z_D"]])
        lift = np.array([F["X_L"], F["Z_L"]])
        np.testing.assert_allclose(drag, -0.5 * rho * Af * cd * V2 * np.array([np.cos(al), np.sin(al)]), rtol=1e-12)
        assert abs(lift @ [u, w]) < 1e-12                                  # lift perpendicular to the velocity
        assert F["Z_L"] == pytest.approx(-0.5 * rho * Af * p["CL_alpha"] * V2 * al * np.cos(al), rel=1e-12)   # paper eq. (33)
        assert F["M_H"] == pytest.approx(0.5 * rho * Af * p["length"] * p["CM_alpha"] * al * V2, rel=1e-12)
        if w > 0:   # the paper's small-angle expansion (32) agrees to O(alpha^3)
            Dx = -0.5 * rho * Af * (p["c"] * u * abs(u) + p["b"] * u * w + (p["a"] + 0.5 * p["c"]) * w * abs(w))
            assert F["X_D"] == pytest.approx(Dx, rel=5 * al**3)


def test_fin_forces_use_the_aspect_ratio_formulas_with_speed_squared():
    m = get_model("glider")
    p = m.params_series()
    lam = p["fin_span"] / p["fin_chord"]
    cl = 6.13 * lam / (2.25 + lam)
    assert cl == pytest.approx(2.885, abs=1e-3)
    area = p["fin_span"] * p["fin_chord"]
    d = np.deg2rad(10.0)
    for V in (1.0, 3.0):
        F = m.forces(0.0, [0, 0, 0, V, 0, 0], [d])      # alpha = 0: lift is -z, drag is -x
        L = 0.5 * p["rho"] * area * cl * np.sin(d) * np.cos(d) * V**2
        D = 0.5 * p["rho"] * area * cl**2 / (np.pi * lam) * np.sin(d) ** 2 * V**2
        assert F["Z_F"] == pytest.approx(-L, rel=1e-12) and F["X_F"] == pytest.approx(-D, rel=1e-12)
        assert F["M_F"] == pytest.approx(p["x_fin"] * L, rel=1e-12)    # aft fin lifting up: nose-down moment
    # pitch rate changes the fin's flow angle: damping moment opposes q
    F = m.forces(0.0, [0, 0, 0, 2.0, 0, 0.5], [0.0])
    assert F["M_F"] < 0


def test_restoring_forces_match_paper_eq34():
    m = get_model("glider").with_params({"x_g": 0.01, "z_g": 0.005})
    p = m.params_series()
    W, B = p["m"] * p["g"], p["rho"] * p["volume"] * p["g"]
    th = 0.3
    F = m.forces(0.0, [0, 0, th, 0, 0, 0], [0.0])
    assert F["X_G"] == pytest.approx(-(W - B) * np.sin(th))
    assert F["Z_G"] == pytest.approx((W - B) * np.cos(th))
    assert F["M_G"] == pytest.approx(-0.005 * W * np.sin(th) - 0.01 * W * np.cos(th))


def test_sample_point_and_batched_parameters():
    m = get_model("glider")
    rng = np.random.default_rng(3)
    x, u = m.sample_point(rng, batch=(5,))
    P = np.tile(m.params, (5, 1))
    P[:, m.param_index("x_g")] = np.linspace(-0.05, 0, 5)
    f = m.rhs(0.0, x, u, P)
    for i in range(5):
        np.testing.assert_allclose(f[i], m.rhs(0.0, x[i], u[i], P[i]), rtol=1e-13)
    J = m.jac_p(0.0, x, u, P)
    assert J.shape == (5, 6, m.np) and np.all(np.isfinite(J))
