"""MMG standard model (shipid.models.mmg) against the independent shipmmg package,
the published KVLCC2 manoeuvres, and Froude-scale invariance.

shipmmg (0.0.11) is used as an ORACLE only.  It differs from Yasukawa &
Yoshimura (2015) in three places; the cross-check patches exactly those lines
of its source (in memory, for this test) and then requires agreement to
integration accuracy, and separately measures what each difference does:

1. wake in manoeuvring: shipmmg uses w_P = w_P0 exp(-4 beta_P^2) (an older
   MMG form); the paper (eq. 16) uses 1 - w_P = (1 - w_P0)(1 + (1 - exp(-C1|beta_P|))(C2 - 1)).
2. shipmmg evaluates U and beta with the sway velocity v - x_G r instead of
   the midship v_m its equations of motion use (paper: U = sqrt(u^2 + v_m^2),
   beta = atan(-v_m/u)).
3. shipmmg's rudder lever (github.com/ShipMMG/shipmmg/issues/31): the rudder yaw moment N_R = -(x_R + a_H x_H) F_N cos(delta)
   needs the dimensional x_R = -0.5 L; older shipmmg code used -0.5 (no L).  In
   0.0.11 x_R is an argument; passing the non-dimensional -0.5 reproduces the bug.
"""
from __future__ import annotations

import contextlib

import inspect
import math
import sys
import types

import numpy as np
import pytest
from scipy.optimize import brentq

from shipid import _jit
from shipid.models import get_model
from shipid.models.mmg import MMG_PARAM_NAMES, MMGModel, MMGParticulars
from shipid.simulate import simulate

shipmmg = pytest.importorskip("shipmmg", reason="shipmmg (test extra) is the oracle of this cross-check")

U0 = 1.179  # KVLCC2 L7 approach speed [m/s] (Fn 0.142)


def _steady_n(model, speed):
    return brentq(lambda n: model.rhs(0.0, [0, 0, 0, speed, 0, 0], [0.0, n])[3], 0.5, 100.0, xtol=1e-12)


def _shipmmg_args(model: MMGModel, x_R=None):
    """shipmmg's basic/manoeuvring parameter objects for the same ship and coefficients (SI units)."""
    from shipmmg.mmg_3dof import Mmg3DofBasicParams, Mmg3DofManeuveringParams

    P, c = model.particulars, model.params_series()
    L, d, rho = P.lpp, P.draught, P.rho
    m = rho * P.displacement
    basic = Mmg3DofBasicParams(
        L_pp=L, B=P.breadth, d=d, x_G=P.x_G, D_p=P.D_p, m=m, I_zG=m * (P.kzz * L) ** 2, A_R=P.A_R,
        η=P.D_p / P.H_R, m_x=c.mx * 0.5 * rho * L**2 * d, m_y=c.my * 0.5 * rho * L**2 * d,
        J_z=c.Jz * 0.5 * rho * L**4 * d, f_α=c.f_alpha, ϵ=c.eps, t_R=c.tR,
        x_R=P.x_R * L if x_R is None else x_R, a_H=c.aH, x_H=c.xH * L, γ_R_minus=c.gammaR_m,
        γ_R_plus=c.gammaR_p, l_R=c.lR, κ=c.kappa, t_P=c.tP, w_P0=c.wP0, x_P=c.xP,
    )
    man = Mmg3DofManeuveringParams(
        k_0=c.k0, k_1=c.k1, k_2=c.k2, R_0_dash=c.R0, X_vv_dash=c.Xvv, X_vr_dash=c.Xvr, X_rr_dash=c.Xrr,
        X_vvvv_dash=c.Xvvvv, Y_v_dash=c.Yv, Y_r_dash=c.Yr, Y_vvv_dash=c.Yvvv, Y_vvr_dash=c.Yvvr,
        Y_vrr_dash=c.Yvrr, Y_rrr_dash=c.Yrrr, N_v_dash=c.Nv, N_r_dash=c.Nr, N_vvv_dash=c.Nvvv,
        N_vvr_dash=c.Nvvr, N_vrr_dash=c.Nvrr, N_rrr_dash=c.Nrrr,
    )
    return basic, man


