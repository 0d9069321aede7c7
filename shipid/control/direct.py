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
from tqdm.auto import tqdm

from .ipopt import solve_ipopt
from .problem import Problem, check_problem_size, one_blas_thread
from .result import ControlResult
from .shooting import _MS

__all__ = ["solve_direct"]


def solve_direct(problem: Problem, *, method: str = "slsqp", n_segments: int | None = None, max_iter: int | None = None,
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
    max_iter : int, optional
        Iteration limit (trust-constr gets ten times as many).  Default 500 for SLSQP and trust-constr
        (paper scenario 3 needs 339 SLSQP iterations; 300 stopped it at a scaled violation of 0.0148), and
        :func:`~shipid.control.ipopt.solve_ipopt`'s own default for IPOPT, whose interior-point iterations
        are cheaper and more numerous.
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
        return solve_ipopt(problem, n_segments=n_segments, tol=tol, U0=U0, tf0=tf0,
                           **({} if max_iter is None else {"max_iter": max_iter}))
    max_iter = 500 if max_iter is None else int(max_iter)
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
