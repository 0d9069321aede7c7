"""Optimal-control problem definition and its shared transcription.

A :class:`Problem` holds the dynamics (any protocol model), the initial
state, the Bolza cost (final time and/or a Mayer term and/or a running cost),
box bounds on the inputs, bounds on input rates, path bounds on the states and
terminal equality/inequality conditions.  Both solvers discretise the
controls the same way: ``n_intervals`` piecewise-constant values over the
(free or fixed) horizon, each interval integrated with ``substeps`` classical
RK4 steps of the model's ``rhs``.  :func:`rk4_sensitivities` gives the exact
derivatives of one RK4 step with respect to state, input and step size from
the model's ``jac_x``/``jac_u``; the indirect solver propagates costates
backwards with them and the direct solver uses them for its constraint
Jacobians.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Mapping

import numpy as np

from .._blas import one_blas_thread  # noqa: F401  (re-exported: the control solvers' context)
from .._io import check_memory
from ..integrate import rk4_step
from ..models.base import Model

__all__ = ["Problem", "rk4_sensitivities", "Trajectory", "evaluate", "Bounds", "one_blas_thread", "check_problem_size"]


Bounds = Mapping[str, tuple]


def rk4_sensitivities(model: Model, x, u, p, h):
    """One RK4 step and its derivatives.

    Parameters
    ----------
    model : Model
    x : array (..., nx)
    u : array (..., nu)
    p : array (np,)
    h : float
        Step [s].

    Returns
    -------
    xn : (..., nx)
    A : (..., nx, nx)  ``d xn / d x``
    B : (..., nx, nu)  ``d xn / d u``
    c : (..., nx)      ``d xn / d h``
    """
    f, fx, fu = model._rhs, model._jac_x, model._jac_u
    nx = x.shape[-1]
    eye = np.eye(nx)
    k1 = f(0.0, x, u, p)
    A1, B1 = fx(0.0, x, u, p), fu(0.0, x, u, p)
    x2 = x + h / 2 * k1
    k2 = f(0.0, x2, u, p)
    A2, B2 = fx(0.0, x2, u, p), fu(0.0, x2, u, p)
    x3 = x + h / 2 * k2
    k3 = f(0.0, x3, u, p)
    A3, B3 = fx(0.0, x3, u, p), fu(0.0, x3, u, p)
    x4 = x + h * k3
    k4 = f(0.0, x4, u, p)
    A4, B4 = fx(0.0, x4, u, p), fu(0.0, x4, u, p)

    K1x, K1u, K1h = A1, B1, np.zeros_like(k1)
    K2x = A2 @ (eye + h / 2 * K1x)
    K2u = A2 @ (h / 2 * K1u) + B2
    K2h = (A2 @ (k1 / 2 + h / 2 * K1h)[..., None])[..., 0]
    K3x = A3 @ (eye + h / 2 * K2x)
    K3u = A3 @ (h / 2 * K2u) + B3
    K3h = (A3 @ (k2 / 2 + h / 2 * K2h)[..., None])[..., 0]
    K4x = A4 @ (eye + h * K3x)
    K4u = A4 @ (h * K3u) + B4
    K4h = (A4 @ (k3 + h * K3h)[..., None])[..., 0]
    ksum = k1 + 2 * k2 + 2 * k3 + k4
    xn = x + h / 6 * ksum
    A = eye + h / 6 * (K1x + 2 * K2x + 2 * K3x + K4x)
    B = h / 6 * (K1u + 2 * K2u + 2 * K3u + K4u)
    c = ksum / 6 + h / 6 * (K1h + 2 * K2h + 2 * K3h + K4h)
    return xn, A, B, c


@dataclass
class Problem:
    """A (time-)optimal control problem on a protocol model.

    Cost (Bolza)::

        J = time_weight * t_f + mayer(x(t_f), t_f) + int_0^t_f running(x, u) dt

    Parameters
    ----------
    model : Model
        Dynamics (``rhs``, ``jac_x``, ``jac_u`` of the model protocol).
    x0 : array (nx,) or mapping
        Initial state (a mapping fills unnamed states with 0).
    input_bounds : mapping name -> (lo, hi)
        Box bounds on the inputs (every input needs one).
    final_time : float or None
        Fixed final time [s]; None for a free final time.
    tf_guess : float
        Initial guess of the final time [s] (free final time).
    tf_bounds : (lo, hi)
        Bounds of the free final time [s].
    state_bounds : mapping name -> (lo, hi)
        Path constraints ``lo <= x(t) <= hi`` (``None``/inf for a one-sided bound).
    terminal : mapping name -> value
        Terminal equality conditions ``x(t_f) = value``.
    terminal_bounds : mapping name -> (lo, hi)
        Terminal inequality conditions.
    input_rate_bounds : mapping name -> rate
        ``|du/dt| <= rate`` imposed on differences of consecutive control values
        ``|u_{j+1} - u_j| <= rate * t_f / n_intervals`` (and from ``u_initial``).
    u_initial : array (nu,) or mapping, optional
        Input applied before ``t = 0`` (start of the rate limit).
    u_guess : array (n_intervals, nu) or (nu,), optional
        Initial guess of the controls (default: mid-range).
    time_weight : float
        Weight of ``t_f`` in the cost (1 for minimum time).
    mayer : callable ``(xf, tf) -> (phi, dphi/dxf, dphi/dtf)``, optional
    running : callable ``(x, u) -> (g, dg/dx, dg/du)`` batch-aware, optional
    n_intervals : int
        Number of piecewise-constant control intervals.
    substeps : int
        RK4 steps per interval.
    state_scale : mapping name -> scale, optional
        Scales used to normalise constraints (default: half-range of the
        state's bounds, else 1 SI unit).
    name : str
        A label for reports.
    switch_input : str or None
        Input whose single bang-bang switch time is reported.
    shooting_segments : int
        Default number of multiple-shooting segments for :func:`solve_direct`.
    """

    model: Model
    x0: object
    input_bounds: Bounds
    final_time: float | None = None
    tf_guess: float = 60.0
    tf_bounds: tuple = (1.0, 1000.0)
    state_bounds: Bounds = field(default_factory=dict)
    terminal: Mapping[str, float] = field(default_factory=dict)
    terminal_bounds: Bounds = field(default_factory=dict)
    input_rate_bounds: Mapping[str, float] = field(default_factory=dict)
    u_initial: object = None
    u_guess: object = None
    time_weight: float = 1.0
    mayer: Callable | None = None
    running: Callable | None = None
    n_intervals: int = 40
    substeps: int = 4
    state_scale: Mapping[str, float] = field(default_factory=dict)
    name: str = "problem"
    switch_input: str | None = None
    shooting_segments: int = 5

    def __post_init__(self):
        m = self.model
        self.x0 = self._vec(self.x0, m.state_names, "x0")
        if self.u_initial is not None:
            self.u_initial = self._vec(self.u_initial, m.input_names, "u_initial")
        lo, hi = np.full(m.nu, -np.inf), np.full(m.nu, np.inf)
        for name, (a, b) in dict(self.input_bounds).items():
            i = m.input_index(name)
            lo[i], hi[i] = float(a), float(b)
            if not lo[i] <= hi[i]:
                raise ValueError(f"input_bounds['{name}'] = ({a}, {b}): need lo <= hi (lo == hi holds the input fixed)")
        missing = [n for i, n in enumerate(m.input_names) if not (np.isfinite(lo[i]) and np.isfinite(hi[i]))]
        if missing:
            raise ValueError(f"input_bounds: every input needs finite bounds; missing for {missing}")
        self.u_lo, self.u_hi = lo, hi
        #: input ranges used for scaling (1 for inputs held fixed by lo == hi)
        self.u_range = np.where(hi > lo, hi - lo, 1.0)
        self.u_fixed = hi == lo
        if self.n_intervals < 2 or self.substeps < 1:
            raise ValueError(f"n_intervals must be >= 2 and substeps >= 1, got {self.n_intervals}, {self.substeps}")
        check_problem_size(m, self.n_intervals, self.substeps, self.name, n_segments=self.shooting_segments)
        if self.final_time is not None and not self.final_time > 0:
            raise ValueError(f"final_time must be positive [s], got {self.final_time!r}")
        a, b = self.tf_bounds
        if not 0 < a < b:
            raise ValueError(f"tf_bounds must satisfy 0 < lo < hi, got {self.tf_bounds!r}")
        # state scales
        sc = np.ones(m.nx)
        for name, (a, b) in dict(self.state_bounds).items():
            i = m.state_index(name)
            a = -np.inf if a is None else float(a)
            b = np.inf if b is None else float(b)
            if np.isfinite(a) and np.isfinite(b):
                sc[i] = (b - a) / 2
            elif np.isfinite(b):
                sc[i] = max(abs(b), 1e-9) if b != 0 else 1.0
            elif np.isfinite(a):
                sc[i] = max(abs(a), 1e-9) if a != 0 else 1.0
        for name, s in dict(self.state_scale).items():
            sc[m.state_index(name)] = float(s)
        self.x_scale = sc
        # path constraints as rows (index, sign, bound): sign*(x - bound) <= 0
        rows = []
        for name, (a, b) in dict(self.state_bounds).items():
            i = m.state_index(name)
            if a is not None and np.isfinite(float(a)):
                rows.append((i, -1.0, float(a), f"{name} >= {a}"))
            if b is not None and np.isfinite(float(b)):
                rows.append((i, 1.0, float(b), f"{name} <= {b}"))
        self.path_rows = rows
        self.term_idx = np.array([m.state_index(n) for n in self.terminal], dtype=int)
        self.term_val = np.array([float(v) for v in self.terminal.values()])
        trows = []
        for name, (a, b) in dict(self.terminal_bounds).items():
            i = m.state_index(name)
            if a is not None and np.isfinite(float(a)):
                trows.append((i, -1.0, float(a), f"{name}(tf) >= {a}"))
            if b is not None and np.isfinite(float(b)):
                trows.append((i, 1.0, float(b), f"{name}(tf) <= {b}"))
        self.term_rows = trows
        self.rate = np.full(m.nu, np.inf)
        for name, r in dict(self.input_rate_bounds).items():
            if not float(r) > 0:
                raise ValueError(f"input_rate_bounds['{name}'] must be positive, got {r!r}")
            self.rate[m.input_index(name)] = float(r)
        if self.switch_input is not None:
            m.input_index(self.switch_input)

    @staticmethod
    def _vec(val, names, what):
        if isinstance(val, Mapping):
            unknown = sorted(set(val) - set(names))
            if unknown:
                raise ValueError(f"{what}: unknown name(s) {unknown}; expected some of {list(names)}")
            return np.array([float(val.get(n, 0.0)) for n in names])
        arr = np.asarray(val, dtype=float).reshape(-1)
        if arr.shape != (len(names),):
            raise ValueError(f"{what}: expected {len(names)} values {list(names)}, got shape {np.shape(val)}")
        return arr

    # ------------------------------------------------------------ helpers
    @property
    def free_final_time(self) -> bool:
        return self.final_time is None

    def initial_controls(self) -> np.ndarray:
        """Initial guess of the controls, shape (n_intervals, nu)."""
        N, nu = self.n_intervals, self.model.nu
        if self.u_guess is None:
            return np.tile((self.u_lo + self.u_hi) / 2, (N, 1))
        g = np.asarray(self.u_guess, dtype=float)
        if g.shape == (nu,):
            g = np.tile(g, (N, 1))
        if g.shape != (N, nu):
            raise ValueError(f"u_guess: expected shape ({N}, {nu}) or ({nu},), got {g.shape}")
        return np.clip(g, self.u_lo, self.u_hi)

    def initial_tf(self) -> float:
        return float(self.final_time) if self.final_time is not None else float(self.tf_guess)

    def simulate(self, U, tf, substeps: int | None = None):
        """Forward simulation of controls ``U`` (n_intervals, nu) over ``[0, tf]``.

        Returns times (K+1,), states (K+1, nx) on the RK4 grid and the input
        applied on each step (K, nu), ``K = n_intervals * substeps``.
        """
        s = self.substeps if substeps is None else int(substeps)
        N = self.n_intervals
        h = tf / (N * s)
        x = self.x0.copy()
        X = [x]
        Us = np.repeat(U, s, axis=0)
        p = self.model.params
        for k in range(N * s):
            x = rk4_step(self.model, 0.0, x, Us[k], p, h)
            X.append(x)
        return np.linspace(0, tf, N * s + 1), np.array(X), Us


@dataclass
class Trajectory:
    """A state/control history with its constraint evaluation."""

    t: np.ndarray
    x: np.ndarray
    u: np.ndarray
    violations: dict
    max_violation: float


def evaluate(problem: Problem, U, tf, substeps: int = 10) -> Trajectory:
    """Simulate ``U`` on a fine grid and measure every constraint violation.

    Violations are dimensionless: each divided by its quantity's scale
    (``problem.x_scale`` for states; the bound range for inputs; the rate
    bound for rates), so one number can summarise them.
    """
    U = np.asarray(U, float)
    t, X, Us = problem.simulate(U, tf, substeps=substeps)
    viol = {}
    sc = problem.x_scale
    for i, sgn, b, label in problem.path_rows:
        viol[label] = max(0.0, float(np.max(sgn * (X[:, i] - b))) / sc[i])
    xf = X[-1]
    for i, val, name in zip(problem.term_idx, problem.term_val, problem.terminal):
        viol[f"{name}(tf) = {val}"] = abs(float(xf[i] - val)) / sc[i]
    for i, sgn, b, label in problem.term_rows:
        viol[label] = max(0.0, float(sgn * (xf[i] - b))) / sc[i]
    rng = problem.u_range
    for j, name in enumerate(problem.model.input_names):
        v = max(float(np.max(U[:, j] - problem.u_hi[j])), float(np.max(problem.u_lo[j] - U[:, j])), 0.0)
        viol[f"{name} within bounds"] = v / rng[j]
        if np.isfinite(problem.rate[j]):
            dt = tf / problem.n_intervals
            d = np.diff(U[:, j])
            if problem.u_initial is not None:
                d = np.r_[U[0, j] - problem.u_initial[j], d]
            viol[f"|d{name}/dt| <= {problem.rate[j]}"] = max(0.0, float(np.max(np.abs(d) / dt)) / problem.rate[j] - 1.0)
    if not np.all(np.isfinite(X)):
        viol["finite states"] = np.inf
    mv = max(viol.values()) if viol else 0.0
    return Trajectory(t=t, x=X, u=np.vstack([Us, Us[-1:]]), violations=viol, max_violation=mv)


def check_problem_size(model, n_intervals: int, substeps: int, where: str = "problem",
                       n_segments: int = 5) -> None:
    """Refuse a transcription whose estimated memory exceeds :func:`shipid._io.memory_limit_bytes`.

    The estimate is the largest of the multiple-shooting sensitivities (``N * substeps * L * nx * nu``
    doubles, ``L = N / n_segments``), the dense constraint Jacobian of SLSQP (``(N * substeps + N * nu) *
    (N * nu + n_segments * nx)`` doubles) and its quasi-Newton matrix (``(N * nu + ...)**2``).
    """
    N, ns, nx, nu = int(n_intervals), int(substeps), model.nx, model.nu
    if N > 10**9 or ns > 10**9:
        N, ns = min(N, 10**9), min(ns, 10**9)  # (the estimate below already refuses these; no float overflow)
    nvar = N * nu + n_segments * nx + 1
    need = 8.0 * max(N * ns * max(N // n_segments, 1) * nx * nu, (N * ns + 2 * N * nu) * nvar, nvar ** 2)
    shown = ", ".join(f"{k} {v if v < 10**12 else f'{v:.3g}'}" for k, v in
                      (("n_intervals", int(n_intervals)), ("substeps", int(substeps))))
    check_memory(need, f"{where}: {shown}", "use fewer n_intervals or substeps")
