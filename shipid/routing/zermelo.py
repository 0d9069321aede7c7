"""Zermelo's navigation problem: time-optimal route of a constant-speed boat in a current.

Problem (Zwierzewicz)::

    x' = V cos(theta) + w_x(t, x, y),   y' = V sin(theta) + w_y(t, x, y),   min t_f

with the heading ``theta`` (math angle from east, counter-clockwise) as control,
from ``start`` to ``target``.  Two solvers:

:func:`solve_pmp` -- the paper's method.  Pontryagin: ``H = p . (V e + w) - 1``
is maximised by ``e = p / |p|`` (the paper's ``tan u = p2 / p1``); costates
``p' = -(dw/dx)^T p``; at the target ``H = 0`` fixes ``|p|`` so the extremals
form a one-parameter family in the final heading ``theta_f`` (the paper's
``alpha``, ``u(t_f) = alpha + pi``).  The family is integrated *backwards* from
the target; a vectorised scan over ``theta_f`` finds candidates and Newton's
method on ``(theta_f, t_f)`` hits the start exactly.  Steady fields only.

:func:`solve_transcription` -- a general direct method: Hermite--Simpson
collocation of the state with the heading at nodes and mid-points, free final
time, solved by SLSQP with analytic constraint Jacobians.  Works for
time-dependent and gridded fields and where the current is faster than the
boat (the target must be reachable).  It finds a local optimum near its
initial guess (default: the straight line, or ``guess=`` a previous route).

Both return a :class:`ZermeloResult` (route, heading schedule as math angle
and nautical course, time, whether the target was reached).

The paper example is :func:`paper_problem` (in nautical miles, knots and hours
so the numbers read as in the paper).  Its reported ``t_f = 10.93 h`` is the
closed-form time ``(cot(u0 - pi) - cot(alpha)) / k`` of the extremal with the
*rounded* angles ``u(0) = 345 deg, alpha = 30 deg``: exactly ``4 (1 + sqrt 3) =
10.9282 h``.  That extremal does not start at the printed ``A = (-1.86, 3.66)``
but about 0.01 nm away from it; the extremal through the printed A takes
10.9157 h with ``u(0) = 344.98 deg`` (see ``docs/routing.md``).

Reference: Zwierzewicz (in Polish): optimal ship control in an area with a variable current -- the
time-optimal route problem (Zermelo's navigation problem solved by Pontryagin's maximum principle).
"""
from __future__ import annotations

from dataclasses import dataclass, field as dc_field
from typing import Sequence

import numpy as np
import pandas as pd
from scipy.integrate import solve_ivp
from scipy.optimize import minimize

from ..integrate import rk4_step
from ..models.base import Model
from ..results import ResultMixin
from .fields import HOUR, KNOT, NM, Field, as_field, course_from_math, linear_shear

__all__ = ["ZermeloProblem", "ZermeloResult", "solve_pmp", "solve_transcription", "paper_problem",
           "extremal", "PAPER_TF_CLOSED_FORM_H"]

#: The paper example's closed-form time for u(0) = 345 deg, alpha = 30 deg: 4 (1 + sqrt 3) h.
PAPER_TF_CLOSED_FORM_H = 4.0 * (1.0 + np.sqrt(3.0))


@dataclass
class ZermeloProblem:
    """A Zermelo problem.

    Parameters
    ----------
    speed : float
        Boat speed through the water ``V`` (> 0), length unit per time unit
        (SI: m/s).
    field : Field
        Current ``w(t, xy)`` in the same units.
    start, target : (2,) array
        Positions (x east, y north).
    t0 : float
        Departure time (matters only for time-dependent fields).
    """

    speed: float
    field: Field
    start: Sequence[float]
    target: Sequence[float]
    t0: float = 0.0

    def __post_init__(self):
        self.field = as_field(self.field)
        self.start = np.asarray(self.start, dtype=float).reshape(2)
        self.target = np.asarray(self.target, dtype=float).reshape(2)
        if not (np.isfinite(self.speed) and self.speed > 0):
            raise ValueError(f"ZermeloProblem: speed must be a positive number, got {self.speed}")
        if not (np.all(np.isfinite(self.start)) and np.all(np.isfinite(self.target))):
            raise ValueError(f"ZermeloProblem: start {self.start} and target {self.target} must be finite")

    @property
    def distance(self) -> float:
        """Straight-line distance start-target."""
        return float(np.hypot(*(self.target - self.start)))


