# Why one file: the PSO planners (DOPSO, EOPSO, OCPSO), their swarm and the voyage that judges them share one method's problem, cost and geometry (Li et al.).
"""Energy-optimal USV path planning around circular obstacles by particle swarm optimisation (Li et al.).

Encoding (the paper's "dimension circles")
------------------------------------------
Polar coordinates centred at the start ``S`` with the polar axis towards the
goal ``G``.  Each circular obstacle whose centre is nearer to ``S`` than ``G``
defines a dimension circle through its centre (radius ``r_i = |c_i - S|``,
sorted); exactly one waypoint lies on each circle, so a particle is the vector
of the waypoints' polar angles ``[rho_1, ..., rho_m]`` (``rho_S = rho_G = 0``).

Constraints (infinite cost, as in the paper)
--------------------------------------------
* forbidden angles: a waypoint whose incoming leg crosses an obstacle disc, or
  which lies inside one, is forbidden (the arcs ``T1`` and ``T2`` of the
  paper's Fig. 7; :func:`forbidden_arcs` returns them explicitly); the last leg
  to ``G`` must be clear too;
* minimum turning radius ``r_min`` (15 m): at every waypoint the fillet arc of
  radius ``r_min`` must fit, i.e. its tangent length ``r_min tan(dpsi/2)`` is at
  most half of each adjacent leg (our reading -- the paper states the
  constraint but not its formula);
* on each leg the speed over ground must be positive (a head current faster
  than the boat makes a leg impossible).

Objectives: DOPSO the path length; EOPSO the energy ``W = sum P_i L_i / u_i``
(eq. 13) with the leg speed and power of a speed-power model
(:mod:`shipid.routing.energy`); OCPSO re-runs EOPSO from the current position
when the measured current/wind changes, keeping the waypoints already sailed
and the one being sailed to (the paper's step 4), and adds the energy already
spent (eq. 14).

Leg kinematics: ``"paper"`` takes the speed over ground along the leg as
``us = w + Uc cos psi_rc`` (the cross-leg current is ignored, as in the paper);
``"crab"`` lets the boat crab to hold the leg, ``us = c_along + sqrt(w^2 -
c_cross^2)`` (infeasible when the cross current exceeds ``w``).  See
``docs/routing.md`` for why the choice matters.

The optimiser :func:`pso` is a plain global-best PSO on numpy (inertia
decreasing linearly 0.7298 -> 0.4, ``c1 = c2 = 1.5``, velocity clamp at 20 % of
the range; the paper gives no settings), vectorised over the swarm and seeded
by a :class:`numpy.random.Generator`.  The planners run one swarm per
left/right class of passing the obstacles (:func:`stratified_init`): the
feasible set falls apart into such classes, and one swarm over the whole box
(the paper's set-up, ``stratify=False``) often settles in the wrong one.

Reference: Li, Liao, Liu, Jia, Li & Zhai (Harbin Engineering University, in Chinese): energy-optimal
path planning of an unmanned surface vehicle by particle swarm optimisation.
"""
from __future__ import annotations

import itertools
from dataclasses import dataclass, field as dc_field
from typing import Callable, Sequence

import numpy as np
import pandas as pd
from scipy.optimize import differential_evolution
from tqdm.auto import tqdm

from .._io import check_memory
from ..results import ResultMixin
from .energy import PaperUSVModel
from .fields import Field, PiecewiseTimeField, UniformField, as_field

__all__ = [
    "Obstacle", "USVProblem", "PSOResult", "pso", "PathCost", "PlanResult", "plan", "plan_dopso", "plan_eopso",
    "Voyage", "sail", "OCPSOResult", "plan_ocpso", "forbidden_arcs", "differential_evolution_check",
    "lonlat_to_local", "local_to_lonlat", "paper_scenario", "compare_planners", "side_classes", "class_bounds",
    "stratified_init",
]

EARTH_RADIUS = 6371008.8  # mean Earth radius [m] (IUGG)


def lonlat_to_local(lon, lat, lon0: float, lat0: float) -> np.ndarray:
    """Equirectangular projection about ``(lon0, lat0)`` [deg] -> ``(..., 2)`` east/north [m] (fine for a few km)."""
    lon, lat = np.asarray(lon, dtype=float), np.asarray(lat, dtype=float)
    x = np.radians(lon - lon0) * EARTH_RADIUS * np.cos(np.radians(lat0))
    y = np.radians(lat - lat0) * EARTH_RADIUS
    return np.stack([x, y], axis=-1)


def local_to_lonlat(xy, lon0: float, lat0: float) -> np.ndarray:
    """Inverse of :func:`lonlat_to_local`: ``(..., 2)`` [m] -> ``(..., 2)`` (lon, lat) [deg]."""
    xy = np.asarray(xy, dtype=float)
    lon = lon0 + np.degrees(xy[..., 0] / (EARTH_RADIUS * np.cos(np.radians(lat0))))
    lat = lat0 + np.degrees(xy[..., 1] / EARTH_RADIUS)
    return np.stack([lon, lat], axis=-1)


@dataclass(frozen=True)
class Obstacle:
    """Circular obstacle: centre (x east, y north) [m] and radius [m] (obstacle size plus safety margin)."""

    x: float
    y: float
    radius: float

    @property
    def center(self) -> np.ndarray:
        return np.array([self.x, self.y])


