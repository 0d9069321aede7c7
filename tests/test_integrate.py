"""shipid.integrate: the adaptive Dormand-Prince 5(4) integrator against analytic solutions, and
simulate(method="dopri5") against converged fixed-step RK4 on the MMG model."""
from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

from shipid.integrate import dopri5
from shipid.models import get_model
from shipid.simulate import simulate

W = np.array([1.0, 2.0, 3.0])


def _osc(t, x):
    """Three harmonic oscillators (one per batch member): x'' = -w^2 x."""
    return np.stack([x[..., 1], -W**2 * x[..., 0]], axis=-1)


X0 = np.stack([np.ones(3), np.zeros(3)], axis=-1)
T_EVAL = np.linspace(0.0, 10.0, 1001)


@pytest.mark.parametrize("rtol", [1e-6, 1e-9])
def test_batch_error_follows_the_tolerance(rtol):
    r = dopri5(_osc, 0.0, X0, 10.0, T_EVAL, rtol=rtol, atol=1e-3 * rtol)
    assert r.success
    err = np.max(np.abs(r.x[..., 0] - np.cos(W * T_EVAL[:, None])))
    assert err < 20 * rtol
    assert r.n_fev == 6 * (r.n_steps + r.n_rejected) + 2  # FSAL: 6 new stages per step, 2 for the first step


def test_tighter_tolerance_needs_fewer_than_two_times_the_steps_per_decade_and_is_more_accurate():
    errs, steps = [], []
    for rtol in (1e-5, 1e-7, 1e-9):
        r = dopri5(_osc, 0.0, X0, 10.0, T_EVAL, rtol=rtol, atol=1e-3 * rtol)
        errs.append(np.max(np.abs(r.x[..., 0] - np.cos(W * T_EVAL[:, None]))))
        steps.append(r.n_steps)
    assert errs[0] > 30 * errs[1] > 900 * errs[2]
    assert steps[1] < 3 * steps[0] and steps[2] < 3 * steps[1]  # fifth order: 100x tolerance = 2.5x steps


def test_dense_output_is_fourth_order_between_steps():
    """Fixed steps (tolerance never binding): the interpolated error falls ~2^5 per halving of the step."""
    e = []
    for h in (0.2, 0.1, 0.05):
        r = dopri5(_osc, 0.0, X0, 10.0, T_EVAL, rtol=1e3, atol=1e3, h0=h, h_max=h)
        assert r.n_steps == pytest.approx(10.0 / h, abs=1)
        e.append(np.max(np.abs(r.x[..., 0] - np.cos(W * T_EVAL[:, None]))))
    assert e[0] / e[1] > 20 and e[1] / e[2] > 20


def test_events_are_located_per_member_and_handled_in_time_order():
    hits = []
    r = dopri5(_osc, 0.0, X0, 2.0, None, rtol=1e-10, atol=1e-13, event=lambda t, x: 0.5 - x[..., 0],
               on_event=lambda t, x, m: hits.append((t, m.copy())))
    exact = np.arccos(0.5) / W  # first time cos(w t) = 0.5
    assert r.success and len(hits) == 3
    order = np.argsort(exact)
    for (t, mask), k in zip(hits, order):
        assert mask.tolist() == [i == k for i in range(3)]
        assert t == pytest.approx(exact[k], abs=1e-9)


def test_simultaneous_events_fire_together_and_an_unchanged_root_does_not_retrigger():
    w2 = np.array([2.0, 2.0])
    hits = []
    r = dopri5(lambda t, x: np.stack([x[..., 1], -w2**2 * x[..., 0]], axis=-1), 0.0, np.array([[1.0, 0.0], [1.0, 0.0]]),
               1.0, None, rtol=1e-8, atol=1e-11, event=lambda t, x: 0.5 - x[..., 0],
               on_event=lambda t, x, m: hits.append((t, m.copy())))
    assert r.success and len(hits) == 1 and hits[0][1].tolist() == [True, True]
    assert hits[0][0] == pytest.approx(math.acos(0.5) / 2, abs=1e-8)


