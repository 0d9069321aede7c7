"""Integration shared by the simulator and the EKF: fixed-step RK4 (with tangents) and adaptive Dormand-Prince 5(4).

One Runge-Kutta step of a protocol model, and the same step with its exact
tangent (the Jacobian of the discrete map with respect to the state and the
parameters, obtained by differentiating the RK4 stages).  The EKF uses the
tangent as its transition matrix, so the filter's discrete model and the
simulator's are the same map.
"""
from __future__ import annotations

import bisect
import math
import warnings
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Callable

import numpy as np

from .models.base import Model

__all__ = ["interval_steps", "hold_steps", "rk4_step", "rk4_map", "rk4_step_tangent", "rk4_step_taylor_tangent", "euler_step_tangent", "STEP_TANGENTS",
           "dopri5", "AdaptiveResult"]


@lru_cache(maxsize=16)
def _eye(n: int) -> np.ndarray:
    """A cached read-only identity (built once per size; steps are called per sample)."""
    eye = np.eye(n)
    eye.flags.writeable = False
    return eye


def _stage_inputs(u, u1):
    """Inputs at the start, middle and end of a step: ``u`` held (``u1`` None) or linear from ``u`` to ``u1``.

    The middle value ``0.5 * (u + u1)`` is the first-order-hold input at half the step; with
    ``u1 = u`` it equals ``u`` exactly (floating point), so zero-order hold is the special case
    of equal end inputs.
    """
    if u1 is None:
        return u, u, u
    return u, 0.5 * (u + u1), u1


def interval_steps(t: np.ndarray, substeps: int, h_max: float | None) -> np.ndarray:
    """RK4 steps per sample interval: ``n_k = max(substeps, ceil(dt_k / h_max - 1e-9))``.

    ``t (..., N)`` sample times [s] -> ``(..., N-1)`` int; ``h_max`` None gives ``substeps``
    everywhere.  The ``1e-9`` keeps an interval of exactly ``m * h_max`` (to rounding) at ``m`` steps.
    """
    dt = np.diff(np.asarray(t, dtype=float), axis=-1)
    n = np.full(dt.shape, int(substeps), dtype=np.int64)
    if h_max is not None:
        if not h_max > 0:
            raise ValueError(f"h_max must be positive or None, got {h_max}")
        n = np.maximum(n, np.ceil(dt / float(h_max) - 1e-9).astype(np.int64))
    return n


def hold_steps(u0, u1, n: int):
    """End inputs ``(u_a, u_b)`` of the ``n`` equal steps that cross one sample interval.

    First-order hold (``u1`` given): step ``i`` runs from ``(1 - w_i) u0 + w_i u1`` to the same at
    ``w_{i+1}``, ``w_i = i / n``; the first starts on ``u0`` and the last ends on ``u1`` exactly.
    Zero-order hold (``u1`` None): ``(u0, None)`` for every step (the step functions then hold ``u0``).
    """
    ua = u0
    for i in range(n):
        if u1 is None:
            yield u0, None
            continue
        if i == n - 1:
            ub = u1
        else:
            w = (i + 1) / n
            ub = (1.0 - w) * u0 + w * u1
        yield ua, ub
        ua = ub


def rk4_step(model: Model, t, x, u, p, h, u1=None):
    """One classical RK4 step.

    Shapes: ``x (..., nx)``, ``u (..., nu)``, ``p (..., np)``; ``h`` scalar or
    ``(...)``.  Returns ``x(t + h)``.  The input is held at ``u`` over the step
    (zero-order hold) or, with ``u1`` (the input at ``t + h``), linear from ``u``
    to ``u1`` (first-order hold): each RK4 stage sees the input at its stage time
    (``u`` at ``t``, ``(u + u1) / 2`` at ``t + h/2``, ``u1`` at ``t + h``).
    """
    rhs = model._rhs
    return rk4_map(lambda tt, xx, uu: rhs(tt, xx, uu, p), t, x, u, h, u1)