@dataclass
class USVProblem:
    """A planning problem of Li et al..

    Parameters
    ----------
    start, goal : (2,) [m]
        Local east/north coordinates.
    obstacles : sequence of Obstacle
    current, wind : Field
        Current velocity (towards) and wind velocity (the air's motion,
        i.e. *towards*; a wind "from the east" at 7 m/s is ``(-7, 0)``) [m/s].
        May be time dependent; planners freeze them at the planning time
        (the paper's static-environment assumption).
    vessel : speed-power model
        Default :class:`~shipid.routing.energy.PaperUSVModel`.
    r_min : float
        Minimum turning radius [m] (15 m for the paper's USV).
    angle_bound : float
        Waypoint polar angles are searched in ``[-angle_bound, angle_bound]`` [rad].
    kinematics : {"paper", "crab"}
        Leg speed model (module docstring).
    n_sub : int
        Pieces per leg at which spatially varying fields are sampled (1 is exact
        for uniform fields).
    origin : (lon, lat) or None
        Geographic origin of the local frame, for lon/lat output.
    """

    start: Sequence[float]
    goal: Sequence[float]
    obstacles: Sequence[Obstacle]
    current: Field = dc_field(default_factory=UniformField)
    wind: Field = dc_field(default_factory=UniformField)
    vessel: object = dc_field(default_factory=PaperUSVModel)
    r_min: float = 15.0
    angle_bound: float = np.pi / 2
    kinematics: str = "paper"
    n_sub: int = 1
    origin: tuple[float, float] | None = None

    def __post_init__(self):
        self.start = np.asarray(self.start, dtype=float).reshape(2)
        self.goal = np.asarray(self.goal, dtype=float).reshape(2)
        self.current = as_field(self.current)
        self.wind = as_field(self.wind)
        self.obstacles = [o if isinstance(o, Obstacle) else Obstacle(*o) for o in self.obstacles]
        if self.kinematics not in ("paper", "crab"):
            raise ValueError(f"kinematics must be 'paper' or 'crab', got {self.kinematics!r}")
        D = np.hypot(*(self.goal - self.start))
        if D <= 0:
            raise ValueError("start and goal coincide")
        for i, o in enumerate(self.obstacles):
            if o.radius <= 0:
                raise ValueError(f"obstacle {i}: radius must be > 0 m, got {o.radius}")
            for name, p in (("start", self.start), ("goal", self.goal)):
                if np.hypot(*(p - o.center)) <= o.radius:
                    raise ValueError(f"obstacle {i} at ({o.x:.1f}, {o.y:.1f}) m, radius {o.radius} m, covers the {name}; move it or shrink it")
        self.axis_angle = float(np.arctan2(*(self.goal - self.start)[::-1]))
        r = np.array([np.hypot(*(o.center - self.start)) for o in self.obstacles])
        order = [i for i in np.argsort(r, kind="stable") if r[i] < D]
        self.radii = r[order]
        #: polar angle [rad] of the obstacle centre that defines each dimension circle
        self.dim_center_angles = np.array([
            np.angle(np.exp(1j * (np.arctan2(*(self.obstacles[i].center - self.start)[::-1]) - self.axis_angle)))
            for i in order])
        if self.radii.size == 0:
            raise ValueError("no obstacle is nearer to the start than the goal, so there is no dimension circle; the straight line is the plan")
        self.centers = np.array([o.center for o in self.obstacles]).reshape(-1, 2)
        self.obstacle_radii = np.array([o.radius for o in self.obstacles])

    @property
    def n_dims(self) -> int:
        """Number of waypoints (dimension circles)."""
        return int(self.radii.size)

    def waypoints(self, rho, dims=None) -> np.ndarray:
        """Waypoints ``(..., k, 2)`` [m] of polar angles ``rho (..., k)`` on dimension circles ``dims``."""
        rho = np.asarray(rho, dtype=float)
        radii = self.radii if dims is None else self.radii[np.asarray(dims)]
        ang = self.axis_angle + rho
        return self.start + radii[..., :, None] * np.stack([np.cos(ang), np.sin(ang)], axis=-1)

    def plot(self, ax=None, circles: bool = True):
        """Obstacles, dimension circles (dotted), start and goal; returns the axes."""
        import matplotlib.pyplot as plt  # only when plotting: pyplot takes ~1 s to import

        ax = ax or plt.gca()
        for o in self.obstacles:
            ax.add_patch(plt.Circle((o.x, o.y), o.radius, color="0.85"))
        if circles:
            for r in self.radii:
                ax.add_patch(plt.Circle(tuple(self.start), r, fill=False, ls=":", color="0.6"))
        ax.plot(*self.start, "k^")
        ax.plot(*self.goal, "k*")
        ax.set_aspect("equal")
        return ax

    def path(self, rho) -> np.ndarray:
        """Full path ``(..., m + 2, 2)``: start, waypoints, goal."""
        wp = self.waypoints(rho)
        lead = wp.shape[:-2]
        S = np.broadcast_to(self.start, lead + (1, 2))
        G = np.broadcast_to(self.goal, lead + (1, 2))
        return np.concatenate([S, wp, G], axis=-2)


# ----------------------------------------------------------- geometry/costs
def _segments_clear(P0, P1, centers, radii) -> np.ndarray:
    """True where segment P0-P1 (..., 2) stays outside every disc (centers (K, 2), radii (K,))."""
    d = P1 - P0
    L2 = np.sum(d * d, axis=-1)[..., None]
    rel = centers - P0[..., None, :]  # (..., K, 2)
    s = np.clip(np.sum(rel * d[..., None, :], axis=-1) / np.where(L2 > 0, L2, 1.0), 0.0, 1.0)
    closest = P0[..., None, :] + s[..., None] * d[..., None, :]
    dist2 = np.sum((closest - centers) ** 2, axis=-1)
    return np.all(dist2 >= radii**2, axis=-1)


def _turns_ok(points, r_min, incoming_length=None) -> np.ndarray:
    """Fillet of radius r_min fits at each interior vertex of ``points (..., k, 2)``."""
    d = np.diff(points, axis=-2)
    L = np.hypot(d[..., 0], d[..., 1])
    if points.shape[-2] < 3 or r_min <= 0:
        return np.ones(points.shape[:-2], dtype=bool)
    a = np.arctan2(d[..., 1], d[..., 0])
    turn = np.abs(np.angle(np.exp(1j * (a[..., 1:] - a[..., :-1]))))
    tangent = r_min * np.tan(np.minimum(turn, np.pi * (1 - 1e-12)) / 2)
    Lin = L[..., :-1].copy()
    if incoming_length is not None:
        Lin[..., 0] = incoming_length
    ok = (tangent <= 0.5 * Lin) & (tangent <= 0.5 * L[..., 1:]) & (turn < np.pi * (1 - 1e-9))
    return np.all(ok, axis=-1)