def test_stops_on_a_kink_of_the_right_hand_side_make_the_solution_exact():
    f = lambda t, x: np.minimum(t, 1.0) * np.ones_like(x)  # noqa: E731  x = t^2/2, then 1/2 + (t - 1)
    te = np.array([0.5, 1.0, 2.0])
    r = dopri5(f, 0.0, np.zeros(1), 2.0, te, rtol=1e-3, atol=1e-3, stops=[1.0])
    assert r.x[:, 0] == pytest.approx([0.125, 0.5, 1.5], abs=1e-13)
    free = dopri5(f, 0.0, np.zeros(1), 2.0, te, rtol=1e-3, atol=1e-3, h0=0.3)  # a step straddles the kink
    assert abs(free.x[-1, 0] - 1.5) > 1e-8


def test_blow_up_reports_failure():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        r = dopri5(lambda t, x: x * x, 0.0, np.ones(1), 2.0, np.linspace(0, 2, 5), rtol=1e-6)
    assert not r.success and "non-finite" in r.message
    assert np.isnan(r.x[-1, 0]) and r.t_final < 1.0 + 1e-6


def test_non_finite_start_or_right_hand_side_fails_instead_of_hanging():
    """A NaN start made the first step size NaN, which never shrank below the step floor: an endless loop."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        r = dopri5(lambda t, x: -x, 0.0, np.array([np.nan]), 1.0, np.linspace(0, 1, 3))
        assert not r.success and "non-finite" in r.message
        r = dopri5(lambda t, x: x * np.nan, 0.0, np.ones(2), 1.0, np.linspace(0, 1, 3), h0=0.1)
        assert not r.success and "non-finite" in r.message


def test_bad_arguments():
    with pytest.raises(ValueError, match="t_end"):
        dopri5(_osc, 1.0, X0, 0.0)
    with pytest.raises(ValueError, match="t_eval"):
        dopri5(_osc, 0.0, X0, 1.0, np.array([0.5, 0.2]))
    m = get_model("mmg")
    with pytest.raises(ValueError, match="method"):
        simulate(m, [0, 0, 0, 1, 0, 0], [0, 1], np.zeros((2, 2)), method="euler")


# ------------------------------------------------------------------ simulate(method="dopri5") on the MMG model
@pytest.fixture(scope="module")
def turn():
    m = get_model("mmg")
    U0 = 1.179
    n = 10.0
    t = np.linspace(0.0, 150.0, 301)
    U = np.tile([math.radians(35), n], (t.size, 1))
    U[:20, 0] = 0.0  # rudder amidships for 10 s, then a step: a breakpoint of the inputs
    x0 = [0, 0, 0, U0, 0, 0]
    ref = simulate(m, x0, t, U, substeps=40)  # RK4 with dt = 0.0125 s: converged to ~1e-9 L
    return m, x0, t, U, ref


def test_dopri5_matches_converged_rk4_with_few_evaluations(turn):
    m, x0, t, U, ref = turn
    res = simulate(m, x0, t, U, method="dopri5", rtol=1e-8)
    assert res.success and res.meta["method"] == "dopri5"
    err = np.max(np.hypot(*(res.x[:, :2] - ref.x[:, :2]).T)) / m.lpp
    assert err < 1e-6
    assert np.array_equal(res.u, ref.u)
    assert res.meta["n_fev"] < 0.25 * 4 * 40 * (t.size - 1)  # far fewer than the converged RK4
    loose = simulate(m, x0, t, U, method="dopri5", rtol=1e-4)
    err_loose = np.max(np.hypot(*(loose.x[:, :2] - ref.x[:, :2]).T)) / m.lpp
    assert err < err_loose < 1e-3 and loose.meta["n_fev"] < res.meta["n_fev"]


def test_dopri5_batch_equals_members_within_tolerance(turn):
    m, x0, t, U, _ = turn
    X0 = np.array([x0, [0, 0, 0, 1.0, 0, 0]])
    UU = np.stack([U, U * [-1, 1]])
    both = simulate(m, X0, t, UU, method="dopri5", rtol=1e-8)
    for i in range(2):
        one = simulate(m, X0[i], t, UU[i], method="dopri5", rtol=1e-8)
        assert np.max(np.abs(both.x[i, :, :2] - one.x[:, :2])) / m.lpp < 1e-6


# ------------------------------------------------------------------ RK4 steps with first-order-hold inputs
def test_first_order_hold_step_integrates_a_linear_input_exactly_and_zoh_is_the_equal_end_case():
    """x' = u with u linear over the step: RK4 with stage inputs is exact (x0 + h (u0 + u1) / 2)."""
    from shipid.integrate import rk4_step_tangent, rk4_step_taylor_tangent

    m = get_model("kcs-response", "synthetic-truth")

    class Ramp:  # the protocol's private hooks on a one-state ODE x' = u
        def _rhs(self, t, x, u, p):
            return u[..., :1] * np.ones_like(x)

        def _jac_x(self, t, x, u, p):
            return np.zeros(x.shape + (1,))

        def _jac_p(self, t, x, u, p):
            return np.zeros(x.shape + (1,))

    r = Ramp()
    x0, u0, u1, h = np.array([1.0]), np.array([2.0]), np.array([5.0]), 0.3
    for step in (rk4_step_tangent, rk4_step_taylor_tangent):
        assert step(r, 0.0, x0, u0, None, h, u1)[0][0] == pytest.approx(1.0 + h * 3.5, abs=1e-15)
        assert step(r, 0.0, x0, u0, None, h)[0][0] == pytest.approx(1.0 + h * 2.0, abs=1e-15)
    # on a real model: u1 = u0 gives the held step bit for bit
    x = np.array([0.0, 0.0, 0.1, 1.6, 0.01, 0.02])
    u = np.array([0.3, 10.0])
    a = rk4_step_tangent(m, 0.0, x, u, m.params, 0.1)
    b = rk4_step_tangent(m, 0.0, x, u, m.params, 0.1, u.copy())
    for ai, bi in zip(a, b):
        assert np.array_equal(ai, bi)


