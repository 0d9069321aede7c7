"""Schemas: how a log file's columns map to shipid channels, and the presets shipped with shipid.

A schema says, for one kind of file, which column holds which channel (by name
or 1-based number), the units of the values, the axes of the velocities
(``"body"`` or ``"earth"``), the rudder sign relative to the shipid convention,
how many preamble lines to skip, whether there is a header line, the
delimiter, and the ship particulars that go with the data.  Presets
(:data:`PRESETS`) cover the datasets the project knows; a schema file (JSON,
or YAML with PyYAML) holds the same keys for anything else::

    {"columns": {"time": 1, "x": 2, "y": 3, "psi": 4, "u": 5, "v": 6, "r": 8, "delta": 9, "n": 10},
     "units": {"psi": "deg", "r": "deg/s", "delta": "deg", "n": "rpm"},
     "velocity_frame": "earth", "rudder_sign": -1, "skip_rows": 4, "header": false,
     "delimiter": "whitespace"}

The shipid convention that every reader delivers (and the models use): x
forward / y to starboard of x / z down, heading psi measured from the earth x
axis towards the earth y axis (clockwise seen from above), yaw rate r = dpsi/dt,
u, v the body-axis surge and sway velocities, and a positive rudder angle delta
turning the ship to starboard (positive r).
"""
from __future__ import annotations

import os
import re
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from ._text import load_mapping_file

__all__ = ["Schema", "PRESETS", "load_schema", "OPTIONAL_CHANNELS"]

#: Channels a schema may map that a file of that kind need not have (the log then lacks them):
#: the wind, logged on some runs only, apparent or true or both.
OPTIONAL_CHANNELS = ("wind_speed_rel", "wind_dir_rel", "wind_speed_true", "wind_dir_true")

_KEYS = ("name", "fmt", "columns", "units", "velocity_frame", "rudder_sign", "signs", "skip_rows", "header",
         "delimiter", "ship", "conventions", "meas_std")