@dataclass
class ZermeloResult(ResultMixin):
    """Time-optimal route.

    Attributes
    ----------
    t : ndarray (n,)
        Times along the route (``t[0] = t0``).
    xy : ndarray (n, 2)
        Positions.
    heading : ndarray (n,)
        Heading through the water, math angle [rad] (from east, ccw).
    course : ndarray (n,)
        The same heading as a nautical course [rad] (from north, clockwise).
    time : float
        Time to the target ``t_f - t0``.
    reached : bool
        Whether the route ends at the target within ``miss`` of it.
    miss : float
        Distance between the route's end (PMP: its start) and the target
        (start).
    success, status, message : as in scipy's ``OptimizeResult``.
    method : str
    info : dict
        Solver details (``theta_f``, iterations, evaluations, ...).
    """

    t: np.ndarray
    xy: np.ndarray
    heading: np.ndarray
    time: float
    reached: bool
    miss: float
    success: bool
    status: int
    message: str
    method: str
    info: dict = dc_field(default_factory=dict)

    @property
    def course(self) -> np.ndarray:
        return course_from_math(self.heading)

    def to_pandas(self) -> pd.DataFrame:
        """Route table: ``t, x, y, heading_deg`` (math) and ``course_deg`` (nautical)."""
        return pd.DataFrame({
            "t": self.t, "x": self.xy[:, 0], "y": self.xy[:, 1],
            "heading_deg": np.degrees(np.mod(self.heading, 2 * np.pi)),
            "course_deg": np.degrees(self.course),
        })

    def summary(self) -> pd.DataFrame:
        """Headline numbers (``value``): time to the target, whether it was reached, the miss distance,
        the start and final course [deg] and the route's points (units are the problem's)."""
        c = np.degrees(self.course) if len(self.heading) else np.array([np.nan])
        rows = {"time": self.time, "reached": bool(self.reached), "miss": self.miss,
                "course_start_deg": float(c[0]), "course_end_deg": float(c[-1]), "points": int(len(self.t))}
        return pd.DataFrame({"value": pd.Series(rows, dtype=object)}).rename_axis("quantity")

    def _html_title(self) -> str:
        return f"Zermelo route ({self.method})"

    def plot(self, ax=None, **kw):
        """Plot the route (y against x); ``kw`` go to matplotlib's ``plot``.  Returns the axes."""
        import matplotlib.pyplot as plt  # only when plotting: pyplot takes ~1 s to import

        ax = ax or plt.gca()
        ax.plot(self.xy[:, 0], self.xy[:, 1], label=kw.pop("label", f"{self.method}: {self.time:.4g}"), **kw)
        ax.set_aspect("equal")
        return ax


def paper_problem(units: str = "nautical") -> ZermeloProblem:
    """The Zwierzewicz example: V = 0.5 kn, w = (0, k x1), k = -0.5 1/h, A = (-1.86, 3.66) nm, target (0, 0).

    The paper's ``x1`` points north and ``x2`` east (its heading ``u`` from
    ``x1`` towards ``x2`` is the nautical course), so in the east/north frame
    the start is ``(3.66, -1.86)`` and the current ``(k y, 0)``.

    Parameters
    ----------
    units : {"nautical", "si"}
        ``"nautical"``: nm, kn, h (times come out in hours);
        ``"si"``: m, m/s, s.
    """
    if units == "nautical":
        return ZermeloProblem(0.5, linear_shear(-0.5), (3.66, -1.86), (0.0, 0.0))
    if units == "si":
        return ZermeloProblem(0.5 * KNOT, linear_shear(-0.5 / HOUR), (3.66 * NM, -1.86 * NM), (0.0, 0.0))
    raise ValueError(f"units must be 'nautical' or 'si', got {units!r}")