def rk4_map(f: Callable, t, x, u, h, u1=None):
    """The RK4 step of :func:`rk4_step` for a right-hand side ``f(t, x, u)`` with the parameters bound
    (e.g. ``model._rhs_bound(p)``, which integrators fetch once per run); ``u1`` as there."""
    if isinstance(h, float):
        hh = h
    else:
        h = np.asarray(h, dtype=float)
        hh = h[..., None] if h.ndim else h
    ua, um, ub = _stage_inputs(u, u1)
    k1 = f(t, x, ua)
    k2 = f(t + h / 2, x + hh / 2 * k1, um)
    k3 = f(t + h / 2, x + hh / 2 * k2, um)
    k4 = f(t + h, x + hh * k3, ub)
    return x + hh / 6 * (k1 + 2 * k2 + 2 * k3 + k4)


def rk4_step_tangent(model: Model, t, x, u, p, h, u1=None):
    """RK4 step and its exact Jacobians ``(x_next, dxn/dx, dxn/dp)``.

    Inputs per stage as in :func:`rk4_step` (``u1`` None: held; else linear to ``u1``); the
    Jacobians of each stage are taken at that stage's input.
    Returns arrays of shapes ``(..., nx)``, ``(..., nx, nx)``, ``(..., nx, np)``.
    """
    h = np.asarray(h, dtype=float)
    hh = h[..., None] if h.ndim else h
    hm = h[..., None, None] if h.ndim else h
    f, fx, fp = model._rhs, model._jac_x, model._jac_p
    nx = x.shape[-1]
    eye = _eye(nx)
    ua, um, ub = _stage_inputs(u, u1)

    k1 = f(t, x, ua, p)
    A1, B1 = fx(t, x, ua, p), fp(t, x, ua, p)
    K1x, K1p = A1, B1

    x2 = x + hh / 2 * k1
    A2, B2 = fx(t + h / 2, x2, um, p), fp(t + h / 2, x2, um, p)
    K2x = A2 @ (eye + hm / 2 * K1x)
    K2p = A2 @ (hm / 2 * K1p) + B2
    k2 = f(t + h / 2, x2, um, p)

    x3 = x + hh / 2 * k2
    A3, B3 = fx(t + h / 2, x3, um, p), fp(t + h / 2, x3, um, p)
    K3x = A3 @ (eye + hm / 2 * K2x)
    K3p = A3 @ (hm / 2 * K2p) + B3
    k3 = f(t + h / 2, x3, um, p)

    x4 = x + hh * k3
    A4, B4 = fx(t + h, x4, ub, p), fp(t + h, x4, ub, p)
    K4x = A4 @ (eye + hm * K3x)
    K4p = A4 @ (hm * K3p) + B4
    k4 = f(t + h, x4, ub, p)

    xn = x + hh / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    Fx = eye + hm / 6 * (K1x + 2 * K2x + 2 * K3x + K4x)
    Fp = hm / 6 * (K1p + 2 * K2p + 2 * K3p + K4p)
    return xn, Fx, Fp


def euler_step_tangent(model: Model, t, x, u, p, h, u1=None):
    """Explicit Euler step and its Jacobians (cheaper, first order); uses the input at the step
    start only, so ``u1`` (accepted for a common signature) has no effect."""
    h = np.asarray(h, dtype=float)
    hh = h[..., None] if h.ndim else h
    hm = h[..., None, None] if h.ndim else h
    xn = x + hh * model._rhs(t, x, u, p)
    Fx = _eye(x.shape[-1]) + hm * model._jac_x(t, x, u, p)
    Fp = hm * model._jac_p(t, x, u, p)
    return xn, Fx, Fp


def rk4_step_taylor_tangent(model: Model, t, x, u, p, h, u1=None):
    """RK4 step with a second-order Taylor tangent (cheaper than the exact one).

    The state is advanced by RK4 (stage inputs as in :func:`rk4_step`); the
    Jacobians are those of the exact flow to second order in ``h`` about the
    start point ``(t, x, u)``:
    ``Fx = I + h A + h^2 A^2 / 2`` and ``Fp = h (I + h A / 2) B`` with
    ``A = df/dx``, ``B = df/dp``.  They differ from the exact RK4 tangent by
    O(h^3 |A|^3) (and, under first-order hold, by O(h^2 |df/du| |u1 - u|)),
    negligible when the step is short against the model's time constants
    (checked in the tests); one Jacobian evaluation instead of four.
    """
    h = np.asarray(h, dtype=float)
    hm = h[..., None, None] if h.ndim else h
    xn = rk4_step(model, t, x, u, p, h, u1)
    A = model._jac_x(t, x, u, p)
    Bp = model._jac_p(t, x, u, p)
    hA = hm * A
    eye = _eye(x.shape[-1])
    half = eye + 0.5 * hA
    Fx = eye + hA @ half
    Fp = hm * (half @ Bp)
    return xn, Fx, Fp