@dataclass(frozen=True)
class Schema:
    """How to read one kind of log file.

    Parameters
    ----------
    name : str
        Preset name or the schema file's name (used in notes).
    fmt : {"csv", "marin"}
        Reader: ``"csv"`` (delimited or whitespace text table) or ``"marin"``
        (MARIN SIMMAN ``.dat``).
    columns : dict
        Channel -> the file's column name or 1-based column number.  Channels
        that are not ship channels (e.g. ``wind_speed_true``) become extra
        channels of the log.
    units : dict
        Channel -> unit of the values in the file (default: the header's
        bracketed unit, else SI/radians).
    velocity_frame : {"body", "earth"}
        Axes of the file's u, v: body axes, or earth-fixed (dx/dt, dy/dt),
        rotated into body axes by the heading.
    rudder_sign : {+1, -1}
        Multiplies the file's rudder angle to give the shipid convention
        (positive delta turns to starboard).
    signs : dict
        Channel -> +1 or -1: any other channel logged with the opposite sign
        to shipid's (e.g. ``{"r": -1}`` for a yaw rate positive to port).
    skip_rows : int
        Lines to skip before the header (or before the data without a header).
    header : bool
        Whether the (first unskipped) line names the columns; without a
        header, ``columns`` must give column numbers.
    delimiter : str or None
        ``","``, ``";"``, tab, ``"whitespace"``; None = comma with detection of
        the evident alternatives.
    ship : str or None
        A bundled ship (``"kvlcc2"``, ``"esso_osaka_3m"``) or a ship file path,
        used when the caller gives none.
    conventions : str
        The format's conventions in plain words (what was checked; shown in the
        log's notes).
    meas_std : dict
        Channel -> standard deviation of the facility's sensor in SI units (m,
        rad, m/s, rad/s): the measurement noise :func:`shipid.identify.fit_logs`
        (``shipid fit``) uses when the caller gives none (instead of the
        identifier's estimate from the data).  The logs carry it
        (``TrialLog.meas_std``).  Empty: estimated from the data.
    """

    name: str = "shipid"
    fmt: str = "csv"
    columns: Mapping[str, Any] = field(default_factory=dict)
    units: Mapping[str, str] = field(default_factory=dict)
    velocity_frame: str = "body"
    rudder_sign: float = 1.0
    signs: Mapping[str, float] = field(default_factory=dict)
    skip_rows: int = 0
    header: bool = True
    delimiter: str | None = None
    ship: str | None = None
    conventions: str = ""
    meas_std: Mapping[str, float] = field(default_factory=dict)

    def __post_init__(self):
        src = f"schema '{self.name}'"
        if not isinstance(self.meas_std, Mapping):
            raise ValueError(f"{src}: meas_std must be a mapping channel -> standard deviation, got "
                             f"{type(self.meas_std).__name__}")
        for ch, sd in self.meas_std.items():
            if isinstance(sd, bool) or not isinstance(sd, (int, float)) or not (np.isfinite(sd) and sd > 0):
                raise ValueError(f"{src}: meas_std['{ch}'] = {sd!r}; give a positive standard deviation in SI "
                                 "units (m, rad, m/s, rad/s)")
        if self.fmt not in ("csv", "marin"):
            raise ValueError(f"{src}: fmt = {self.fmt!r}; use 'csv' or 'marin'")
        check_frame(self.velocity_frame, f"{src}: velocity_frame")
        check_rudder_sign(self.rudder_sign, f"{src}: rudder_sign")
        if isinstance(self.skip_rows, bool) or not isinstance(self.skip_rows, int) or self.skip_rows < 0:
            raise ValueError(f"{src}: skip_rows = {self.skip_rows!r}; give a whole number >= 0")
        if not isinstance(self.header, bool):
            raise ValueError(f"{src}: header = {self.header!r}; give true or false")
        for what, m in (("columns", self.columns), ("units", self.units), ("signs", self.signs)):
            if not isinstance(m, Mapping):
                raise ValueError(f"{src}: {what} must be a mapping channel -> value, got {type(m).__name__}")
        for ch, col in self.columns.items():
            if isinstance(col, bool) or not isinstance(col, (str, int)):
                raise ValueError(f"{src}: columns['{ch}'] = {col!r}; give a column name or a 1-based number")
        if not self.header:
            # without a header, columns are numbers (1-based; "5" from the CLI counts) or the names col1, col2, ...
            cols = {c: int(col) if isinstance(col, str) and col.strip().isdigit() else col
                    for c, col in self.columns.items()}
            object.__setattr__(self, "columns", cols)
            named = [c for c, col in cols.items() if not isinstance(col, int) and not re.fullmatch(r"col\d+", col)]
            if named:
                raise ValueError(f"{src}: header = false but columns {named} are given by name; give column "
                                 "numbers (1-based) when the file has no header line")
        for ch, sg in self.signs.items():
            check_rudder_sign(sg, f"{src}: signs['{ch}']")
        object.__setattr__(self, "rudder_sign", float(self.rudder_sign))

    def to_dict(self) -> dict:
        """Plain dict with the schema-file keys."""
        return {k: (dict(getattr(self, k)) if k in ("columns", "units", "signs", "meas_std") else getattr(self, k))
                for k in _KEYS}


