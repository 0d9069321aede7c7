"""Low-speed four-quadrant model (shipid.models.lowspeed) and the defect fixes of mmg, the response
models and simulate() found on the Esso Osaka runs."""
from __future__ import annotations

import warnings

import numpy as np
import pytest

from shipid.models import get_model
from shipid.models.base import Model
from shipid.models.lowspeed import LowSpeedModel
from shipid.simulate import simulate


@pytest.fixture(scope="module")
def ls():
    return get_model("lowspeed")


def test_registered_with_esso_particulars(ls):
    assert isinstance(ls, LowSpeedModel) and ls.lpp == 3.0
    P = ls.particulars
    assert P.rho * P.displacement == pytest.approx(244.6)  # README mass
    assert P.D_p == 0.084 and P.A_R == 0.0106 and P.x_G == 0.094
    assert "NOT identified" in ls.parameter_set("esso-osaka-prior").caveat


#: The MMG standard method's side-dependent terms at the KVLCC2's published values (Yasukawa & Yoshimura
#: 2015, Table 2): gamma_R 0.640 / 0.395 for beta_R > 0 / < 0 and the wake falling with beta_P.
MMG_ASYMMETRIC = {"dgammaR": 0.1225, "C1": 2.0, "C2p": 1.6, "C2m": 1.1, "xP": -0.48,
                  "YPf": 0.002, "NPf": -0.001, "delta0": 0.03, "dfalpha": 0.15, "kstall": 1.0 / np.sin(np.radians(24.0))}


@pytest.mark.parametrize("terms", ["prior", "asymmetric"])
@pytest.mark.parametrize("quadrant", [(1, 1), (1, -1), (-1, 1), (-1, -1)])
def test_jacobians_match_finite_differences_in_all_quadrants(ls, quadrant, terms):
    ls = ls.with_params(MMG_ASYMMETRIC) if terms == "asymmetric" else ls
    su, sn = quadrant
    rng = np.random.default_rng(3)
    x, u = ls.sample_point(rng, (6,))
    x[:, 3] = su * (0.05 + np.abs(x[:, 3]))
    x[:, 4] = np.where(np.arange(6) % 2, 1.0, 0.1) * x[:, 4] * 5  # drift angles up to ~90 deg and beyond
    u[:, 1] = sn * (2.0 + np.abs(u[:, 1]))
    for which in ("x", "u", "p"):
        a = getattr(ls, f"jac_{which}")(0.0, x, u)
        fd = Model._fd(ls, 0.0, x, u, ls.params, which)
        np.testing.assert_allclose(a, fd, rtol=1e-5, atol=1e-8, err_msg=f"jac_{which} quadrant {quadrant}")


def test_finite_at_rest_and_astern(ls):
    for n in (-10.0, 0.0, 10.0):
        for d in (-0.6, 0.0, 0.6):
            f = ls.rhs(0.0, np.zeros(6), [d, n])
            assert np.all(np.isfinite(f))
    f_ahead = ls.rhs(0.0, np.zeros(6), [0.0, 10.0])
    f_astern = ls.rhs(0.0, np.zeros(6), [0.0, -10.0])
    assert f_ahead[3] > 0 > f_astern[3]
    # astern bollard thrust / ahead bollard thrust = CTa0 / ((1 - tP) k0)
    p = ls.params_series()
    assert f_astern[3] / f_ahead[3] == pytest.approx(p["CTa0"] / ((1 - p["tP"]) * p["k0"]), rel=1e-9)
    # pure sway at 90 deg drift and going astern stay finite with the right sign of the damping
    assert ls.rhs(0.0, [0, 0, 0, 0.0, 0.2, 0.0], [0.0, 0.0])[4] < 0
    assert ls.rhs(0.0, [0, 0, 0, -0.2, 0.0, 0.0], [0.0, 0.0])[3] > 0


def test_cross_flow_integral_against_closed_form(ls):
    """The Gauss-Legendre cross-flow integral against int (a + b s)|a + b s| ds = [w^2 |w| / 3]/b."""
    m = ls.with_params({"Yv": 0.0, "Yr": 0.0, "CD": 1.0, "CrY": 1.0})
    q = 0.5 * m.particulars.rho * m.lpp * m.particulars.draught
    for v, r in ((0.1, 0.0), (0.05, 0.05), (-0.02, 0.08), (0.0, -0.1)):
        a, b = v, r * m.lpp
        if b == 0:
            exact = a * abs(a)
        else:
            w1, w2 = a - b / 2, a + b / 2
            exact = (w2**2 * abs(w2) - w1**2 * abs(w1)) / (3 * b)
        YH = m.forces([0, 0, 0, 0.0, v, r], [0.0, 0.0])["Y_H"]
        assert YH == pytest.approx(-q * exact, rel=2e-3, abs=1e-12)