#: Discretisations available to the EKF: name -> step-with-tangent function.
STEP_TANGENTS = {"rk4": rk4_step_taylor_tangent, "rk4-exact": rk4_step_tangent, "euler": euler_step_tangent}


# --------------------------------------------------------------------------- adaptive Dormand-Prince 5(4)
# Tableau of Dormand & Prince (1980), "A family of embedded Runge-Kutta formulae", J Comp Appl Math 6:19-26;
# error weights E = b5 - b4 and the dense output of Shampine (1986), "Some practical Runge-Kutta formulas",
# Math Comp 46:135-150, in the form of Hairer, Norsett & Wanner, Solving ODEs I (2nd ed.), sec. II.6 (DOPRI5).
_DP_C = np.array([0.0, 0.2, 0.3, 0.8, 8.0 / 9.0, 1.0, 1.0])
_DP_A = np.zeros((7, 7))
_DP_A[1, :1] = [0.2]
_DP_A[2, :2] = [3.0 / 40.0, 9.0 / 40.0]
_DP_A[3, :3] = [44.0 / 45.0, -56.0 / 15.0, 32.0 / 9.0]
_DP_A[4, :4] = [19372.0 / 6561.0, -25360.0 / 2187.0, 64448.0 / 6561.0, -212.0 / 729.0]
_DP_A[5, :5] = [9017.0 / 3168.0, -355.0 / 33.0, 46732.0 / 5247.0, 49.0 / 176.0, -5103.0 / 18656.0]
_DP_A[6, :6] = [35.0 / 384.0, 0.0, 500.0 / 1113.0, 125.0 / 192.0, -2187.0 / 6784.0, 11.0 / 84.0]
_DP_E = np.array([71.0 / 57600.0, 0.0, -71.0 / 16695.0, 71.0 / 1920.0, -17253.0 / 339200.0, 22.0 / 525.0, -1.0 / 40.0])
_DP_D = np.array([-12715105075.0 / 11282082432.0, 0.0, 87487479700.0 / 32700410799.0, -10690763975.0 / 1880347072.0,
                  701980252875.0 / 199316789632.0, -1453857185.0 / 822651844.0, 69997945.0 / 29380423.0])


@dataclass
class AdaptiveResult:
    """Result of :func:`dopri5` (fields as scipy's OdeResult where they overlap).

    Attributes
    ----------
    t : ndarray (n_eval,)  output times [s]
    x : ndarray (n_eval, ...)  states at ``t`` (NaN after a failure)
    t_final : float  time reached
    x_final : ndarray  state at ``t_final``
    h_last : float  step proposed for a continuation [s] (from the last error estimate)
    n_steps, n_rejected, n_fev : int  accepted / rejected steps, right-hand-side evaluations
    t_events : list of (time, member mask)  events located (see ``event``)
    success : bool
    message : str
    """

    t: np.ndarray
    x: np.ndarray
    t_final: float
    x_final: np.ndarray
    h_last: float
    n_steps: int = 0
    n_rejected: int = 0
    n_fev: int = 0
    t_events: list = field(default_factory=list)
    success: bool = True
    message: str = "integration finished"