def earth_to_body(ue: np.ndarray, ve: np.ndarray, psi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Earth-fixed velocities (dx/dt, dy/dt) [m/s] -> body-axis (u, v) [m/s] by the heading psi [rad].

    ``u = ue cos psi + ve sin psi``, ``v = -ue sin psi + ve cos psi`` (the
    inverse of ``dx/dt = u cos psi - v sin psi``, ``dy/dt = u sin psi + v cos psi``
    of the shipid kinematics).  Arrays of shape (n,).
    """
    c, s = np.cos(psi), np.sin(psi)
    return ue * c + ve * s, -ue * s + ve * c


def apply_conventions(ch: dict, units_in: dict, notes: list, schema: "Schema", where) -> None:
    """Bring a reader's SI channels to the shipid convention in place: earth-fixed u, v rotated into
    body axes (``schema.velocity_frame == "earth"``), rudder multiplied by ``schema.rudder_sign``."""
    if schema.velocity_frame == "earth" and ("u" in ch or "v" in ch):
        missing = [c for c in ("u", "v", "psi") if c not in ch]
        if missing:
            raise where.error(f"velocity_frame='earth' needs u, v and psi to rotate the velocities into body "
                              f"axes; missing {missing}: map them or use velocity_frame='body'", missing[0])
        ch["u"], ch["v"] = earth_to_body(ch["u"], ch["v"], ch["psi"])
        units_in["u"] = units_in["v"] = f"{units_in.get('u') or 'm/s'} (earth-fixed)"
        notes.append(f"u, v in the file are earth-fixed (dx/dt, dy/dt; schema '{schema.name}'); rotated into "
                     "body axes by psi")
    for c, sg in schema.signs.items():
        if sg == -1 and c in ch:
            ch[c] = -ch[c]
            notes.append(f"'{c}' multiplied by -1 (schema '{schema.name}' signs)")
    if schema.rudder_sign == -1 and "delta" in ch:
        ch["delta"] = -ch["delta"]
        notes.append(f"rudder angle multiplied by -1 (schema '{schema.name}': the file's rudder is positive to "
                     "port; shipid's is positive to starboard)")


def check_frame(frame, what: str = "velocity_frame") -> str:
    if frame not in ("body", "earth"):
        raise ValueError(f"{what} = {frame!r}; use 'body' (u, v in ship axes) or 'earth' (earth-fixed dx/dt, dy/dt)")
    return frame


def check_rudder_sign(sign, what: str = "rudder_sign") -> float:
    if isinstance(sign, bool) or not isinstance(sign, (int, float)) or sign not in (1, -1):
        raise ValueError(f"{what} = {sign!r}; use +1 (file already in shipid's sign) or -1 (flip)")
    return float(sign)


def check_signs(signs, what: str = "signs") -> dict:
    """``{channel: +1 or -1}`` as floats; ValueError naming the channel and the value otherwise (the rudder
    has its own ``rudder_sign``; time has no sign)."""
    if not isinstance(signs, Mapping):
        raise ValueError(f"{what} must be a mapping channel -> +1 or -1, e.g. {{'r': -1}}; got {type(signs).__name__}")
    out = {}
    for ch, sg in signs.items():
        if ch == "delta":
            raise ValueError(f"{what}['delta']: give the rudder's sign as rudder_sign=-1 (CLI: --rudder-sign -1)")
        if ch == "time":
            raise ValueError(f"{what}['time']: time cannot be negated; give signs for measured channels, e.g. r=-1")
        out[ch] = check_rudder_sign(sg, f"{what}['{ch}']")
    return out


_ESSO_CONVENTIONS = (
    "Esso Osaka FRT-DS-ESSO conventions as checked against the motion in all 33 files: u_velo, vm_velo are "
    "body-axis (midship) velocities (they match the heading-rotated derivative of x, y with correlation "
    "0.88-1.00); psi_hat is wrapped to (-pi, pi] and is unwrapped here; r_angvelo = d psi/dt (slope 0.93-1.03); "
    "a positive delta_rudder turns to starboard (positive r) as in shipid, so no flip; n_prop < 0 is astern; "
    "wind directions are the direction the wind comes FROM, in radians, measured clockwise (towards starboard / "
    "the earth y axis) from the bow (wind_dir_rel) or from the earth x axis (wind_dir_true), in [0, 2 pi) as in "
    "the file; wind speeds in m/s: the relative wind equals the true wind minus the ship's velocity at midship "
    "(rms direction error <= 0.0063 rad, rms speed error < 0.01 m/s in every file) only under this convention "
    "(reading the directions as 'going to' misses the relative speed by ~0.3 m/s rms)")

#: Measurement noise of the Esso Osaka pond's sensors as ``shipid fit`` uses it (SI): 1 cm in position, 0.003 rad
#: (0.17 deg) in heading, 1 cm/s in velocity, 0.003 rad/s in yaw rate.  Set a priori in the Esso Osaka study
#: (``studies.esso_osaka.MEAS_STD`` in a source checkout, before any held-out error was computed; docs/environment.md)
#: and used in every cross-validated number since.  The identifier's own estimate from the data does not suit
#: these logs: the GNSS positions freeze for up to 2 s and then jump, and the study fits at 0.5 Hz, where
#: sample-to-sample differences are motion, not noise.
_ESSO_MEAS_STD = {"x": 0.01, "y": 0.01, "psi": 0.003, "u": 0.01, "v": 0.01, "r": 0.003}

#: Schemas shipped with shipid, by name.
PRESETS: dict[str, Schema] = {
    "shipid": Schema(
        name="shipid", fmt="csv",
        conventions="shipid CSV: SI/radians unless the header's bracketed unit says otherwise, body-axis u, v, "
                    "rudder positive to starboard"),
    "marin": Schema(
        name="marin", fmt="marin", ship="kvlcc2", velocity_frame="earth", rudder_sign=-1,
        conventions="MARIN SIMMAN 2008 .dat: degrees, deg/s, rpm; u, v earth-fixed dx0/dt, dy0/dt (rotated into "
                    "body axes by psi); the file's rudder is positive to port (flipped: checked on tc_35, whose "
                    "+35 deg in the file turns the ship to port, r < 0, and reads as delta = -35 deg here; tc_-35 "
                    "reads +35.1 deg with r > 0)"),
    "esso-frt": Schema(
        name="esso-frt", fmt="csv", ship="esso_osaka_3m",
        columns={"time": "t", "x": "x_position_mid", "y": "y_position_mid", "psi": "psi_hat", "u": "u_velo",
                 "v": "vm_velo", "r": "r_angvelo", "n": "n_prop", "delta": "delta_rudder",
                 "wind_speed_rel": "wind_velo_relative_mid", "wind_dir_rel": "wind_dir_relative_mid",
                 "wind_speed_true": "wind_velo_true", "wind_dir_true": "wind_dir_true"},
        conventions=_ESSO_CONVENTIONS, meas_std=_ESSO_MEAS_STD),
}


def load_schema(spec: "str | os.PathLike | Schema | Mapping") -> Schema:
    """A :class:`Schema` from a preset name, a schema file (JSON/YAML) or a mapping.

    Raises
    ------
    ValueError
        Unknown preset (the message lists the presets), unreadable file, or
        unknown / ill-typed keys (the message lists the known keys).
    """
    if isinstance(spec, Schema):
        return spec
    if isinstance(spec, Mapping):
        return _from_mapping(spec, "schema")
    s = str(spec)
    if s in PRESETS:
        return PRESETS[s]
    p = Path(s)
    if p.suffix.lower() not in (".json", ".yaml", ".yml") and not p.exists():
        raise ValueError(f"schema {s!r}: not a preset ({', '.join(PRESETS)}) and no such schema file; give a "
                         "preset name or a .json/.yaml schema file")
    return _from_mapping(load_mapping_file(p, "schema file"), f"`{p.name}`", default_name=p.stem)


def _from_mapping(d: Mapping, source: str, default_name: str = "schema") -> Schema:
    if not isinstance(d, Mapping):
        raise ValueError(f"{source}: expected a mapping of schema keys, got {type(d).__name__}")
    unknown = sorted(str(k) for k in d if k not in _KEYS)
    if unknown:
        raise ValueError(f"{source}: unknown key(s) {unknown}; known keys are {list(_KEYS)}")
    kw = dict(d)
    kw.setdefault("name", default_name)
    try:
        return Schema(**kw)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{source}: {exc}") from None


def merged(schema: Schema, **overrides) -> Schema:
    """``schema`` with the non-None ``overrides`` applied (columns/units merged per channel)."""
    kw = {}
    for k, v in overrides.items():
        if v is None:
            continue
        if k in ("columns", "units", "signs"):
            v = {**getattr(schema, k), **v}
        kw[k] = v
    return replace(schema, **kw) if kw else schema
