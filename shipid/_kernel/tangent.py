"""The RK4 map of the compiled kernel and its tangent (the state transition and its Jacobians with
respect to states and estimated parameters), with the input hold between samples.  The model's
equations (``k_consts``, ``k_rhs``, ``k_jac``) are globals supplied by :func:`shipid._jit.rebind`."""
from __future__ import annotations

import math

import numpy as np

from .linalg import mat_mul

def rk4_rest(t, x, um, ub, c, h, k1, k2, k3, k4, xs, xn):
    """The classical RK4 step from ``x`` given its first stage ``k1 = rhs(t, x, ua)``: stages 2-4 (inputs
    ``um`` at the middle, ``ub`` at the end) into ``k2..k4`` and the new state into ``xn`` (may be ``x``).
    The one RK4 step of the filter's Taylor-tangent method and of the open-loop replay."""
    nx = x.shape[0]
    for i in range(nx):
        xs[i] = x[i] + h / 2 * k1[i]
    k_rhs(t + h / 2, xs, um, c, k2)
    for i in range(nx):
        xs[i] = x[i] + h / 2 * k2[i]
    k_rhs(t + h / 2, xs, um, c, k3)
    for i in range(nx):
        xs[i] = x[i] + h * k3[i]
    k_rhs(t + h, xs, ub, c, k4)
    for i in range(nx):
        xn[i] = x[i] + h / 6 * (k1[i] + 2 * k2[i] + 2 * k3[i] + k4[i])


def hold_inputs(U, b, k, i, n, foh, ua, ub, um):
    """The inputs of step ``i`` of the ``n`` that cross interval ``k`` of member ``b`` (``ua``: its start
    inputs): under first-order hold (``foh``) the end inputs ``ub`` are ``(1 - w) U_k + w U_k+1`` at
    ``w = (i+1)/n`` (the last one ``U_k+1`` itself) and the middle ones ``um`` their mean with ``ua``; else
    ``U_k`` throughout (the filter's interval crossing and the replay; as ``ekf._cross_interval``)."""
    for j in range(ua.shape[0]):
        if not foh:
            ub[j] = U[b, k, j]
        elif i == n - 1:
            ub[j] = U[b, k + 1, j]
        else:
            wt = (i + 1) / n
            ub[j] = (1.0 - wt) * U[b, k, j] + wt * U[b, k + 1, j]
        um[j] = 0.5 * (ua[j] + ub[j]) if foh else ua[j]


def tangent(method, t, x, ua, um, ub, p, P, c, cols, h, scale, xn, Fx, Fp, k1, k2, k3, k4, xs, A, Bp, Kx, Kp, Kxs,
            Kps, M, Be):
    """One step of the discrete map and its tangent: ``xn``, ``Fx (nx, nx)``, ``Fp (nx, ne)`` (the
    parameter columns ``cols``, multiplied by ``scale``).  ``method``: 0 RK4 with the second-order
    Taylor tangent at the step start (:func:`shipid.integrate.rk4_step_taylor_tangent`), 1 RK4 with
    its exact tangent (:func:`~shipid.integrate.rk4_step_tangent`), 2 Euler.  Stage inputs ``ua`` (start),
    ``um`` (middle), ``ub`` (end) as :func:`shipid.integrate._stage_inputs`; ``c = k_consts(p, P)``;
    ``k1 .. Be``: work arrays (see :func:`_work`; passed one by one, not as a tuple: unpacking a tuple of arrays
    at every step costs an atomic reference count per array)."""
    nx = x.shape[0]
    ne = cols.shape[0]
    k_rhs(t, x, ua, c, k1)
    k_jac(t, x, ua, p, P, c, cols, A, Bp)
    for j in range(ne):
        for i in range(nx):
            Be[i, j] = Bp[i, cols[j]]
    if method == 2:  # Euler
        for i in range(nx):
            xn[i] = x[i] + h * k1[i]
            for j in range(nx):
                Fx[i, j] = (1.0 if i == j else 0.0) + h * A[i, j]
            for j in range(ne):
                Fp[i, j] = h * Be[i, j] * scale[j]
        return
    if method == 0:
        rk4_rest(t, x, um, ub, c, h, k1, k2, k3, k4, xs, xn)
        # half = I + h A / 2; Fx = I + h A half; Fp = h half B
        for i in range(nx):
            for j in range(nx):
                M[i, j] = (1.0 if i == j else 0.0) + 0.5 * (h * A[i, j])
        # row updates (the inner loops run along the rows of M and Be; each entry sums over a in order)
        for i in range(nx):
            for j in range(nx):
                Kx[i, j] = 0.0
            for j in range(ne):
                Kp[i, j] = 0.0
            for a in range(nx):
                f = h * A[i, a]
                for j in range(nx):
                    Kx[i, j] += f * M[a, j]
            for a in range(nx):
                f = M[i, a]
                for j in range(ne):
                    Kp[i, j] += f * Be[a, j]
            for j in range(nx):
                Fx[i, j] = (1.0 if i == j else 0.0) + Kx[i, j]
            for j in range(ne):
                Fp[i, j] = h * Kp[i, j] * scale[j]
        return
    # exact RK4 tangent: K_s = A_s (I + a_s h K_{s-1}) for the state, A_s a_s h K_{s-1} + B_s for p
    for i in range(nx):
        for j in range(nx):
            Kx[i, j] = A[i, j]
            Fx[i, j] = A[i, j]
        for j in range(ne):
            Kp[i, j] = Be[i, j]
            Fp[i, j] = Be[i, j]
    kprev = k1
    for s_ in range(1, 4):
        a = 0.5 if s_ < 3 else 1.0
        wgt = 2.0 if s_ < 3 else 1.0
        for i in range(nx):
            xs[i] = x[i] + h * a * kprev[i]
        ks = k2 if s_ == 1 else (k3 if s_ == 2 else k4)
        ts = t + h * a
        us = um if s_ < 3 else ub
        k_jac(ts, xs, us, p, P, c, cols, A, Bp)
        for j in range(ne):
            for i in range(nx):
                Be[i, j] = Bp[i, cols[j]]
        for i in range(nx):
            for j in range(nx):
                M[i, j] = (1.0 if i == j else 0.0) + (h * a) * Kx[i, j]
        mat_mul(A, M, Kxs)
        for i in range(nx):
            for j in range(ne):
                Kps[i, j] = (h * a) * Kp[i, j]
        mat_mul(A, Kps, Kp)
        for i in range(nx):
            for j in range(ne):
                Kp[i, j] += Be[i, j]
            for j in range(nx):
                Kx[i, j] = Kxs[i, j]
        for i in range(nx):
            for j in range(nx):
                Fx[i, j] += wgt * Kx[i, j]
            for j in range(ne):
                Fp[i, j] += wgt * Kp[i, j]
        k_rhs(ts, xs, us, c, ks)
        kprev = ks
    for i in range(nx):
        xn[i] = x[i] + h / 6 * (k1[i] + 2 * k2[i] + 2 * k3[i] + k4[i])
        for j in range(nx):
            Fx[i, j] = (1.0 if i == j else 0.0) + h / 6 * Fx[i, j]
        for j in range(ne):
            Fp[i, j] = h / 6 * Fp[i, j] * scale[j]
