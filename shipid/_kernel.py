"""Compiled numerics (numba, ``shipid[fast]``): the RK4 map with its tangent, the EKF filter step, the
RTS smoother's recursion and the open-loop RK4 replay, compiled together with a model's equations.

It sits below both users, :mod:`shipid.identify.ekf` (the filter and smoother drivers
``_run_compiled``/``_smooth_compiled``) and :mod:`shipid.simulate` (open-loop replay with sampled
inputs), and imports neither.  The same algorithm as :func:`shipid.identify.ekf.run_ekf` and
:func:`~shipid.identify.ekf.rts_smooth` (which dispatch here), written per
batch member as loops over samples so that numba compiles it together with
the model's equations.  The model's equations are not copied: a model
declares them (``Model._equations``, the kernel protocol ``k_consts``,
``k_rhs``, ``k_jac`` of e.g. :mod:`shipid.models._response_equations`), and
:func:`shipid._jit.rebind` builds this module's functions with those as
globals, compiled once per model (numba's disk cache keeps them; the cache
tag carries a hash of the equations' source files, so an edited equation is
recompiled).  Parameter-derived constants (``k_consts``) are computed once
per step and member.

Semantics (kept equal to the numpy path, to rounding; ``tests/test_kernel.py``):
measurement update with the finite, not-diverged channels (Joseph form,
``A - (A H^T - K R) K^T`` with ``A = P - K H P``), divergence check (NIS
above ``nis_limit``, non-finite or non-positive trace) freezing the member at
its last good values, RK4 map with the tangent of ``method`` over ``substeps``
steps per interval (input held from sample k), resets, process noise
``q dt`` per interval.  Without numba, or with ``SHIPID_JIT=0``, nothing here
is used.
"""
from __future__ import annotations

import hashlib
import inspect
import math
import re
import types
import warnings

import numpy as np

from . import _jit

__all__ = ["filter_functions", "replay_compiled", "METHODS", "SMOOTHER", "FASTMATH", "INLINE"]

#: Transition methods of the kernel (codes of ``EKFProblem.method``).
METHODS = {"rk4": 0, "rk4-exact": 1, "euler": 2}



# ------------------------------------------------------------------ small dense helpers (compiled)
def cholesky(A, n, L):
    """Lower Cholesky factor of ``A[:n, :n]`` into ``L[:n, :n]``; False when ``A`` is not positive
    definite or not finite (the filter's innovation covariance and the smoother's prediction covariance)."""
    for i in range(n):
        for j in range(i + 1):
            s = A[i, j]
            for m in range(j):
                s -= L[i, m] * L[j, m]
            if i == j:
                if not s > 0.0:
                    return False
                L[i, i] = math.sqrt(s)
            else:
                L[i, j] = s / L[j, j]
    return True


def chol_solve(L, n, X, w, a):
    """Solve ``L L^T [X | a] = [X | a]`` in place for the first ``n`` rows (``X`` ``w`` columns wide,
    ``a`` a vector), by forward then backward substitution a row at a time: the filter's gain
    ``[K^T, S^-1 e]`` and the smoother's ``[K^T, S^-1 e]`` and ``S^-1``."""
    for i in range(n):
        s = a[i]
        for m in range(i):
            lim = L[i, m]
            s -= lim * a[m]
            for j in range(w):
                X[i, j] -= lim * X[m, j]
        lii = L[i, i]
        a[i] = s / lii
        for j in range(w):
            X[i, j] = X[i, j] / lii
    for i in range(n - 1, -1, -1):
        s = a[i]
        for m in range(i + 1, n):
            lmi = L[m, i]
            s -= lmi * a[m]
            for j in range(w):
                X[i, j] -= lmi * X[m, j]
        lii = L[i, i]
        a[i] = s / lii
        for j in range(w):
            X[i, j] = X[i, j] / lii


def mat_mul(A, B, out):
    """``out = A @ B`` (small matrices; loops)."""
    n, m = A.shape
    k = B.shape[1]
    for i in range(n):
        for j in range(k):
            s = 0.0
            for a in range(m):
                s += A[i, a] * B[a, j]
            out[i, j] = s


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


def _work(nx, n_par, ne):
    return (np.zeros(nx), np.zeros(nx), np.zeros(nx), np.zeros(nx), np.zeros(nx),
            np.zeros((nx, nx)), np.zeros((nx, n_par)), np.zeros((nx, nx)), np.zeros((nx, nx)), np.zeros((nx, ne)),
            np.zeros((nx, nx)), np.zeros((nx, ne)), np.zeros((nx, nx)), np.zeros((nx, ne)))