def _legs_speed_power(problem: USVProblem, P0, P1, t_env, n_sub: int | None = None):
    """Per-piece (ds, us, P) of legs P0->P1 (..., 2) cut into n_sub pieces (default problem.n_sub); fields at t_env."""
    n = max(int(problem.n_sub if n_sub is None else n_sub), 1)
    d = P1 - P0
    L = np.hypot(d[..., 0], d[..., 1])
    e = d / np.where(L > 0, L, 1.0)[..., None]
    frac = (np.arange(n) + 0.5) / n
    mids = P0[..., None, :] + frac[:, None] * d[..., None, :]  # (..., n, 2)
    c = problem.current.velocity(t_env, mids)
    wv = problem.wind.velocity(t_env, mids)
    ee = e[..., None, :]
    c_al = np.sum(c * ee, axis=-1)
    c_cr = c[..., 1] * ee[..., 0] - c[..., 0] * ee[..., 1]
    a_ag = -np.sum(wv * ee, axis=-1)
    if problem.kinematics == "paper":
        us, P, w = problem.vessel.leg(c_al, a_ag)
    else:  # crab: the through-water velocity has a cross-leg part cancelling the cross current
        us0, P, w = problem.vessel.leg(np.zeros_like(c_al), a_ag + c_al)
        with np.errstate(invalid="ignore"):
            us = c_al + np.sqrt(w**2 - c_cr**2)
        us = np.where(np.abs(c_cr) < w, us, np.nan)
    ds = np.broadcast_to((L / n)[..., None], us.shape)
    return ds, us, P


def _energy_time(problem, P0, P1, t_env):
    """Energy [J] and time [s] of legs P0->P1 (..., 2) with the fields frozen at t_env; inf if not sailable."""
    ds, us, P = _legs_speed_power(problem, P0, P1, t_env)
    bad = ~(us > 1e-9)
    with np.errstate(divide="ignore", invalid="ignore"):
        dt = np.where(bad, np.inf, ds / np.where(bad, 1.0, us))
        E = np.where(bad, np.inf, P * dt)
    return np.sum(E, axis=-1), np.sum(dt, axis=-1)


class PathCost:
    """Vectorised cost of a swarm of particles (DOPSO length or EOPSO/OCPSO energy).

    The evaluated path is ``prefix`` points, then the waypoints of the free
    dimension circles ``dims`` at the particle's angles, then the goal.

    Parameters
    ----------
    problem : USVProblem
    objective : {"distance", "energy"}
    prefix : (k, 2), optional
        Fixed leading points (default: the start).  The cost counts the legs
        from ``prefix[0]`` on.
    dims : sequence of int, optional
        Indices of the free dimension circles (default: all).
    t_env : float
        Time [s] at which the fields are frozen.
    incoming_length : float, optional
        Length of the full leg the boat is on at ``prefix[0]`` (for the
        turning check at ``prefix[1]``).
    """

    def __init__(self, problem: USVProblem, objective: str = "energy", *, prefix=None, dims=None,
                 t_env: float = 0.0, incoming_length: float | None = None):
        if objective not in ("distance", "energy"):
            raise ValueError(f"objective must be 'distance' or 'energy', got {objective!r}")
        self.problem = problem
        self.objective = objective
        self.prefix = problem.start[None] if prefix is None else np.asarray(prefix, dtype=float).reshape(-1, 2)
        self.dims = np.arange(problem.n_dims) if dims is None else np.asarray(dims, dtype=int)
        self.t_env = float(t_env)
        self.incoming_length = incoming_length
        self.nfev = 0

    @property
    def n_free(self) -> int:
        return int(self.dims.size)

    def points(self, rho) -> np.ndarray:
        rho = np.asarray(rho, dtype=float)
        lead = rho.shape[:-1]
        wp = self.problem.waypoints(rho, self.dims) if self.n_free else np.zeros(lead + (0, 2))
        pre = np.broadcast_to(self.prefix, lead + self.prefix.shape)
        G = np.broadcast_to(self.problem.goal, lead + (1, 2))
        return np.concatenate([pre, wp, G], axis=-2)

    def feasible(self, rho) -> np.ndarray:
        """Boolean (B,): forbidden-angle (obstacle) and turning-radius constraints hold."""
        pts = self.points(rho)
        pr = self.problem
        clear = np.all(_segments_clear(pts[..., :-1, :], pts[..., 1:, :], pr.centers, pr.obstacle_radii), axis=-1)
        return clear & _turns_ok(pts, pr.r_min, self.incoming_length)

    def evaluate(self, rho):
        """``(cost, feasible, length, energy, time)`` arrays of shape (B,)."""
        rho = np.atleast_2d(np.asarray(rho, dtype=float))
        pts = self.points(rho)
        self.nfev += rho.shape[0]
        ok = self.feasible(rho)
        d = np.diff(pts, axis=-2)
        length = np.sum(np.hypot(d[..., 0], d[..., 1]), axis=-1)
        if self.objective == "distance":
            return np.where(ok, length, np.inf), ok, length, None, None
        E, T = _energy_time(self.problem, pts[..., :-1, :], pts[..., 1:, :], self.t_env)
        E, T = np.sum(E, axis=-1), np.sum(T, axis=-1)
        return np.where(ok, E, np.inf), ok & np.isfinite(E), length, E, T

    def __call__(self, rho) -> np.ndarray:
        return self.evaluate(rho)[0]


# ---------------------------------------------------------------- optimiser
@dataclass
class PSOResult(ResultMixin):
    """Result of :func:`pso` (fields as scipy's ``OptimizeResult``)."""

    x: np.ndarray
    fun: float
    nit: int
    nfev: int
    success: bool
    status: int
    message: str
    history: np.ndarray

    def summary(self) -> pd.DataFrame:
        """Best objective, iterations, evaluations and the best position (``x[i]``), one row each."""
        rows = {"fun": float(self.fun), "nit": int(self.nit), "nfev": int(self.nfev)}
        rows.update({f"x[{i}]": float(v) for i, v in enumerate(np.ravel(self.x))})
        return pd.DataFrame({"value": pd.Series(rows, dtype=float)}).rename_axis("quantity")

    def to_pandas(self) -> pd.DataFrame:
        """Best objective after each iteration (column ``best``, index ``iteration``)."""
        return pd.DataFrame({"best": np.asarray(self.history, dtype=float)}, index=pd.RangeIndex(len(self.history), name="iteration"))

    def plot(self, ax=None):
        """Best objective against iteration; returns the axes."""
        import matplotlib.pyplot as plt  # only when plotting: pyplot takes ~1 s to import

        ax = ax or plt.subplots(figsize=(5, 3))[1]
        ax.plot(np.arange(len(self.history)), self.history)
        ax.set_xlabel("iteration")
        ax.set_ylabel("best objective")
        return ax