# ------------------------------------------------------------------ PMP
class _Extremal(Model):
    """State/costate dynamics of the Zermelo extremals, written in *backward* time s = t_f - t.

    States ``x, y, p1, p2``; no inputs; parameter ``V``.  Used only by the
    shooting method (not a ship model, so not registered).
    """

    name = "zermelo-extremal"
    state_names = ("x", "y", "p1", "p2")
    input_names = ()
    param_names = ("V",)

    def __init__(self, field: Field, speed: float):
        self.field = field
        super().__init__([speed])

    def _rhs(self, s, z, u, p):
        xy = z[..., :2]
        p1, p2 = z[..., 2], z[..., 3]
        Vn = p[0] / np.hypot(p1, p2)
        w = self.field._velocity(s, xy)
        J = self.field._gradient(s, xy)
        out = np.empty(np.broadcast_shapes(z.shape, w.shape[:-1] + (4,)))
        out[..., 0] = -(Vn * p1 + w[..., 0])
        out[..., 1] = -(Vn * p2 + w[..., 1])
        pp = z[..., 2:]
        out[..., 2] = J[..., 0, 0] * pp[..., 0] + J[..., 1, 0] * pp[..., 1]
        out[..., 3] = J[..., 0, 1] * pp[..., 0] + J[..., 1, 1] * pp[..., 1]
        return out


def _terminal_costate(problem: ZermeloProblem, theta_f):
    e = np.stack([np.cos(theta_f), np.sin(theta_f)], axis=-1)
    w = problem.field.velocity(problem.t0, problem.target)
    denom = problem.speed + e @ w
    return e / denom[..., None], denom


def extremal(problem: ZermeloProblem, theta_f: float, duration: float, n: int = 201) -> ZermeloResult:
    """The extremal that *ends* at the target with heading ``theta_f`` after ``duration``.

    Integrated backwards (RK45, rtol 1e-11).  ``result.xy[0]`` is where it
    starts; ``result.miss`` is its distance from ``problem.start``.
    """
    sys = _Extremal(problem.field, problem.speed)
    p0, denom = _terminal_costate(problem, np.asarray(theta_f, dtype=float))
    if denom <= 0:
        raise ValueError(f"final heading {np.degrees(theta_f):.2f} deg is against a current faster than the boat at the target")
    z0 = np.concatenate([problem.target, p0])
    s_eval = np.linspace(0.0, duration, n)
    sol = solve_ivp(lambda s, z: sys._rhs(s, z, None, sys.params), (0.0, duration), z0, method="DOP853",
                    rtol=1e-12, atol=1e-12 * max(1.0, problem.distance), t_eval=s_eval)
    z = sol.y.T[::-1]
    t = problem.t0 + duration - s_eval[::-1]
    heading = np.arctan2(z[:, 3], z[:, 2])
    miss = float(np.hypot(*(z[0, :2] - problem.start)))
    return ZermeloResult(t=t - t[0] + problem.t0, xy=z[:, :2], heading=heading, time=float(duration),
                         reached=True, miss=miss, success=bool(sol.success), status=0 if sol.success else -1,
                         message=sol.message, method="extremal", info={"theta_f": float(theta_f)})