def dopri5(f: Callable, t0: float, x0, t_end: float, t_eval=None, *, rtol: float = 1e-6, atol=1e-9,
           h0: float | None = None, h_max: float = np.inf, stops=(), event: Callable | None = None,
           on_event: Callable | None = None, max_steps: int = 1_000_000) -> AdaptiveResult:
    """Integrate ``dx/dt = f(t, x)`` with the embedded Dormand-Prince 5(4) pair and error control.

    Batch-aware: ``x0`` may have any shape ``(..., nx)``; one step size is shared by the whole batch
    and chosen from the largest per-member error, so a batch advances together (vectorised) and every
    member is at least as accurate as it would be alone at the same tolerance.

    Parameters
    ----------
    f : callable ``(t, x) -> dx/dt``  same shape as ``x``; must be smooth between ``stops`` and events.
    t0, t_end : float  start and end time [s]
    x0 : array (..., nx)
    t_eval : array (n_eval,), optional  increasing output times in [t0, t_end] (default ``[t0, t_end]``);
        states between steps come from the 4th-order dense output of Shampine (1986).
    rtol, atol : float or array (nx,)  error tolerance per component: |err| <= atol + rtol |x|
        (RMS over the components, as in Hairer's DOPRI5 and scipy's RK45).
    h0 : float, optional  first step [s] (default: Hairer's starting-step heuristic)
    h_max : float  largest step [s]
    stops : sequence of float  times the integration must step onto exactly: kinks of ``f`` in time (a rudder
        ramp starting or ending); ``f`` is re-evaluated there (no first-same-as-last reuse across a stop).
        ``f`` itself must be continuous: a jump is integrated as separate runs (as ``simulate`` does for
        zero-order-hold inputs).
    event : callable ``(t, x) -> g``, optional  event functions, shape ``x.shape[:-1]`` (one per member);
        an event is a crossing of ``g`` from negative to ``>= 0`` within a step.  The earliest crossing is
        located on the dense output (Illinois regula falsi), the step is redone to end exactly there,
        and ``on_event(t, x, mask)`` is called with the members that cross there; ``f`` may change
        behaviour after it (it is re-evaluated).
    max_steps : int  limit on accepted + rejected steps

    Returns
    -------
    AdaptiveResult
    """
    x = np.array(x0, dtype=float)
    shape = x.shape
    nx = shape[-1]
    t_eval = np.array([t0, t_end], dtype=float) if t_eval is None else np.asarray(t_eval, dtype=float)
    if t_end <= t0:
        raise ValueError(f"dopri5: t_end ({t_end}) must be after t0 ({t0})")
    if t_eval.size and (t_eval[0] < t0 - 1e-12 * max(1.0, abs(t0)) or t_eval[-1] > t_end + 1e-12 * max(1.0, abs(t_end))
                        or np.any(np.diff(t_eval) < 0)):
        raise ValueError("dopri5: t_eval must be increasing and inside [t0, t_end]")
    atol = np.broadcast_to(np.asarray(atol, dtype=float), (nx,))
    X = np.full((t_eval.size,) + shape, np.nan)
    ie = int(np.searchsorted(t_eval, t0, side="right"))
    X[:ie] = x
    stop_list = sorted(float(s) for s in stops if t0 < s < t_end) + [float(t_end)]
    si = 0
    n_fev = n_steps = n_rej = 0
    K = np.zeros((7,) + shape)
    Kf = K.reshape(7, -1)
    flat = x.ndim == 1
    A, C, E = _DP_A, _DP_C, _DP_E
    members = shape[:-1]
    inv_sqrt_nx = 1.0 / math.sqrt(nx)

    def err_norm(v, sc):
        q = v / sc
        if members:
            return math.sqrt(float(np.max(np.einsum("...i,...i->...", q, q)))) * inv_sqrt_nx
        return math.sqrt(q.dot(q)) * inv_sqrt_nx

    # dense output is evaluated once at the end over all steps (vectorised): steps with outputs are kept
    pending: list = []
    n_eval = t_eval.size

    t_eval_list = t_eval.tolist()  # bisect on a list: far cheaper per step than np.searchsorted

    def keep(ie, t, hs, x, x_new):
        t_end_step = t + hs * (1.0 + 1e-12)
        if ie < n_eval and t_eval_list[ie] <= t_end_step:
            je = bisect.bisect_right(t_eval_list, t_end_step)
            pending.append((ie, je, t, hs, x, x_new, K.copy()))
            return je
        return ie

    t = float(t0)
    K[0] = f(t, x)
    n_fev += 1
    if h0 is None:  # Hairer, Norsett & Wanner II.4: h from the sizes of x, f and an Euler probe
        sc = atol + rtol * np.abs(x)
        d0, d1 = err_norm(x, sc), err_norm(K[0], sc)
        h = 1e-6 if (d0 < 1e-5 or d1 < 1e-5) else 0.01 * d0 / d1
        h = min(h, t_end - t)
        f1 = f(t + h, x + h * K[0])
        n_fev += 1
        d2 = err_norm(f1 - K[0], sc) / h
        h1 = max(1e-6, h * 1e-3) if max(d1, d2) <= 1e-15 else (0.01 / max(d1, d2)) ** 0.2
        h = min(100 * h, h1)
    else:
        h = float(h0)
    h = min(h, h_max)
    g_now = event(t, x) if event is not None else None
    ax = np.abs(x)
    t_events: list = []
    ok, msg = True, "integration finished"
    while True:
        t_stop = stop_list[si]
        last = h >= t_stop - t - 1e-12 * max(1.0, abs(t_stop))
        hs = t_stop - t if last else h
        # stages (A is strictly lower triangular and K is finite, so A[i] @ K uses only stages < i)
        Ah = hs * A
        for i in range(1, 6):
            K[i] = f(t + C[i] * hs, x + (Ah[i].dot(Kf) if flat else Ah[i].dot(Kf).reshape(shape)))
        # stage 7 is evaluated at x + hs * (A[6] @ K) = x_new (A[6] = b5): K[6] = f(t + hs, x_new)
        x_new = x + (Ah[6].dot(Kf) if flat else Ah[6].dot(Kf).reshape(shape))
        K[6] = f(t + hs, x_new)
        n_fev += 6
        ax_new = np.abs(x_new)
        sc = atol + rtol * np.maximum(ax, ax_new)
        err = err_norm((hs * E).dot(Kf) if flat else (hs * E).dot(Kf).reshape(shape), sc)
        if not math.isfinite(err):
            # a non-finite start, input or step (NaN h never shrinks below the floor) ends here too
            if not (hs >= 1e-12 * max(1.0, abs(t))) or n_steps + n_rej > max_steps:
                ok, msg = False, f"state became non-finite at t = {t:.6g} s; the model or its parameters are unstable here"
                break
            h = 0.1 * hs
            n_rej += 1
            continue
        if err > 1.0:
            h = hs * max(0.2, 0.9 * err ** -0.2)
            n_rej += 1
            if n_steps + n_rej > max_steps:
                ok, msg = False, f"more than {max_steps} steps"
                break
            continue
        # accepted
        fac = min(10.0, max(0.2, 0.9 * max(err, 1e-10) ** -0.2))
        if event is not None:
            g_new = event(t + hs, x_new)
            cross = (g_now < 0) & (g_new >= 0)
            if np.any(cross):
                th = _locate_events(event, x, x_new, K, hs, t, g_now, g_new, cross, shape)
                t_ev = t + hs * float(np.min(th[cross]))
                mask = cross & (t + hs * th <= t_ev + 1e-9 * hs)
                h_next = min(hs * fac, h_max)
                if t_ev < t + hs * (1.0 - 1e-12):  # redo the step to end on the event
                    hs = t_ev - t
                    Ah = hs * A
                    for i in range(1, 6):
                        K[i] = f(t + C[i] * hs, x + Ah[i].dot(Kf).reshape(shape))
                    x_new = x + Ah[6].dot(Kf).reshape(shape)
                    K[6] = f(t + hs, x_new)
                    n_fev += 6
                    ax_new = np.abs(x_new)
                ie = keep(ie, t, hs, x, x_new)
                t, x, ax = t_ev, x_new, ax_new
                g_pre = event(t, x)
                on_event(t, x, mask)
                t_events.append((t, mask))
                K[0] = f(t, x)
                n_fev += 1
                g_now = event(t, x)
                # a member whose g the handler left unchanged sits on its root (g ~ 0 up to the
                # integration error): it must not re-trigger at once
                same = mask & (np.abs(g_now - g_pre) <= 1e-9 * (1.0 + np.abs(g_pre)))
                g_now = np.where(same, np.maximum(g_now, 0.0), g_now)
                n_steps += 1
                h = h_next
                continue
            g_now = g_new
        ie = keep(ie, t, hs, x, x_new)
        n_steps += 1
        t, x, ax = (t_stop if last else t + hs), x_new, ax_new
        if last:
            si += 1
            if si >= len(stop_list):
                break
            K[0] = f(t, x)  # the inputs may kink/jump at a stop
            n_fev += 1
            if event is not None:
                g_now = event(t, x)
            h = min(max(h, hs * fac), h_max)
        else:
            K[0] = K[6]
            h = min(hs * fac, h_max)
        if n_steps + n_rej > max_steps:
            ok, msg = False, f"more than {max_steps} steps"
            break
    _dense_fill(X, t_eval, pending)
    if not ok:
        warnings.warn(msg, RuntimeWarning, stacklevel=2)
    return AdaptiveResult(t=t_eval, x=X, t_final=t, x_final=x, h_last=h, n_steps=n_steps, n_rejected=n_rej,
                          n_fev=n_fev, t_events=t_events, success=ok, message=msg)


