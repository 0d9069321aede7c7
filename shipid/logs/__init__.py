"""Trial logs: read, validate and carry free-running manoeuvre records.

Everything that enters the identifier passes through here and comes out in SI
units and radians, with body-axis velocities and a continuous (unwrapped)
heading, in a :class:`TrialLog`.  Bad input raises :class:`LogError` (a
``ValueError``) whose one-line message names the file, the column and the file
line, shows the value and says what to do.  Gaps in *measured* channels are
data (NaN, reported with their file rows); gaps in *input* channels are errors
unless interpolation is requested.  The input file is only ever read.

Readers
-------
* CSV (default schema ``time [s], x [m], y [m], psi [rad], u [m/s], v [m/s],
  r [rad/s], delta [rad], n [rps]``; a bracketed unit in a header declares the
  column's unit; ``columns=`` maps names, ``units=`` declares units).
* MARIN SIMMAN 2008 ``.dat`` files (``fmt="marin"``, or auto-detected), whose
  u, v columns are earth-fixed and are rotated into body axes here.

See ``docs/logs.md`` for the user guide and the heuristics behind the
"looks like degrees" checks.
"""
from __future__ import annotations

from .consistency import ConsistencyResult, check_consistency
from .reader import read_log
from .ship import ShipParticulars, read_ship
from .trial_log import LogError, TrialLog
from .units import SCHEMA, SHIP_CHANNELS, SI_UNIT, UNITS

__all__ = ["LogError", "ShipParticulars", "TrialLog", "read_log", "read_ship", "check_consistency",
           "ConsistencyResult", "UNITS", "SI_UNIT", "SHIP_CHANNELS", "SCHEMA"]