def pso(cost: Callable[[np.ndarray], np.ndarray], lb, ub, *, n_particles: int = 40, max_iter: int = 150,
        n_swarms: int = 1, inertia: tuple[float, float] = (0.7298, 0.4), c1: float = 1.5, c2: float = 1.5,
        vmax: float = 0.2, rng: np.random.Generator | int | None = None, init: np.ndarray | None = None,
        feasible: Callable[[np.ndarray], np.ndarray] | None = None, f_tol: float = 0.0, patience: int = 0,
        max_init_tries: int = 200, callback: Callable[[int, float], None] | None = None) -> PSOResult:
    """Global-best particle swarm minimisation of a vectorised ``cost(X (B, D)) -> (B,)``.

    ``n_swarms`` independent swarms (each with its own global best and,
    optionally, its own box) are advanced together in one vectorised cost
    call per iteration; the best of them is returned.  The planners give each
    swarm one left/right class of passing the obstacles: the feasible set is
    split into such disconnected pieces, and a single swarm collapses onto
    the first piece it finds (often not the best one).

    Parameters
    ----------
    cost : callable
        Vectorised objective; ``inf`` marks infeasible particles.
    lb, ub : (D,) or (n_swarms, D) arrays
        Box bounds (one per swarm if 2-D); positions are clipped and the
        clipped velocity components zeroed.
    n_particles, max_iter : int
        Particles per swarm and iterations.
    n_swarms : int
        Independent swarms.
    inertia : (float, float)
        Inertia weight at the first and last iteration (linear schedule).
    c1, c2 : float
        Cognitive and social acceleration.
    vmax : float
        Velocity clamp as a fraction of ``ub - lb``.
    rng : Generator or seed
        Source of randomness (results are reproducible for a given seed).
    init : (k, D), optional
        Particles to start with (particle ``j`` belongs to swarm ``j // n_particles``;
        the rest are random).
    feasible : callable, optional
        ``feasible(X) -> bool (B,)``; random initial particles are re-drawn
        until feasible (up to ``max_init_tries`` rounds), as the paper's
        infinite cost gives infeasible particles no information.
    f_tol, patience : float, int
        Stop when the best cost improved by less than ``f_tol`` (relative)
        over ``patience`` iterations (``patience=0``: run ``max_iter``).
    callback : callable, optional
        ``callback(iteration, best_cost)`` after every iteration (progress display; its return value is ignored).
    """
    rng = np.random.default_rng(rng)
    S, Pn = int(n_swarms), int(n_particles)
    N = S * Pn
    swarm = np.repeat(np.arange(S), Pn)
    lb, ub = np.asarray(lb, dtype=float), np.asarray(ub, dtype=float)
    D = lb.shape[-1]
    if lb.ndim == 2:  # one box per swarm
        lb, ub = lb[swarm], ub[swarm]
    else:
        lb, ub = np.broadcast_to(lb, (N, D)), np.broadcast_to(ub, (N, D))
    span = ub - lb
    X = lb + rng.random((N, D)) * span
    k0 = 0
    if init is not None:
        init = np.atleast_2d(np.asarray(init, dtype=float))[:N]
        k0 = init.shape[0]
        X[:k0] = np.clip(init, lb, ub)
    if feasible is not None:
        for _ in range(max_init_tries):
            bad = ~feasible(X)
            bad[:k0] = False
            if not bad.any():
                break
            X[bad] = lb[bad] + rng.random((int(bad.sum()), D)) * span[bad]
    V = (rng.random((N, D)) * 2 - 1) * vmax * span
    f = np.asarray(cost(X), dtype=float)
    nfev = N
    pbest, pf = X.copy(), f.copy()

    def bests():
        pfs = pf.reshape(S, Pn)
        g = np.argmin(pfs, axis=1) + np.arange(S) * Pn
        return pbest[g], pf[g]

    gbest, gf = bests()
    hist = [float(np.min(gf))]
    status, msg = 1, "maximum number of iterations reached"
    it = 0
    for it in range(1, max_iter + 1):
        w = inertia[0] + (inertia[1] - inertia[0]) * (it - 1) / max(max_iter - 1, 1)
        r1, r2 = rng.random((N, D)), rng.random((N, D))
        V = w * V + c1 * r1 * (pbest - X) + c2 * r2 * (gbest[swarm] - X)
        V = np.clip(V, -vmax * span, vmax * span)
        Xn = np.clip(X + V, lb, ub)
        V = np.where((Xn == lb) | (Xn == ub), 0.0, V)
        X = Xn
        f = np.asarray(cost(X), dtype=float)
        nfev += N
        better = f < pf
        pbest[better], pf[better] = X[better], f[better]
        gbest, gf = bests()
        if callback is not None:
            callback(it, float(np.min(gf)))
        hist.append(float(np.min(gf)))
        if patience and it > patience and np.isfinite(hist[-1]):
            old = hist[-1 - patience]
            if np.isfinite(old) and old - hist[-1] <= f_tol * abs(hist[-1]):
                status, msg = 0, f"best cost changed by <= {f_tol:g} (relative) over {patience} iterations"
                break
    k = int(np.argmin(gf))
    success = bool(np.isfinite(gf[k]))
    if not success:
        status, msg = 2, "no feasible particle found"
    return PSOResult(gbest[k].copy(), float(gf[k]), it, nfev, success, status, msg, np.array(hist))