def solve_pmp(problem: ZermeloProblem, *, n_scan: int = 36, t_max: float | None = None, n_steps: int = 60,
              n_candidates: int = 3, tol: float = 1e-9, rtol: float = 1e-10, max_iter: int = 30,
              n_out: int = 201) -> ZermeloResult:
    """Time-optimal route by Pontryagin's principle and shooting on the final heading (Zwierzewicz).

    Parameters
    ----------
    problem : ZermeloProblem
        Steady field only (``field.time_dependent`` False); use
        :func:`solve_transcription` for time-dependent currents.
    n_scan : int
        Number of final headings of the initial scan (uniform over 360 deg).
    t_max : float, optional
        Longest route considered [time unit]; default ``4 * distance / V``.
    n_steps : int
        RK4 steps of the scan.
    n_candidates : int
        Scan minima refined by Newton; the fastest converged one is returned.
    tol : float
        Newton stops when the start is missed by less than ``tol * max(distance, 1)``.
    rtol : float
        Relative tolerance of the DOP853 integrations of the Newton steps.
    max_iter : int
        Newton iterations per candidate.
    n_out : int
        Points of the returned route.

    Returns
    -------
    ZermeloResult
        ``info["theta_f"]`` is the final heading (math angle); ``reached``
        tells whether the extremal hits the start within the tolerance.
    """
    if problem.field.time_dependent:
        raise ValueError("solve_pmp needs a steady current; the field is time dependent -- use solve_transcription")
    V, d = problem.speed, problem.distance
    if d == 0:
        return ZermeloResult(np.array([problem.t0]), problem.start[None], np.zeros(1), 0.0, True, 0.0, True, 0,
                             "start equals target", "pmp")
    t_max = 4.0 * d / V if t_max is None else float(t_max)
    sys = _Extremal(problem.field, V)
    # ---- scan: batch of extremals integrated backwards with fixed-step RK4
    th = np.linspace(-np.pi, np.pi, n_scan, endpoint=False)
    p0, denom = _terminal_costate(problem, th)
    ok = denom > 1e-9 * V
    th, p0 = th[ok], p0[ok]
    z = np.concatenate([np.broadcast_to(problem.target, p0.shape), p0], axis=-1)
    h = t_max / n_steps
    best_d = np.full(th.size, np.inf)
    best_s = np.zeros(th.size)
    empty = np.zeros((th.size, 0))
    for k in range(n_steps):
        z = rk4_step(sys, k * h, z, empty, sys.params, h)
        dist = np.hypot(z[:, 0] - problem.start[0], z[:, 1] - problem.start[1])
        better = dist < best_d
        best_d = np.where(better, dist, best_d)
        best_s = np.where(better, (k + 1) * h, best_s)
    nfev = 4 * n_steps * th.size
    # local minima of the miss distance over the (circular) heading scan
    prev, nxt = np.roll(best_d, 1), np.roll(best_d, -1)
    cand = np.flatnonzero((best_d <= prev) & (best_d <= nxt) & np.isfinite(best_d))
    cand = cand[np.argsort(best_d[cand])][:n_candidates]

    fun = lambda s, zz: sys._rhs(s, zz.reshape(3, 4), None, sys.params).ravel()  # noqa: E731
    scale = max(d, 1.0)
    results = []
    for c in cand[np.argsort(best_s[cand])]:
        if any(r[0] == 0 and best_s[c] > 1.2 * r[1] for r in results):
            continue  # clearly slower than an extremal already found
        theta, T = float(th[c]), float(best_s[c])
        dth = 1e-5
        status, miss, sol = 1, np.inf, None
        for it in range(max_iter):
            thetas = np.array([theta - dth, theta, theta + dth])
            pp, den = _terminal_costate(problem, thetas)
            if np.any(den <= 0):
                status = 2
                break
            z0 = np.concatenate([np.broadcast_to(problem.target, pp.shape), pp], axis=-1).ravel()
            sol = solve_ivp(fun, (0.0, T), z0, method="DOP853", rtol=rtol, atol=rtol * 0.1 * scale,
                            dense_output=True)
            nfev += sol.nfev
            if not sol.success:
                status = 3
                break
            zT = sol.y[:, -1].reshape(3, 4)
            F = zT[1, :2] - problem.start
            miss = float(np.hypot(*F))
            if miss < tol * scale:
                status = 0
                break
            dF_dth = (zT[2, :2] - zT[0, :2]) / (2 * dth)
            dF_dT = sys._rhs(T, zT[1], None, sys.params)[:2]
            Jm = np.column_stack([dF_dth, dF_dT])
            try:
                step = np.linalg.solve(Jm, -F)
            except np.linalg.LinAlgError:
                status = 4
                break
            # damp steps that would flip the time or jump by more than ~30 deg
            lam = min(1.0, 0.5 / max(abs(step[0]), 1e-300))
            while T + lam * step[1] <= 0:
                lam *= 0.5
            theta += lam * step[0]
            T += lam * step[1]
        results.append((status, T, theta, miss, it + 1, sol))
    if not results:
        return ZermeloResult(np.zeros(0), np.zeros((0, 2)), np.zeros(0), np.nan, False, np.inf, False, 5,
                             "no admissible final heading (current at the target faster than the boat in all scanned directions)",
                             "pmp", {"nfev": nfev})
    conv = [r for r in results if r[0] == 0]
    if conv:
        status, T, theta, miss, iters, sol = min(conv, key=lambda r: r[1])
        msg = f"extremal through the start found (final heading {np.degrees(theta):.6f} deg, {iters} Newton iterations)"
    else:
        status, T, theta, miss, iters, sol = min(results, key=lambda r: r[3])
        msg = (f"no extremal from the target reaches the start within tol (closest miss {miss:.3g}); "
               "the start may be unreachable, or increase t_max/n_scan")
    if sol is None or not sol.success:
        route = extremal(problem, theta, T, n=n_out)
        xy, heading, t = route.xy, route.heading, route.t
    else:
        s_eval = np.linspace(0.0, T, n_out)
        z = sol.sol(s_eval)[4:8].T[::-1]
        xy, heading = z[:, :2], np.arctan2(z[:, 3], z[:, 2])
        t = problem.t0 + (T - s_eval[::-1])
    return ZermeloResult(t=t, xy=xy, heading=heading, time=float(T), reached=status == 0,
                         miss=float(miss), success=status == 0, status=int(status), message=msg, method="pmp",
                         info={"theta_f": float(theta), "course_f": float(course_from_math(theta)),
                               "candidates": [r[:5] for r in results], "nfev": int(nfev)})


