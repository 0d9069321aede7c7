"""Optional CasADi + IPOPT backend of the direct method (``solve_direct(..., method="ipopt")``).

The transcription is the one of :mod:`shipid.control.direct`: piecewise-
constant controls scaled to [0, 1], ``n_segments`` multiple-shooting segments
whose end states (scaled by ``problem.x_scale``) are decision variables, the
free final time scaled by its guess, continuity and terminal equalities, path
bounds at every RK4 node, rate limits on consecutive control values, the same
Bolza cost.  CasADi builds it symbolically (MX), including the RK4 stages;
IPOPT solves it with its sparse interior-point method and a limited-memory
Hessian approximation (no second derivatives of the model exist).

**The model enters once, as a black box.**  shipid's models are numpy code
and cannot be traced with CasADi symbols: ``planing-boat`` fails inside
``np.stack`` and in the tabulated (PCHIP) Savitsky curve, ``mmg`` in
``np.real``; ``kcs-response`` writes into a float ``np.empty`` and, under
CasADi's legacy numpy mode, silently returns NaN (checked with casadi 3.8.2,
both numpy modes).  Re-typing the equations in CasADi would make a second copy
of every model, which shipid does not allow.  So the model's ``rhs`` is a
CasADi :class:`casadi.Callback` evaluated on a batch (all shooting segments in
one Python call, through the protocol's leading batch axis) whose Jacobian is
another callback returning the model's ``jac_x``/``jac_u`` (analytic where the
model provides them, finite differences otherwise) as a block-diagonal sparse
matrix.  CasADi's AD chains these through the RK4 stages; the result is the
same exact derivative of the discretised problem the SLSQP path uses.
Mayer and running costs are wrapped the same way.

CasADi is optional: this module imports it lazily and raises
:class:`MissingExtraError` (a ValueError, so ``shipid plan`` exits 2 with the
message) naming ``pip install shipid[casadi]`` when it is absent.
"""
from __future__ import annotations

import time

import numpy as np

from ..integrate import rk4_step
from .problem import Problem, rk4_sensitivities
from .result import ControlResult
from .shooting import _MS

__all__ = ["solve_ipopt", "MissingExtraError", "have_casadi"]


class MissingExtraError(ImportError, ValueError):
    """An optional dependency (a shipid extra) is not installed."""


def _casadi():
    try:
        import casadi  # optional (the casadi extra)
    except ImportError:
        raise MissingExtraError(
            "solve_direct(method='ipopt') needs CasADi (IPOPT ships in its wheel), which is not installed; "
            "install the extra with `pip install shipid[casadi]` or use method 'slsqp'") from None
    return casadi


def have_casadi() -> bool:
    """True when CasADi can be imported."""
    try:
        _casadi()
    except MissingExtraError:
        return False
    return True


def _callback(ca, name: str, sp_in: tuple, sp_out: tuple, evaluate, keep: list, jacobian=None):
    """A CasADi ``Callback`` with fixed input/output sparsities whose numerics are ``evaluate(arg)``.

    ``jacobian``: a zero-argument factory of the callback computing the Jacobian (CasADi asks for it
    once), or None.  Every callback is appended to ``keep``: CasADi holds only a weak reference.
    """

    class _CB(ca.Callback):
        def __init__(self):
            ca.Callback.__init__(self)
            self.construct(name, {"enable_fd": False})

        def get_n_in(self):
            return len(sp_in)

        def get_n_out(self):
            return len(sp_out)

        def get_sparsity_in(self, i):
            return sp_in[i]

        def get_sparsity_out(self, i):
            return sp_out[i]

        def eval(self, arg):
            return evaluate(arg)

        def has_jacobian(self):
            return jacobian is not None

        def get_jacobian(self, jname, inames, onames, opts):
            return jacobian()

    cb = _CB()
    keep.append(cb)
    return cb


def _blockdiag(ca, blocks, sp):
    """Nonzeros of a block-diagonal pattern ``sp`` of K dense (m, n) ``blocks`` (K, m, n), column-major."""
    return ca.DM(sp, np.ascontiguousarray(np.transpose(blocks, (0, 2, 1))).ravel())