def ekf_member(b, t, U, Y, fin, any_k, reset, x_reset, P_reset, q, dtq, nsteps, R, z0, P0, p_base, est_idx, scale,
               meas_idx, Pk, nx, method, foh, gate, gate_run, nis_limit, store, compact,
               z_post, P_post, z_prior, P_prior, Fs, z_fin, P_fin, innov, S_diag, nis, logdet, gated,
               div, div_at, d2_at, gains, Kst, ast, Sist):
    """The filter over the samples of batch member ``b`` (arrays as in :func:`shipid.identify.ekf._run_compiled`; what a
    diverged member does not compute is set NaN).  With ``gains`` the update's ``K^T``, ``S^-1 e`` and ``S^-1`` at the
    accepted channels are stored (``Kst (B, N, nm, nz)``, ``ast (B, N, nm)``, ``Sist (B, N, nm, nm)``, rows and
    columns in channel order; other entries are not written) for the smoother, which then need not solve for them
    again (:func:`bf_member`; the same numbers: it solved the same system the same way)."""
    N = t.shape[1]
    nz = z0.shape[1]
    ne = nz - nx
    nm = meas_idx.shape[0]
    nu = U.shape[2]
    n_par = p_base.shape[1]
    z = z0[b].copy()
    P = P0[b].copy()
    p = p_base[b].copy()
    zn = np.empty(nz)
    Pn = np.empty((nz, nz))
    Ftop = np.zeros((nx, nz))
    Fx = np.zeros((nx, nx))
    Fp = np.zeros((nx, ne))
    Ax = np.zeros((nx, nx))
    Ap = np.zeros((nx, ne))
    tmpx = np.zeros((nx, nx))
    tmpp = np.zeros((nx, ne))
    x = np.empty(nx)
    xn = np.empty(nx)
    ua = np.empty(nu)
    ub = np.empty(nu)
    um = np.empty(nu)
    M = np.empty((nx, nz))
    k1, k2, k3, k4, xs, A, Bp, _, Kx, Kp, Kxs, Kps, Mt, Be = _work(nx, n_par, ne)
    sel = np.empty(nm, dtype=np.int64)
    run = np.zeros(nm, dtype=np.int64)
    S = np.empty((nm, nm))
    S0 = np.empty((nm, nm))
    L = np.empty((nm, nm))
    PH = np.empty((nm, nz))
    Kt = np.empty((nm, nz))
    W = np.empty((nm, nz))
    e = np.empty(nm)
    a = np.empty(nm)
    a2 = np.empty(nm)
    Si = np.empty((nm, nm))
    dz = np.empty(nz)
    zg = z0[b].copy()  # the last good posterior (before any update: the initial condition)
    Pg = P0[b].copy()
    if store:
        z_prior[b, 0] = z
        if compact:  # the rows at the measured states, the ship rows of F (ekf.run_ekf's ``compact``)
            for c_ in range(nm):
                P_prior[b, 0, c_] = P[meas_idx[c_]]
        else:
            P_prior[b, 0] = P
    for k in range(N):
        # ---- update with the measurements of sample k (gated channels count as missing)
        if gate > 0 and reset[b, k]:
            run[:] = 0
        if any_k[k]:
            cnt = 0
            for j in range(nm):
                if fin[b, k, j]:
                    ej = Y[b, k, j] - z[meas_idx[j]]
                    if gate > 0:
                        Sjj = P[meas_idx[j], meas_idx[j]] + R[b, j]
                        if ej * ej > gate * gate * Sjj and run[j] < gate_run:
                            run[j] += 1
                            gated[b, k, j] = True
                            innov[b, k, j] = ej
                            S_diag[b, k, j] = Sjj
                            continue
                        run[j] = 0
                    sel[cnt] = j
                    cnt += 1
            d2 = 0.0
            ld = 0.0
            ok = True
            if cnt > 0:
                # rows of P at the measured states (P is exactly symmetric: H P), contiguous
                for a_ in range(cnt):
                    ja = sel[a_]
                    e[a_] = Y[b, k, ja] - z[meas_idx[ja]]
                    r_ = meas_idx[ja]
                    for i in range(nz):
                        PH[a_, i] = P[r_, i]
                for a_ in range(cnt):
                    for c_ in range(cnt):
                        S0[a_, c_] = PH[c_, meas_idx[sel[a_]]]  # H P H^T
                        S[a_, c_] = S0[a_, c_]
                    S[a_, a_] += R[b, sel[a_]]
                ok = cholesky(S, cnt, L)  # S = L L^T (False: not positive definite or not finite)
                if ok:
                    # [K^T, a] = S^-1 [H P, e]
                    for i in range(cnt):
                        for j in range(nz):
                            Kt[i, j] = PH[i, j]
                        a[i] = e[i]
                    chol_solve(L, cnt, Kt, nz, a)
                    if gains:  # (what bf_member would solve for again: S^-1 as it does, then all three stored)
                        for i in range(cnt):
                            for j in range(cnt):
                                Si[i, j] = 1.0 if i == j else 0.0
                            a2[i] = 0.0
                        chol_solve(L, cnt, Si, cnt, a2)
                        for c_ in range(cnt):
                            r_ = sel[c_]
                            ast[b, k, r_] = a[c_]
                            for j in range(nz):
                                Kst[b, k, r_, j] = Kt[c_, j]
                            for d_ in range(cnt):
                                Sist[b, k, r_, sel[d_]] = Si[c_, d_]
                    for i in range(cnt):
                        ld += 2.0 * math.log(L[i, i])
                        d2 += e[i] * a[i]
                    for i in range(nz):
                        dz[i] = 0.0
                    for c_ in range(cnt):
                        ec = e[c_]
                        for i in range(nz):
                            dz[i] += Kt[c_, i] * ec
                    for i in range(nz):
                        z[i] += dz[i]
                    # Joseph form A - (A H^T - K R) K^T with A = P - K H P: W = (A H^T - K R)^T, then the
                    # lower triangle of P - K (H P) - W^T K^T, mirrored (P stays exactly symmetric)
                    for d_ in range(cnt):
                        for i in range(nz):
                            W[d_, i] = PH[d_, i]
                    for c_ in range(cnt):  # (rows innermost-but-one, as below)
                        for d_ in range(cnt):
                            sdc = S0[d_, c_]
                            for i in range(nz):
                                W[d_, i] -= sdc * Kt[c_, i]
                    for d_ in range(cnt):
                        rd = R[b, sel[d_]]
                        for i in range(nz):
                            W[d_, i] -= Kt[d_, i] * rd
                    # (channel outermost: consecutive updates hit different rows, so they do not wait on
                    # each other; each entry still sums its channels in order, the same result to the bit)
                    for c_ in range(cnt):
                        for i in range(nz):
                            kci = Kt[c_, i]
                            wci = W[c_, i]
                            for j in range(i + 1):
                                P[i, j] -= kci * PH[c_, j] + wci * Kt[c_, j]
                    for i in range(nz):
                        for j in range(i):
                            P[j, i] = P[i, j]
                else:
                    d2 = np.nan
                    ld = np.nan
                for a_ in range(cnt):
                    ja = sel[a_]
                    innov[b, k, ja] = e[a_]
                    S_diag[b, k, ja] = S[a_, a_]
                nis[b, k] = d2
                logdet[b, k] = ld
            # ---- divergence check (NaN fails every comparison); the member stops here
            tr = 0.0
            for i in range(nz):
                tr += P[i, i] + 0.0 * z[i]
            if cnt == 0 and not math.isfinite(tr):
                d2 = np.nan
            margin = min(min(nis_limit - d2, tr), np.inf - tr)
            if not margin > 0:
                div[b] = True
                div_at[b] = k
                d2_at[b] = d2
                if store:  # not computed from here on
                    z_post[b, k:] = np.nan
                    P_post[b, k:] = np.nan
                    z_prior[b, k + 1:] = np.nan
                    P_prior[b, k + 1:] = np.nan
                    Fs[b, k:] = np.nan
                z_fin[b] = zg
                P_fin[b] = Pg
                return
        if store:
            for i in range(nz):
                z_post[b, k, i] = z[i]
            for i in range(P_post.shape[2]):  # all rows, or the ship rows (``compact="ship"``)
                for j in range(nz):
                    P_post[b, k, i, j] = P[i, j]
        if k == N - 1:
            break
        # ---- predict to sample k+1 (nothing is integrated into a reset sample)
        rs = reset[b, k + 1]
        if not rs:
            for j in range(ne):
                p[est_idx[j]] = z[nx + j] * scale[j]
            c = k_consts(p, Pk)
            # cross the interval in n steps of length h (as ``ekf._cross_interval``): step i starts at t_k + i h,
            # its inputs as :func:`hold_inputs`; xn, Fx, Fp receive the end state and the interval's transition
            # (parameter columns scaled).  (Written here, on elements: array views or a tuple of work arrays made
            # at every step would each cost atomic reference counts, ~1/4 of the step.)
            n = nsteps[b, k]
            t0 = t[b, k]
            h = (t[b, k + 1] - t0) / n
            for j in range(nx):
                x[j] = z[j]
            for j in range(nu):
                ua[j] = U[b, k, j]
            for i in range(n):
                hold_inputs(U, b, k, i, n, foh, ua, ub, um)
                ti = t0 + i * h if i else t0
                if i > 0:
                    for j in range(nx):
                        x[j] = xn[j]
                # the first step's tangent is the interval's, later ones (Ax, Ap) are chained onto it; one call
                # site, as tangent is inlined (compile time)
                tangent(method, ti, x, ua, um, ub, p, Pk, c, est_idx, h, scale, xn, Fx if i == 0 else Ax,
                        Fp if i == 0 else Ap, k1, k2, k3, k4, xs, A, Bp, Kx, Kp, Kxs, Kps, Mt, Be)
                if i > 0:
                    mat_mul(Ax, Fp, tmpp)
                    for r in range(nx):
                        for j in range(ne):
                            Fp[r, j] = tmpp[r, j] + Ap[r, j]
                    mat_mul(Ax, Fx, tmpx)
                    for r in range(nx):
                        for j in range(nx):
                            Fx[r, j] = tmpx[r, j]
                for j in range(nu):
                    ua[j] = ub[j]
        for i in range(nx):
            zn[i] = x_reset[b, k + 1, i] if rs else xn[i]
            for j in range(nz):
                Ftop[i, j] = 0.0 if rs else (Fx[i, j] if j < nx else Fp[i, j - nx])
        for i in range(nx, nz):
            zn[i] = z[i]
        # P_next = F P F^T with F = [[Ftop], [0 I]] + Q (P is exactly symmetric, so is P_next)
        for i in range(nx):  # M = top rows of F P (nx, nz), a row of P at a time (for each, the rows of M in
            for j in range(nz):  # turn: independent updates; each entry sums in the same order)
                M[i, j] = 0.0
        for m in range(nz):
            for i in range(nx):
                f = Ftop[i, m]
                for j in range(nz):
                    M[i, j] += f * P[m, j]
        for i in range(nx):  # top-left block M F_top^T (symmetric: P is)
            for j in range(i + 1):
                s = 0.0
                for m in range(nz):
                    s += M[i, m] * Ftop[j, m]
                Pn[i, j] = s
                Pn[j, i] = s
            for j in range(ne):  # off-diagonal blocks: the top rows of F P, mirrored
                Pn[i, nx + j] = M[i, nx + j]
                Pn[nx + j, i] = M[i, nx + j]
        for i in range(ne):
            for j in range(ne):
                Pn[nx + i, nx + j] = P[nx + i, nx + j]
        for i in range(nz):
            Pn[i, i] += 0.0 if (rs and i < nx) else q[b, i] * dtq[b, k]
        if rs:
            for i in range(nx):
                for j in range(nx):
                    Pn[i, j] += P_reset[b, i, j]
        if store:
            for i in range(nx):
                for j in range(nz):
                    Fs[b, k, i, j] = Ftop[i, j]
            for i in range(nz):
                z_prior[b, k + 1, i] = zn[i]
            if compact:
                for c_ in range(nm):
                    r_ = meas_idx[c_]
                    for j in range(nz):
                        P_prior[b, k + 1, c_, j] = Pn[r_, j]
            else:
                for i in range(nx, nz):
                    for j in range(nz):
                        Fs[b, k, i, j] = 1.0 if i == j else 0.0
                P_prior[b, k + 1] = Pn
        # the posterior becomes the last good one, the prediction the state: buffers rotate, nothing is copied
        zg, z, zn = z, zn, zg
        Pg, P, Pn = P, Pn, Pg
    z_fin[b] = z
    P_fin[b] = P
    if store:
        for i in range(Fs.shape[2]):
            for j in range(nz):
                Fs[b, N - 1, i, j] = 1.0 if i == j else 0.0