# ------------------------------------------------------------------ plans
@dataclass
class PlanResult(ResultMixin):
    """A planned path.

    Attributes
    ----------
    rho : (m,) polar angles of the waypoints [rad]
    points : (m + 2, 2) path S, waypoints, G [m]
    length : float [m]
    energy : float [J] predicted with the fields frozen at ``t_env``
    time : float [s] predicted voyage time
    objective : str
    opt : PSOResult
    """

    rho: np.ndarray
    points: np.ndarray
    length: float
    energy: float
    time: float
    objective: str
    opt: PSOResult

    @property
    def success(self) -> bool:
        return bool(self.opt.success and np.isfinite(self.length))

    @property
    def status(self) -> int:
        return int(self.opt.status)

    @property
    def message(self) -> str:
        return self.opt.message

    def plot(self, ax=None, **kw):
        """Plot the path (north against east); returns the axes."""
        import matplotlib.pyplot as plt  # only when plotting: pyplot takes ~1 s to import

        ax = ax or plt.gca()
        ax.plot(self.points[:, 0], self.points[:, 1], "-s", label=kw.pop("label", self.objective), **kw)
        ax.set_aspect("equal")
        return ax

    def summary(self) -> pd.DataFrame:
        """Length [m], predicted energy [J] and voyage time [s], waypoints, optimiser iterations."""
        rows = {"length_m": self.length, "energy_J": self.energy, "time_s": self.time,
                "waypoints": float(len(self.rho)), "nit": float(self.opt.nit), "nfev": float(self.opt.nfev)}
        return pd.DataFrame({"value": pd.Series(rows, dtype=float)}).rename_axis("quantity")

    def _html_title(self) -> str:
        return f"Planned path ({self.objective})"

    def to_pandas(self, origin=None) -> pd.DataFrame:
        """The path's points ``x, y`` [m] (east, north); with ``origin=(lon, lat)`` also ``lon, lat``."""
        df = pd.DataFrame({"x": self.points[:, 0], "y": self.points[:, 1]})
        if origin is not None:
            ll = local_to_lonlat(self.points, *origin)
            df["lon"], df["lat"] = ll[:, 0], ll[:, 1]
        return df


def side_classes(problem: USVProblem, dims=None) -> list[tuple[int, ...]]:
    """All left/right combinations (+1: polar angle above the obstacle centre's, -1: below) of ``dims``."""
    k = problem.n_dims if dims is None else len(dims)
    return list(itertools.product((-1, 1), repeat=k))


def class_bounds(problem: USVProblem, signs, dims=None):
    """Box ``(lb, ub)`` of polar angles passing each defining obstacle on the side ``signs``."""
    dims = np.arange(problem.n_dims) if dims is None else np.asarray(dims, dtype=int)
    c = problem.dim_center_angles[dims]
    b = problem.angle_bound
    signs = np.asarray(signs)
    lb = np.where(signs > 0, np.clip(c, -b, b), -b)
    ub = np.where(signs > 0, b, np.clip(c, -b, b))
    return lb, ub


def stratified_init(problem: USVProblem, cost: "PathCost", n_particles: int, rng, tries: int = 50):
    """Feasible initial particles, ``n_particles`` per left/right class that has any.

    Returns ``(X (S * n_particles, k), lb (S, k), ub (S, k))`` for the ``S``
    classes with a feasible sample after ``tries`` rounds, or ``None``.
    """
    blocks, lbs, ubs = [], [], []
    for signs in side_classes(problem, cost.dims):
        lb, ub = class_bounds(problem, signs, cost.dims)
        good = np.zeros((0, lb.size))
        for _ in range(tries):
            X = lb + rng.random((4 * n_particles, lb.size)) * (ub - lb)
            good = np.vstack([good, X[cost.feasible(X)]])
            if good.shape[0] >= n_particles:
                break
        if good.shape[0] == 0:
            continue
        if good.shape[0] < n_particles:  # a narrow class: repeat its samples
            good = good[rng.integers(0, good.shape[0], n_particles)]
        blocks.append(good[:n_particles])
        lbs.append(lb)
        ubs.append(ub)
    if not blocks:
        return None
    return np.vstack(blocks), np.array(lbs), np.array(ubs)


def plan(problem: USVProblem, objective: str = "energy", *, rng=None, t_env: float = 0.0, n_particles: int = 25,
         max_iter: int = 120, patience: int = 0, f_tol: float = 0.0, stratify: bool = True,
         callback=None) -> PlanResult:
    """Plan with the fields frozen at ``t_env``: DOPSO (``objective="distance"``) or EOPSO (``"energy"``).

    With ``stratify`` (default) one swarm of ``n_particles`` searches each
    left/right class of passing the obstacles (``2^m`` swarms for ``m``
    dimension circles, fewer when a class is infeasible), each in its own
    box; otherwise one swarm searches the whole box from a uniform random
    start, as in the paper.  ``callback(iteration, best_cost)`` is passed to :func:`pso`.
    """
    rng = np.random.default_rng(rng)
    cost = PathCost(problem, objective, t_env=t_env)
    res = _run_pso(problem, cost, rng, n_particles, max_iter, stratify, patience=patience, f_tol=f_tol,
                   callback=callback)
    return _plan_result(problem, cost, res, objective, t_env)


def _run_pso(problem, cost, rng, n_particles, max_iter, stratify, *, start=None, patience=0, f_tol=0.0,
             callback=None):
    strat = stratified_init(problem, cost, n_particles, rng) if stratify else None
    if strat is None:
        lb = np.full(cost.n_free, -problem.angle_bound)
        ub = -lb
        init, n_sw = (None if start is None else start[None]), 1
    else:
        init, lb, ub = strat
        n_sw = lb.shape[0]
    res = pso(cost, lb, ub, rng=rng, n_particles=n_particles, n_swarms=n_sw, max_iter=max_iter, init=init,
              feasible=cost.feasible, patience=patience, f_tol=f_tol, callback=callback)
    if start is not None:  # never return something worse than the incumbent
        f0 = float(cost(start[None])[0])
        if f0 <= res.fun:
            res.x, res.fun = start.copy(), f0
    return res


def _plan_result(problem, cost, res, objective, t_env):
    ev_cost = PathCost(problem, "energy", t_env=t_env)
    _, ok, L, E, T = ev_cost.evaluate(res.x[None])
    return PlanResult(res.x.copy(), problem.path(res.x), float(L[0]), float(E[0]) if ok[0] else np.inf,
                      float(T[0]) if ok[0] else np.inf, objective, res)


def plan_dopso(problem: USVProblem, **kw) -> PlanResult:
    """Distance-optimal plan (DOPSO)."""
    return plan(problem, "distance", **kw)


def plan_eopso(problem: USVProblem, **kw) -> PlanResult:
    """Energy-optimal plan in the environment frozen at ``t_env`` (EOPSO)."""
    return plan(problem, "energy", **kw)