def _batched_callback(ca, name: str, fun, jac, na: int, nb: int, no: int, batch: int, keep: list):
    """CasADi function ``(A (na, K), B (nb, K)) -> O (no, K)`` of a batch-aware numpy function.

    ``fun(a (K, na), b (K, nb)) -> (K, no)``; ``jac(a, b) -> (dO/dA (K, no, na), dO/dB (K, no, nb))``.
    Column ``k`` of the output depends only on column ``k`` of the inputs, so the Jacobians are
    block diagonal; they are declared sparse so IPOPT sees the structure.
    """
    K = batch
    # CasADi vectorises column-major: entry (i, k) of an (n, K) matrix is element i + n k.
    sp_a = ca.diagcat(*[ca.Sparsity.dense(no, na)] * K)
    sp_b = ca.diagcat(*[ca.Sparsity.dense(no, nb)] * K)

    dense = ca.Sparsity.dense
    sp_in = (dense(na, K), dense(nb, K))

    def evaluate(arg):
        a, b = np.array(arg[0]).T, np.array(arg[1]).T
        return [ca.DM(np.asarray(fun(a, b), float).reshape(K, no).T)]

    def evaluate_jac(arg):
        a, b = np.array(arg[0]).T, np.array(arg[1]).T
        ja, jb = jac(a, b)
        return [_blockdiag(ca, ja, sp_a), _blockdiag(ca, jb, sp_b)]

    return _callback(ca, name, sp_in, (dense(no, K),), evaluate, keep,
                     jacobian=lambda: _callback(ca, f"jac_{name}", (*sp_in, dense(no, K)), (sp_a, sp_b),
                                                evaluate_jac, keep))


def _interval_callback(ca, pr: Problem, batch: int, keep: list):
    """CasADi function ``(X0 (nx, K), U (nu, K), h) -> X (nx * s, K)``: one control interval.

    Column ``k`` integrates the model from ``X0[:, k]`` with the input ``U[:, k]`` held over
    ``s = problem.substeps`` RK4 steps of size ``h`` and stacks the ``s`` states after each
    step (the path-constraint nodes; the last one is the interval's end).  The RK4 map and its
    exact Jacobians are :func:`shipid.control.problem.rk4_sensitivities` (the model's ``rhs``,
    ``jac_x``, ``jac_u``), the code the SLSQP path uses; the Jacobian callback returns them as
    block-diagonal sparse matrices (column ``k`` depends only on column ``k``).
    """
    m, p = pr.model, pr.model.params
    nx, nu, s, K = m.nx, m.nu, pr.substeps, batch
    no = nx * s
    sp_x = ca.diagcat(*[ca.Sparsity.dense(no, nx)] * K)
    sp_u = ca.diagcat(*[ca.Sparsity.dense(no, nu)] * K)

    def _unpack(arg):
        return np.array(arg[0]).T, np.array(arg[1]).T, float(np.array(arg[2])[0, 0])

    dense = ca.Sparsity.dense
    sp_in = (dense(nx, K), dense(nu, K), dense(1, 1))

    def evaluate(arg):
        x, u, h = _unpack(arg)
        out = np.empty((K, s, nx))
        with np.errstate(all="ignore"):
            for j in range(s):
                x = rk4_step(m, 0.0, x, u, p, h)
                out[:, j] = x
        return [ca.DM(out.reshape(K, no).T)]

    def evaluate_jac(arg):
        x, u, h = _unpack(arg)
        Ax = np.broadcast_to(np.eye(nx), (K, nx, nx))
        Bu = np.zeros((K, nx, nu))
        ch = np.zeros((K, nx))
        JX, JU, JH = (np.empty((K, s, nx, nx)), np.empty((K, s, nx, nu)), np.empty((K, s, nx)))
        with np.errstate(all="ignore"):
            for j in range(s):
                x, A, B, c = rk4_sensitivities(m, x, u, p, h)
                Ax, Bu = A @ Ax, A @ Bu + B
                ch = (A @ ch[..., None])[..., 0] + c  # d x_j / d h, every step has size h
                JX[:, j], JU[:, j], JH[:, j] = Ax, Bu, ch
        return [_blockdiag(ca, JX.reshape(K, no, nx), sp_x), _blockdiag(ca, JU.reshape(K, no, nu), sp_u),
                ca.DM(JH.reshape(K, no).T.reshape(-1, 1, order="F"))]

    return _callback(ca, "interval", sp_in, (dense(no, K),), evaluate, keep,
                     jacobian=lambda: _callback(ca, "jac_interval", (*sp_in, dense(no, K)),
                                                (sp_x, sp_u, dense(no * K, 1)), evaluate_jac, keep))


