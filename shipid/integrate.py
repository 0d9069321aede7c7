"""Fixed-step integration shared by the simulator and the EKF.

One Runge-Kutta step of a protocol model, and the same step with its exact
tangent (the Jacobian of the discrete map with respect to the state and the
parameters, obtained by differentiating the RK4 stages).  The EKF uses the
tangent as its transition matrix, so the filter's discrete model and the
simulator's are the same map.
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

from .models.base import Model

__all__ = ["rk4_step", "rk4_step_tangent", "rk4_step_taylor_tangent", "euler_step_tangent", "STEP_TANGENTS"]


@lru_cache(maxsize=16)
def _eye(n: int) -> np.ndarray:
    """A cached read-only identity (built once per size; steps are called per sample)."""
    eye = np.eye(n)
    eye.flags.writeable = False
    return eye


def rk4_step(model: Model, t, x, u, p, h):
    """One classical RK4 step with the input held constant over the step.

    Shapes: ``x (..., nx)``, ``u (..., nu)``, ``p (..., np)``; ``h`` scalar or
    ``(...)``.  Returns ``x(t + h)``.
    """
    h = np.asarray(h, dtype=float)
    hh = h[..., None] if h.ndim else h
    f = model._rhs
    k1 = f(t, x, u, p)
    k2 = f(t + h / 2, x + hh / 2 * k1, u, p)
    k3 = f(t + h / 2, x + hh / 2 * k2, u, p)
    k4 = f(t + h, x + hh * k3, u, p)
    return x + hh / 6 * (k1 + 2 * k2 + 2 * k3 + k4)


def rk4_step_tangent(model: Model, t, x, u, p, h):
    """RK4 step and its exact Jacobians ``(x_next, dxn/dx, dxn/dp)``.

    Returns arrays of shapes ``(..., nx)``, ``(..., nx, nx)``, ``(..., nx, np)``.
    """
    h = np.asarray(h, dtype=float)
    hh = h[..., None] if h.ndim else h
    hm = h[..., None, None] if h.ndim else h
    f, fx, fp = model._rhs, model._jac_x, model._jac_p
    nx = x.shape[-1]
    eye = _eye(nx)

    k1 = f(t, x, u, p)
    A1, B1 = fx(t, x, u, p), fp(t, x, u, p)
    K1x, K1p = A1, B1

    x2 = x + hh / 2 * k1
    A2, B2 = fx(t + h / 2, x2, u, p), fp(t + h / 2, x2, u, p)
    K2x = A2 @ (eye + hm / 2 * K1x)
    K2p = A2 @ (hm / 2 * K1p) + B2
    k2 = f(t + h / 2, x2, u, p)

    x3 = x + hh / 2 * k2
    A3, B3 = fx(t + h / 2, x3, u, p), fp(t + h / 2, x3, u, p)
    K3x = A3 @ (eye + hm / 2 * K2x)
    K3p = A3 @ (hm / 2 * K2p) + B3
    k3 = f(t + h / 2, x3, u, p)

    x4 = x + hh * k3
    A4, B4 = fx(t + h, x4, u, p), fp(t + h, x4, u, p)
    K4x = A4 @ (eye + hm * K3x)
    K4p = A4 @ (hm * K3p) + B4
    k4 = f(t + h, x4, u, p)

    xn = x + hh / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    Fx = eye + hm / 6 * (K1x + 2 * K2x + 2 * K3x + K4x)
    Fp = hm / 6 * (K1p + 2 * K2p + 2 * K3p + K4p)
    return xn, Fx, Fp


def euler_step_tangent(model: Model, t, x, u, p, h):
    """Explicit Euler step and its Jacobians (cheaper, first order)."""
    h = np.asarray(h, dtype=float)
    hh = h[..., None] if h.ndim else h
    hm = h[..., None, None] if h.ndim else h
    xn = x + hh * model._rhs(t, x, u, p)
    Fx = _eye(x.shape[-1]) + hm * model._jac_x(t, x, u, p)
    Fp = hm * model._jac_p(t, x, u, p)
    return xn, Fx, Fp


def rk4_step_taylor_tangent(model: Model, t, x, u, p, h):
    """RK4 step with a second-order Taylor tangent (cheaper than the exact one).

    The state is advanced by RK4; the Jacobians are those of the exact flow to
    second order in ``h`` about the start point:
    ``Fx = I + h A + h^2 A^2 / 2`` and ``Fp = h (I + h A / 2) B`` with
    ``A = df/dx``, ``B = df/dp``.  They differ from the exact RK4 tangent by
    O(h^3 |A|^3), negligible when the step is short against the model's time
    constants (checked in the tests); one Jacobian evaluation instead of four.
    """
    h = np.asarray(h, dtype=float)
    hm = h[..., None, None] if h.ndim else h
    xn = rk4_step(model, t, x, u, p, h)
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