def differential_evolution_check(problem: USVProblem, objective: str = "energy", *, seed: int = 0,
                                 t_env: float = 0.0, popsize: int = 30, maxiter: int = 300, tol: float = 1e-10,
                                 signs=None):
    """The same cost minimised by :func:`scipy.optimize.differential_evolution` (an independent oracle).

    Infeasible particles get a finite penalty (1e30) because DE needs finite
    values; no gradient polish.  ``signs`` restricts the search to one
    left/right class (:func:`class_bounds`).  Returns scipy's ``OptimizeResult``.
    """
    cost = PathCost(problem, objective, t_env=t_env)

    def f(X):  # DE vectorised: X has shape (D, S)
        c = cost(np.asarray(X).T)
        return np.where(np.isfinite(c), c, 1e30)

    if signs is None:
        b = [(-problem.angle_bound, problem.angle_bound)] * problem.n_dims
    else:
        b = list(zip(*class_bounds(problem, signs)))
    return differential_evolution(f, b, seed=seed, popsize=popsize, maxiter=maxiter, tol=tol, atol=0,
                                  vectorized=True, updating="deferred", polish=False)


# ----------------------------------------------------------------- voyage
@dataclass
class Voyage(ResultMixin):
    """Sailing a polyline through time-varying fields.

    Attributes
    ----------
    t, xy, energy : arrays (n,), (n, 2), (n,)
        Time [s], position [m] and energy spent [J] at each record
        (vertices, field breakpoints and sub-piece ends).
    leg : array (n,) int
        Index of the leg being sailed (towards ``points[leg + 1]``).
    arrived : bool
    points : (k, 2) the polyline
    """

    t: np.ndarray
    xy: np.ndarray
    energy: np.ndarray
    leg: np.ndarray
    arrived: bool
    points: np.ndarray
    message: str = ""

    @property
    def total_energy(self) -> float:
        return float(self.energy[-1])

    @property
    def duration(self) -> float:
        return float(self.t[-1] - self.t[0])

    @property
    def success(self) -> bool:
        return bool(self.arrived)

    def to_pandas(self) -> pd.DataFrame:
        """The records: ``t`` [s], ``x, y`` [m], ``energy_J`` and ``leg``."""
        return pd.DataFrame({"t": self.t, "x": self.xy[:, 0], "y": self.xy[:, 1], "energy_J": self.energy,
                             "leg": self.leg})

    def summary(self) -> pd.DataFrame:
        """Whether it arrived, duration [s], energy [J], legs sailed."""
        rows = {"arrived": bool(self.arrived), "duration_s": self.duration, "energy_J": self.total_energy,
                "legs": int(self.leg.max()) + 1 if len(self.leg) else 0}
        return pd.DataFrame({"value": pd.Series(rows, dtype=object)}).rename_axis("quantity")

    def plot(self, ax=None, **kw):
        """Energy spent [J] against time [s]; returns the axes."""
        import matplotlib.pyplot as plt  # only when plotting: pyplot takes ~1 s to import

        ax = ax or plt.gca()
        ax.plot(self.t, self.energy, **kw)
        ax.set_xlabel("t [s]")
        ax.set_ylabel("energy [J]")
        return ax


def sail(problem: USVProblem, points, *, t0: float = 0.0, e0: float = 0.0, stop_time: float | None = None) -> Voyage:
    """Sail ``points (k, 2)`` with the problem's vessel through its (time-varying) fields.

    Each leg is cut into ``problem.n_sub`` pieces; on each piece the speed
    and power are those at its mid-point at the current time, and pieces are
    split at the fields' breakpoints, so piecewise-constant-in-time uniform
    fields are sailed exactly.  Stops at the goal or at ``stop_time``.
    """
    pts = np.asarray(points, dtype=float)
    bps = sorted(set(problem.current.breakpoints) | set(problem.wind.breakpoints))
    t, E = float(t0), float(e0)
    T, XY, EN, LEG = [t], [pts[0].copy()], [E], [0]
    n = max(int(problem.n_sub), 1)
    for i in range(pts.shape[0] - 1):
        A, B = pts[i], pts[i + 1]
        for j in range(n):
            a = A + (B - A) * j / n
            b = A + (B - A) * (j + 1) / n
            pos = a.copy()
            while True:
                rem = np.hypot(*(b - pos))
                if rem <= 1e-12:
                    break
                ds, us, P = _legs_speed_power(problem, a, b, t, n_sub=1)  # the piece's mid-point
                us, P = float(us[0]), float(P[0])
                if not us > 1e-9:
                    return Voyage(np.array(T), np.array(XY), np.array(EN), np.array(LEG), False, pts,
                                  f"leg {i} cannot be sailed at t = {t:.1f} s (speed over ground {us:.3g} m/s)")
                dt = rem / us
                nxt = [bp for bp in bps if t + 1e-9 < bp < t + dt]
                limit = min(nxt + ([stop_time] if stop_time is not None and stop_time < t + dt else []), default=None)
                if limit is not None:
                    h = limit - t
                    pos = pos + (b - pos) * (h * us / rem)
                    t, E = limit, E + P * h
                    T.append(t), XY.append(pos.copy()), EN.append(E), LEG.append(i)
                    if stop_time is not None and t >= stop_time - 1e-12:
                        return Voyage(np.array(T), np.array(XY), np.array(EN), np.array(LEG), False, pts, "stopped")
                    continue
                t, E, pos = t + dt, E + P * dt, b.copy()
                T.append(t), XY.append(pos.copy()), EN.append(E), LEG.append(i)
                break
    return Voyage(np.array(T), np.array(XY), np.array(EN), np.array(LEG), True, pts, "arrived")


