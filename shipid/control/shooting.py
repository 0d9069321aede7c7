"""Multiple-shooting transcription of an optimal-control :class:`~shipid.control.problem.Problem`: the
decision vector (scaled controls, segment-boundary states, final time), the batched segment integration
with exact RK4 sensitivities, and the continuity/path constraints with their Jacobians.  Shared by the
SLSQP/trust-constr solver (:mod:`shipid.control.direct`) and the IPOPT solver (:mod:`shipid.control.ipopt`).
"""
from __future__ import annotations

import numpy as np

from .problem import Problem, rk4_sensitivities


class _MS:
    """Multiple-shooting transcription with ``n_seg`` segments of ``L`` control intervals."""

    def __init__(self, pr: Problem, n_segments: int):
        self.pr = pr
        m = pr.model
        self.N, self.s, self.nx, self.nu = pr.n_intervals, pr.substeps, m.nx, m.nu
        q = max(1, min(int(n_segments), self.N))
        while self.N % q:
            q -= 1
        self.nseg, self.L = q, self.N // q
        self.rng = pr.u_range
        self.free = ~pr.u_fixed  # inputs held fixed (lo == hi) are not decision variables
        self.nuf = int(self.free.sum())
        self.col = np.cumsum(self.free) - 1  # input index -> column among the free inputs
        self.tf_ref = pr.initial_tf()
        self.nU = self.N * self.nuf
        self.nS = self.nseg * self.nx
        self.n = self.nU + self.nS + (1 if pr.free_final_time else 0)
        self.nfev = 0
        self._cache_key = None

    def unpack(self, w):
        pr = self.pr
        U = np.tile(pr.u_lo, (self.N, 1))
        U[:, self.free] += w[: self.nU].reshape(self.N, self.nuf) * self.rng[self.free]
        S = w[self.nU: self.nU + self.nS].reshape(self.nseg, self.nx) * pr.x_scale
        tf = w[-1] * self.tf_ref if pr.free_final_time else float(pr.final_time)
        return U, S, tf

    def pack(self, U, S, tf):
        pr = self.pr
        w = np.r_[((U - pr.u_lo) / self.rng)[:, self.free].ravel(), (S / pr.x_scale).ravel()]
        if pr.free_final_time:
            w = np.r_[w, tf / self.tf_ref]
        return w

    def shoot(self, w):
        """States at every interval end and their sensitivities (cached per w).

        Returns ``U, S, tf, X (nseg, L, nx), Ax (nseg, L, nx, nx), Bu (nseg, L, L, nx, nu), ch (nseg, L, nx)``;
        ``Bu[q, l, j]`` is the derivative of the state at the end of interval ``l`` of segment ``q``
        with respect to the control of interval ``j`` of that segment.
        """
        key = w.tobytes()
        if key == self._cache_key:
            return self._cache
        self.nfev += 1
        pr = self.pr
        U, S, tf = self.unpack(w)
        nseg, L, nx, nu = self.nseg, self.L, self.nx, self.nu
        x = np.vstack([pr.x0[None], S[:-1]])
        h = tf / (self.N * self.s)
        Ax = np.broadcast_to(np.eye(nx), (nseg, nx, nx)).copy()
        Bu = np.zeros((nseg, L, nx, nu))
        ch = np.zeros((nseg, nx))
        ns = self.s
        X = np.empty((nseg, L * ns, nx))
        AxN = np.empty((nseg, L * ns, nx, nx))
        BuN = np.empty((nseg, L * ns, L, nx, nu))
        chN = np.empty((nseg, L * ns, nx))
        Useg = U.reshape(nseg, L, nu)
        p = pr.model.params
        with np.errstate(all="ignore"):
            for l in range(L):
                for sub in range(ns):
                    x, A, B, c = rk4_sensitivities(pr.model, x, Useg[:, l], p, h)
                    Ax = A @ Ax
                    Bu = A[:, None] @ Bu
                    Bu[:, l] += B
                    ch = (A @ ch[..., None])[..., 0] + c
                    k = l * ns + sub
                    X[:, k], AxN[:, k], BuN[:, k], chN[:, k] = x, Ax, Bu, ch
        self._cache_key, self._cache = key, (U, S, tf, X, AxN, BuN, chN)
        return self._cache

    def _dstate(self, q, k, w_rows):
        """Jacobian rows (nx, n) of the unscaled state after RK4 step k of segment q."""
        pr = self.pr
        U, S, tf, X, Ax, Bu, ch = self._cache
        nx, L = self.nx, self.L
        D = np.zeros((nx, self.n))
        for j in range(k // self.s + 1):
            i = q * L + j
            nf = self.nuf
            D[:, i * nf:(i + 1) * nf] = (Bu[q, k, j] * self.rng[None, :])[:, self.free]
        if q > 0:
            D[:, self.nU + (q - 1) * nx: self.nU + q * nx] = Ax[q, k] * pr.x_scale[None, :]
        if pr.free_final_time:
            D[:, -1] = ch[q, k] / (self.N * self.s) * self.tf_ref
        return D

    # objective -----------------------------------------------------------
    def cost(self, w):
        pr = self.pr
        U, S, tf = self.unpack(w)
        g = np.zeros(self.n)
        J = pr.time_weight * tf
        dtf = pr.time_weight
        sx = pr.x_scale
        if pr.mayer is not None:
            phi, phix, phit = pr.mayer(S[-1], tf)
            J += phi
            dtf += phit
            g[self.nU + self.nS - self.nx: self.nU + self.nS] += phix * sx
        if pr.running is not None:
            # rectangle rule on the interval starts (needs the shooting states)
            _, _, _, X, _, _, _ = self.shoot(w)
            starts = np.vstack([pr.x0[None], X[:, self.s - 1::self.s].reshape(-1, self.nx)[:-1]])
            gg, gx, gu = pr.running(starts, U)
            dt = tf / self.N
            J += dt * np.sum(gg)
            dtf += np.sum(gg) / self.N
            g[: self.nU] += (dt * gu * self.rng)[:, self.free].ravel()
            for k in range(1, self.N):
                q, l = divmod(k - 1, self.L)
                g += dt * gx[k] @ self._dstate(q, l * self.s + self.s - 1, None)
        if pr.free_final_time:
            g[-1] += dtf * self.tf_ref
        scale = self.tf_ref if pr.time_weight > 0 else 1.0
        return J / scale, g / scale

    # constraints -----------------------------------------------------------
    def eq(self, w):
        pr = self.pr
        U, S, tf, X, Ax, Bu, ch = self.shoot(w)
        cont = ((X[:, -1] - S) / pr.x_scale).ravel()
        term = (S[-1, pr.term_idx] - pr.term_val) / pr.x_scale[pr.term_idx]
        return np.r_[cont, term]

    def eq_jac(self, w):
        pr = self.pr
        self.shoot(w)
        nx = self.nx
        sx = pr.x_scale
        nt = len(pr.term_idx)
        Jm = np.zeros((self.nseg * nx + nt, self.n))
        for q in range(self.nseg):
            rows = slice(q * nx, (q + 1) * nx)
            Jm[rows] = self._dstate(q, self.L * self.s - 1, None) / sx[:, None]
            Jm[rows, self.nU + q * nx: self.nU + (q + 1) * nx] -= np.eye(nx)
        for k, i in enumerate(pr.term_idx):
            Jm[self.nseg * nx + k, self.nU + (self.nseg - 1) * nx + i] = 1.0
        return Jm

    def ineq(self, w):
        """Path bounds at every RK4 node and rate limits, as ``g(w) >= 0``."""
        pr = self.pr
        U, S, tf, X, Ax, Bu, ch = self.shoot(w)
        Xf = X.reshape(-1, self.nx)[:-1]  # all RK4 nodes except the final state (a bounded variable)
        out = [-(sgn * (Xf[:, i] - b)) / pr.x_scale[i] for i, sgn, b, _ in pr.path_rows]
        dt = tf / self.N
        for j in np.where(np.isfinite(pr.rate))[0]:
            seq = U[:, j] if pr.u_initial is None else np.r_[pr.u_initial[j], U[:, j]]
            d = np.diff(seq) / (pr.rate[j] * dt)
            out.append(1.0 - d)
            out.append(1.0 + d)
        return np.concatenate(out) if out else np.zeros(0)

    def ineq_jac(self, w):
        pr = self.pr
        U, S, tf, X, Ax, Bu, ch = self.shoot(w)
        rows = []
        if pr.path_rows:
            D = [self._dstate(*divmod(k, self.L * self.s), None) for k in range(self.N * self.s - 1)]
            for i, sgn, b, _ in pr.path_rows:
                rows.append(np.array([-sgn * Dk[i] / pr.x_scale[i] for Dk in D]).reshape(-1, self.n))
        dt = tf / self.N
        for j in np.where(np.isfinite(pr.rate))[0]:
            seq = U[:, j] if pr.u_initial is None else np.r_[pr.u_initial[j], U[:, j]]
            n_d = len(seq) - 1
            off = len(seq) - self.N
            D = np.zeros((n_d, self.n))
            for k in range(n_d):
                for idx, sg in ((k + 1, 1.0), (k, -1.0)):
                    ui = idx - off
                    if ui >= 0 and self.free[j]:
                        D[k, ui * self.nuf + self.col[j]] += sg * self.rng[j] / (pr.rate[j] * dt)
            d = np.diff(seq) / (pr.rate[j] * dt)
            if pr.free_final_time:
                D[:, -1] = -d / tf * self.tf_ref
            rows.append(-D)
            rows.append(D)
        return np.vstack(rows) if rows else np.zeros((0, self.n))

    def n_ineq(self):
        n = len(self.pr.path_rows) * (self.N * self.s - 1)
        n += int(np.isfinite(self.pr.rate).sum()) * 2 * self.N
        return n

    def bounds(self):
        pr = self.pr
        lb = np.full(self.n, -np.inf)
        ub = np.full(self.n, np.inf)
        lb[: self.nU], ub[: self.nU] = 0.0, 1.0
        sx = pr.x_scale
        for i, sgn, b, _ in pr.path_rows:
            sl = slice(self.nU + i, self.nU + self.nS, self.nx)
            if sgn > 0:
                ub[sl] = np.minimum(ub[sl], b / sx[i])
            else:
                lb[sl] = np.maximum(lb[sl], b / sx[i])
        last = self.nU + (self.nseg - 1) * self.nx
        for i, sgn, b, _ in pr.term_rows:
            if sgn > 0:
                ub[last + i] = min(ub[last + i], b / sx[i])
            else:
                lb[last + i] = max(lb[last + i], b / sx[i])
        if pr.free_final_time:
            lb[-1], ub[-1] = pr.tf_bounds[0] / self.tf_ref, pr.tf_bounds[1] / self.tf_ref
        return lb, ub