def test_port_starboard_mirror_ahead(ls):
    x = np.array([0, 0, 0, 0.3, 0.04, 0.02])
    u = np.array([0.3, 8.0])
    f = ls.rhs(0.0, x, u)
    g = ls.rhs(0.0, x * [1, 1, 1, 1, -1, -1], u * [-1, 1])
    np.testing.assert_allclose(g[3:], f[3:] * [1, -1, -1], rtol=1e-12)


def test_side_dependent_terms_follow_the_mmg_standard(ls):
    """dgammaR and the drift-dependent wake (defaults: off, the mirror symmetry above holds) against the MMG
    standard method's formulas written out here: gamma_R = gammaR +- dgammaR for beta_R >< 0, and
    1 - w_P = (1 - w_P0)(1 + (1 - exp(-C1 |beta_P|))(C2 - 1)) with beta_P = atan(-(v + x_P L r)/u)."""
    p = ls.params_series()
    assert p["dgammaR"] == 0.0 and p["C2p"] == p["C2m"] == 1.0
    m = ls.with_params(MMG_ASYMMETRIC)
    L = m.lpp
    for v, r in ((0.03, 0.01), (-0.03, -0.01), (0.0, 0.02), (0.05, -0.03)):
        x, u = [0, 0, 0, 0.3, v, r], [0.2, 10.0]
        f = m.forces(x, u)
        w = v + p["lR"] * L * r
        g = p["gammaR"] + (0.1225 if w < 0 else -0.1225)  # beta_R = -w/U > 0 when w < 0
        assert f["v_R"] == pytest.approx(-g * w, rel=1e-12, abs=1e-15)
        # thrust linear in u_P (k0 = k2 = 0, k1 = 1): T = rho D^3 n u_P gives u_P
        mk = m.with_params({"k0": 0.0, "k1": 1.0, "k2": 0.0})
        D = m.particulars.D_p
        uP = mk.forces(x, u)["T"] / (m.particulars.rho * D ** 3 * 10.0)
        bP = np.arctan(-(v - 0.48 * L * r) / 0.3)
        C2 = 1.6 if bP > 0 else 1.1
        assert uP == pytest.approx(0.3 * (1 - p["wP0"]) * (1 + (1 - np.exp(-2.0 * abs(bP))) * (C2 - 1)), rel=1e-12)
    # astern (u < 0): no wake, as before
    assert m.with_params({"k0": 0.0, "k1": 1.0, "k2": 0.0}).forces([0, 0, 0, -0.1, 0.05, 0.0], [0.0, 10.0])["T"] \
        == pytest.approx(m.particulars.rho * m.particulars.D_p ** 3 * 10.0 * -0.1, rel=1e-12)


def test_ahead_propeller_side_force_and_rudder_neutral_angle(ls):
    """YPf, NPf (side force and yaw moment of the propeller turning ahead, q n^2 D^2 YPf and q L n^2 D^2 NPf;
    none astern) and delta0 (the rudder acts as if at delta - delta0): defaults off, exact when on."""
    p = ls.params_series()
    assert p["YPf"] == p["NPf"] == p["delta0"] == 0.0
    P = ls.particulars
    q = 0.5 * P.rho * ls.lpp * P.draught
    m = ls.with_params({"YPf": 0.002, "NPf": -0.001})
    x = [0, 0, 0, 0.3, 0.02, -0.01]
    for n in (12.0, 0.0, -8.0):
        f0, f = ls.forces(x, [0.1, n]), m.forces(x, [0.1, n])
        ahead = n >= 0
        assert f["Y_P"] - f0["Y_P"] == pytest.approx(ahead * q * n * n * P.D_p ** 2 * 0.002, rel=1e-12, abs=1e-15)
        assert f["N_P"] - f0["N_P"] == pytest.approx(ahead * q * ls.lpp * n * n * P.D_p ** 2 * -0.001,
                                                     rel=1e-12, abs=1e-15)
        for k in ("X_H", "Y_H", "N_H", "X_P", "X_R", "Y_R", "N_R", "T"):
            assert f[k] == f0[k]
    md = ls.with_params({"delta0": 0.03})
    for n, u in ((10.0, 0.3), (-8.0, -0.1)):
        np.testing.assert_allclose(md.rhs(0.0, [0, 0, 0, u, 0.02, 0.01], [0.13, n]),
                                   ls.rhs(0.0, [0, 0, 0, u, 0.02, 0.01], [0.10, n]), rtol=1e-12, atol=1e-15)