# ------------------------------------------------------- direct transcription
def solve_transcription(problem: ZermeloProblem, *, n: int = 40, guess: ZermeloResult | None = None,
                        t_guess: float | None = None, t_bounds: tuple[float, float] | None = None,
                        tol: float = 1e-10, max_iter: int = 300) -> ZermeloResult:
    """Time-optimal route by Hermite--Simpson direct transcription (any field, free final time).

    Parameters
    ----------
    problem : ZermeloProblem
    n : int
        Number of collocation intervals (error ~ (t_f / n)^4).
    guess : ZermeloResult, optional
        Initial route (interpolated onto the grid); default the straight line.
    t_guess : float, optional
        Initial final time; default ``distance / max(V + w_along, 0.2 V)``
        with the along-track current at the start.
    t_bounds : (float, float), optional
        Bounds of the final time; default ``(1e-6, 100) * distance / V``.
    tol, max_iter : SLSQP tolerance and iteration limit.

    Returns
    -------
    ZermeloResult
        Route at the ``2 n + 1`` nodes and mid-points; ``reached`` when the
        largest collocation defect is below ``1e-6 * distance``.
    """
    V, fld = problem.speed, problem.field
    A, B = problem.start, problem.target
    d = problem.distance
    if d == 0:
        return ZermeloResult(np.array([problem.t0]), A[None], np.zeros(1), 0.0, True, 0.0, True, 0, "start equals target", "transcription")
    N = int(n)
    if N < 2:
        raise ValueError(f"solve_transcription: n must be >= 2 intervals, got {n}")
    s_nodes = np.linspace(0.0, 1.0, N + 1)
    s_all = np.linspace(0.0, 1.0, 2 * N + 1)
    e = (B - A) / d
    if guess is not None:
        tg = (guess.t - guess.t[0]) / max(guess.time, 1e-300)
        X0 = np.column_stack([np.interp(s_nodes, tg, guess.xy[:, 0]), np.interp(s_nodes, tg, guess.xy[:, 1])])
        U0 = np.interp(s_all, tg, np.unwrap(guess.heading))
        T0 = guess.time
    else:
        X0 = A + np.outer(s_nodes, B - A)
        w0 = fld.velocity(problem.t0, A)
        along = float(e @ w0)
        # heading that cancels the cross-track current where possible
        cross = float(e[0] * w0[1] - e[1] * w0[0])
        ang = np.arctan2(e[1], e[0]) - np.arcsin(np.clip(cross / V, -1, 1))
        U0 = np.full(2 * N + 1, ang)
        T0 = d / max(V + along, 0.2 * V)
    if t_guess is not None:
        T0 = float(t_guess)
    lo, hi = t_bounds if t_bounds is not None else (1e-6 * d / V, 100.0 * d / V)
    T0 = float(np.clip(T0, lo * 1.0001, hi * 0.9999))
    nxi = 2 * (N - 1)

    def unpack(z):
        X = np.empty((N + 1, 2))
        X[0], X[-1] = A, B
        X[1:-1] = z[:nxi].reshape(N - 1, 2)
        U = z[nxi:nxi + 2 * N + 1]
        return X, U, z[-1]

    def defects(z, want_jac=False):
        X, U, T = unpack(z)
        h = T / N
        t_n = problem.t0 + T * s_nodes
        t_m = problem.t0 + T * (s_nodes[:-1] + 0.5 / N)
        Un, Um = U[0::2], U[1::2]
        bn = V * np.column_stack([np.cos(Un), np.sin(Un)])
        bm = V * np.column_stack([np.cos(Um), np.sin(Um)])
        fn = bn + fld._velocity(t_n, X)
        xm = 0.5 * (X[:-1] + X[1:]) + h / 8 * (fn[:-1] - fn[1:])
        fm = bm + fld._velocity(t_m, xm)
        D = X[1:] - X[:-1] - h / 6 * (fn[:-1] + 4 * fm + fn[1:])
        if not want_jac:
            return D.ravel()
        An = fld._gradient(t_n, X)
        Am = fld._gradient(t_m, xm)
        I2 = np.eye(2)
        jac = np.zeros((2 * N, z.size))
        dbn = V * np.column_stack([-np.sin(Un), np.cos(Un)])
        dbm = V * np.column_stack([-np.sin(Um), np.cos(Um)])
        for k in range(N):
            r = slice(2 * k, 2 * k + 2)
            dxm_dxk = 0.5 * I2 + h / 8 * An[k]
            dxm_dxk1 = 0.5 * I2 - h / 8 * An[k + 1]
            if 1 <= k <= N - 1:  # x_k is a variable
                c = 2 * (k - 1)
                jac[r, c:c + 2] = -I2 - h / 6 * (An[k] + 4 * Am[k] @ dxm_dxk)
            if k + 1 <= N - 1:
                c = 2 * k
                jac[r, c:c + 2] = I2 - h / 6 * (An[k + 1] + 4 * Am[k] @ dxm_dxk1)
            cu = nxi + 2 * k
            jac[r, cu] = -h / 6 * (dbn[k] + 4 * Am[k] @ (h / 8 * dbn[k]))
            jac[r, cu + 1] = -h / 6 * 4 * dbm[k]
            jac[r, cu + 2] = -h / 6 * (dbn[k + 1] - 4 * Am[k] @ (h / 8 * dbn[k + 1]))
        dT = 1e-7 * max(T, 1e-12)
        zp = z.copy()
        zp[-1] += dT
        zm = z.copy()
        zm[-1] -= dT
        jac[:, -1] = (defects(zp) - defects(zm)) / (2 * dT)
        return jac

    z0 = np.concatenate([X0[1:-1].ravel(), U0, [T0]])
    obj_grad = np.zeros(z0.size)
    obj_grad[-1] = 1.0
    bounds = [(None, None)] * (nxi + 2 * N + 1) + [(lo, hi)]
    res = minimize(lambda z: z[-1], z0, jac=lambda z: obj_grad, method="SLSQP", bounds=bounds,
                   constraints=[{"type": "eq", "fun": defects, "jac": lambda z: defects(z, True)}],
                   options={"ftol": tol, "maxiter": max_iter})
    X, U, T = unpack(res.x)
    viol = float(np.max(np.abs(defects(res.x))))
    reached = viol < 1e-6 * d
    # route at nodes and mid-points
    h = T / N
    t_n = problem.t0 + T * s_nodes
    fn = V * np.column_stack([np.cos(U[0::2]), np.sin(U[0::2])]) + fld._velocity(t_n, X)
    xm = 0.5 * (X[:-1] + X[1:]) + h / 8 * (fn[:-1] - fn[1:])
    xy = np.empty((2 * N + 1, 2))
    xy[0::2], xy[1::2] = X, xm
    heading = np.arctan2(np.sin(U), np.cos(U))
    success = bool(res.success) and reached
    msg = res.message if reached else f"{res.message}; largest collocation defect {viol:.3g} (target not reached)"
    return ZermeloResult(t=problem.t0 + T * s_all, xy=xy, heading=heading, time=float(T), reached=bool(reached),
                         miss=viol, success=success, status=int(res.status), message=str(msg), method="transcription",
                         info={"nit": int(res.nit), "nfev": int(res.nfev), "n": N, "max_defect": viol})