# ------------------------------------------------------------------ OCPSO
@dataclass
class OCPSOResult(ResultMixin):
    """Online replanning result.

    Attributes
    ----------
    points : (m + 2, 2) the path finally sailed
    voyage : Voyage of that path through the time-varying fields
    initial : PlanResult (EOPSO at t = 0)
    events : list of dict
        One per replanning time: time, position, target waypoint, energy
        spent so far, predicted total of the old and the new plan, whether
        the plan changed.
    """

    points: np.ndarray
    voyage: Voyage
    initial: PlanResult
    events: list

    @property
    def energy(self) -> float:
        return self.voyage.total_energy

    @property
    def success(self) -> bool:
        return bool(self.voyage.arrived and self.initial.success)

    @property
    def message(self) -> str:
        n = sum(e["replanned"] for e in self.events)
        return f"{self.voyage.message}; {len(self.events)} replanning event(s), {n} changed the plan"

    @property
    def length(self) -> float:
        d = np.diff(self.points, axis=0)
        return float(np.sum(np.hypot(d[:, 0], d[:, 1])))

    def summary(self) -> pd.DataFrame:
        """Energy spent [J] and voyage time [s] of the sailed path against the initial plan's prediction,
        path length [m], replanning events and how many changed the plan."""
        rows = {"energy_J": self.energy, "initial_plan_energy_J": self.initial.energy, "duration_s": self.voyage.duration,
                "length_m": self.length, "replanning_events": float(len(self.events)),
                "plans_changed": float(sum(bool(e["replanned"]) for e in self.events))}
        return pd.DataFrame({"value": pd.Series(rows, dtype=float)}).rename_axis("quantity")

    def _html_title(self) -> str:
        return "Online replanned path (OCPSO)"

    def to_pandas(self) -> pd.DataFrame:
        """The replanning events, one row each (time, position, target waypoint, energies, replanned)."""
        return pd.DataFrame(self.events)

    def plot(self, ax=None, **kw):
        """The initial plan (dotted) and the path sailed (north against east); returns the axes."""
        import matplotlib.pyplot as plt  # only when plotting: pyplot takes ~1 s to import

        ax = ax or plt.gca()
        ax.plot(self.initial.points[:, 0], self.initial.points[:, 1], ":", color="0.5", label="initial plan")
        ax.plot(self.points[:, 0], self.points[:, 1], "-s", label=kw.pop("label", "sailed"), **kw)
        ax.set_aspect("equal")
        return ax


def plan_ocpso(problem: USVProblem, *, replan_times: Sequence[float] | None = None, rng=None,
               n_particles: int = 25, max_iter: int = 120, stratify: bool = True, callback=None) -> OCPSOResult:
    """OCPSO: EOPSO at the start, then replanning whenever the measured environment changes.

    At each replanning time the boat's position, its target waypoint ``P_i``
    and the energy spent so far are taken from :func:`sail`; the waypoints up
    to ``P_i`` are kept (the paper's step 4) and EOPSO re-optimises the later
    ones with the fields frozen at that time.  The new plan is adopted when
    its predicted remaining energy is lower than the old plan's under the new
    fields.  Replanning is taken as instantaneous (the paper's check that the
    target waypoint is unchanged after the computation is then always true).

    Parameters
    ----------
    replan_times : sequence of float, optional
        Times [s] at which the environment is re-measured; default the
        breakpoints of the current and wind fields.
    callback : callable, optional
        ``callback(iteration, best_cost)``, passed to every :func:`pso` run (the first plan and each replanning).
    """
    rng = np.random.default_rng(rng)
    if replan_times is None:
        replan_times = sorted(set(problem.current.breakpoints) | set(problem.wind.breakpoints))
    first = plan(problem, "energy", rng=rng, t_env=0.0, n_particles=n_particles, max_iter=max_iter,
                 stratify=stratify, callback=callback)
    rho = first.rho.copy()
    events = []
    for te in replan_times:
        pts = problem.path(rho)
        v = sail(problem, pts, stop_time=te)
        if v.arrived:
            break
        Q, leg, spent = v.xy[-1], int(v.leg[-1]), float(v.energy[-1])
        target = leg + 1  # index in points of the waypoint being sailed to
        kept_dims = target  # waypoints 1..target are kept (dims 0..target-1)
        free = np.arange(kept_dims, problem.n_dims)
        prefix = np.vstack([Q, pts[target:target + 1]]) if target <= problem.n_dims else Q[None]
        inc = float(np.hypot(*(pts[target] - pts[target - 1]))) if target <= problem.n_dims else None
        cost = PathCost(problem, "energy", prefix=prefix, dims=free, t_env=te, incoming_length=inc)
        old_rem = float(cost(rho[free][None])[0]) if free.size else float(cost(np.zeros((1, 0)))[0])
        ev = {"time": float(te), "x": float(Q[0]), "y": float(Q[1]), "target_waypoint": int(target),
              "energy_spent_J": spent, "old_predicted_total_J": spent + old_rem, "replanned": False}
        if free.size:
            res = _run_pso(problem, cost, rng, n_particles, max_iter, stratify, start=rho[free], callback=callback)
            ev["new_predicted_total_J"] = spent + float(res.fun)
            if res.fun < old_rem * (1 - 1e-9):
                rho = rho.copy()
                rho[free] = res.x
                ev["replanned"] = True
        else:
            ev["new_predicted_total_J"] = spent + old_rem
        events.append(ev)
    final = problem.path(rho)
    return OCPSOResult(final, sail(problem, final), first, events)


def forbidden_arcs(problem: USVProblem, prev_point, dim: int, n: int = 3601) -> list[tuple[float, float]]:
    """Forbidden polar-angle intervals [rad] on dimension circle ``dim`` given the previous waypoint.

    An angle is forbidden when the waypoint there lies in an obstacle or the
    leg from ``prev_point`` to it crosses one (the paper's arcs T1 and T2).
    Computed on an ``n``-point grid over ``[-pi, pi)`` with the ends refined
    by bisection to 1e-10 rad.
    """
    prev = np.asarray(prev_point, dtype=float).reshape(2)
    r = problem.radii[dim]

    def bad(th):
        th = np.asarray(th, dtype=float)
        P = problem.start + r * np.stack([np.cos(problem.axis_angle + th), np.sin(problem.axis_angle + th)], -1)
        return ~_segments_clear(np.broadcast_to(prev, P.shape), P, problem.centers, problem.obstacle_radii)

    th = np.linspace(-np.pi, np.pi, n, endpoint=False)
    b = bad(th)
    if b.all():
        return [(-np.pi, np.pi)]
    if not b.any():
        return []

    def edge(lo, hi):  # bad(lo) != bad(hi)
        blo = bad(lo)
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            if bad(mid) == blo:
                lo = mid
            else:
                hi = mid
        return 0.5 * (lo + hi)

    k0 = int(np.argmin(b))  # start from an allowed angle
    order = (np.arange(n) + k0) % n
    arcs, start = [], None
    for a, c in zip(order, np.roll(order, -1)):
        lo, hi = th[a], th[c] + (2 * np.pi if c < a else 0)
        if not b[a] and b[c]:
            start = edge(lo, hi)
        elif b[a] and not b[c]:
            end = edge(lo, hi)
            arcs.append((float(np.angle(np.exp(1j * start))), float(np.angle(np.exp(1j * end)))))
    return arcs