def _patched_shipmmg(model: MMGModel):
    """shipmmg's simulate_mmg_3dof with differences 1 and 2 replaced by the paper's formulas."""
    import shipmmg.mmg_3dof as mod

    c = model.params_series()
    src = inspect.getsource(mod)
    patches = [
        ("U = np.sqrt(u**2 + (v - r * x_G) ** 2)", "U = np.sqrt(u**2 + v**2)"),
        ("β = 0.0 if U == 0.0 else np.arcsin(-(v - r * x_G) / U)", "β = 0.0 if U == 0.0 else np.arcsin(-v / U)"),
        ("w_P = w_P0 * np.exp(-4.0 * (β - x_P * r_dash) ** 2)", "w_P = _paper_wake(w_P0, β - x_P * r_dash)"),
    ]
    for old, new in patches:
        assert src.count(old) == 1, f"shipmmg source changed; cannot patch {old!r}"
        src = src.replace(old, new)

    def _paper_wake(w_P0, beta_P):
        C2 = c.C2p if beta_P > 0 else c.C2m
        return 1.0 - (1.0 - w_P0) * (1.0 + (1.0 - math.exp(-c.C1 * abs(beta_P))) * (C2 - 1.0))

    name = "shipmmg_patched_for_test"
    patched = types.ModuleType(name)
    patched._paper_wake = _paper_wake
    sys.modules[name] = patched  # dataclasses resolve annotations through sys.modules
    try:
        exec(compile(src, name, "exec"), patched.__dict__)
    finally:
        del sys.modules[name]
    return patched.simulate_mmg_3dof


def _run_shipmmg(sim_fn, model, delta, n, t_end, x_R=None, rtol=1e-10):
    basic, man = _shipmmg_args(model, x_R=x_R)
    t = np.linspace(0.0, t_end, 401)
    sol = sim_fn(basic, man, t, np.full(t.size, delta), np.full(t.size, n), u0=U0,
                 ρ=model.particulars.rho, method="RK45", rtol=rtol, atol=1e-12 * model.lpp)
    y = sol.sol(t)  # rows u, v, r, x, y, psi, delta, n
    return t, np.stack([y[3], y[4], y[5], y[0], y[1], y[2]], axis=-1)


def _run_shipid(model, delta, n, t):
    res = simulate(model, [0, 0, 0, U0, 0, 0], t, np.tile([delta, n], (t.size, 1)), substeps=4)
    assert res.success
    return res.x


@pytest.fixture(scope="module")
def kvlcc2():
    return get_model("mmg")


@pytest.fixture(scope="module")
def turn35(kvlcc2):
    """35 deg rudder held from t = 0 (a step: no input-interpolation ambiguity), 250 s at L7 scale."""
    n = _steady_n(kvlcc2, U0)
    t = np.linspace(0.0, 250.0, 401)
    return {"n": n, "t": t, "shipid": _run_shipid(kvlcc2, math.radians(35), n, t)}


def test_parameter_set_is_the_published_kvlcc2(kvlcc2):
    c = kvlcc2.params_series()
    # Yasukawa & Yoshimura (2015) Tables 2-4, a few spot checks
    assert (c.Yv, c.Nr, c.Nvvr, c.f_alpha, c.lR, c.C2p, c.C2m) == (-0.315, -0.049, -0.294, 2.747, -0.710, 1.6, 1.1)
    P = kvlcc2.particulars
    assert (P.lpp, P.draught, P.displacement, P.A_R) == (7.0, 0.46, 3.27, 0.0539)
    assert "Yasukawa" in kvlcc2.parameter_set("kvlcc2").source
    kcs = get_model("mmg", "kcs")
    assert kcs.lpp == pytest.approx(4.36) and "NOT identified" in kcs.parameter_set("kcs").caveat
    # m' of KVLCC2 from the particulars: the paper quotes m' = 0.2953... (computed here, not typed)
    assert kvlcc2.mass_properties()["m_prime"] == pytest.approx(3.27 / (0.5 * 7.0**2 * 0.46), rel=1e-12)


def test_patched_shipmmg_agrees_with_shipid(kvlcc2, turn35):
    """Cross-check on a 35 deg turn: same parameters, shipmmg with the paper's wake and U/beta."""
    t_sm, X_sm = _run_shipmmg(_patched_shipmmg(kvlcc2), kvlcc2, math.radians(35), turn35["n"], 250.0)
    X = turn35["shipid"]
    L = kvlcc2.lpp
    pos_err = np.hypot(X[:, 0] - X_sm[:, 0], X[:, 1] - X_sm[:, 1]).max() / L
    assert pos_err < 1e-5, f"track differs by {pos_err:.2e} L"
    np.testing.assert_allclose(X[:, 2], X_sm[:, 2], atol=1e-6)            # heading [rad]
    np.testing.assert_allclose(X[:, 3:5], X_sm[:, 3:5], atol=1e-6 * U0)    # u, v
    np.testing.assert_allclose(X[:, 5], X_sm[:, 5], atol=1e-7)            # r [rad/s]
    assert X[-1, 2] > 3 * math.pi  # really a turning circle (> 540 deg)


