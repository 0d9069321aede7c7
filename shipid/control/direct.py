"""Direct solver: multiple shooting with scipy's SLSQP or trust-constr.

Decision variables: the piecewise-constant controls (scaled to [0, 1] by
their bounds), the states at the segment boundaries and the final state
(scaled by ``problem.x_scale``) and, for a free final time, ``t_f``.  The
horizon is cut into ``n_segments`` shooting segments of several control
intervals; each interval is integrated with ``substeps`` RK4 steps of the
model, all segments at once (batched over the leading axis of the model
protocol).  Few segments keep SLSQP's dense subproblem small.  Constraints:

* continuity ``x_end(interval j) = s_{j+1}`` (equalities, exact Jacobians from
  :func:`shipid.control.problem.rk4_sensitivities`);
* terminal equalities; terminal bounds as bounds of the final-state
  variables; path bounds at every RK4 node (nonlinear
  inequalities; :func:`evaluate` reports any violation between them on a
  fine grid);
* input-rate limits as linear inequalities on consecutive controls.

The cost is ``time_weight * t_f`` plus the Mayer term plus the running cost
by the rectangle rule on the shooting nodes.
"""
from __future__ import annotations

import time
import warnings

import numpy as np
from scipy.optimize import BFGS, Bounds, NonlinearConstraint, minimize

from .problem import Problem, one_blas_thread, rk4_sensitivities
from .result import ControlResult

__all__ = ["solve_direct"]


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


def solve_direct(problem: Problem, *, method: str = "slsqp", n_segments: int | None = None, max_iter: int = 300,
                 ftol: float = 1e-9, tol: float = 1e-2, U0: np.ndarray | None = None,
                 tf0: float | None = None, progress: bool = False) -> ControlResult:
    """Solve ``problem`` by multiple shooting.

    Parameters
    ----------
    problem : Problem
    method : {"slsqp", "trust-constr", "ipopt"}
        Optimiser: scipy's SLSQP or trust-constr, or IPOPT through CasADi (the same
        transcription built by :func:`shipid.control.ipopt.solve_ipopt`; needs the extra
        ``pip install shipid[casadi]``).
    n_segments : int, optional
        Shooting segments (default ``problem.shooting_segments``) (reduced to a divisor of ``n_intervals``); each holds
        ``n_intervals / n_segments`` control intervals.  Path bounds are imposed
        at every RK4 node.
    max_iter : int
        Iteration limit (SLSQP, IPOPT; trust-constr gets ten times as many).
    ftol : float
        SLSQP's objective tolerance (trust-constr: ``gtol``/``xtol``).
    tol : float
        Largest admissible scaled constraint violation for ``success``.
    U0, tf0 : optional
        Initial guess; the node states are initialised by simulating it.
    progress : bool
        Show a progress bar over the optimiser's iterations (tqdm, on stderr; SLSQP and trust-constr).
    """
    if method not in ("slsqp", "trust-constr", "ipopt"):
        raise ValueError(f"solve_direct: method must be 'slsqp', 'trust-constr' or 'ipopt', got {method!r}")
    if method == "ipopt":
        from .ipopt import solve_ipopt

        return solve_ipopt(problem, n_segments=n_segments, max_iter=max_iter, tol=tol, U0=U0, tf0=tf0)
    from .spec import check_problem_size

    nseg = problem.shooting_segments if n_segments is None else n_segments
    check_problem_size(problem.model, problem.n_intervals, problem.substeps, problem.name, n_segments=nseg)
    t0 = time.perf_counter()
    ms = _MS(problem, nseg)
    U = problem.initial_controls() if U0 is None else np.clip(np.asarray(U0, float), problem.u_lo, problem.u_hi)
    tf = problem.initial_tf() if tf0 is None else float(tf0)
    _, X, _ = problem.simulate(U, tf)
    S = X[problem.substeps * ms.L::problem.substeps * ms.L]
    lb, ub = ms.bounds()
    w0 = np.clip(ms.pack(U, S, tf), lb, ub)
    has_ineq = ms.n_ineq() > 0
    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=max_iter * (10 if method == "trust-constr" else 1), desc=f"{problem.name} ({method})",
                   unit="it", leave=False)
    step = (lambda *a: bar.update(1)) if bar is not None else None
    with warnings.catch_warnings(), one_blas_thread():
        warnings.simplefilter("ignore", RuntimeWarning)
        if method == "slsqp":
            cons = [{"type": "eq", "fun": ms.eq, "jac": ms.eq_jac}]
            if has_ineq:
                cons.append({"type": "ineq", "fun": ms.ineq, "jac": ms.ineq_jac})
            res = minimize(ms.cost, w0, jac=True, method="SLSQP", bounds=Bounds(lb, ub), constraints=cons,
                           options={"maxiter": max_iter, "ftol": ftol}, callback=step)
        else:
            cons = [NonlinearConstraint(ms.eq, 0.0, 0.0, jac=ms.eq_jac)]
            if has_ineq:
                cons.append(NonlinearConstraint(ms.ineq, 0.0, np.inf, jac=ms.ineq_jac))
            res = minimize(ms.cost, w0, jac=True, method="trust-constr", bounds=Bounds(lb, ub, keep_feasible=False),
                           constraints=cons, hess=BFGS(), callback=step,
                           options={"maxiter": max_iter * 10, "gtol": 1e-8, "xtol": 1e-10, "verbose": 0})
    if bar is not None:
        bar.close()
    U, S, tf = ms.unpack(res.x)
    nit = int(getattr(res, "nit", 0))
    return ControlResult(problem=problem, method=f"direct-{method}", controls=U, final_time=float(tf), nit=nit,
                         nfev=ms.nfev, optimizer_success=bool(res.success), optimizer_message=str(res.message),
                         wall_time=time.perf_counter() - t0, tol=tol)
