"""A model's closed-loop standard manoeuvre matching a measured run (kind, rudder angle, side, switch angle,
approach speed): what validation compares with the run and what the fit recipe's metric refinement scores."""
from __future__ import annotations

import math

import numpy as np

from ..models.base import Model
from .turning import turning_circle
from .zigzag import zigzag

__all__ = ["standard_manoeuvre"]


def standard_manoeuvre(model: Model, measured, *, rudder_rate=None, lpp=None, params=None,
                       heading_change_deg: float = 540.0, t_max: float | None = None):
    """The model's closed-loop standard manoeuvre matching a measured one.

    ``measured``: the log's :class:`~shipid.manoeuvres.TurningMetrics` or
    :class:`~shipid.manoeuvres.ZigzagMetrics` (manoeuvre kind, ordered rudder angle, side, switch
    angle, approach speed).  ``rudder_rate`` [rad/s] defaults to the model's.  ``params`` (np,) or
    (B, np): with B parameter sets the B manoeuvres run as one batch, member b with ``params[b]``.
    ``heading_change_deg``: how far a turning circle runs; ``t_max`` [s]: the simulators' time limit (default
    theirs).  Returns the
    :class:`~shipid.manoeuvres.ManoeuvreResult`; raises ValueError when the log's approach speed or
    rudder angle is unknown or the model cannot run the manoeuvre.
    """
    m = measured
    rudder, speed = abs(float(m.rudder_deg)), float(m.approach_speed)
    if not (math.isfinite(speed) and speed > 0) or not rudder > 0:
        raise ValueError("approach speed or rudder angle of the log unknown")
    per_member = params is not None and np.ndim(params) == 2
    spd = np.full(len(params), speed) if per_member else speed  # one member per parameter set
    if m.manoeuvre == "turning":
        return turning_circle(model, rudder, speed=spd, side=m.side, rudder_rate=rudder_rate, lpp=lpp,
                              params=params, heading_change_deg=heading_change_deg, t_max=t_max)
    # the rudder reversal is located within the step (shipid.manoeuvres.ZigzagRudder), so the default
    # step gives the overshoots to ~0.01 deg (tests/test_manoeuvres.py)
    return zigzag(model, rudder, float(m.switch_deg), speed=spd, first=m.first_side, rudder_rate=rudder_rate,
                  lpp=lpp, params=params, t_max=t_max)
