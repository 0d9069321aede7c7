"""Standard manoeuvres (turning circle, zigzag) for any model, and their metrics.

Simulation
----------
:func:`turning_circle`, :func:`zigzag` and :func:`turning_sweep` run the
standard manoeuvres of ITTC 7.5-04-02-01 / IMO MSC.137(76) for **any**
protocol model with states ``x, y, psi, u, v, r`` and inputs ``delta, n``,
as one vectorised batch through :func:`shipid.simulate.simulate`:
steady approach (the propeller rps that holds the approach speed with the
rudder amidships is solved through the model's own ``rhs``), rudder moved at
the ship's steering rate to the ordered angle (turning circle: held until the
heading has changed by at least 540 deg; zigzag: reversed each time the
heading deviation reaches the switch angle -- a batch-aware feedback law).

Sign convention: positive ``delta`` is the model's own positive rudder; the
side of a turn is taken from the heading change (positive psi change =
starboard for the shipped models).  Logs may use the opposite rudder sign
(the MARIN files do: +35 deg there turns to port); the metrics never use the
rudder sign, only the execute time and the heading.

Metrics
-------
:func:`turning_metrics`, :func:`zigzag_metrics` and :func:`metrics` work on
plain arrays, on a DataFrame/TrialLog (columns ``time, x, y, psi, u, [v],
delta``) and on a simulation, with the same code:

* execute: the first sample with ``|delta - delta[0]| > 0.5 deg`` (as in the
  MARIN README), unless the execute time is known (simulations pass it);
* advance / transfer: position change along / across the heading at the
  execute when the heading has changed by 90 deg (linear interpolation
  between samples); tactical diameter: across-distance at 180 deg;
* steady turning diameter: least-squares circle through the track after the
  heading change has passed 360 deg (270 deg when the run is shorter), speed
  loss ``1 - U_steady/U_approach`` over the same part;
* zigzag: first / second overshoot angle and their times from the first
  execute, time to second execute, and the initial turning ability (track
  length from the first to the second execute, IMO's 10 deg heading change);
* IMO MSC.137(76) criteria with the L/V-dependent overshoot limits.

The results state the reference point of the positions they used: the
model's origin (midship for ``mmg``) for simulations, the logged point for
logs unless ``reference_offset`` moves it to midship.
"""
from __future__ import annotations

from ._series import EXECUTE_THRESHOLD_DEG, detect_execute
from .imo import imo_limits
from .laws import RampSchedule, SampledHold, TurningRudder, ZigzagRudder
from .runner import ManoeuvreResult, ship_info, steady_rps
from .turning import TurningMetrics, _turning_rows, turning_circle, turning_metrics, turning_sweep
from .zigzag import ZigzagMetrics, infer_check_angle, rudder_reversals, zigzag, zigzag_metrics
from .run_metrics import NotStandardManoeuvre, SteadyTurn, detect_manoeuvre, metrics, steady_turn
from .matched import standard_manoeuvre

__all__ = [
    "TurningMetrics",
    "ZigzagMetrics",
    "ManoeuvreResult",
    "turning_metrics",
    "zigzag_metrics",
    "metrics",
    "steady_turn",
    "standard_manoeuvre",
    "SteadyTurn",
    "NotStandardManoeuvre",
    "detect_manoeuvre",
    "detect_execute",
    "imo_limits",
    "turning_circle",
    "zigzag",
    "turning_sweep",
    "steady_rps",
    "ship_info",
    "RampSchedule",
    "TurningRudder",
    "ZigzagRudder",
    "SampledHold",
    "infer_check_angle",
    "rudder_reversals",
]