def test_side_dependent_rudder_force_and_stall(ls):
    """dfalpha (F_N + dfalpha |F_N|) and kstall (sin alpha_R levelling off at 1/kstall): defaults off and
    exact, the formulas when on, and a force that stays finite at rest."""
    p = ls.params_series()
    assert p["dfalpha"] == p["kstall"] == 0.0
    P = ls.particulars
    x = [0, 0, 0, 0.3, 0.02, -0.01]
    for d in (0.35, -0.35, 0.05):
        f0 = ls.forces(x, [d, 12.0])
        sa = f0["u_R"] * np.sin(d) - f0["v_R"] * np.cos(d)
        UR = np.hypot(f0["u_R"], f0["v_R"])
        assert f0["F_N"] == pytest.approx(0.5 * P.rho * P.A_R * p["f_alpha"] * UR * sa, rel=1e-12)
        fs = ls.with_params({"dfalpha": 0.2}).forces(x, [d, 12.0])
        assert fs["F_N"] == pytest.approx(f0["F_N"] * (1.2 if f0["F_N"] > 0 else 0.8), rel=1e-12)
        k = 1.0 / np.sin(np.radians(24.0))
        fk = ls.with_params({"kstall": k}).forces(x, [d, 12.0])
        s = sa / UR
        assert fk["F_N"] == pytest.approx(f0["F_N"] / (1.0 + (k * s) ** 8) ** 0.125, rel=1e-12)
        for key in ("X_H", "Y_H", "N_H", "X_P", "Y_P", "N_P", "T", "u_R", "v_R"):
            assert fs[key] == f0[key] and fk[key] == f0[key]
    # the plateau: beyond the stall angle the normal force hardly grows, below it hardly changes
    k = 1.0 / np.sin(np.radians(24.0))
    fn = [ls.with_params({"kstall": k}).forces([0, 0, 0, 0.3, 0, 0], [np.radians(a), 12.0])["F_N"] for a in (5, 24, 40)]
    fn0 = [ls.forces([0, 0, 0, 0.3, 0, 0], [np.radians(a), 12.0])["F_N"] for a in (5, 24, 40)]
    assert fn[0] == pytest.approx(fn0[0], rel=1e-4)
    assert fn[2] / fn[1] < 1.1 < fn0[2] / fn0[1]
    at_rest = ls.with_params({"kstall": k, "dfalpha": 0.2}).rhs(0.0, [0, 0, 0, 0, 0, 0], [0.3, 0.0])
    assert np.all(np.isfinite(at_rest))


def test_rudder_force_reverses_in_reversed_flow(ls):
    fa = ls.forces([0, 0, 0, 0.2, 0, 0], [0.3, 0.0])["F_N"]
    fb = ls.forces([0, 0, 0, -0.2, 0, 0], [0.3, 0.0])["F_N"]
    assert fa > 0 > fb


@pytest.mark.parametrize("terms", ["prior", "asymmetric"])
def test_froude_scaling(ls, terms):
    ls = ls.with_params(MMG_ASYMMETRIC) if terms == "asymmetric" else ls
    lam = 2.0
    big = ls.scaled(3.0 * lam)
    t = np.arange(0.0, 40.0, 0.1)
    U = np.column_stack([np.where(t > 5, 0.5, 0.0), np.full(t.size, 8.0)])
    x0 = np.array([0, 0, 0, 0.2, 0, 0])
    a = simulate(ls, x0, t, U)
    ts = t * np.sqrt(lam)
    Us = U * [1.0, 1.0 / np.sqrt(lam)]
    b = simulate(big, x0 * np.sqrt(lam), ts, Us)
    np.testing.assert_allclose(b.x[:, :2], lam * a.x[:, :2], rtol=1e-8, atol=1e-9)


# ------------------------------------------------------------------ defects found on the Esso runs
def test_mmg_finite_at_rest_and_thrust_reverses_astern():
    m = get_model("mmg", "kvlcc2", lpp=3.0)
    for n in (-10.0, 0.0, 10.0):
        f = m.rhs(0.0, np.zeros(6), [0.1, n])
        assert np.all(np.isfinite(f)), n
    T = {n: m.forces([0, 0, 0, 0.2, 0, 0], [0.0, n])["T"] for n in (-10.0, 10.0)}
    assert T[10.0] > 0 > T[-10.0]
    # at rest the n|n| K_T(0) bollard thrust is antisymmetric in n
    Tb = {n: m.forces([0, 0, 0, 0.0, 0, 0], [0.0, n])["T"] for n in (-10.0, 10.0)}
    assert Tb[-10.0] == pytest.approx(-Tb[10.0], rel=1e-12)


@pytest.mark.parametrize("name", ["kcs-response", "response-nl"])
def test_response_a9_term_keeps_the_sign_of_n(name):
    m = get_model(name)
    only = m.with_params({k: (1.0 if k == "a9" else 0.0) for k in m.param_names})
    du = [only.rhs(0.0, np.zeros(6) + [0, 0, 0, 1.0, 0, 0], [0.0, n])[3] for n in (-3.0, 3.0)]
    assert du[0] == pytest.approx(-9.0) and du[1] == pytest.approx(9.0)