def test_exact_tangent_with_first_order_hold_matches_finite_differences():
    from shipid.integrate import rk4_step, rk4_step_tangent

    m = get_model("kcs-response", "synthetic-truth")
    x = np.array([0.0, 0.0, 0.1, 1.6, 0.01, 0.02])
    u0, u1, p, h = np.array([0.1, 10.0]), np.array([0.4, 11.0]), m.params, 0.2
    xn, Fx, Fp = rk4_step_tangent(m, 0.0, x, u0, p, h, u1)
    assert np.allclose(xn, rk4_step(m, 0.0, x, u0, p, h, u1), rtol=0, atol=1e-15)
    eps = 1e-6
    Fx_fd = np.stack([(rk4_step(m, 0.0, x + eps * e, u0, p, h, u1) - rk4_step(m, 0.0, x - eps * e, u0, p, h, u1))
                      / (2 * eps) for e in np.eye(m.nx)], axis=-1)
    dp = eps * np.maximum(np.abs(p), 1e-3)
    Fp_fd = np.stack([(rk4_step(m, 0.0, x, u0, p + d * e, h, u1) - rk4_step(m, 0.0, x, u0, p - d * e, h, u1))
                      / (2 * d) for d, e in zip(dp, np.eye(m.np))], axis=-1)
    np.testing.assert_allclose(Fx, Fx_fd, rtol=1e-6, atol=1e-9)
    # a central difference with step d carries a round-off error of about eps_machine * |x| / d per column
    roundoff = 8 * np.finfo(float).eps * np.max(np.abs(xn)) / dp
    assert np.all(np.abs(Fp - Fp_fd) <= 1e-5 * np.abs(Fp_fd) + np.maximum(roundoff[None, :], 1e-12))


def test_first_order_hold_replay_agrees_between_rk4_and_dopri5_and_differs_from_zoh(turn):
    m, x0, t, U, _ = turn
    U = U.copy()
    U[:, 0] = np.radians(20.0) * np.sin(0.2 * t)  # a rudder that moves between samples
    fine = simulate(m, x0, t, U, substeps=20, input_hold="foh")
    adapt = simulate(m, x0, t, U, method="dopri5", rtol=1e-9, input_hold="foh")
    zoh = simulate(m, x0, t, U, substeps=20)
    d = lambda a, b: np.max(np.hypot(*(a.x[:, :2] - b.x[:, :2]).T)) / m.lpp  # noqa: E731
    assert d(fine, adapt) < 1e-6
    assert d(fine, zoh) > 1e-3  # holding the rudder for 0.5 s shifts the track by more than 0.1 % L
    with pytest.raises(ValueError, match="input_hold"):
        simulate(m, x0, t, U, input_hold="linear")