def _track_stats(X, L):
    """Steady turning diameter [L] from the last half of the run (circle centre by mean)."""
    half = X[X.shape[0] // 2:]
    cx, cy = half[:, 0].mean(), half[:, 1].mean()
    return 2 * np.hypot(half[:, 0] - cx, half[:, 1] - cy).mean() / L


def test_stock_shipmmg_differences_are_documented(kvlcc2, turn35):
    """Measure what shipmmg's own formulas do on this turn (numbers quoted in docs/validation.md)."""
    L = kvlcc2.lpp
    d_ref = _track_stats(turn35["shipid"], L)
    _, X_stock = _run_shipmmg(shipmmg.mmg_3dof.simulate_mmg_3dof, kvlcc2, math.radians(35), turn35["n"], 250.0)
    _, X_bug31 = _run_shipmmg(shipmmg.mmg_3dof.simulate_mmg_3dof, kvlcc2, math.radians(35), turn35["n"], 250.0,
                              x_R=kvlcc2.particulars.x_R)  # -0.5, not -0.5 L: shipmmg/issues/31
    d_stock, d_bug = _track_stats(X_stock, L), _track_stats(X_bug31, L)
    print(f"steady diameter/L: paper formulas {d_ref:.3f}, stock shipmmg {d_stock:.3f}, "
          f"stock shipmmg with issue-#31 x_R {d_bug:.3f}")
    # differences 1+2 change the steady turn by a few per cent, not by integration noise
    assert 0.005 < abs(d_stock / d_ref - 1) < 0.2
    # the #31 lever arm (x_R = -0.5 m instead of -3.5 m at L7) weakens the rudder moment: much wider circle
    assert d_bug > 1.3 * d_ref


def test_rudder_moment_lever_is_dimensional(kvlcc2):
    """N_R = -(x_R + a_H x_H) F_N cos(delta) with x_R = -0.5 L (shipmmg/issues/31), checked on the force breakdown."""
    x = np.array([0, 0, 0, U0, -0.02, 0.01])
    F = kvlcc2.forces(x, [math.radians(20), 11.0])
    c = kvlcc2.params_series()
    L = kvlcc2.lpp
    lever = -(-0.5 * L + c.aH * c.xH * L)
    assert F["N_R"] == pytest.approx(lever * F["F_N"] * math.cos(math.radians(20)), rel=1e-12)
    assert F["Y_R"] == pytest.approx(-(1 + c.aH) * F["F_N"] * math.cos(math.radians(20)), rel=1e-12)
    assert F["F_N"] > 0 and F["N_R"] > 0  # positive rudder turns to starboard


def test_scalar_and_batch_backends_agree(kvlcc2):
    """One copy of the equations, four ways to run it: Python floats (one sample), numpy (batched),
    and -- with numba installed -- compiled for one sample and for a batch; all agree to 1e-13."""
    rng = np.random.default_rng(3)
    x, u = MMGModel.sample_point(rng, batch=(9,))
    with _jit.disabled():
        batch = kvlcc2.rhs(0.0, x, u)  # numpy
        for i in range(9):  # Python floats
            np.testing.assert_allclose(kvlcc2.rhs(0.0, x[i], u[i]), batch[i], rtol=1e-13, atol=1e-15)
        p = np.tile(kvlcc2.params, (9, 1))  # per-member parameters
        np.testing.assert_allclose(kvlcc2.rhs(0.0, x, u, p), batch, rtol=1e-13, atol=1e-15)
        pm = p * (1 + 0.05 * rng.normal(size=p.shape))
        batch_pm = kvlcc2.rhs(0.0, x, u, pm)
    if not _jit.enabled():
        pytest.skip("numba not installed (extra 'fast') or SHIPID_JIT=0: compiled path not tested")
    np.testing.assert_allclose(kvlcc2.rhs(0.0, x, u), batch, rtol=1e-13, atol=1e-15)
    f = kvlcc2._rhs_bound(kvlcc2.params)
    for i in range(9):
        np.testing.assert_allclose(kvlcc2.rhs(0.0, x[i], u[i]), batch[i], rtol=1e-13, atol=1e-15)
        np.testing.assert_allclose(f(0.0, x[i], u[i]), batch[i], rtol=1e-13, atol=1e-15)
    np.testing.assert_allclose(f(0.0, x, u), batch, rtol=1e-13, atol=1e-15)
    np.testing.assert_allclose(kvlcc2.rhs(0.0, x, u, pm), batch_pm, rtol=1e-13, atol=1e-15)
    np.testing.assert_allclose(kvlcc2._rhs_bound(pm)(0.0, x, u), batch_pm, rtol=1e-13, atol=1e-15)
    with _jit.disabled():  # a broadcast (3, 4) batch through the compiled loop
        b3 = kvlcc2.rhs(0.0, x[:3, None], u[None, :4])
    np.testing.assert_allclose(kvlcc2.rhs(0.0, x[:3, None], u[None, :4]), b3, rtol=1e-13, atol=1e-15)


def test_compiled_and_pure_simulations_agree(kvlcc2):
    """A 35 deg turn with the adaptive integrator: compiled and pure paths give the same track."""
    if not _jit.enabled():
        pytest.skip("numba not installed (extra 'fast') or SHIPID_JIT=0: compiled path not tested")
    n = _steady_n(kvlcc2, U0)
    t = np.linspace(0.0, 100.0, 51)
    U = np.tile([math.radians(35), n], (t.size, 1))
    fast = simulate(kvlcc2, [0, 0, 0, U0, 0, 0], t, U, method="dopri5", rtol=1e-8)
    with _jit.disabled():
        pure = simulate(kvlcc2, [0, 0, 0, U0, 0, 0], t, U, method="dopri5", rtol=1e-8)
    assert fast.meta["n_fev"] == pure.meta["n_fev"]
    np.testing.assert_allclose(fast.x, pure.x, rtol=1e-10, atol=1e-10)


def test_complex_step_jacobians_match_central_differences(kvlcc2):
    from shipid.models.base import Model

    rng = np.random.default_rng(4)
    x, u = MMGModel.sample_point(rng, batch=(4,))
    for which in ("x", "u", "p"):
        J = getattr(kvlcc2, f"jac_{which}")(0.0, x, u)
        fd = Model._fd(kvlcc2, 0.0, x, u, np.broadcast_to(kvlcc2.params, (4, kvlcc2.np)).copy(), which)
        np.testing.assert_allclose(J, fd, rtol=1e-5, atol=1e-8)
    assert kvlcc2.jac_p(0.0, x, u).shape == (4, 6, len(MMG_PARAM_NAMES))


def test_compiled_and_numpy_complex_step_jacobians_agree(kvlcc2):
    """The compiled complex-step Jacobians (the same equations with cmath globals) equal the numpy ones
    to 1e-13, for shared and per-member parameters, one sample and broadcast batches."""
    if not _jit.enabled():
        pytest.skip("numba not installed (extra 'fast') or SHIPID_JIT=0: compiled path not tested")
    rng = np.random.default_rng(5)
    x, u = MMGModel.sample_point(rng, batch=(4,))
    full = kvlcc2.scaled(320.0)
    pb = full.params * (1 + 0.05 * rng.normal(size=(4, full.np)))
    for model, p in ((kvlcc2, kvlcc2.params), (full, full.params), (full, pb)):
        for which in ("x", "u", "p"):
            jac = getattr(model, f"_jac_{which}")
            fast = jac(0.0, x, u, p)
            one = jac(0.0, x[1], u[1], p[1] if p.ndim == 2 else p)
            bcast = jac(0.0, x[:, None], u[None, :2], p[:, None] if p.ndim == 2 else p)
            with _jit.disabled():
                ref = jac(0.0, x, u, p)
                ref_b = jac(0.0, x[:, None], u[None, :2], p[:, None] if p.ndim == 2 else p)
            np.testing.assert_allclose(fast, ref, rtol=1e-13, atol=1e-13 * np.abs(ref).max())
            np.testing.assert_allclose(one, ref[1], rtol=1e-13, atol=1e-13 * np.abs(ref).max())
            np.testing.assert_allclose(bcast, ref_b, rtol=1e-13, atol=1e-13 * np.abs(ref).max())


def test_jacobian_of_selected_parameter_columns(kvlcc2):
    """``jac_p(..., columns=)`` computes only those columns (the equation-error start asks for the estimated
    ones): equal to the bit to the full Jacobian's columns, compiled (when numba is on) and numpy, shared and
    per-member parameters; a model without its own column path slices the full one."""
    rng = np.random.default_rng(6)
    x, u = MMGModel.sample_point(rng, batch=(5,))
    full = kvlcc2.scaled(320.0)
    pb = full.params * (1 + 0.05 * rng.normal(size=(5, full.np)))
    cols = np.array([full.param_index(n) for n in ("Nr", "Yv", "aH", "C2p", "delta0")])
    paths = [_jit.disabled] + ([contextlib.nullcontext] if _jit.enabled() else [])
    for path in paths:
        with path():
            for p in (full.params, pb):
                ref = full.jac_p(0.0, x, u, p)
                got = full.jac_p(0.0, x, u, p, columns=cols)
                assert got.shape == (5, 6, cols.size)
                np.testing.assert_array_equal(got, ref[..., cols])
    kcs = get_model("kcs-response")
    xk, uk = np.zeros((3, 6)) + [0, 0, 0, 1.0, 0.01, 0.002], np.zeros((3, 2)) + [0.1, 10.0]
    np.testing.assert_array_equal(kcs.jac_p(0.0, xk, uk, columns=[3, 0]), kcs.jac_p(0.0, xk, uk)[..., [3, 0]])


def test_particulars_and_dimensional_conversion(kvlcc2):
    full = kvlcc2.scaled(320.0)
    lam = 320.0 / 7.0
    assert full.particulars.displacement == pytest.approx(3.27 * lam**3)
    assert full.rudder_rate == pytest.approx(kvlcc2.rudder_rate / math.sqrt(lam))
    np.testing.assert_array_equal(full.params, kvlcc2.params)
    assert get_model("mmg", None, lpp=320.0).lpp == 320.0
    dim = kvlcc2.to_dimensional(U0)
    P = kvlcc2.particulars
    assert dim["Yv"] == pytest.approx(-0.315 * 0.5 * P.rho * P.lpp * P.draught * U0)
    assert dim["Nr"] == pytest.approx(-0.049 * 0.5 * P.rho * P.lpp**4 * P.draught * U0 / P.lpp)
    with pytest.raises(ValueError, match="unknown field"):
        MMGParticulars.from_mapping({**P.to_dict(), "bogus": 1.0})
    with pytest.raises(ValueError, match="no parameter set 'nope'"):
        get_model("mmg", "nope")


# ------------------------------------------------------------------ manoeuvres with the MMG model
@pytest.fixture(scope="module")
def kvlcc2_turns(kvlcc2):
    from shipid.manoeuvres import turning_circle

    return turning_circle(kvlcc2, 35.0, side="both")


def test_froude_scaling_keeps_nondimensional_turning_metrics(kvlcc2, kvlcc2_turns):
    """L7 model (7 m) and the full-scale KVLCC2 (320 m) with the same coefficients: identical advance/L, TD/L...
    and times scaling with sqrt(lambda)."""
    from shipid.manoeuvres import turning_circle

    full = turning_circle(kvlcc2.scaled(320.0), 35.0, side="both")
    lam = 320.0 / 7.0
    assert full.settings["speed"].iloc[0] == pytest.approx(U0 * math.sqrt(lam), rel=1e-12)
    assert full.settings["n"].iloc[0] == pytest.approx(kvlcc2_turns.settings["n"].iloc[0] / math.sqrt(lam), rel=1e-9)
    for a, b in zip(kvlcc2_turns.metrics, full.metrics):
        for key in ("advance_L", "transfer_L", "tactical_diameter_L", "steady_diameter_L", "speed_loss"):
            assert getattr(b, key) == pytest.approx(getattr(a, key), rel=1e-7), key
        assert b.time_90 == pytest.approx(a.time_90 * math.sqrt(lam), rel=1e-7)


def test_scaling_helpers():
    from shipid.scaling import froude_factors, scale_inputs, scale_states, scale_time

    lam = 4.0
    x = scale_states([10.0, 1.0, 0.3, 2.0, 0.1, 0.05], ("x", "y", "psi", "u", "v", "r"), lam)
    np.testing.assert_allclose(x, [40.0, 4.0, 0.3, 4.0, 0.2, 0.025])
    np.testing.assert_allclose(scale_inputs([0.1, 10.0], ("delta", "n"), lam), [0.1, 5.0])
    np.testing.assert_allclose(scale_time([0.0, 3.0], lam), [0.0, 6.0])
    assert froude_factors(lam)["force"] == 64.0
    with pytest.raises(ValueError, match="don't know how 'q' scales"):
        scale_states([1.0], ("q",), lam)


MARIN = __import__("pathlib").Path(__file__).parents[1] / ".." / "shared" / "data" / "kvlcc2_marin"
# MARIN README (measured, logged point): tc_35 turns to port, tc_-35 to starboard
MEASURED_TURN = {"starboard": {"advance_L": 3.09, "transfer_L": 1.35, "tactical_diameter_L": 3.33},
                 "port": {"advance_L": 3.02, "transfer_L": 1.20, "tactical_diameter_L": 3.07}}
MEASURED_ZZ = {(10, "starboard"): 8.1, (10, "port"): 9.4, (20, "starboard"): 12.7, (20, "port"): 15.6}


def test_kvlcc2_35deg_turn_against_marin_measurements(kvlcc2_turns):
    """Published-coefficient MMG prediction vs the MARIN free-running KVLCC2 turns (README values).

    Yasukawa & Yoshimura (2015) show their KVLCC2 simulations only as plots, so the check is against the
    measured values, with a 12 % tolerance (typical MMG-vs-free-running agreement in SIMMAN 2008);
    the actual differences are printed and quoted in docs/validation.md.
    """
    if not MARIN.is_dir():
        pytest.skip(f"MARIN KVLCC2 data not found at {MARIN.resolve()}")
    for m in kvlcc2_turns.metrics:
        ref = MEASURED_TURN[m.side]
        for key, val in ref.items():
            got = getattr(m, key)
            print(f"{m.side} {key}: MMG {got:.3f} measured {val:.2f} ({100 * (got / val - 1):+.1f} %)")
            assert got == pytest.approx(val, rel=0.12), f"{m.side} {key}"


def test_kvlcc2_zigzags_against_marin_measurements(kvlcc2):
    """First overshoots of the published-coefficient MMG vs MARIN: the MMG set under-predicts them by 1.5-3 deg
    (printed; docs/validation.md).  The bound here is that measured gap, not a goal."""
    from shipid.manoeuvres import zigzag

    for amp in (10, 20):
        res = zigzag(kvlcc2, float(amp), first="both")
        for m in res.metrics:
            meas = MEASURED_ZZ[(amp, m.first_side)]
            print(f"{amp}/{amp} {m.first_side} first: overshoot1 MMG {m.overshoot1_deg:.2f} measured {meas}")
            assert m.overshoot1_deg == pytest.approx(meas, abs=3.5)


def test_rudder_neutral_angle_makes_the_ship_asymmetric(kvlcc2):
    """delta0 > 0: no rudder force at delta = delta0 (a straight course needs that rudder), and the turn
    to port (negative rudder, larger |alpha_R|) becomes the tighter one.  The published set is already
    slightly asymmetric through gamma_R and C2 (different for beta_R, beta_P < 0 and > 0); with those
    made equal the turns are mirror images."""
    from shipid.manoeuvres import turning_circle

    d0 = math.radians(1.0)
    x = np.array([0, 0, 0, 1.179, 0, 0.0])
    n = 10.0
    asym = kvlcc2.with_params({"delta0": d0})
    assert abs(asym.forces(x, [d0, n])["F_N"]) < 1e-12 and abs(asym.rhs(0.0, x, [d0, n])[5]) < 1e-15
    assert abs(kvlcc2.forces(x, [d0, n])["F_N"]) > 1.0
    p = dict(zip(kvlcc2.param_names, kvlcc2.params))
    mirror = {"gammaR_m": p["gammaR_p"], "C2m": p["C2p"]}
    td = {}
    for name, m in (("published", kvlcc2), ("published+delta0", asym),
                    ("mirror", kvlcc2.with_params(mirror)), ("mirror+delta0", kvlcc2.with_params({**mirror, "delta0": d0}))):
        res = turning_circle(m, 35.0, side="both")
        td[name] = [r.tactical_diameter_L for r in res.metrics]  # members: starboard, port
    assert td["mirror"][0] == pytest.approx(td["mirror"][1], rel=1e-6)
    assert td["mirror+delta0"][1] < td["mirror"][1] < td["mirror+delta0"][0]
    gap = {k: v[0] - v[1] for k, v in td.items()}  # starboard minus port
    assert gap["published+delta0"] > gap["published"] + 0.02 > 0.02