def test_simulate_batch_finishes_the_other_members():
    m = get_model("lowspeed")
    x0 = np.zeros((3, 6))
    x0[:, 3] = 0.2
    x0[1, 3] = np.nan
    t = np.arange(0.0, 3.0, 0.1)
    U = np.column_stack([np.zeros(t.size), np.full(t.size, 8.0)])
    with pytest.warns(RuntimeWarning, match="1 of 3 batch member"):
        r = simulate(m, x0, t, U)
    assert not r.success and r.meta["failed"] == [1]
    assert np.all(np.isfinite(r.x[[0, 2]])) and np.all(np.isnan(r.x[1, 1:]))
    single = simulate(m, x0[0], t, U)
    np.testing.assert_allclose(r.x[0], single.x)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert simulate(m, x0[[0, 2]], t, U).success


@pytest.mark.parametrize("hold, case", [("zoh", "nan-start"), ("foh", "nan-start"), ("zoh", "unstable"),
                                        ("foh", "unstable")])
def test_dopri5_batch_finishes_the_other_members_and_reports_the_failed_one(hold, case):
    """A member that starts non-finite, or whose (absurd, Nr = +1e4) parameters make it overflow: the
    others finish with the values of their own runs, the failed one is reported."""
    m = get_model("lowspeed")
    x0 = np.zeros((3, 6))
    x0[:, 3], x0[:, 5] = [0.2, 0.2, 0.1], 0.01
    P = np.repeat(m.params[None], 3, axis=0)
    if case == "nan-start":
        x0[1, 3] = np.nan
    else:
        P[1, m.param_index("Nr")] = 1e4
    t = np.arange(0.0, 3.0, 0.1)
    U = np.column_stack([np.where(t < 1.5, 0.0, 0.3), np.full(t.size, 8.0)])
    with pytest.warns(RuntimeWarning, match="1 of 3 batch member"):
        r = simulate(m, x0, t, U, method="dopri5", input_hold=hold, params=P)
    assert not r.success and r.meta["failed"] == [1] and r.meta["per_member"]
    k = int(np.searchsorted(t, r.meta["failed_at"][0]))
    assert np.all(np.isfinite(r.x[[0, 2]])) and np.all(np.isnan(r.x[1, k:]))
    for b in (0, 2):
        single = simulate(m, x0[b], t, U, method="dopri5", input_hold=hold)
        np.testing.assert_allclose(r.x[b], single.x, rtol=1e-12, atol=1e-12)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        ok = simulate(m, x0[[0, 2]], t, U, method="dopri5", input_hold=hold)
    assert ok.success and "per_member" not in ok.meta
    with pytest.raises(ValueError, match=r"x0 must be finite; x0\[\d\] \('\w+'\) = nan"):  # one start: an argument error
        simulate(m, x0[1] if case == "nan-start" else x0[0] * np.nan, t, U, method="dopri5", input_hold=hold)


def test_response_nl_damping_keeps_its_sign_astern():
    """The guard against the low-speed blow-ups: the speed-proportional damping of response-nl uses |u|
    (and its surge term a8 u|n|), so sway/yaw/surge damping is the same going astern or with the propeller
    astern; an astern run of the default set scaled to 3 m stays finite (it reached 1e87 m/s with u, n)."""
    m = get_model("response-nl", lpp=3.0)
    x = np.array([0.0, 0.0, 0.0, 0.3, 0.05, 0.02])
    xa = x * [1, 1, 1, -1, 1, 1]
    J, Ja, Jn = m.jac_x(0, x, [0.1, 8.0]), m.jac_x(0, xa, [0.1, 8.0]), m.jac_x(0, x, [0.1, -8.0])
    assert J[4, 4] == pytest.approx(Ja[4, 4], rel=1e-12) and J[5, 5] == pytest.approx(Ja[5, 5], rel=1e-12)
    assert J[3, 3] == pytest.approx(Jn[3, 3], rel=1e-12)
    for xx, uu in ((xa, [0.1, -8.0]), (x, [0.1, -8.0])):  # analytic Jacobians still match finite differences
        fd = Model._fd(m, 0.0, xx, np.array(uu), m.params, "x")
        np.testing.assert_allclose(m.jac_x(0, xx, uu), fd, rtol=1e-6, atol=1e-8)
    t = np.arange(0.0, 120.0, 0.2)
    U = np.column_stack([np.full(t.size, 0.35), np.full(t.size, -10.0)])
    r = simulate(m, [0.0, 0.0, 0.0, 0.1, 0.0, 0.0], t, U)
    assert r.success and np.all(np.abs(r.x[:, 3:]) < 2.0)
