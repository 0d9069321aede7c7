"""The compiled smoothers (model-free): the RTS backward recursion and the Bryson-Frazier form with the
ship states' variances."""
from __future__ import annotations

import math

import numpy as np

from .linalg import chol_solve, cholesky

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