def ekf_batch(t, U, Y, fin, any_k, reset, x_reset, P_reset, q, dtq, nsteps, R, z0, P0, p_base, est_idx, scale,
              meas_idx, Pk, nx, method, foh, gate, gate_run, nis_limit, store, compact,
              z_post, P_post, z_prior, P_prior, Fs, z_fin, P_fin, innov, S_diag, nis, logdet, gated, div, div_at, d2_at,
              gains, Kst, ast, Sist):
    for b in range(t.shape[0]):
        ekf_member(b, t, U, Y, fin, any_k, reset, x_reset, P_reset, q, dtq, nsteps, R, z0, P0, p_base, est_idx, scale,
                   meas_idx, Pk, nx, method, foh, gate, gate_run, nis_limit, store, compact,
                   z_post, P_post, z_prior, P_prior, Fs, z_fin, P_fin, innov, S_diag, nis, logdet, gated,
                   div, div_at, d2_at, gains, Kst, ast, Sist)


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


FILTER = {"cholesky": cholesky, "chol_solve": chol_solve, "mat_mul": mat_mul, "rk4_rest": rk4_rest,
          "hold_inputs": hold_inputs, "tangent": tangent, "_work": _work,
          "ekf_member": ekf_member, "ekf_batch": ekf_batch, "rk4_replay": rk4_replay}