def _dense_coeffs(x, x_new, K, hs, D):
    shape = x.shape
    dx = x_new - x
    b = hs * K[0] - dx
    return x, dx, b, dx - hs * K[6] - b, hs * (D @ K.reshape(7, -1)).reshape(shape)


def _dense_eval(coef, th):
    """Shampine's interpolant at fractions ``th`` (broadcast against the state's leading axes)."""
    r1, r2, r3, r4, r5 = coef
    s = 1.0 - th
    return r1 + th * (r2 + s * (r3 + th * (r4 + s * r5)))


def _dense_fill(X, t_eval, pending):
    """Write the outputs of all kept steps at once: ``pending`` holds (ie, je, t, hs, x, x_new, K) of each
    step with outputs t_eval[ie:je] in (t, t + hs]."""
    if not pending:
        return
    ie0, je1 = pending[0][0], pending[-1][1]
    counts = np.array([je - ie for ie, je, *_ in pending])
    rep = np.repeat(np.arange(len(pending)), counts)
    T0 = np.array([p[2] for p in pending])
    H = np.array([p[3] for p in pending])
    X0 = np.stack([p[4] for p in pending])
    X1 = np.stack([p[5] for p in pending])
    K = np.stack([p[6] for p in pending])  # (m, 7, ...)
    lead = (slice(None),) + (None,) * (X0.ndim - 1)
    Hb = H[lead]
    dx = X1 - X0
    b = Hb * K[:, 0] - dx
    r4 = dx - Hb * K[:, 6] - b
    r5 = Hb * np.tensordot(K, _DP_D, axes=([1], [0]))  # (m, ...)
    th = ((t_eval[ie0:je1] - T0[rep]) / H[rep])[lead]
    s = 1.0 - th
    # Horner form of _dense_eval, in place on the output block (no full-size temporaries)
    out = X[ie0:je1]
    np.multiply(s, r5[rep], out=out)
    out += r4[rep]
    out *= th
    out += b[rep]
    out *= s
    out += dx[rep]
    out *= th
    out += X0[rep]
    # outputs that fall on a step end take the step's state itself
    end = np.abs(t_eval[ie0:je1] - (T0 + H)[rep]) <= 1e-12 * np.maximum(1.0, np.abs(t_eval[ie0:je1]))
    if np.any(end):
        X[ie0:je1][end] = X1[rep[end]]