def solve_ipopt(problem: Problem, *, n_segments: int | None = None, max_iter: int = 3000, tol: float = 1e-2,
                ipopt_tol: float = 1e-8, U0: np.ndarray | None = None, tf0: float | None = None,
                print_level: int = 0) -> ControlResult:
    """Solve ``problem`` by multiple shooting with CasADi + IPOPT.

    Parameters
    ----------
    problem : Problem
    n_segments : int, optional
        Shooting segments (default ``problem.shooting_segments``), reduced to a divisor of
        ``n_intervals``.
    max_iter : int
        IPOPT iteration limit.
    tol : float
        Largest admissible scaled constraint violation for ``success`` (re-simulated on a fine grid).
    ipopt_tol : float
        IPOPT's convergence tolerance (``tol``; its ``constr_viol_tol`` is ``tol / 10``).
    U0, tf0 : optional
        Initial guess; the node states are initialised by simulating it.
    print_level : int
        IPOPT's print level (0 silent, 5 verbose).

    Returns
    -------
    ControlResult
        ``method="direct-ipopt"``; ``nit`` IPOPT iterations, ``nfev`` evaluations of the constraints.
    """
    ca = _casadi()
    t0 = time.perf_counter()
    pr = problem
    ms = _MS(pr, pr.shooting_segments if n_segments is None else n_segments)
    N, s, nx, nu, nseg, L = ms.N, ms.s, ms.nx, ms.nu, ms.nseg, ms.L
    keep: list = []  # the callbacks must outlive the solver

    F = _interval_callback(ca, pr, nseg, keep)

    w = ca.MX.sym("w", ms.n)
    # controls (nu, N): free inputs from the scaled variables, fixed ones constant
    Uz = ca.reshape(w[: ms.nU], ms.nuf, N)
    rows = []
    for j in range(nu):
        if ms.free[j]:
            rows.append(pr.u_lo[j] + pr.u_range[j] * Uz[int(ms.col[j]), :])
        else:
            rows.append(ca.DM.ones(1, N) * pr.u_lo[j])
    U = ca.vertcat(*rows)
    xs = ca.DM(pr.x_scale)
    S = ca.reshape(w[ms.nU: ms.nU + ms.nS], nx, nseg) * ca.repmat(xs, 1, nseg)
    tf = w[-1] * ms.tf_ref if pr.free_final_time else ca.DM(float(pr.final_time))
    h = tf / (N * s)

    # the control intervals of all segments at once (columns = segments)
    x = ca.horzcat(ca.DM(pr.x0), S[:, :-1]) if nseg > 1 else ca.DM(pr.x0)
    nodes = []
    starts = []
    for l in range(L):
        Ul = U[:, [q * L + l for q in range(nseg)]]
        starts.append(x)
        out = F(x, Ul, h)
        for sub in range(s):
            nodes.append(out[sub * nx:(sub + 1) * nx, :])
        x = nodes[-1]
    # constraints, in the order of shooting._MS: continuity, terminal equalities, then inequalities
    g, lbg, ubg = [], [], []
    cont = (x - S) / ca.repmat(xs, 1, nseg)
    g.append(ca.vec(cont))
    lbg.append(np.zeros(nx * nseg))
    ubg.append(np.zeros(nx * nseg))
    for i, val in zip(pr.term_idx, pr.term_val):
        g.append((S[int(i), -1] - val) / pr.x_scale[i])
        lbg.append([0.0])
        ubg.append([0.0])
    if pr.path_rows:
        # node k of segment q: nodes[k][:, q]; all RK4 nodes except the final state (a bounded variable)
        allx = ca.horzcat(*[nodes[k][:, q] for q in range(nseg) for k in range(L * s)])[:, :-1]
        for i, sgn, b, _ in pr.path_rows:
            g.append(ca.vec(-(sgn * (allx[i, :] - b)) / pr.x_scale[i]))
            lbg.append(np.zeros(N * s - 1))
            ubg.append(np.full(N * s - 1, np.inf))
    dt = tf / N
    for j in np.where(np.isfinite(pr.rate))[0]:
        seq = U[j, :] if pr.u_initial is None else ca.horzcat(ca.DM(pr.u_initial[j]), U[j, :])
        d = (seq[1:] - seq[:-1]) / (pr.rate[j] * dt)
        g.append(ca.vec(d))
        lbg.append(np.full(d.numel(), -1.0))
        ubg.append(np.full(d.numel(), 1.0))

    # cost
    J = pr.time_weight * tf
    if pr.mayer is not None:
        def mayer(xf, t):
            return np.atleast_1d(pr.mayer(xf[0], float(t[0, 0]))[0])[None]

        def mayer_jac(xf, t):
            _, phix, phit = pr.mayer(xf[0], float(t[0, 0]))
            return np.asarray(phix, float).reshape(1, 1, nx), np.full((1, 1, 1), float(phit))

        Mf = _batched_callback(ca, "mayer", mayer, mayer_jac, nx, 1, 1, 1, keep)
        J = J + Mf(S[:, -1], tf)
    if pr.running is not None:
        # rectangle rule on the interval starts, as shooting._MS.cost
        Xs = ca.horzcat(*[starts[l][:, q] for q in range(nseg) for l in range(L)])

        def run(xx, uu):
            return np.asarray(pr.running(xx, uu)[0], float).reshape(-1, 1)

        def run_jac(xx, uu):
            _, gx, gu = pr.running(xx, uu)
            return np.asarray(gx, float)[:, None, :], np.asarray(gu, float)[:, None, :]

        R = _batched_callback(ca, "running", run, run_jac, nx, nu, 1, N, keep)
        J = J + dt * ca.sum2(R(Xs, U))
    scale = ms.tf_ref if pr.time_weight > 0 else 1.0
    J = J / scale

    lb, ub = ms.bounds()
    U0a = pr.initial_controls() if U0 is None else np.clip(np.asarray(U0, float), pr.u_lo, pr.u_hi)
    tf0a = pr.initial_tf() if tf0 is None else float(tf0)
    _, Xsim, _ = pr.simulate(U0a, tf0a)
    S0 = Xsim[s * L::s * L]
    w0 = np.clip(ms.pack(U0a, S0, tf0a), lb, ub)
    w0 = np.where(np.isfinite(w0), w0, 0.0)

    nlp = {"x": w, "f": J, "g": ca.vertcat(*g)}
    opts = {"ipopt": {"max_iter": int(max_iter), "tol": float(ipopt_tol), "constr_viol_tol": float(tol) / 10,
                      "hessian_approximation": "limited-memory", "print_level": int(print_level),
                      "mu_strategy": "adaptive", "sb": "yes"},
            "print_time": False}
    solver = ca.nlpsol("shipid_direct_ipopt", "ipopt", nlp, opts)
    sol = solver(x0=w0, lbx=lb, ubx=ub, lbg=np.concatenate([np.ravel(a) for a in lbg]),
                 ubg=np.concatenate([np.ravel(a) for a in ubg]))
    st = solver.stats()
    wopt = np.array(sol["x"]).ravel()
    Uo, _, tfo = ms.unpack(wopt)
    nit = int(st.get("iter_count", 0))
    nfev = int(st.get("n_call_nlp_g", 0))
    status = str(st.get("return_status", ""))
    ok = bool(st.get("success", False))
    return ControlResult(problem=pr, method="direct-ipopt", controls=Uo, final_time=float(tfo), nit=nit, nfev=nfev,
                         optimizer_success=ok, optimizer_message=f"IPOPT: {status}",
                         wall_time=time.perf_counter() - t0, tol=tol)