# ------------------------------------------------------------------ RTS smoother (model-free)
def rts_member(zf, Pf, zp, Pp, F, zs, Ps):
    """Backward recursion of one member: ``G = Pf F^T Pp^-1`` (solved as ``Pp G^T = F Pf`` by Cholesky;
    the pseudo-inverse where ``Pp`` is not positive definite), ``zs_k = zf_k + G (zs_{k+1} - zp_{k+1})``,
    ``Ps_k = Pf_k + G (Ps_{k+1} - Pp_{k+1}) G^T`` (its lower triangle, mirrored).  Loops over rows of
    ``nz`` (they vectorise); the zero entries of ``F`` (its parameter rows are the identity) are skipped
    (exact: the filtered covariances of a member that did not diverge are finite)."""
    N, nz = zf.shape
    zs[N - 1] = zf[N - 1]
    Ps[N - 1] = Pf[N - 1]
    d = np.empty(nz)
    dzs = np.empty(nz)
    Gt = np.empty((nz, nz))
    T = np.empty((nz, nz))
    L = np.empty((nz, nz))
    for k in range(N - 2, -1, -1):
        Fk, Pfk, Ppk = F[k], Pf[k], Pp[k + 1]
        for i in range(nz):  # Gt = F Pf
            for j in range(nz):
                Gt[i, j] = 0.0
            for m in range(nz):
                f = Fk[i, m]
                if f != 0.0:
                    for j in range(nz):
                        Gt[i, j] += f * Pfk[m, j]
        ok = cholesky(Ppk, nz, L)  # Pp = L L^T
        if ok:  # Gt = Pp^-1 F Pf: forward and backward substitution a row at a time
            for i in range(nz):
                for m in range(i):
                    lim = L[i, m]
                    for j in range(nz):
                        Gt[i, j] -= lim * Gt[m, j]
                lii = L[i, i]
                for j in range(nz):
                    Gt[i, j] = Gt[i, j] / lii
            for i in range(nz - 1, -1, -1):
                for m in range(i + 1, nz):
                    lmi = L[m, i]
                    for j in range(nz):
                        Gt[i, j] -= lmi * Gt[m, j]
                lii = L[i, i]
                for j in range(nz):
                    Gt[i, j] = Gt[i, j] / lii
        else:  # not positive definite (singular prediction covariance): pseudo-inverse
            Gt[:, :] = np.dot(np.linalg.pinv(Ppk.astype(np.float64)), Gt.copy())
        for i in range(nz):
            d[i] = zs[k + 1, i] - zp[k + 1, i]
            dzs[i] = 0.0
        for m in range(nz):  # zs = zf + G d = zf + Gt^T d
            dm = d[m]
            for i in range(nz):
                dzs[i] += Gt[m, i] * dm
        for i in range(nz):
            zs[k, i] = zf[k, i] + dzs[i]
        for i in range(nz):  # T = (Ps - Pp)_{k+1} Gt
            for j in range(nz):
                T[i, j] = 0.0
            for m in range(nz):
                dl = Ps[k + 1, i, m] - Ppk[i, m]
                for j in range(nz):
                    T[i, j] += dl * Gt[m, j]
        for i in range(nz):  # Ps = Pf + Gt^T T, lower triangle, mirrored
            for j in range(i + 1):
                d[j] = 0.0
            for m in range(nz):
                g = Gt[m, i]
                for j in range(i + 1):
                    d[j] += g * T[m, j]
            for j in range(i + 1):
                v = Pfk[i, j] + d[j]
                Ps[k, i, j] = v
                Ps[k, j, i] = v


