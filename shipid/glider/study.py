"""The paper's launch sweeps as one vectorised batch.

Divsalar et al. section 6-2 varies launch speed (0.5, 0.8, 1, 2, 3, 4, 5 m/s),
launch angle from the vertical (15, 30, 45, 60 deg), fin incidence (0, 5, 10,
15, 20 deg) and CG offset (0, -1, -3, -5 cm): the full factorial is 560
launches, run here as a single batch of :func:`shipid.glider.launch`.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np
import pandas as pd

from ..models.base import Model
from .launch import LaunchResult, launch

__all__ = ["PAPER_SWEEP", "PAPER_REFERENCE", "sweep", "paper_reference_case"]

#: The paper's sweep values: speed [m/s], angle from the vertical [deg], fin [deg], CG offset [m].
PAPER_SWEEP: dict[str, tuple[float, ...]] = {
    "speed": (0.5, 0.8, 1.0, 2.0, 3.0, 4.0, 5.0),
    "angle_deg": (15.0, 30.0, 45.0, 60.0),
    "fin_deg": (0.0, 5.0, 10.0, 15.0, 20.0),
    "cg_m": (0.0, -0.01, -0.03, -0.05),
}

#: The launch the paper reports numbers for (section 6-3-1, figure 13) and its numbers.
PAPER_REFERENCE: dict[str, float] = {
    "speed": 5.0, "angle_deg": 45.0, "fin_deg": 0.0, "cg_m": 0.01,
    "max_depth_m": 1.68, "horizontal_m": 4.73,
}


def sweep(
    speed: Sequence[float] = PAPER_SWEEP["speed"],
    angle_deg: Sequence[float] = PAPER_SWEEP["angle_deg"],
    fin_deg: Sequence[float] = PAPER_SWEEP["fin_deg"],
    cg_m: Sequence[float] = PAPER_SWEEP["cg_m"],
    *,
    model: Model | None = None,
    dt: float | None = None,
    t_max: float = 60.0,
    keep_trajectories: bool = False,
    progress: bool = False,
) -> LaunchResult:
    """Full-factorial launch study, all launches in one vectorised batch.

    Parameters
    ----------
    speed, angle_deg, fin_deg, cg_m : sequences of float
        Levels of each factor (default: the paper's, 7 x 4 x 5 x 4 = 560
        launches).  Units as in :func:`shipid.glider.launch`.
    model, dt, t_max, keep_trajectories, progress
        Passed to :func:`shipid.glider.launch`.

    Returns
    -------
    LaunchResult
        ``launches`` (and ``summary()``) has one row per combination, ordered with ``cg_m``
        varying fastest.
    """
    levels = [np.atleast_1d(np.asarray(v, dtype=float)) for v in (speed, angle_deg, fin_deg, cg_m)]
    for name, lv in zip(("speed", "angle_deg", "fin_deg", "cg_m"), levels):
        if lv.ndim != 1 or lv.size == 0:
            raise ValueError(f"{name} must be a non-empty 1-D sequence of levels, got shape {lv.shape}")
    grids = np.meshgrid(*levels, indexing="ij")
    return launch(*(g.ravel() for g in grids), model=model, dt=dt, t_max=t_max,
                  keep_trajectories=keep_trajectories, progress=progress)


def paper_reference_case(model: Model | None = None, *, cg_m: float = PAPER_REFERENCE["cg_m"]) -> pd.Series:
    """The paper's reported launch (5 m/s, 45 deg, fin 0, CG +0.01 m) next to its numbers.

    Returns
    -------
    pandas.Series
        ``max_depth_m``, ``horizontal_m`` (computed), ``paper_max_depth_m``,
        ``paper_horizontal_m`` and the relative differences ``depth_rel_diff``,
        ``horizontal_rel_diff`` (computed / paper - 1).
    """
    r = launch(PAPER_REFERENCE["speed"], PAPER_REFERENCE["angle_deg"], PAPER_REFERENCE["fin_deg"], cg_m,
               model=model, keep_trajectories=False)
    d, h = r.max_depth_m, r.horizontal_m
    return pd.Series({
        "max_depth_m": d, "horizontal_m": h, "duration_s": r.duration_s, "exit_angle_deg": r.exit_angle_deg,
        "paper_max_depth_m": PAPER_REFERENCE["max_depth_m"], "paper_horizontal_m": PAPER_REFERENCE["horizontal_m"],
        "depth_rel_diff": d / PAPER_REFERENCE["max_depth_m"] - 1.0,
        "horizontal_rel_diff": h / PAPER_REFERENCE["horizontal_m"] - 1.0,
    })
