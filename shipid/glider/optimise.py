"""Choose launch speed, angle, fin incidence and CG offset with differential evolution.

Objective (stated, not fitted to the paper's answer)
----------------------------------------------------
Divsalar et al. picks its launch by a trade-off it describes in words: a higher
launch speed is better for both depth and horizontal travel (section 6-3-1);
the fin angle is chosen because it gives "values close to the maximum of
each" of depth and horizontal travel (section 6-3-3); the angle because it
gives "a suitable ratio of depth and horizontal progress" (6-3-2); a CG near
the centre of buoyancy because it gives the most depth and travel, with a
small offset preferred for a less vertical exit (6-3-4).  The reading used
here is the max-min (Chebyshev) form of "close to the maximum of each"::

    J = min(depth / depth_ref, horizontal / horizontal_ref)      (maximised)

with ``depth_ref`` and ``horizontal_ref`` the largest maximum depth and the
largest horizontal travel found on the paper's grid at the top launch speed,
and a penalty ``10 * (exit_angle - max_exit_angle) / 90`` when the exit
flight-path angle above the horizontal exceeds ``max_exit_angle_deg``.
Launches that do not surface score -1.

Each generation of scipy's differential evolution is evaluated as one
vectorised batch of launches (``vectorized=True``).
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import numpy as np
import pandas as pd
from scipy.optimize import differential_evolution
from tqdm.auto import tqdm

from ..models import get_model
from ..models.base import Model
from ..results import ResultMixin
from .launch import launch
from .study import sweep

__all__ = ["optimise_launch", "launch_objective", "GliderOptimum", "DEFAULT_BOUNDS"]

#: Search box: the paper's ranges (speed [m/s], angle from vertical [deg], fin [deg], CG [m]).
DEFAULT_BOUNDS: dict[str, tuple[float, float]] = {
    "speed": (0.5, 5.0),
    "angle_deg": (15.0, 60.0),
    "fin_deg": (0.0, 20.0),
    "cg_m": (-0.05, 0.0),
}


@dataclass
class GliderOptimum(ResultMixin):
    """Result of :func:`optimise_launch` (fields like scipy's OptimizeResult).

    Attributes
    ----------
    x : dict
        Best ``speed`` [m/s], ``angle_deg``, ``fin_deg``, ``cg_m`` [m].
    objective : float
        ``J`` at the optimum (larger is better).
    launch : pandas.Series
        Summary row of the best launch (depth, horizontal travel, exit angle...).
    depth_ref, horizontal_ref : float
        Normalisers of ``J`` [m].
    grid_best : pandas.Series
        The best launch (under the same ``J``) of the paper's angle x fin x
        CG grid at the top speed, restricted to the bounds.
    success, status, message, nfev, nit
        From :func:`scipy.optimize.differential_evolution`.
    """

    x: dict
    objective: float
    launch: pd.Series
    depth_ref: float
    horizontal_ref: float
    grid_best: pd.Series
    success: bool
    status: int
    message: str
    nfev: int
    nit: int
    settings: dict = field(default_factory=dict)

    def summary(self) -> pd.DataFrame:
        """The optimum's settings, objective, depth and horizontal travel beside the best launch of the grid."""
        keys = ["speed_m_s", "angle_deg", "fin_deg", "cg_m", "max_depth_m", "horizontal_m", "exit_angle_deg", "surfaced"]
        opt = {k: self.launch.get(k, np.nan) for k in keys}
        grid = {k: self.grid_best.get(k, np.nan) for k in keys}
        opt["objective"], grid["objective"] = float(self.objective), self.grid_best.get("objective", np.nan)
        return pd.DataFrame({"optimum": pd.Series(opt, dtype=object), "grid_best": pd.Series(grid, dtype=object)})

    def to_pandas(self) -> pd.DataFrame:
        """The optimum's launch row and the grid's best row side by side (every column of a launch)."""
        return pd.DataFrame({"optimum": self.launch, "grid_best": self.grid_best})

    def _html_title(self) -> str:
        return "Glider launch optimum"

    def _key_numbers(self) -> dict:
        return {"objective J": float(self.objective), "evaluations": int(self.nfev), "iterations": int(self.nit)}

    def plot(self, ax=None):
        """The optimum and the grid's best launch in the (horizontal travel, maximum depth) plane; returns the axes."""
        import matplotlib.pyplot as plt  # only when plotting: pyplot takes ~1 s to import

        if ax is None:
            _, ax = plt.subplots(figsize=(5, 3.5))
        for row, label, mk in ((self.launch, "optimum", "o"), (self.grid_best, "grid best", "s")):
            ax.plot([row.get("horizontal_m", np.nan)], [row.get("max_depth_m", np.nan)], mk, label=label)
        if not ax.yaxis_inverted():
            ax.invert_yaxis()
        ax.set_xlabel("horizontal travel at surfacing [m]")
        ax.set_ylabel("maximum depth [m]")
        ax.legend(loc="best", fontsize="small")
        return ax

    def as_dict(self) -> dict:
        """JSON-ready dict."""
        def clean(s):
            return {k: (bool(v) if isinstance(v, (bool, np.bool_)) else v if isinstance(v, str) else float(v))
                    for k, v in s.items()}
        return {
            "x": {k: float(v) for k, v in self.x.items()},
            "objective": float(self.objective),
            "launch": clean(self.launch),
            "depth_ref_m": float(self.depth_ref), "horizontal_ref_m": float(self.horizontal_ref),
            "grid_best": clean(self.grid_best),
            "success": bool(self.success), "status": int(self.status), "message": self.message,
            "nfev": int(self.nfev), "nit": int(self.nit), "settings": self.settings,
        }


def launch_objective(summary: pd.DataFrame, depth_ref: float, horizontal_ref: float,
                     max_exit_angle_deg: float | None = 75.0) -> np.ndarray:
    """The trade-off ``J`` (larger is better) of each launch in a summary frame.

    Parameters
    ----------
    summary : DataFrame
        :attr:`LaunchResult.launches`.
    depth_ref, horizontal_ref : float
        Normalisers [m] (> 0).
    max_exit_angle_deg : float or None
        Exit flight-path angle above which the penalty applies (None: no penalty).

    Returns
    -------
    ndarray, shape (n_launches,)
    """
    d = summary["max_depth_m"].to_numpy() / depth_ref
    h = summary["horizontal_m"].to_numpy() / horizontal_ref
    J = np.minimum(d, h)
    if max_exit_angle_deg is not None:
        over = np.clip(summary["exit_angle_deg"].to_numpy() - max_exit_angle_deg, 0.0, None)
        J = J - 10.0 * over / 90.0
    ok = summary["surfaced"].to_numpy() & np.isfinite(J)
    return np.where(ok, J, -1.0)


def optimise_launch(
    *,
    model: Model | None = None,
    bounds: dict[str, tuple[float, float]] | None = None,
    max_exit_angle_deg: float | None = 75.0,
    popsize: int = 10,
    maxiter: int = 30,
    seed: int | None = 0,
    tol: float = 1e-3,
    progress: bool = False,
) -> GliderOptimum:
    """Find the launch that maximises the stated trade-off ``J``.

    Parameters
    ----------
    model : Model, optional
        ``glider`` model (default: the paper parameter set).
    bounds : dict, optional
        ``{"speed": (lo, hi), "angle_deg": ..., "fin_deg": ..., "cg_m": ...}``;
        missing keys take :data:`DEFAULT_BOUNDS`.  Equal ``lo == hi`` fixes a
        variable.
    max_exit_angle_deg : float or None
        Exit-angle limit of the penalty [deg].
    popsize, maxiter, seed, tol
        Differential-evolution settings (population ``popsize * n_free``).
    progress : bool
        tqdm bar over generations.

    Returns
    -------
    GliderOptimum
    """
    model = get_model("glider") if model is None else model
    b = dict(DEFAULT_BOUNDS)
    for k, v in (bounds or {}).items():
        if k not in DEFAULT_BOUNDS:
            raise ValueError(f"bounds has unknown variable '{k}'; use {list(DEFAULT_BOUNDS)}")
        lo, hi = (float(v[0]), float(v[1]))
        if not (np.isfinite(lo) and np.isfinite(hi) and lo <= hi):
            raise ValueError(f"bounds['{k}'] = {v!r}: need finite lo <= hi")
        b[k] = (lo, hi)
    if popsize < 2 or maxiter < 1:
        raise ValueError(f"popsize ({popsize}) must be >= 2 and maxiter ({maxiter}) >= 1")
    names = list(DEFAULT_BOUNDS)
    free = [k for k in names if b[k][0] < b[k][1]]
    fixed = {k: b[k][0] for k in names if k not in free}

    # normalisers: best depth and best horizontal travel on the paper's grid at the top speed
    top = b["speed"][1]
    grid = sweep([top], model=model).launches
    depth_ref = float(np.nanmax(grid["max_depth_m"]))
    horizontal_ref = float(np.nanmax(grid["horizontal_m"]))
    if not (depth_ref > 0 and horizontal_ref > 0):
        raise ValueError(f"reference launches at {top:g} m/s give depth {depth_ref:g} m and "
                         f"horizontal travel {horizontal_ref:g} m; the objective needs both > 0")
    full = grid.copy()
    full["J"] = launch_objective(full, depth_ref, horizontal_ref, max_exit_angle_deg)
    inside = np.ones(len(full), bool)
    for k, col in (("angle_deg", "angle_deg"), ("fin_deg", "fin_deg"), ("cg_m", "cg_m")):
        inside &= (full[col] >= b[k][0] - 1e-12) & (full[col] <= b[k][1] + 1e-12)
    full = full[inside] if inside.any() else full
    grid_best = full.loc[full["J"].idxmax()]

    def unpack(X):
        X = np.atleast_2d(X)                       # (n_free, S)
        cols = {k: X[free.index(k)] if k in free else np.full(X.shape[1], fixed[k]) for k in names}
        return cols

    def f(X):
        c = unpack(X)
        r = launch(c["speed"], c["angle_deg"], c["fin_deg"], c["cg_m"], model=model, keep_trajectories=False)
        return -launch_objective(r.launches, depth_ref, horizontal_ref, max_exit_angle_deg)

    bar = cb = None
    if progress:
        bar = tqdm(total=maxiter, desc="glider DE", unit="gen")

        def _tick(intermediate_result):
            bar.update(1)

        cb = _tick

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        if free:
            res = differential_evolution(
                f, [b[k] for k in free], vectorized=True, updating="deferred", popsize=popsize,
                maxiter=maxiter, seed=seed, tol=tol, polish=False, callback=cb,
            )
            xbest = res.x
            success, status, message, nfev, nit = bool(res.success), int(getattr(res, "status", 0)), str(res.message), int(res.nfev), int(res.nit)
        else:
            xbest = np.zeros(0)
            success, status, message, nfev, nit = True, 0, "all variables fixed", 0, 0
    if bar is not None:
        bar.close()
    c = unpack(xbest[:, None] if xbest.size else np.zeros((0, 1)))
    best = {k: float(c[k][0]) for k in names}
    r = launch(best["speed"], best["angle_deg"], best["fin_deg"], best["cg_m"], model=model, keep_trajectories=False)
    row = r.launches.iloc[0].copy()
    J = float(launch_objective(r.launches, depth_ref, horizontal_ref, max_exit_angle_deg)[0])
    row["J"] = J
    return GliderOptimum(
        x=best, objective=J, launch=row, depth_ref=depth_ref, horizontal_ref=horizontal_ref,
        grid_best=grid_best, success=success, status=status, message=message, nfev=nfev, nit=nit,
        settings={"bounds": {k: list(v) for k, v in b.items()}, "max_exit_angle_deg": max_exit_angle_deg,
                  "popsize": popsize, "maxiter": maxiter, "seed": seed, "tol": tol},
    )