def rts_batch(zf, Pf, zp, Pp, F, zs, Ps):
    for b in range(zf.shape[0]):
        if np.isfinite(zf[b, -1]).all():
            rts_member(zf[b], Pf[b], zp[b], Pp[b], F[b], zs[b], Ps[b])
        else:  # a member that stopped at its divergence: nothing to smooth
            zs[b] = np.nan
            Ps[b] = np.nan


def rows_times(A, i, i2, B, nz, row, row2):
    """``row = A[i] B``, ``row2 = A[i2] B`` (B: nz x nz), two rows at a time: each entry sums over B's rows in
    order, and consecutive updates hit different entries."""
    for j in range(nz):
        row[j] = 0.0
        row2[j] = 0.0
    for m in range(nz):
        f = A[i, m]
        f2 = A[i2, m]
        for j in range(nz):
            bmj = B[m, j]
            row[j] += f * bmj
            row2[j] += f2 * bmj


def ship_variances(Pfk, Lam, nx, nz, rows, n, row, row2, out):
    """``out[i] = Pf_ii - (Pf_i Lam) . Pf_i`` (the smoothed variance) for the ship rows ``rows[:n]``, two
    rows at a time (an odd last row is computed twice)."""
    for a_ in range(0, n, 2):
        i = rows[a_]
        i2 = rows[min(a_ + 1, n - 1)]
        rows_times(Pfk, i, i2, Lam, nz, row, row2)
        s = 0.0
        s2 = 0.0
        for j in range(nz):
            s += row[j] * Pfk[i, j]
            s2 += row2[j] * Pfk[i2, j]
        out[i] = Pfk[i, i] - s
        out[i2] = Pfk[i2, i2] - s2


