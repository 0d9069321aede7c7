"""Open-loop RK4 replay of a batch under sampled inputs (the simulator's compiled path), with the
filter's input hold."""
from __future__ import annotations

import math

import numpy as np

from .tangent import hold_inputs, rk4_rest

def rk4_replay(t, U, x0, p, Pk, nsteps, foh, X):
    """Open-loop RK4 of every member from ``x0 (B, nx)`` over the sample times ``t (nt,)`` under the
    inputs ``U (B, nt, nu)`` with parameters ``p (1 or B, np)``, ``nsteps (nt-1,)`` steps per interval,
    the input hold of :func:`ekf_member`, into ``X (B, nt, nx)`` -- the map of
    :func:`shipid.integrate.rk4_map` (stage inputs start, middle, middle, end).  Returns the number of
    members whose state became non-finite (they are left unfinished; the caller decides)."""
    B, nx = x0.shape
    nt = t.shape[0]
    nu = U.shape[2]
    k1, k2, k3, k4 = np.empty(nx), np.empty(nx), np.empty(nx), np.empty(nx)
    x, xs = np.empty(nx), np.empty(nx)
    ua, ub, um = np.empty(nu), np.empty(nu), np.empty(nu)
    bad = 0
    c = k_consts(p[0], Pk)
    for b in range(B):
        if p.shape[0] > 1:
            c = k_consts(p[b], Pk)
        x[:] = x0[b]
        X[b, 0] = x
        ok = True
        for k in range(nt - 1):
            n = nsteps[k]
            h = (t[k + 1] - t[k]) / n
            for j in range(nu):  # (element by element here and below: an array view made per sample costs an
                ua[j] = U[b, k, j]  # atomic reference count when compiled)
            for i in range(n):
                hold_inputs(U, b, k, i, n, foh, ua, ub, um)
                ti = t[k] + i * h if i else t[k]
                k_rhs(ti, x, ua, c, k1)
                rk4_rest(ti, x, um, ub, c, h, k1, k2, k3, k4, xs, x)  # in place: x[m] is read before written
                ua[:] = ub
            for m in range(nx):
                if not math.isfinite(x[m]):
                    ok = False
            for m in range(nx):
                X[b, k + 1, m] = x[m]
            if not ok:
                bad += 1
                break
    return bad