# ------------------------------------------------------------ the paper case
#: Li et al.'s start and goal (lon, lat) [deg] near Zhanjiang.
PAPER_START_LONLAT = (110.421910, 21.263390)
PAPER_GOAL_LONLAT = (110.422070, 21.260650)


def paper_scenario(*, time_scale: float = 0.1, kinematics: str = "paper",
                   current_courses_deg: tuple[float, float, float] = (90.0, 0.0, 270.0)) -> USVProblem:
    """The Li et al. scenario with our stated obstacles and current directions.

    Start/goal are the paper's (305 m apart, goal almost due south).  Wind
    from the east at 7 m/s; current 1.2 m/s.  The obstacle positions and the
    current directions are given only in the paper's figures, so we state ours
    (module-level, in the local frame with the start at the origin):

    * obstacles as (distance along the start-goal axis, offset to the left of
      the direction of travel -- i.e. east, since the route runs south --,
      radius): (80 m, +12 m, 22 m), (160 m, -15 m, 25 m), (235 m, +10 m, 20 m);
    * current flowing towards the nautical directions ``current_courses_deg``
      (default east, then north -- against the route --, then west: a current
      rotating anticlockwise in 90 deg steps; the outcome depends strongly
      on this unknown choice, so ``docs/routing.md`` reports all 64
      combinations of N/E/S/W),
      turning at minutes 8 and 32 **times** ``time_scale``.

    Why ``time_scale``: with the paper's own thrust/drag curves the USV makes
    1.78 m/s through the water, so the 305 m voyage lasts about 3-6 min and
    would end before minute 8; the default 0.1 keeps the ratio of the two
    event times and puts them (48 s, 192 s) inside the voyage.
    """
    lon0, lat0 = PAPER_START_LONLAT
    S = np.zeros(2)
    G = lonlat_to_local(*PAPER_GOAL_LONLAT, lon0, lat0)
    e = G / np.hypot(*G)
    left = np.array([-e[1], e[0]])
    obstacles = [Obstacle(*(S + a * e + c * left), r) for a, c, r in
                 ((80.0, 12.0, 22.0), (160.0, -15.0, 25.0), (235.0, 10.0, 20.0))]
    currents = [UniformField.from_speed_direction(1.2, np.radians(c), convention="towards") for c in current_courses_deg]
    current = PiecewiseTimeField([0.0, 8 * 60 * time_scale, 32 * 60 * time_scale], currents)
    wind = UniformField.from_speed_direction(7.0, np.radians(90.0), convention="from")
    return USVProblem(S, G, obstacles, current=current, wind=wind, kinematics=kinematics,
                      origin=(lon0, lat0))


def compare_planners(problem: USVProblem, *, rng=0, n_particles: int = 25, max_iter: int = 120,
                     replan_times: Sequence[float] | None = None, progress: bool = False) -> dict:
    """DOPSO (sailed through the time-varying fields), EOPSO at t = 0 and OCPSO; the paper's comparison.

    ``replan_times`` [s] are passed to :func:`plan_ocpso` (default: the fields' breakpoints).
    ``progress`` shows a bar (tqdm, on stderr) over the PSO iterations of the three planners; its total
    counts one run per replanning time, of which OCPSO may skip some (the boat already arrived).
    Returns a dict with the three paths, their voyages and
    ``saving_vs_distance_optimal = 1 - W_OCPSO / W_DOPSO`` (both sailed).
    """
    check_pso_size(int(n_particles), int(max_iter), len(problem.obstacles), "compare_planners")
    rng = np.random.default_rng(rng)
    bar, callback = None, None
    if progress:
        n_replan = len(replan_times if replan_times is not None else
                       set(problem.current.breakpoints) | set(problem.wind.breakpoints))
        bar = tqdm(total=int(max_iter) * (3 + n_replan), desc="route (PSO iterations)", leave=False)

        def callback(it, best):
            bar.update(1)
    try:
        do = plan_dopso(problem, rng=rng, n_particles=n_particles, max_iter=max_iter, callback=callback)
        eo = plan_eopso(problem, rng=rng, n_particles=n_particles, max_iter=max_iter, callback=callback)
        oc = plan_ocpso(problem, rng=rng, n_particles=n_particles, max_iter=max_iter, replan_times=replan_times,
                        callback=callback)
    finally:
        if bar is not None:
            bar.close()
    vd, ve = sail(problem, do.points), sail(problem, eo.points)
    ok = vd.arrived and oc.voyage.arrived
    return {"dopso": do, "eopso": eo, "ocpso": oc, "dopso_voyage": vd, "eopso_voyage": ve,
            "saving_vs_distance_optimal": (1.0 - oc.energy / vd.total_energy) if ok else float("nan"),
            "success": bool(ok and do.success and oc.initial.success)}


def check_pso_size(n_particles: int, max_iter: int, n_obstacles: int, where: str = "PSO") -> None:
    """Refuse a PSO run whose estimated memory exceeds :func:`shipid._io.memory_limit_bytes`.

    One swarm per left/right class (``2**k`` for ``k`` obstacles, at most 64 counted), each of
    ``n_particles`` particles with ``k`` waypoints; a cost evaluation holds about 64 doubles per
    particle and leg, and the initialisation draws ``4 n_particles`` candidates per class.
    """
    k = max(int(n_obstacles), 1)
    swarms = 2 ** min(k, 6)
    need = 8.0 * swarms * 4 * n_particles * (k + 1) * 64
    check_memory(need, f"{where}: n_particles {n_particles}", "use fewer n_particles (25 is the default)")
    if n_particles * max_iter > 10**9:
        raise ValueError(f"{where}: n_particles x max_iter = {n_particles * max_iter:.3g} evaluations would run "
                         "for days; use n_particles <= 1000 and max_iter <= 10000")