def bf_member(zf, Pf, Pp, pp_rows, F, innov, acc, R, meas_idx, nx, zs, var_x, Ps0, gains, Kst, ast, Sist):
    """Bryson-Frazier (adjoint) form of the same smoother for one member, without inverting ``Pp`` and
    without the full smoothed covariance at every sample: the adjoint ``lam`` (nz) and ``Lam`` (nz, nz)
    run backwards, ``zs_k = zf_k + Pf_k lam_k`` and ``Ps_k = Pf_k - Pf_k Lam_k Pf_k``, of which the
    ship-state variances ``var_x (N, nx)`` are kept at every sample and the whole matrix ``Ps0`` at
    sample 0.  Through the update at sample k (accepted channels ``acc[k]``; gain
    ``K = Pp H^T S^-1``, ``S = H Pp H^T + R``, recomputed as the filter computed it):
    ``lam~ = lam + H^T (S^-1 e - K^T lam)``, ``Lam~ = (I - K H)^T Lam (I - K H) + H^T S^-1 H``; through
    the transition from k-1: ``lam = F^T lam~``, ``Lam = F^T Lam~ F`` (its lower triangle, mirrored), with the
    transition's parameter rows the identity (the random walks; a reset's ship rows are zero).  Only
    the ship rows of ``F`` and the rows ``pp_rows`` of ``Pp`` (those at the measured states, channel
    ``j`` in row ``pp_rows[j]``) are read, so the compact storage of the filter serves.  With ``gains``
    the filter's stored ``K^T``, ``S^-1 e`` and ``S^-1`` (:func:`ekf_member`) are read instead of solving
    for them (``Pp`` is then not read)."""
    N, nz = zf.shape
    nr = Pf.shape[1]  # rows of Pf stored: all, or the ship rows (compact="ship": no parameter means, no Ps0)
    nm = meas_idx.shape[0]
    lam = np.zeros(nz)
    Lam = np.zeros((nz, nz))
    A = np.empty((nz, nz))
    row = np.empty(nz)
    row2 = np.empty(nz)
    sel = np.empty(nm, dtype=np.int64)
    S = np.empty((nm, nm))
    L = np.empty((nm, nm))
    Kt = np.empty((nm, nz))
    Si = np.empty((nm, nm))
    e = np.empty(nm)
    a = np.empty(nm)
    a2 = np.empty(nm)  # chol_solve's vector for S^-1 (solves zeros)
    LKt = np.empty((nm, nz))
    KLK = np.empty((nm, nm))
    all_rows = np.arange(nx)
    vrows = np.empty(nx, dtype=np.int64)
    vrow_of = np.empty(nx, dtype=np.int64)
    for k in range(N - 1, -1, -1):
        Pfk = Pf[k]
        for i in range(nr):  # smoothed mean
            s = 0.0
            for j in range(nz):
                s += Pfk[i, j] * lam[j]
            zs[k, i] = zf[k, i] + s
        for i in range(nr, nz):
            zs[k, i] = np.nan
        if k == 0:
            ship_variances(Pfk, Lam, nx, nz, all_rows, nx, row, row2, var_x[k])
        if k == 0 and nr < nz:
            Ps0[:, :] = np.nan
            break
        if k == 0:
            for i in range(nz):  # A = Lam Pf, then Ps0 = Pf - Pf A (lower triangle, mirrored)
                for j in range(nz):
                    A[i, j] = 0.0
                for m in range(nz):
                    f = Lam[i, m]
                    for j in range(nz):
                        A[i, j] += f * Pfk[m, j]
            for i in range(nz):
                for j in range(i + 1):
                    s = 0.0
                    for m in range(nz):
                        s += Pfk[i, m] * A[m, j]
                    v = Pfk[i, j] - s
                    Ps0[i, j] = v
                    Ps0[j, i] = v
            break
        # ---- back through the update at sample k
        cnt = 0
        for j in range(nm):
            if acc[k, j]:
                sel[cnt] = j
                cnt += 1
        nv = 0  # ship rows whose variance needs the product Pf_i Lam (not given by the gain, below)
        for i in range(nx):
            vrow_of[i] = -1
        for c_ in range(cnt):
            r_ = meas_idx[sel[c_]]
            if r_ < nx:
                vrow_of[r_] = c_
        for i in range(nx):
            if vrow_of[i] < 0:
                vrows[nv] = i
                nv += 1
        if cnt == 0:
            ship_variances(Pfk, Lam, nx, nz, vrows, nv, row, row2, var_x[k])
        if cnt > 0 and gains:  # the filter's
            for c_ in range(cnt):
                r_ = sel[c_]
                a[c_] = ast[k, r_]
                for i in range(nz):
                    Kt[c_, i] = Kst[k, r_, i]
                for d_ in range(cnt):
                    Si[c_, d_] = Sist[k, r_, sel[d_]]
        elif cnt > 0:
            for c_ in range(cnt):
                r_ = pp_rows[sel[c_]]
                e[c_] = innov[k, sel[c_]]
                for i in range(nz):
                    Kt[c_, i] = Pp[k, r_, i]
                for d_ in range(cnt):
                    S[c_, d_] = Pp[k, r_, meas_idx[sel[d_]]]
                    Si[c_, d_] = 1.0 if c_ == d_ else 0.0
                S[c_, c_] += R[sel[c_]]
            cholesky(S, cnt, L)  # positive definite: the filter factorised the same S at this sample
            # [K^T, a, S^-1] = S^-1 [H Pp, e, I]
            for i in range(cnt):
                a[i] = e[i]
                a2[i] = 0.0
            chol_solve(L, cnt, Kt, nz, a)
            chol_solve(L, cnt, Si, cnt, a2)
        if cnt > 0:
            for c_ in range(0, cnt, 2):  # LKt = (Lam K)^T = K^T Lam (Lam symmetric), two rows at a time
                c2 = min(c_ + 1, cnt - 1)  # (an odd last row is computed twice)
                rows_times(Kt, c_, c2, Lam, nz, row, row2)
                for i in range(nz):
                    LKt[c_, i] = row[i]
                    LKt[c2, i] = row2[i]
            # ship-state variances Pf_ii - (Pf_i Lam) . Pf_i; the rows of Pf at the accepted measured states
            # are R K^T (H Pf = H Pp - (S - R) K^T = R K^T for the optimal gain), so there Pf_i Lam = R_c
            # (K^T Lam)_c, a row already computed: only the other rows need the product
            ship_variances(Pfk, Lam, nx, nz, vrows, nv, row, row2, var_x[k])
            for i in range(nx):
                c_ = vrow_of[i]
                if c_ >= 0:
                    s = 0.0
                    for j in range(nz):
                        s += LKt[c_, j] * Pfk[i, j]
                    var_x[k, i] = Pfk[i, i] - R[sel[c_]] * s
            for c_ in range(cnt):  # lam += H^T (a - K^T lam)
                s = 0.0
                for j in range(nz):
                    s += Kt[c_, j] * lam[j]
                row[c_] = a[c_] - s
            for c_ in range(cnt):  # H^T (K^T Lam K + S^-1) H, before Lam changes
                for d_ in range(cnt):
                    s = Si[c_, d_]
                    for j in range(nz):
                        s += Kt[c_, j] * LKt[d_, j]
                    KLK[c_, d_] = s
            for c_ in range(cnt):
                lam[meas_idx[sel[c_]]] += row[c_]
            for c_ in range(cnt):  # Lam -= H^T LK^T + LK H
                r_ = meas_idx[sel[c_]]
                for i in range(nz):
                    Lam[r_, i] -= LKt[c_, i]
                for i in range(nz):
                    Lam[i, r_] -= LKt[c_, i]
            for c_ in range(cnt):
                r_ = meas_idx[sel[c_]]
                for d_ in range(cnt):
                    Lam[r_, meas_idx[sel[d_]]] += KLK[c_, d_]
        # ---- back through the transition from k-1 (F's parameter rows are the identity)
        Fk = F[k - 1]
        for j in range(nz):
            s = lam[j] if j >= nx else 0.0
            for m in range(nx):
                s += Fk[m, j] * lam[m]
            row[j] = s
        for j in range(nz):
            lam[j] = row[j]
        for i in range(0, nz, 2):  # A = Lam F: the ship rows, and of the others the lower triangle (all F^T A
            i2 = min(i + 1, nz - 1)  # reads), two rows at a time (an odd last row is computed twice, the
            jn = nz if i2 < nx else i2 + 1  # second copy in row2)
            for j in range(min(nx, jn)):
                A[i, j] = 0.0
                row2[j] = 0.0
            for j in range(nx, jn):
                A[i, j] = Lam[i, j]
                row2[j] = Lam[i2, j]
            for m in range(nx):
                lim = Lam[i, m]
                li2 = Lam[i2, m]
                for j in range(jn):
                    fmj = Fk[m, j]
                    A[i, j] += lim * fmj
                    row2[j] += li2 * fmj
            if i2 != i:
                for j in range(jn):
                    A[i2, j] = row2[j]
        for i in range(nz):  # Lam = F^T A: its lower triangle (a symmetric product), mirrored
            for j in range(i + 1):
                Lam[i, j] = A[i, j] if i >= nx else 0.0
        for m in range(nx):  # (rows innermost-but-one: independent updates, each entry summed in order)
            for i in range(nz):
                f = Fk[m, i]
                for j in range(i + 1):
                    Lam[i, j] += f * A[m, j]
        for i in range(nz):
            for j in range(i):
                Lam[j, i] = Lam[i, j]


