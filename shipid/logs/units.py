"""Units and channel dimensions of trial logs (SI is what every reader delivers)."""
from __future__ import annotations

import math
import re

#: unit name -> (dimension, factor to SI).  Aliases are lower-case.
UNITS: dict[str, tuple[str, float]] = {
    "s": ("time", 1.0), "sec": ("time", 1.0), "ms": ("time", 1e-3), "min": ("time", 60.0), "h": ("time", 3600.0),
    "m": ("length", 1.0), "km": ("length", 1000.0), "nm": ("length", 1852.0), "nmi": ("length", 1852.0),
    "rad": ("angle", 1.0), "deg": ("angle", math.pi / 180.0), "degree": ("angle", math.pi / 180.0),
    "degrees": ("angle", math.pi / 180.0),
    "m/s": ("speed", 1.0), "km/h": ("speed", 1.0 / 3.6), "kmh": ("speed", 1.0 / 3.6), "kph": ("speed", 1.0 / 3.6),
    "knots": ("speed", 1852.0 / 3600.0), "knot": ("speed", 1852.0 / 3600.0),
    "kn": ("speed", 1852.0 / 3600.0), "kt": ("speed", 1852.0 / 3600.0), "kts": ("speed", 1852.0 / 3600.0),
    "rad/s": ("rate", 1.0), "deg/s": ("rate", math.pi / 180.0), "deg/min": ("rate", math.pi / 180.0 / 60.0),
    "rad/min": ("rate", 1.0 / 60.0),
    "rps": ("revs", 1.0), "hz": ("revs", 1.0), "1/s": ("revs", 1.0), "rpm": ("revs", 1.0 / 60.0),
    "1/min": ("revs", 1.0 / 60.0), "r/min": ("revs", 1.0 / 60.0), "rev/min": ("revs", 1.0 / 60.0),
    "r/s": ("revs", 1.0), "rev/s": ("revs", 1.0),
}

#: SI unit written for each dimension.
SI_UNIT: dict[str, str] = {"time": "s", "length": "m", "angle": "rad", "speed": "m/s", "rate": "rad/s", "revs": "rps"}

#: Channels with a known meaning (ship schema and common extras) -> dimension.
SHIP_CHANNELS: dict[str, str] = {
    "time": "time",
    "x": "length", "y": "length", "z": "length",
    "psi": "angle", "phi": "angle", "theta": "angle", "delta": "angle", "fin": "angle",
    "u": "speed", "v": "speed", "w": "speed", "U": "speed",
    "r": "rate", "p": "rate", "q": "rate",
    "n": "revs",
}

#: Order of the default CSV schema.
SCHEMA: tuple[str, ...] = ("time", "x", "y", "psi", "u", "v", "r", "delta", "n")

#: unit name -> dimension (for channels whose meaning is unknown)
_UNKNOWN_DIMS = {k: v[0] for k, v in UNITS.items()}


def unit_key(unit) -> str:
    """A unit as written in a file or option -> its key in :data:`UNITS` (lower case, no spaces, the degree
    sign as ``deg``, ``/sec`` as ``/s``): ``"°/s"`` -> ``"deg/s"``, ``"Deg/Sec"`` -> ``"deg/s"``."""
    key = str(unit).strip().lower().replace("°", "deg").replace(" ", "")
    return re.sub(r"/sec$", "/s", key)


def _units_for(dim: str) -> str:
    return ", ".join(k for k, (d, _) in UNITS.items() if d == dim)