def _locate_events(event, x, x_new, K, hs, t, g0, g1, cross, shape):
    """Fractions in (0, 1] of the step where each crossing member's ``g`` reaches 0 (Illinois method)."""
    coef = _dense_coeffs(x, x_new, K, hs, _DP_D)
    lo = np.zeros(g0.shape)
    hi = np.ones(g0.shape)
    glo, ghi = np.where(cross, g0, -1.0), np.where(cross, g1, 1.0)
    side = np.zeros(g0.shape)
    best, gbest = hi.copy(), np.where(cross, np.abs(g1), np.inf)
    for _ in range(60):
        th = np.where(cross, (lo * ghi - hi * glo) / (ghi - glo), 1.0)
        th = np.clip(th, lo, hi)
        xm = _dense_eval(coef, th[..., None])
        gm = event(t + hs * th, xm)
        up = gm >= 0
        better = cross & (np.abs(gm) < gbest)
        best, gbest = np.where(better, th, best), np.where(better, np.abs(gm), gbest)
        # Illinois: halve the stale end's value when the same end is kept twice
        glo_new = np.where(up, np.where(side == -1, glo * 0.5, glo), gm)
        ghi_new = np.where(up, gm, np.where(side == 1, ghi * 0.5, ghi))
        side = np.where(up, -1, 1)
        hi, ghi = np.where(up & cross, th, hi), np.where(cross, ghi_new, ghi)
        lo, glo = np.where(~up & cross, th, lo), np.where(cross, glo_new, glo)
        if np.all((hi - lo)[cross] < 1e-14) or np.all(gbest[cross] < 1e-15):
            break
    return np.where(cross, best, 1.0)