def bf_batch(zf, Pf, Pp, pp_rows, F, innov, acc, R, meas_idx, nx, zs, var_x, Ps0, gains, Kst, ast, Sist):
    for b in range(zf.shape[0]):
        if np.isfinite(zf[b, -1]).all():
            bg = b if gains else 0
            bf_member(zf[b], Pf[b], Pp[b], pp_rows, F[b], innov[b], acc[b], R[b], meas_idx, nx, zs[b], var_x[b], Ps0[b],
                      gains, Kst[bg], ast[bg], Sist[bg])
        else:  # a member that stopped at its divergence: nothing to smooth
            zs[b] = np.nan
            var_x[b] = np.nan
            Ps0[b] = np.nan


SMOOTHER = {"cholesky": cholesky, "chol_solve": chol_solve, "rows_times": rows_times, "ship_variances": ship_variances, "rts_member": rts_member, "rts_batch": rts_batch, "bf_member": bf_member,
            "bf_batch": bf_batch}


# ------------------------------------------------------------------ Python side
_noticed: set = set()


def _source_hash(functions: dict) -> str:
    """Hash of the source files of ``functions`` (and of this module): the compiled kernel inlines them.
    Read once per process and set of functions (every fit asks; reading and hashing the files cost ~0.7 ms)."""
    key = tuple(sorted((name, id(f)) for name, f in functions.items()))
    out = _hashes.get(key)
    if out is None:
        files = {inspect.getsourcefile(getattr(f, "py_func", f)) for f in functions.values()} | {__file__}
        h = hashlib.sha1()
        for name in sorted(files):
            with open(name, "rb") as fh:
                h.update(fh.read())
        out = _hashes[key] = h.hexdigest()[:10]
    return out


_hashes: dict = {}


def filter_functions(model, notice: bool = True, refcount: bool = False):
    """The compiled filter for ``model`` (a dict of numba functions), or ``None`` when compilation is
    off (:func:`shipid._jit.enabled`) or the model declares no equations (then, with ``notice``, a
    one-line notice, once per model class).  The model's equations that allocate no array are compiled
    without reference counting (:func:`_refcount_free`); with ``refcount`` (or once that build failed to
    compile, :func:`call`) all of them are reference counted (a separate build and disk cache)."""
    if not _jit.enabled():
        _jit.fallback_notice()
        return None
    eq = getattr(model, "_equations", None)
    if eq is None:
        key = type(model).__name__
        if notice and key not in _noticed:
            _noticed.add(key)
            warnings.warn(f"shipid: model '{model.name}' declares no compiled equations (Model._equations); "
                          "the EKF runs on the numpy path", RuntimeWarning, stacklevel=3)
        return None
    ns = model._equations_namespace()
    tag = "__" + re.sub(r"\W", "_", model.name) + "_" + _source_hash({**eq, **ns})
    base = ("filter", id(eq), tag)
    refcount = refcount or base in _refcounted
    key = base + (refcount,)
    out = _cache.get(key)
    if out is None:
        tag += "_rc" if refcount else ""
        funcs = _jit.rebind(eq, ns, jit=True, tag=tag,
                            no_refcount=frozenset() if refcount else _refcount_free(eq, ns))
        out = _cache[key] = _jit.rebind(FILTER, {**ns, **funcs}, jit=True, tag=tag, fastmath=FASTMATH, inline=INLINE,
                                        error_model="numpy")
        _base_of[id(out)] = base
    return out


def call(model, fns, name, *args):
    """``fns[name](*args)`` for ``fns = filter_functions(model)``.  Should that build not compile (an
    equation compiled without reference counting allocates after all: numba refuses it), the model's
    reference-counted build runs instead, now and from then on (same results, slower)."""
    _jit.compile_notice(fns[name], f"the {model.name} filter")
    try:
        return fns[name](*args)
    except _jit.compile_errors():
        base = _base_of.get(id(fns))
        if base is None or base in _refcounted:
            raise
        _refcounted.add(base)
        return filter_functions(model, refcount=True)[name](*args)


