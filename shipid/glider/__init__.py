"""Glider launch study (Divsalar et al.): launch simulation with surface-return
event detection, vectorised parameter sweeps and a metaheuristic optimiser.

The glider's equations live in :mod:`shipid.models.glider`; this package only
drives :func:`shipid.simulate.simulate` with that model.
"""
from __future__ import annotations

from .dive_log import DEFAULT_SENSOR_STD, dive_log
from .launch import LaunchResult, launch, launch_state
from .optimise import GliderOptimum, launch_objective, optimise_launch
from .study import PAPER_SWEEP, paper_reference_case, sweep

__all__ = [
    "launch", "launch_state", "LaunchResult", "sweep", "PAPER_SWEEP", "paper_reference_case",
    "optimise_launch", "launch_objective", "GliderOptimum", "dive_log", "DEFAULT_SENSOR_STD",
]
