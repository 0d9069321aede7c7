"""Savitsky planing resistance: published relations, an independent oracle (openplaning),
validity limits and the pre-planing bridge."""
import numpy as np
import pytest

from shipid.savitsky import PlaningHull, ResistanceCurve, ittc57_cf, resistance_curve, savitsky_equilibrium

FT = 0.3048
# Savitsky (1964) worked example: 60 000 lb, b = 14 ft, LCG 29 ft, VCG 2 ft, beta 10 deg, eps 4 deg, f 0.5 ft
EXAMPLE = PlaningHull(mass=60000 * 0.45359237, beam=14 * FT, lcg=29 * FT, vcg=2 * FT, deadrise=10.0, length=60 * FT,
                      epsilon=4.0, f=0.5 * FT, rho=1025.87, nu=1.19e-6, dcf=0.0)


def test_equilibrium_satisfies_published_relations():
    pt = savitsky_equilibrium(EXAMPLE, 40 * 1852 / 3600)
    assert pt.success and pt.valid
    b, tau, lam, cv = EXAMPLE.beam, pt.trim, pt.lam, pt.cv
    cl0 = tau**1.1 * (0.0120 * lam**0.5 + 0.0055 * lam**2.5 / cv**2)
    assert cl0 - 0.0065 * 10.0 * cl0**0.6 == pytest.approx(pt.lift_coefficient, rel=1e-9)
    assert pt.lift_coefficient == pytest.approx(EXAMPLE.weight / (0.5 * EXAMPLE.rho * pt.speed**2 * b**2), rel=1e-12)
    assert pt.lp / (lam * b) == pytest.approx(0.75 - 1 / (5.21 * cv**2 / lam**2 + 2.39), rel=1e-12)
    tr = np.radians(tau)
    assert pt.resistance == pytest.approx(EXAMPLE.weight * np.tan(tr) + pt.friction / np.cos(tr), rel=1e-12)
    # Savitsky's example runs at a low trim (about 2.2 deg) with lambda about 3.4
    assert 2.0 < tau < 2.5 and 3.2 < lam < 3.7


@pytest.mark.parametrize("knots", [30, 40])
def test_against_openplaning_oracle(knots):
    op = pytest.importorskip("openplaning", reason="openplaning (test oracle) not installed")
    V = knots * 1852 / 3600
    pt = savitsky_equilibrium(EXAMPLE, V)
    boat = op.PlaningBoat(speed=V, weight=EXAMPLE.weight, beam=EXAMPLE.beam, lcg=EXAMPLE.lcg, vcg=EXAMPLE.vcg,
                          r_g=0.25 * 60 * FT, beta=10, epsilon=4, vT=EXAMPLE.vcg - EXAMPLE.f, lT=0, ahr=0,
                          wetted_lengths_type=2, g=9.80665, rho=1025.87, nu=1.19e-6)
    boat.get_steady_trim()
    boat.get_forces()
    drag = boat.hydrodynamic_force[0] + boat.skin_friction[0]
    # independent implementations of the same method (openplaning solves heave and trim together)
    assert pt.trim == pytest.approx(boat.tau, abs=0.1)
    assert pt.lam == pytest.approx(boat.lambda_W, rel=0.03)
    assert pt.resistance == pytest.approx(drag, rel=0.03)


def test_validity_limits_reported():
    hull = PlaningHull(mass=3600, beam=2.018, lcg=2.518, vcg=0.5, deadrise=20, length=7.95)
    low = savitsky_equilibrium(hull, 2.0)
    assert not low.valid and any("Cv" in v for v in low.violations)
    assert savitsky_equilibrium(hull, 10.0).valid
    with pytest.raises(ValueError, match="speed must be a positive"):
        savitsky_equilibrium(hull, -1.0)
    with pytest.raises(ValueError, match="deadrise"):
        PlaningHull(mass=3600, beam=2.0, lcg=2.5, vcg=0.5, deadrise=50, length=8)


def test_curve_is_c1_and_bridge_below_planing_range():
    hull = PlaningHull(mass=3600, beam=2.018, lcg=2.518, vcg=0.5, deadrise=20, length=7.95)
    c = resistance_curve(hull)
    assert 2.0 < c.planing_speed < 4.0
    assert c(0.0) == 0.0 and c(-3.0) == -c(3.0)
    v = np.linspace(0.05, 24.9, 600)
    R = c(v)
    assert np.all(R > 0)
    # derivative matches finite differences everywhere (C1 curve)
    np.testing.assert_allclose(c.derivative(v), (c(v + 1e-6) - c(v - 1e-6)) / 2e-6, rtol=1e-4, atol=1e-3)
    # below the planing speed: ITTC friction on the static wetted area is a lower bound
    low = v[v < c.planing_speed]
    S = hull.wetted_area_static
    rf = 0.5 * hull.rho * S * low**2 * (ittc57_cf(low * hull.length / hull.nu) + hull.dcf)
    assert np.all(c(low) >= rf - 1e-9)
    # the hump: resistance falls after it (Savitsky's planing lift unloading the hull)
    assert c(8.0) > c(12.0)


def test_user_table_errors():
    with pytest.raises(ValueError, match="increasing"):
        ResistanceCurve(np.array([0, 2, 1.0]), np.array([0, 1, 2.0]))
    t = ResistanceCurve(np.array([1.0, 2.0, 3.0]), np.array([100.0, 400.0, 900.0]))
    assert t(0.0) == 0.0 and t(2.0) == pytest.approx(400.0)


def test_diverged_speed_gives_inf_not_overflow():
    # a diverging trajectory inside an optimiser's line search must give inf (rejected step), not raise
    from shipid.models import get_model

    R = get_model("planing-boat").resistance
    assert R(1e200) == np.inf and R(-1e300) == -np.inf and R.derivative(1e300) == np.inf
    assert np.isnan(R(float("nan")))
    r = R(np.array([np.nan, 1e300, -np.inf, 5.0]))
    assert np.isnan(r[0]) and r[1] == np.inf and r[2] == -np.inf and r[3] == pytest.approx(R(5.0), rel=1e-12)
    assert np.isnan(R.derivative(np.array([np.nan]))[0])