#: Names whose use allocates an array (an equation that uses one is compiled with reference counting).
_ALLOCATING = frozenset({
    "empty", "zeros", "ones", "full", "array", "asarray", "ascontiguousarray", "copy", "empty_like", "zeros_like",
    "ones_like", "full_like", "concatenate", "stack", "vstack", "hstack", "column_stack", "arange", "linspace", "eye",
    "identity", "diag", "outer", "dot", "tile", "repeat", "append", "astype", "flatten", "ravel", "reshape", "sort",
    "argsort", "unique", "where", "cumsum", "cumprod", "transpose", "broadcast_to"})


def _refcount_free(eq: dict, ns: dict) -> frozenset:
    """Names of the model's equations (``Model._equations``, in dependency order) compiled without numba's
    reference counting (:func:`shipid._jit.rebind`'s ``no_refcount``): not ``k_consts`` (it returns a new
    array), no allocating name (:data:`_ALLOCATING`) among the names their code uses, and calling only
    equations of the set that qualify themselves (none that the model's namespace provides, compiled
    elsewhere).  Array arithmetic allocates without a name; numba refuses to compile it without reference
    counting, and :func:`call` then falls back.  Why: ``k_rhs``/``k_jac`` run ~5 times per filter step and
    4 times per replay step with array arguments; their atomic reference counts cost ~7 % of a compiled
    fit (kcs-response)."""
    free: set = set()
    for name, fn in eq.items():
        if name == "k_consts" or name in ns or not isinstance(fn, types.FunctionType):
            continue
        names, codes = set(), [fn.__code__]
        while codes:
            code = codes.pop()
            names.update(code.co_names)
            codes.extend(c for c in code.co_consts if isinstance(c, types.CodeType))
        if names & _ALLOCATING or any(n != name and (n in ns or (n in eq and n not in free)) for n in names):
            continue
        free.add(name)
    return frozenset(free)


_refcounted: set = set()  # base keys of filter builds whose reference-count-free equations did not compile
_base_of: dict = {}
_cache: dict = {}
#: The kernel's helpers that numba inlines into their callers (``_jit.rebind``'s ``inline``): called once
#: or more per sample with up to ~25 array arguments, their calls cost ~0.6 us of a ~4 us filter step
#: (kcs-response, 22 states; same results to the bit), for ~2.5 s more compile time (17.8 -> 20.2 s with
#: an empty cache).  The model's equations and wrappers are not inlined: no measurable gain, and
#: inlining the equations themselves would let the filter's fastmath flags change their rounding.
INLINE = frozenset({"cholesky", "chol_solve", "mat_mul", "rk4_rest", "hold_inputs", "tangent", "ship_variances", "rows_times"})
#: The filter and smoother compile with numba's ``error_model="numpy"`` (a division by zero gives inf/NaN, as
#: on the numpy path, instead of raising: no check per division; smoother ~0.1 us per sample faster, results
#: identical to the bit on the bench log).
#: numba's fastmath flags of the filter and smoother: sums may be reassociated and fused (so that the
#: loops vectorise); not "nnan"/"ninf", which would break the NaN-based divergence checks.
FASTMATH = {"reassoc", "contract"}


def replay_compiled(model, x0, t, U, p, nsteps, foh: bool):
    """Open-loop RK4 of ``model`` on its kernel equations (what :func:`shipid.simulate.simulate` does
    with sampled inputs and ``method="rk4"``): compiled, or -- without compilation, for one
    trajectory -- the same :func:`rk4_replay` run by the Python interpreter on floats (one trajectory
    is a chain of scalar operations, ~3.5x cheaper on floats than on numpy arrays of six entries; a
    batch stays on the caller's numpy path).  ``None`` when neither applies (a batch without
    compilation, a model without kernel equations) or a state became non-finite (the caller's numpy
    path then reports it with its own failure semantics).

    ``x0 (B, nx)``, ``t (nt,)``, ``U (B, nt, nu)``, ``p (np,)`` or ``(B, np)``, ``nsteps (nt-1,)`` int,
    ``foh``: first-order hold.  Returns ``X (B, nt, nx)``.
    """
    fns = filter_functions(model, notice=False)  # the simulator's numpy path is not slower than expected
    if fns is None:
        if len(x0) != 1 or _jit.enabled() or not getattr(model, "_python_replay", False):
            return None
        fns = python_functions(model)
        if fns is None:
            return None
    f64 = lambda a: np.ascontiguousarray(a, dtype=float)  # noqa: E731
    x0 = f64(x0)
    X = np.empty((x0.shape[0], len(t), x0.shape[1]))
    try:
        args = (f64(t), f64(U), x0, f64(np.atleast_2d(p)), f64(model._kernel_constants()),
                np.ascontiguousarray(nsteps, dtype=np.int64), bool(foh), X)
        bad = call(model, fns, "rk4_replay", *args) if _jit.enabled() else fns["rk4_replay"](*args)
    except (ArithmeticError, ValueError):  # the interpreter's float maths raises where numpy gives inf/NaN
        return None
    return None if bad else X


def python_functions(model):
    """:data:`FILTER` with ``model``'s kernel equations as globals, not compiled (run by the interpreter:
    the same source as the compiled kernel), or ``None`` when the model declares no equations."""
    eq = getattr(model, "_equations", None)
    if eq is None:
        return None
    key = ("python", id(eq), type(model))
    hit = _cache.get(key)
    if hit is None or hit[0] is not eq:
        ns = model._equations_namespace()
        hit = _cache[key] = (eq, _jit.rebind(FILTER, {**ns, **_jit.rebind(eq, ns)}))  # eq kept: ids stay unique
    return hit[1]
