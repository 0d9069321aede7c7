"""The compiled EKF: one batch member's forward pass (prediction with the RK4 tangent, Joseph-form
measurement update, gating, divergence checks, resets) and the loop over members."""
from __future__ import annotations

import math

import numpy as np

from .linalg import chol_solve, cholesky, mat_mul
from .tangent import hold_inputs, rk4_rest, tangent

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
