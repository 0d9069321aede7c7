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

import csv
import dataclasses
import io
import json
import math
import os
import re
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np
import pandas as pd

from ._io import atomic_write_text

__all__ = ["LogError", "ShipParticulars", "TrialLog", "read_log", "read_ship", "UNITS", "SHIP_CHANNELS"]

# --------------------------------------------------------------------------------------
# units and channel dimensions
# --------------------------------------------------------------------------------------

#: unit name -> (dimension, factor to SI).  Aliases are lower-case.
UNITS: dict[str, tuple[str, float]] = {
    "s": ("time", 1.0), "sec": ("time", 1.0), "ms": ("time", 1e-3), "min": ("time", 60.0), "h": ("time", 3600.0),
    "m": ("length", 1.0), "km": ("length", 1000.0), "nm": ("length", 1852.0), "nmi": ("length", 1852.0),
    "rad": ("angle", 1.0), "deg": ("angle", math.pi / 180.0), "degree": ("angle", math.pi / 180.0),
    "degrees": ("angle", math.pi / 180.0),
    "m/s": ("speed", 1.0), "knots": ("speed", 1852.0 / 3600.0), "knot": ("speed", 1852.0 / 3600.0),
    "kn": ("speed", 1852.0 / 3600.0), "kt": ("speed", 1852.0 / 3600.0), "kts": ("speed", 1852.0 / 3600.0),
    "rad/s": ("rate", 1.0), "deg/s": ("rate", math.pi / 180.0),
    "rps": ("revs", 1.0), "hz": ("revs", 1.0), "1/s": ("revs", 1.0), "rpm": ("revs", 1.0 / 60.0),
    "1/min": ("revs", 1.0 / 60.0),
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

_MISSING_TOKENS = {"", "nan", "na", "n/a", "null", "none", "-nan"}

# physical plausibility limits (SI); see docs/logs.md
_ABSURD = {"speed": 100.0, "length": 1e8, "rate": 10.0, "revs": 1000.0, "time": 1e10, "angle": 1e6}
_GENERIC_ABSURD = 1e15
_CONTROL_ANGLES = ("delta", "fin")   # |value| > pi/2 rad looks like degrees
_ATTITUDE_ANGLES = ("phi", "theta")  # |value| > pi/2 rad looks like degrees
_RATE_DEG_LIMIT = 3.0                 # |rate| > 3 rad/s looks like deg/s
_RPM_SCORE = 200.0                    # n sqrt(Lpp) [rps m^0.5] above this looks like rpm


# --------------------------------------------------------------------------------------
# errors
# --------------------------------------------------------------------------------------


class LogError(ValueError):
    """A trial log (file or arrays) cannot be used as given.

    Attributes
    ----------
    path : pathlib.Path or None
        The file, or None for arrays.
    column : str or None
        Our channel name (or the file's column name) concerned.
    row : int or None
        1-based line number in the file (header = line 1 when there are no
        comment lines), or the 0-based sample index for arrays.
    value : object
        The offending value, when there is one.
    """

    def __init__(self, message: str, *, path=None, column: str | None = None, row: int | None = None, value=None):
        super().__init__(message)
        self.path = Path(path) if path is not None else None
        self.column = column
        self.row = row
        self.value = value


def _fmt_value(v) -> str:
    if isinstance(v, (float, np.floating)):
        v = float(v)
        if math.isnan(v):
            return "blank/NaN"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return f"{v:.6g}"
    if isinstance(v, str):
        return repr(v if len(v) <= 40 else v[:37] + "...")
    return str(v)


class _Where:
    """How to name places in messages: a file (rows are file lines) or arrays (indices)."""

    def __init__(self, path: Path | None, name: str, rows: np.ndarray | None = None):
        self.path = path
        self.name = name
        self.rows = rows

    @property
    def label(self) -> str:
        return f"`{self.path.name}`" if self.path is not None else f"log '{self.name}'"

    def row_of(self, i: int) -> int:
        return int(self.rows[i]) if self.rows is not None else int(i)

    def place(self, column: str | None = None, i: int | None = None, *, row: int | None = None) -> str:
        s = self.label
        if column is not None:
            s += f" column '{column}'"
        if row is None and i is not None:
            row = self.row_of(i)
        if row is not None:
            s += f" {'row' if self.path is not None else 'index'} {row}"
        return s

    def error(self, msg: str, column: str | None = None, i: int | None = None, *, row: int | None = None, value=None):
        if row is None and i is not None:
            row = self.row_of(i)
        return LogError(f"{self.place(column, row=row)}: {msg}", path=self.path, column=column, row=row, value=value)


# --------------------------------------------------------------------------------------
# ship particulars
# --------------------------------------------------------------------------------------


@dataclass
class ShipParticulars:
    """Main particulars that travel with a log (SI units).

    Parameters
    ----------
    lpp : float
        Length between perpendiculars [m]; required, finite and > 0.
    beam, draught : float, optional
        Breadth and draught [m].
    displacement : float, optional
        Displacement volume [m^3].
    design_speed : float, optional
        Design (approach) speed [m/s].
    rudder_rate : float, optional
        Maximum rudder rate [rad/s].
    rudder_max : float, optional
        Maximum rudder angle [rad].
    name : str, optional
        Ship name, e.g. ``"KVLCC2"``.
    scale : float, optional
        Model scale factor (1 for full scale).
    extra : dict, optional
        Anything else (free-form, JSON-serialisable), e.g. ``{"source": ...}``.
    """

    lpp: float
    beam: float | None = None
    draught: float | None = None
    displacement: float | None = None
    design_speed: float | None = None
    rudder_rate: float | None = None
    rudder_max: float | None = None
    name: str | None = None
    scale: float | None = None
    extra: dict = field(default_factory=dict)

    _POSITIVE = ("lpp", "beam", "draught", "displacement", "design_speed", "rudder_rate", "rudder_max", "scale")

    def __post_init__(self):
        for f in self._POSITIVE:
            val = getattr(self, f)
            if val is None and f != "lpp":
                continue
            try:
                fv = float(val)
            except (TypeError, ValueError):
                raise ValueError(f"ship particulars: {f} = {val!r} is not a number; give {f} in SI units") from None
            if not math.isfinite(fv) or fv <= 0:
                raise ValueError(f"ship particulars: {f} = {val!r} must be finite and > 0")
            setattr(self, f, fv)
        if self.rudder_max is not None and self.rudder_max > math.pi / 2:
            raise ValueError(f"ship particulars: rudder_max = {self.rudder_max} rad is beyond 90 deg; "
                             "give it in radians (35 deg = 0.6109 rad)")
        if self.rudder_rate is not None and self.rudder_rate > 3.0:
            raise ValueError(f"ship particulars: rudder_rate = {self.rudder_rate} rad/s looks like deg/s; "
                             "give it in rad/s (2.32 deg/s = 0.0405 rad/s)")
        if self.extra is None:
            self.extra = {}
        if not isinstance(self.extra, dict):
            raise ValueError(f"ship particulars: extra must be a dict, got {type(self.extra).__name__}")
        if self.name is not None:
            self.name = str(self.name)

    def to_dict(self) -> dict:
        """Plain dict (JSON-serialisable); fields that are None are left out."""
        d = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        return {k: v for k, v in d.items() if v is not None and not (k == "extra" and not v)}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any], *, source: str = "ship particulars") -> "ShipParticulars":
        """Build from a mapping; unknown keys are an error (typos must not pass silently)."""
        if not isinstance(d, Mapping):
            raise ValueError(f"{source}: expected a mapping of particulars, got {type(d).__name__}")
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(d) - known)
        if unknown:
            raise ValueError(f"{source}: unknown field(s) {unknown}; known fields are {sorted(known)} "
                             "(put anything else under 'extra')")
        if "lpp" not in d:
            raise ValueError(f"{source}: 'lpp' (length between perpendiculars, m) is required")
        try:
            return cls(**dict(d))
        except ValueError as exc:
            raise ValueError(f"{source}: {exc}".replace("ship particulars: ", "")) from None

    def __str__(self) -> str:
        s = f"{self.name or 'ship'} Lpp {self.lpp:g} m"
        if self.beam:
            s += f", B {self.beam:g} m"
        if self.draught:
            s += f", T {self.draught:g} m"
        if self.scale and self.scale != 1:
            s += f", scale 1:{self.scale:g}"
        return s


def read_ship(path: str | os.PathLike) -> ShipParticulars:
    """Read ship particulars from a JSON (or YAML, with PyYAML installed) file.

    The file holds one mapping with the fields of :class:`ShipParticulars`
    (SI units; ``lpp`` required), e.g. ``{"name": "KVLCC2", "lpp": 320}``.
    """
    p = Path(path)
    _check_path(p, what="ship file")
    text = p.read_bytes()
    try:
        s = text.decode("utf-8-sig")
    except UnicodeDecodeError:
        raise ValueError(f"`{p.name}`: ship file is not UTF-8 text; write it as JSON") from None
    if p.suffix.lower() in (".yaml", ".yml"):
        try:
            import yaml  # type: ignore
        except ImportError:
            raise ValueError(f"`{p.name}`: reading YAML needs PyYAML (pip install pyyaml); "
                             "or write the ship file as JSON") from None
        try:
            d = yaml.safe_load(s)
        except yaml.YAMLError as exc:
            raise ValueError(f"`{p.name}`: not valid YAML ({' '.join(str(exc).split())})") from None
    else:
        try:
            d = json.loads(s)
        except json.JSONDecodeError as exc:
            raise ValueError(f"`{p.name}` line {exc.lineno}: not valid JSON ({exc.msg}); "
                             "write e.g. {\"name\": \"KVLCC2\", \"lpp\": 320}") from None
    return ShipParticulars.from_dict(d, source=f"`{p.name}`")


def _bundled_ship(name: str) -> ShipParticulars:
    from importlib import resources

    text = resources.files("shipid").joinpath("data_ships", f"{name}.json").read_text("utf-8")
    return ShipParticulars.from_dict(json.loads(text), source=f"bundled ship {name}")


def _as_ship(ship, lpp) -> ShipParticulars | None:
    if ship is not None and not isinstance(ship, ShipParticulars):
        if isinstance(ship, Mapping):
            ship = ShipParticulars.from_dict(ship)
        else:
            ship = read_ship(ship)
    if lpp is not None:
        if ship is None:
            ship = ShipParticulars(lpp=lpp)
        else:
            ship = dataclasses.replace(ship, lpp=lpp)
    return ship


# --------------------------------------------------------------------------------------
# the log object
# --------------------------------------------------------------------------------------


class TrialLog:
    """A validated trial log in SI units and radians.

    Build one with :func:`read_log` or :meth:`TrialLog.from_arrays`; both run
    the same validation.

    Attributes
    ----------
    data : pandas.DataFrame
        Column ``"time"`` [s] plus one column per channel, SI units and
        radians, body-axis velocities, unwrapped heading.  Shape
        ``(n_samples, 1 + n_channels)``; NaN marks a missing measured sample.
    ship : ShipParticulars or None
    name : str
    path : pathlib.Path or None
        The file read (None for arrays).
    sha256 : str or None
        SHA-256 of the file's bytes as read.
    rows : ndarray of int, shape (n_samples,)
        File line number of each sample (1-based; for arrays the 0-based index).
    missing : dict[str, list[int]]
        Channel -> file rows where the measured value is missing.
    dropouts : list[tuple[float, float]]
        Time gaps longer than 3 x the median sample interval, as (t_start, t_end) [s].
    units_in : dict[str, str]
        Unit each channel had in the source, before conversion to SI.
    notes : list[str]
        What the reader did (dropped repeats, rotations, interpolation, ...).
    """

    def __init__(self, data: pd.DataFrame, *, name: str, ship: ShipParticulars | None = None, path: Path | None = None,
                 sha256: str | None = None, rows: np.ndarray | None = None, missing: dict | None = None,
                 dropouts: list | None = None, units_in: dict | None = None, notes: list | None = None,
                 fmt: str = "arrays"):
        self.data = data
        self.name = name
        self.ship = ship
        self.path = path
        self.sha256 = sha256
        self.rows = np.arange(len(data)) if rows is None else np.asarray(rows, dtype=np.int64)
        self.missing = dict(missing or {})
        self.dropouts = list(dropouts or [])
        self.units_in = dict(units_in or {})
        self.notes = list(notes or [])
        self.fmt = fmt

    # --- construction from arrays -------------------------------------------------
    @classmethod
    def from_arrays(
        cls,
        time,
        *,
        name: str = "synthetic",
        ship: ShipParticulars | Mapping | str | os.PathLike | None = None,
        units: Mapping[str, str] | None = None,
        inputs: Sequence[str] = ("delta", "n"),
        interpolate_inputs: bool = False,
        required: Sequence[str] = (),
        min_samples: int = 2,
        unit_checks: bool = True,
        **channels,
    ) -> "TrialLog":
        """Build a log from arrays, with the same validation as :func:`read_log`.

        Parameters
        ----------
        time : array_like, shape (n,)
            Sample times [s] (or the unit in ``units["time"]``), strictly increasing.
        name : str
            Name used in messages and reports.
        ship : ShipParticulars, mapping or path, optional
        units : dict, optional
            Unit of any channel that is not given in SI/radians, e.g. ``{"psi": "deg"}``.
        inputs : sequence of str
            Input channels; NaN there is an error unless ``interpolate_inputs``.
        interpolate_inputs : bool
            Fill NaN in input channels by linear interpolation in time.
        required : sequence of str
            Channels that must be present (none by default: any model's channels are allowed).
        min_samples : int
            Fewest samples accepted.
        unit_checks : bool
            Run the "looks like degrees" heuristics (see docs/logs.md).
        **channels : array_like, shape (n,)
            One array per channel.  Known ship channels (x, y, psi, u, v, r,
            delta, n, phi, p, ...) get the plausibility checks; any other name
            is accepted as is (e.g. a glider's z, theta, w, q, fin).
        """
        where = _Where(None, name)
        t = _as_1d(time, "time", where)
        n = t.shape[0]
        arrays: dict[str, np.ndarray] = {}
        for k, v in channels.items():
            a = _as_1d(v, k, where)
            if a.shape[0] != n:
                raise LogError(f"log '{name}' column '{k}': has {a.shape[0]} samples but time has {n}; "
                               "give every channel on the same time base", column=k, value=a.shape[0])
            arrays[k] = a
        units = dict(units or {})
        t, arrays, units_in = _convert_units({"time": t, **arrays}, units, {}, where)
        return _finish(t, arrays, where=where, name=name, ship=_as_ship(ship, None), path=None, sha256=None,
                       inputs=inputs, interpolate_inputs=interpolate_inputs, required=required,
                       min_samples=min_samples, unit_checks=unit_checks, units_in=units_in, notes=[], fmt="arrays")

    # --- access --------------------------------------------------------------------
    @property
    def time(self) -> np.ndarray:
        """Sample times [s], shape (n_samples,)."""
        return self.data["time"].to_numpy()

    @property
    def channels(self) -> list[str]:
        """Channel names (all columns but ``time``)."""
        return [c for c in self.data.columns if c != "time"]

    def has(self, name: str) -> bool:
        """True when channel ``name`` is present and has at least one finite sample."""
        return name in self.data.columns and bool(np.isfinite(self.data[name].to_numpy()).any())

    def __getitem__(self, name: str) -> np.ndarray:
        if name not in self.data.columns:
            raise KeyError(f"log '{self.name}' has no channel '{name}'; channels: {', '.join(self.data.columns)}")
        return self.data[name].to_numpy()

    def __contains__(self, name: str) -> bool:
        return name in self.data.columns

    def __len__(self) -> int:
        return len(self.data)

    @property
    def dt(self) -> float:
        """Median sample interval [s]."""
        t = self.time
        return float(np.median(np.diff(t))) if t.size > 1 else float("nan")

    def units(self) -> dict[str, str]:
        """SI unit of each column (empty string when the channel's meaning is unknown)."""
        out = {}
        for c in self.data.columns:
            dim = SHIP_CHANNELS.get(c) or _UNKNOWN_DIMS.get(self.units_in.get(c, ""), None)
            out[c] = SI_UNIT.get(dim, "") if dim else ""
        return out

    def to_pandas(self) -> pd.DataFrame:
        """A copy of :attr:`data` indexed by time [s]."""
        return self.data.set_index("time", drop=True).copy()

    def __repr__(self) -> str:
        src = self.path.name if self.path is not None else "arrays"
        return f"TrialLog(name={self.name!r}, source={src!r}, samples={len(self)}, channels={self.channels})"

    def summary(self) -> str:
        """Short text: source, samples, time span, channels, ship, missing samples, dropouts, notes."""
        t = self.time
        u = self.units()
        src = f"{self.path.name}, sha256 {self.sha256[:12]}" if self.path is not None else "arrays"
        lines = [f"TrialLog '{self.name}' ({src})"]
        if len(t):
            lines.append(f"  {len(self)} samples, t = {t[0]:g} .. {t[-1]:g} s, dt = {self.dt:.4g} s (median)")
        lines.append("  channels: " + ", ".join(f"{c} [{u[c]}]" if u[c] else c for c in self.channels))
        conv = {c: v for c, v in self.units_in.items() if v and v != u.get(c)}
        if conv:
            lines.append("  converted from: " + ", ".join(f"{c} {v}" for c, v in conv.items()))
        lines.append(f"  ship: {self.ship}" if self.ship is not None else "  ship: not given (pass lpp= or ship=)")
        if self.missing:
            parts = []
            for c, r in self.missing.items():
                parts.append(f"{c} {len(r)} (rows {_short_list(r)})")
            lines.append("  missing samples: " + "; ".join(parts))
        else:
            lines.append("  missing samples: none")
        if self.dropouts:
            lines.append(f"  dropouts (> 3 dt): {len(self.dropouts)}: "
                         + ", ".join(f"{a:g}-{b:g} s" for a, b in self.dropouts[:5])
                         + (" ..." if len(self.dropouts) > 5 else ""))
        else:
            lines.append("  dropouts: none")
        for n in self.notes:
            lines.append(f"  note: {n}")
        return "\n".join(lines)

    def plot(self, ax=None, channels: Sequence[str] | None = None):
        """Plot each channel against time (one axes per channel); returns the axes.

        Angles and rates are shown in degrees for readability.
        """
        import matplotlib.pyplot as plt

        names = list(channels) if channels is not None else self.channels
        if ax is None:
            _, axs = plt.subplots(len(names), 1, sharex=True, figsize=(7, 1.5 * max(len(names), 1)), squeeze=False)
            axs = axs[:, 0]
        else:
            axs = np.atleast_1d(ax)
            if len(axs) == 1 and len(names) > 1:
                axs = np.repeat(axs, len(names))
        u = self.units()
        t = self.time
        for a, c in zip(axs, names):
            y = self[c]
            unit = u.get(c, "")
            if unit == "rad":
                y, unit = np.degrees(y), "deg"
            elif unit == "rad/s":
                y, unit = np.degrees(y), "deg/s"
            a.plot(t, y, lw=0.8, label=c)
            a.set_ylabel(f"{c} [{unit}]" if unit else c)
        axs[-1].set_xlabel("time [s]")
        axs[0].set_title(self.name)
        return axs

    def to_csv(self, path: str | os.PathLike, *, force: bool = False) -> Path:
        """Write the log as CSV in the default schema (atomically).

        Header ``time [s], x [m], ...`` with units, channels in schema order then
        the others; full float precision; missing samples as blank cells.  Name
        and ship particulars travel as ``# shipid-...`` comment lines, so
        :func:`read_log` reads the file back to the same log.

        Raises
        ------
        OutputExistsError
            When ``path`` exists and ``force`` is False.
        """
        cols = ["time"] + [c for c in SCHEMA[1:] if c in self.data.columns] + \
               [c for c in self.channels if c not in SCHEMA]
        u = self.units()
        header = [f"{c} [{u[c]}]" if u.get(c) else c for c in cols]
        buf = io.StringIO()
        buf.write(f"# shipid-log: {json.dumps({'name': self.name})}\n")
        if self.ship is not None:
            buf.write(f"# shipid-ship: {json.dumps(self.ship.to_dict())}\n")
        df = self.data[cols].copy()
        df.columns = header
        df.to_csv(buf, index=False, float_format="%.17g", na_rep="", lineterminator="\n")
        return atomic_write_text(path, buf.getvalue(), force=force)


_UNKNOWN_DIMS = {k: v[0] for k, v in UNITS.items()}


def _short_list(rows: Sequence[int], k: int = 6) -> str:
    rows = list(rows)
    s = ", ".join(str(r) for r in rows[:k])
    return s + (f", ... ({len(rows) - k} more)" if len(rows) > k else "")


def _as_1d(v, name: str, where: _Where) -> np.ndarray:
    try:
        a = np.asarray(v, dtype=float)
    except (TypeError, ValueError):
        raise LogError(f"{where.label} column '{name}': values are not numbers; give a 1-D numeric array",
                       column=name) from None
    if a.ndim != 1:
        raise LogError(f"{where.label} column '{name}': expected a 1-D array, got shape {a.shape}", column=name,
                       value=a.shape)
    return a.copy()


# --------------------------------------------------------------------------------------
# shared validation pipeline
# --------------------------------------------------------------------------------------


def _convert_units(arrays: dict[str, np.ndarray], units: Mapping[str, str], header_units: Mapping[str, str],
                   where: _Where, columns_in_file: Mapping[str, str] | None = None):
    """Convert every channel to SI; returns (time, channels, units_in)."""
    units = dict(units)
    unknown = [k for k in units if k not in arrays]
    if unknown:
        raise LogError(f"{where.label}: units given for {unknown} but the log has no such channel(s); "
                       f"channels: {', '.join(arrays)}", column=unknown[0])
    out: dict[str, np.ndarray] = {}
    units_in: dict[str, str] = {}
    for name, a in arrays.items():
        unit = units.get(name, header_units.get(name))
        dim = SHIP_CHANNELS.get(name)
        if unit is None:
            units_in[name] = SI_UNIT[dim] if dim else ""
            out[name] = a
            continue
        key = str(unit).strip().lower().replace("°", "deg").replace(" ", "")
        if key not in UNITS:
            col = (columns_in_file or {}).get(name, name)
            raise LogError(f"{where.label} column '{col}': unknown unit {unit!r}; use one of "
                           "s, ms, min, h, m, km, nm (nautical mile), rad, deg, m/s, knots (kn), rad/s, deg/s, "
                           "rps, rpm, Hz",
                           column=name, value=unit)
        udim, factor = UNITS[key]
        if dim is not None and udim != dim:
            col = (columns_in_file or {}).get(name, name)
            raise LogError(f"{where.label} column '{col}': unit {unit!r} is a {udim} unit but '{name}' is a {dim} "
                           f"(use {_units_for(dim)})", column=name, value=unit)
        units_in[name] = unit
        out[name] = a * factor if factor != 1.0 else a
    t = out.pop("time")
    return t, out, units_in


def _units_for(dim: str) -> str:
    return ", ".join(k for k, (d, _) in UNITS.items() if d == dim)


def _finish(t: np.ndarray, ch: dict[str, np.ndarray], *, where: _Where, name: str, ship, path, sha256,
            inputs: Sequence[str], interpolate_inputs: bool, required: Sequence[str], min_samples: int,
            unit_checks: bool, units_in: dict, notes: list, fmt: str) -> TrialLog:
    """Validate SI arrays and build the TrialLog (shared by every reader)."""
    n = t.shape[0]
    missing_req = [c for c in required if c != "time" and c not in ch]
    if missing_req:
        raise where.error(f"required channel(s) {missing_req} missing; channels present: "
                          f"{', '.join(['time', *ch]) }", column=missing_req[0])
    for c in required:
        if c != "time" and not np.isfinite(ch[c]).any():
            raise where.error("required channel is entirely blank/NaN; give a column with values, or leave it "
                              "out of required=", c, 0, value=ch[c][0] if n else None)
    # --- time --------------------------------------------------------------------
    bad = ~np.isfinite(t)
    if bad.any():
        i = int(np.argmax(bad))
        raise where.error(f"time value {_fmt_value(t[i])} is missing or not finite; every sample needs a time "
                          "stamp: fill it in or delete the row", "time", i, value=t[i])
    if np.abs(t).max(initial=0.0) > _ABSURD["time"]:
        i = int(np.argmax(np.abs(t) > _ABSURD["time"]))
        raise where.error(f"value {_fmt_value(t[i])} s is not a plausible time; give time in seconds",
                          "time", i, value=t[i])
    if n < min_samples:
        raise where.error(f"only {n} sample(s); at least {min_samples} are needed to identify anything; "
                          "use a longer record", value=n)
    d = np.diff(t)
    if (d <= 0).any():
        i = int(np.argmax(d <= 0)) + 1
        what = "repeats" if d[i - 1] == 0 else "goes back from"
        prev_row = where.row_of(i - 1)
        raise where.error(f"time {_fmt_value(t[i])} {what} {_fmt_value(t[i - 1])} (row {prev_row}); time must "
                          "increase strictly: sort the log, remove the duplicate row, or fix the clock",
                          "time", i, value=t[i])
    # --- channels: finiteness, plausibility, units --------------------------------
    for c, a in ch.items():
        _check_channel(c, a, where, unit_checks)
    if unit_checks and "psi" in ch:
        _check_heading(t, ch, where)
    if unit_checks and ship is not None and "n" in ch and np.isfinite(ch["n"]).any():
        # Froude scaling keeps n sqrt(Lpp) of ships and their models within ~10..100 rps m^0.5
        # (KVLCC2 1.5 rps x sqrt(320 m) = 27; KCS model 10 rps x sqrt(4.36 m) = 21); rpm gives 60x that
        score = np.abs(ch["n"]) * math.sqrt(ship.lpp)
        if np.nanmax(score) > _RPM_SCORE:
            i = int(np.argmax(score > _RPM_SCORE))
            raise where.error(f"value {_fmt_value(ch['n'][i])} looks like rpm (n sqrt(Lpp) = {score[i]:.0f} "
                              f"rps m^0.5 for Lpp {ship.lpp:g} m; ships and models stay below {_RPM_SCORE:g}); "
                              + _deg_hint("n", "rpm") + " (or unit_checks=False if it really is rps)", "n", i,
                              value=ch["n"][i])
    # --- inputs ------------------------------------------------------------------
    for c in inputs:
        if c not in ch:
            continue
        a = ch[c]
        gap = np.isnan(a)
        if not gap.any():
            continue
        i = int(np.argmax(gap))
        if not interpolate_inputs:
            raise where.error(f"input value is blank/NaN ({int(gap.sum())} such sample(s)); an input gap cannot "
                              "be treated as a missing measurement: fill it, or pass interpolate_inputs=True "
                              "(CLI: --interpolate-inputs) for linear interpolation", c, i, value=a[i])
        ok = ~gap
        if not ok[0] or not ok[-1]:
            j = 0 if not ok[0] else n - 1
            raise where.error(f"input value is blank/NaN at the {'start' if j == 0 else 'end'} of the log; "
                              "interpolation cannot extrapolate: trim the log or fill the value", c, j, value=a[j])
        ch[c] = np.interp(t, t[ok], a[ok])
        notes.append(f"input '{c}': {int(gap.sum())} blank sample(s) filled by linear interpolation "
                     f"(rows {_short_list([where.row_of(k) for k in np.flatnonzero(gap)])})")
    # --- unwrap heading ------------------------------------------------------------
    if "psi" in ch:
        a = ch["psi"]
        ok = np.isfinite(a)
        if ok.any():
            a = a.copy()
            a[ok] = np.unwrap(a[ok])
            ch["psi"] = a
    # --- missing measured samples, dropouts ------------------------------------
    missing: dict[str, list[int]] = {}
    for c, a in ch.items():
        gap = np.isnan(a)
        if gap.any():
            missing[c] = [where.row_of(k) for k in np.flatnonzero(gap)]
    dropouts: list[tuple[float, float]] = []
    if n > 2:
        med = float(np.median(d))
        idx = np.flatnonzero(d > 3.0 * med)
        dropouts = [(float(t[k]), float(t[k + 1])) for k in idx]
    if missing or dropouts:
        parts = [f"{c}: {len(r)} (rows {_short_list(r, 4)})" for c, r in missing.items()]
        msg = f"{where.label}: "
        if parts:
            msg += "missing measured samples kept as NaN -- " + "; ".join(parts)
        if dropouts:
            msg += ("; " if parts else "") + f"{len(dropouts)} time dropout(s) longer than 3 x median dt " \
                   f"(first {dropouts[0][0]:g}-{dropouts[0][1]:g} s)"
        warnings.warn(msg, stacklevel=3)
    data = pd.DataFrame({"time": t, **ch})
    return TrialLog(data, name=name, ship=ship, path=path, sha256=sha256, rows=where.rows, missing=missing,
                    dropouts=dropouts, units_in=units_in, notes=notes, fmt=fmt)


def _deg_hint(c: str, unit: str) -> str:
    return f"pass units={{'{c}': '{unit}'}} (CLI: --units {c}={unit}) or convert"


def _check_channel(c: str, a: np.ndarray, where: _Where, unit_checks: bool) -> None:
    inf = np.isinf(a)
    if inf.any():
        i = int(np.argmax(inf))
        raise where.error(f"value {_fmt_value(a[i])} is not finite; fix or blank the cell "
                          "(blank = missing sample)", c, i, value=a[i])
    dim = SHIP_CHANNELS.get(c)
    absa = np.abs(a)
    with np.errstate(invalid="ignore"):
        mx = float(np.nanmax(absa)) if np.isfinite(a).any() else 0.0
    if dim is None:
        if mx > _GENERIC_ABSURD:
            i = int(np.nanargmax(absa))
            raise where.error(f"value {_fmt_value(a[i])} is absurd (|value| > 1e15); fix the cell", c, i, value=a[i])
        return
    if unit_checks and dim == "rate" and _RATE_DEG_LIMIT < mx <= _RATE_DEG_LIMIT * 180 / math.pi:
        i = int(np.argmax(absa > _RATE_DEG_LIMIT))
        raise where.error(f"value {_fmt_value(a[i])} looks like deg/s (|{c}| > {_RATE_DEG_LIMIT:g} rad/s = "
                          f"{math.degrees(_RATE_DEG_LIMIT):.0f} deg/s is not a ship's turn rate); "
                          + _deg_hint(c, "deg/s") + " (or unit_checks=False if it really is rad/s)", c, i, value=a[i])
    if unit_checks and c in _CONTROL_ANGLES + _ATTITUDE_ANGLES and math.pi / 2 < mx <= 180.0:
        i = int(np.argmax(absa > math.pi / 2))
        kind = "rudder/fin angle" if c in _CONTROL_ANGLES else "roll/pitch angle"
        raise where.error(f"value {_fmt_value(a[i])} looks like degrees (a {kind} beyond 90 deg = 1.571 rad); "
                          + _deg_hint(c, "deg") + " (or unit_checks=False if it really is radians)", c, i, value=a[i])
    limit = _ABSURD[dim]
    if dim == "angle" and c in _CONTROL_ANGLES + _ATTITUDE_ANGLES:
        limit = 180.0 if unit_checks else _ABSURD["angle"]
    if mx > limit:
        i = int(np.argmax(absa > limit))
        raise where.error(f"value {_fmt_value(a[i])} {SI_UNIT[dim]} is absurd for '{c}' (|value| > {limit:g} "
                          f"{SI_UNIT[dim]}); check the column and its unit", c, i, value=a[i])


def _check_heading(t: np.ndarray, ch: dict[str, np.ndarray], where: _Where) -> None:
    """Heuristics for a heading in degrees declared as radians (see docs/logs.md)."""
    psi = ch["psi"]
    ok = np.flatnonzero(np.isfinite(psi))
    if ok.size < 2:
        return
    hint = _deg_hint("psi", "deg") + " (or unit_checks=False if it really is radians)"
    # (1) first valid heading outside +-2 pi: a log normally starts within one turn
    i0 = int(ok[0])
    if abs(psi[i0]) > 2 * math.pi + 0.01:
        raise where.error(f"value {_fmt_value(psi[i0])} looks like degrees (the first heading lies outside "
                          f"+-2 pi rad); " + hint, "psi", i0, value=psi[i0])
    # (2) jumps > pi between consecutive valid samples that are not wrap-arounds (|jump| close to 2 pi)
    dt = np.diff(t)
    med = float(np.median(dt))
    a, b = ok[:-1], ok[1:]
    contiguous = (b - a == 1) & (dt[a] <= 3 * med)
    jump = psi[b] - psi[a]
    bad = contiguous & (np.abs(jump) > math.pi) & (np.abs(np.abs(jump) - 2 * math.pi) > 1.0)
    if bad.any():
        k = int(np.argmax(bad))
        i = int(b[k])
        raise where.error(f"value {_fmt_value(psi[i])} looks like degrees (a jump of {jump[k]:.4g} from the "
                          f"previous sample is neither a turn nor a 2 pi wrap-around); " + hint, "psi", i,
                          value=psi[i])
    # (3) heading change against integrated yaw rate
    if "r" in ch:
        r = ch["r"]
        good = contiguous & np.isfinite(r[a]) & np.isfinite(r[b]) & (np.abs(jump) <= math.pi)
        if good.sum() >= 10:
            rdt = 0.5 * (r[a] + r[b])[good] * dt[a][good]
            dpsi = jump[good]
            turned = float(np.sum(np.abs(rdt)))
            den = float(np.sum(rdt * rdt))
            if turned > 0.2 and den > 0:  # at least ~11 deg of turning to judge
                slope = float(np.sum(dpsi * rdt) / den)
                # standard error of the slope: flag only slopes clearly away from both 0 (noise) and 1
                m = int(good.sum())
                se = math.sqrt(max(float(np.sum((dpsi - slope * rdt) ** 2)) / (m - 1), 0.0) / den)
                clear = abs(slope) > 5 * se and abs(abs(slope) - 1.0) > 5 * se
                if clear and 20.0 < abs(slope) < 200.0:
                    i = int(ok[np.nanargmax(np.abs(psi[ok]))])
                    raise where.error(f"value {_fmt_value(psi[i])} looks like degrees (heading changes "
                                      f"{abs(slope):.1f} x faster than the integral of r; 57.3 = deg/rad); "
                                      + hint, "psi", i, value=psi[i])
                if clear and 1 / 200.0 < abs(slope) < 1 / 20.0:
                    i = int(np.nanargmax(np.abs(r)))
                    raise where.error(f"value {_fmt_value(r[i])} looks like deg/s (the integral of r changes "
                                      f"{1 / abs(slope):.1f} x faster than the heading; 57.3 = deg/rad); "
                                      + _deg_hint("r", "deg/s") + " (or unit_checks=False)", "r", i, value=r[i])
                if slope < -0.5 and clear:
                    warnings.warn(f"{where.label}: heading psi and yaw rate r have opposite signs "
                                  f"(d psi/dt = {slope:.2f} r); check the sign conventions", stacklevel=4)


# --------------------------------------------------------------------------------------
# file reading
# --------------------------------------------------------------------------------------


def _check_path(p: Path, what: str = "log file") -> None:
    if not p.exists():
        hint = ""
        parent = p.parent if str(p.parent) else Path(".")
        if parent.is_dir():
            near = sorted(x.name for x in parent.iterdir() if x.suffix.lower() == p.suffix.lower())[:5]
            if near:
                hint = f" (files there: {', '.join(near)})"
        raise LogError(f"`{p}`: {what} does not exist; check the path{hint}", path=p)
    if p.is_dir():
        raise LogError(f"`{p}`: is a directory, not a {what}; give the file inside it", path=p)


_HEADER_RE = re.compile(r"^\s*(?P<name>.*?)\s*(?:[\[(](?P<unit>[^\])]*)[\])])?\s*$")


def _split_header(cell: str) -> tuple[str, str | None]:
    m = _HEADER_RE.match(cell)
    name = m.group("name").strip().strip('"').strip()
    unit = m.group("unit")
    unit = unit.strip() if unit is not None else None
    return name, (unit if unit and unit != "-" else None)  # "[-]": no unit given


def _decode(raw: bytes, p: Path) -> str:
    if raw.startswith((b"\xff\xfe", b"\xfe\xff")):  # UTF-16 with BOM (Excel "Unicode text")
        try:
            return raw.decode("utf-16")
        except UnicodeDecodeError:
            pass
    nul = raw.find(b"\x00")
    if nul >= 0:
        line = raw.count(b"\n", 0, nul) + 1
        raise LogError(f"`{p.name}` row {line}: NUL byte at byte offset {nul}; this is a binary file, not a text "
                       "log: export the log as CSV text", path=p, row=line, value="\\x00")
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = raw.count(b"\n", 0, exc.start) + 1
        bad = raw[exc.start:exc.start + 1]
        # Latin-1 text (e.g. a degree sign from Excel) is readable; other bytes are not text
        if sum(1 for b in raw[:4096] if b < 9 or 13 < b < 32) == 0:
            try:
                text = raw.decode("cp1252")
            except UnicodeDecodeError:
                text = None
            if text is not None:
                return text
        raise LogError(f"`{p.name}` row {line}: byte 0x{bad.hex()} is not UTF-8 text; this looks like a binary "
                       "file: export the log as CSV text (UTF-8)", path=p, row=line, value=f"0x{bad.hex()}") from None


def _parse_meta(line: str, meta: dict) -> None:
    m = re.match(r"#\s*shipid-(log|ship):\s*(.*)$", line)
    if not m:
        return
    try:
        meta[m.group(1)] = json.loads(m.group(2))
    except json.JSONDecodeError:
        pass


def read_log(
    path: str | os.PathLike,
    *,
    columns: Mapping[str, str] | None = None,
    units: Mapping[str, str] | None = None,
    fmt: str = "auto",
    lpp: float | None = None,
    ship: ShipParticulars | Mapping | str | os.PathLike | None = None,
    interpolate_inputs: bool = False,
    inputs: Sequence[str] = ("delta", "n"),
    required: Sequence[str] = ("time", "u", "v", "r", "delta", "n"),
    min_samples: int = 20,
    delimiter: str | None = None,
    name: str | None = None,
    unit_checks: bool = True,
    marin_time: str = "uniform",
) -> TrialLog:
    """Read and validate a trial log.

    Parameters
    ----------
    path : str or path-like
        CSV file (default schema below) or MARIN SIMMAN ``.dat`` file.
    columns : dict, optional
        Our channel name -> the file's column name (with or without its
        bracketed unit), e.g. ``{"psi": "heading", "n": "prop_rpm"}``, or the
        column's 1-based number (``{"u": 5}``) when names are ambiguous.
    units : dict, optional
        Our channel name -> unit of the values in the file; one of s, m, rad,
        deg, m/s, knots (kn), rad/s, deg/s, rps, rpm, Hz.  Overrides a unit in
        the header.  Default: the header's bracketed unit, else SI/radians.
    fmt : {"auto", "csv", "marin"}
        File format; "auto" picks "marin" for a ``.dat`` file with the MARIN
        title line, else "csv".
    lpp : float, optional
        Length between perpendiculars [m]; sets/overrides ``ship.lpp``.
    ship : ShipParticulars, mapping or path to a JSON/YAML ship file, optional
        Particulars that travel with the log.  A MARIN file defaults to the
        bundled KVLCC2 particulars.
    interpolate_inputs : bool
        Fill blank cells of input channels by linear interpolation in time
        (reported in ``notes``); otherwise an input gap is an error.
    inputs : sequence of str
        Input channels (gaps are errors); other channels are measurements
        (gaps are NaN and reported in ``missing``).
    required : sequence of str
        Channels that must be present.
    min_samples : int
        Fewest samples accepted.
    delimiter : str, optional
        CSV delimiter.  Default ``","``: a file that is evidently separated by
        ``;``, tabs or spaces is refused with a message saying to pass
        ``delimiter=";"`` (or ``"\\t"``, ``"whitespace"``).
    name : str, optional
        Log name (default: the file stem, or the name stored by :meth:`TrialLog.to_csv`).
    unit_checks : bool
        Run the "looks like degrees" heuristics (docs/logs.md).
    marin_time : {"uniform", "drop"}
        MARIN files print time with 3 significant digits, so stamps repeat
        (1 s resolution after 100 s).  "uniform" (default) rebuilds the time
        base as ``t0 + k dt`` after verifying that it rounds to every printed
        stamp; "drop" keeps only the first sample of each repeated stamp.

    Returns
    -------
    TrialLog

    Raises
    ------
    LogError
        For any unusable input; the message names file, column, row (file
        line, 1-based), the value, and what to do.
    """
    p = Path(path)
    _check_path(p)
    try:
        raw = p.read_bytes()
    except PermissionError:
        raise LogError(f"`{p}`: cannot read the file (permission denied); check its permissions", path=p) from None
    import hashlib

    sha = hashlib.sha256(raw).hexdigest()
    if not raw.strip():
        raise LogError(f"`{p.name}`: file is empty; give a log with a header line and data rows", path=p)
    text = _decode(raw, p)
    if fmt not in ("auto", "csv", "marin"):
        raise ValueError(f"fmt={fmt!r}: use 'auto', 'csv' or 'marin'")
    if fmt == "auto":
        fmt = "marin" if _looks_marin(text) else "csv"
    ship_obj = _as_ship(ship, None)
    if fmt == "marin":
        if columns:
            raise ValueError("columns= does not apply to MARIN .dat files (their columns are fixed)")
        t, ch, where, units_in, notes = _read_marin(text, p, units or {}, marin_time)
        if ship_obj is None:
            ship_obj = _bundled_ship("kvlcc2")
            notes.append("ship particulars: bundled KVLCC2 (Lpp 320 m); pass ship= or lpp= to override")
        meta = {}
    else:
        t, ch, where, units_in, notes, meta = _read_csv(text, p, columns or {}, units or {}, required, delimiter)
        if ship_obj is None and isinstance(meta.get("ship"), Mapping):
            ship_obj = ShipParticulars.from_dict(meta["ship"], source=f"`{p.name}` shipid-ship line")
    ship_obj = _as_ship(ship_obj, lpp)
    if name is None:
        name = (meta.get("log") or {}).get("name") if isinstance(meta.get("log"), Mapping) else None
        name = name or p.stem
    where.name = name
    return _finish(t, ch, where=where, name=name, ship=ship_obj, path=p, sha256=sha, inputs=inputs,
                   interpolate_inputs=interpolate_inputs, required=required, min_samples=min_samples,
                   unit_checks=unit_checks, units_in=units_in, notes=notes, fmt=fmt)


# --- CSV --------------------------------------------------------------------------------

_DELIMS = {",": "comma", ";": "semicolon", "\t": "tab", "whitespace": "whitespace"}


def _read_csv(text: str, p: Path, columns: Mapping[str, str], units: Mapping[str, str],
              required: Sequence[str], delimiter: str | None):
    lines = text.splitlines()
    meta: dict = {}
    h = None
    for k, line in enumerate(lines):
        s = line.strip()
        if not s:
            continue
        if s.startswith("#"):
            _parse_meta(s, meta)
            continue
        h = k
        break
    if h is None:
        raise LogError(f"`{p.name}`: file has no header line (only blank or # comment lines); "
                       "give a header like 'time [s], x [m], ...' and data rows", path=p)
    header_line = lines[h]
    data_idx = [k for k in range(h + 1, len(lines)) if lines[k].strip()]
    # --- delimiter --------------------------------------------------------------
    if delimiter is None:
        delim = ","
        if "," not in header_line:
            # the header decides: a comma-free header holding ';' or a tab is a delimiter mistake
            shown = _fmt_value(header_line.strip())
            for cand, label, cli in ((";", "semicolon", ";"), ("\t", "tab", "tab")):
                if cand in header_line:
                    raise LogError(f"`{p.name}` row {h + 1}: the header has no commas but is {label}-separated "
                                   f"({shown}); pass delimiter={cand!r} (CLI: --delimiter {cli}) or save the file "
                                   "as comma-separated CSV", path=p, row=h + 1, value=header_line.strip())
            first = lines[data_idx[0]].split() if data_idx else []
            ntok = len(header_line.split())
            if ntok > 1 and len(first) == ntok and "," not in lines[data_idx[0]]:
                raise LogError(f"`{p.name}` row {h + 1}: the header has no commas but is whitespace-separated "
                               f"({shown}); pass delimiter='whitespace' (CLI: --delimiter whitespace) or save the "
                               "file as comma-separated CSV", path=p, row=h + 1, value=header_line.strip())
    else:
        delim = {"tab": "\t", "\\t": "\t", "space": "whitespace", "spaces": "whitespace"}.get(delimiter, delimiter)
        if delim not in _DELIMS:
            raise ValueError(f"delimiter={delimiter!r}: use ',', ';', '\\t' (tab) or 'whitespace'")

    def split(s: str) -> list[str]:
        if delim == "whitespace":
            return s.split()
        return next(csv.reader([s], delimiter=delim))

    hdr = [c.strip() for c in split(header_line)]
    if not hdr or all(not c for c in hdr):
        raise LogError(f"`{p.name}` row {h + 1}: empty header", path=p, row=h + 1)
    parsed = [_split_header(c) for c in hdr]
    names = [n for n, _ in parsed]
    # numeric header: the file has no header line
    if all(_is_number(n) for n in names if n):
        raise LogError(f"`{p.name}` row {h + 1}: the first line is numbers, not a header "
                       f"({_fmt_value(header_line.strip())}); add a header line like "
                       "'time [s], x [m], y [m], psi [rad], u [m/s], v [m/s], r [rad/s], delta [rad], n [rps]'",
                       path=p, row=h + 1, value=header_line.strip())
    # --- map file columns to our names ---------------------------------------------
    colmap: dict[str, int] = {}   # our name -> column index
    taken: set[int] = set()
    for ours, theirs in columns.items():
        if isinstance(theirs, (int, np.integer)) and not isinstance(theirs, bool):
            if not 1 <= theirs <= len(hdr):
                raise LogError(f"`{p.name}` row {h + 1}: columns maps '{ours}' to column number {theirs} but the "
                               f"header has {len(hdr)} columns (numbers count from 1)", path=p, column=ours,
                               row=h + 1, value=theirs)
            j = int(theirs) - 1
        else:
            j = _find_col(str(theirs), hdr, names)
            if j is None and str(theirs).strip().isdigit() and 1 <= int(theirs) <= len(hdr):
                j = int(theirs) - 1  # a column number given as text (CLI --column u=5)
        if j is None:
            raise LogError(f"`{p.name}` row {h + 1}: columns maps '{ours}' to '{theirs}' but the header has no such "
                           f"column; header: {', '.join(hdr)}", path=p, column=ours, row=h + 1, value=theirs)
        colmap[ours] = j
        taken.add(j)
    known = set(SHIP_CHANNELS) | set(required)
    for j, nm in enumerate(names):  # exact names of known channels
        if j in taken or nm not in known or nm in colmap:
            continue
        colmap[nm] = j
        taken.add(j)
    # case-insensitive fallback ("Time", "PSI") for known names, never stealing a known name ("U" stays U)
    for want in list(dict.fromkeys([*required, *SCHEMA])):
        if want in colmap:
            continue
        cands = [j for j, nm in enumerate(names)
                 if j not in taken and nm.lower() == want.lower() and nm not in SHIP_CHANNELS]
        if len(cands) == 1:
            colmap[want] = cands[0]
            taken.add(cands[0])
    missing_cols = [c for c in required if c not in colmap]
    if missing_cols:
        c = missing_cols[0]
        single = " (the header is a single column: is the file comma-separated?)" if len(hdr) == 1 else ""
        if _looks_marin(header_line):
            single = " (this looks like a MARIN .dat file: pass fmt='marin')"
        raise LogError(f"`{p.name}` row {h + 1}: required column '{c}' not found; header has "
                       f"{', '.join(repr(x) for x in hdr)}{single}; rename the column or map it with "
                       f"columns={{'{c}': 'your name'}} (CLI: --column {c}=NAME)", path=p, column=c, row=h + 1)
    header_units = {ours: parsed[j][1] for ours, j in colmap.items() if parsed[j][1] is not None}
    file_col = {ours: names[j] or hdr[j] for ours, j in colmap.items()}
    # --- data rows -----------------------------------------------------------------
    if not data_idx:
        raise LogError(f"`{p.name}`: header only, no data rows; the log needs samples below the header",
                       path=p, row=h + 1)
    ncol = len(hdr)
    rows_txt: list = []
    keep_rows: list[int] = []
    data_idx = [k for k in data_idx if not lines[k].lstrip().startswith("#")]
    fast = _fast_table(lines, data_idx, delim, ncol)
    if fast is not None:  # all cells numeric or blank, every row complete: pandas' C parser did the work
        table, keep = fast
        rows_txt = [None] * int(keep.sum())
        keep_rows = [k + 1 for k, ok in zip(data_idx, keep) if ok]
        data_idx = []
    if delim == "whitespace":
        split_rows = (lines[k].split() for k in data_idx)
    else:
        split_rows = csv.reader((lines[k] for k in data_idx), delimiter=delim)
    for k, cells in zip(data_idx, split_rows):
        s = lines[k]
        if (not cells or not cells[0].strip()) and all(not c.strip() for c in cells):  # bare delimiters
            continue
        if len(cells) != ncol:
            other = [d for d in (";", "\t") if d != delim and d in s]
            extra = f"; the row contains {_DELIMS[other[0]]}s: wrong delimiter?" if other and len(cells) == 1 else ""
            raise LogError(f"`{p.name}` row {k + 1}: {len(cells)} field(s) but the header has {ncol}{extra}; "
                           "fix the row (every row needs one cell per header column, blank = missing)",
                           path=p, row=k + 1, value=s.strip()[:60])
        rows_txt.append(cells)
        keep_rows.append(k + 1)
    if not rows_txt:
        raise LogError(f"`{p.name}`: header only, no data rows; the log needs samples below the header",
                       path=p, row=h + 1)
    rows = np.asarray(keep_rows, dtype=np.int64)
    where = _Where(p, p.stem, rows)
    cols = list(table.T) if fast is not None else list(zip(*rows_txt))
    arrays: dict[str, np.ndarray] = {}
    first_stamp = None
    for ours, j in colmap.items():
        if ours == "time" and fast is None and _ISO_RE.match(cols[j][0].strip()):
            arrays[ours] = _iso_seconds(cols[j], names[j] or hdr[j], where)
            first_stamp = cols[j][0].strip()
            continue
        arrays[ours] = _to_float(cols[j], ours, names[j] or hdr[j], where, decimal_comma=delim != ",")
    if "time" not in arrays:
        raise LogError(f"`{p.name}` row {h + 1}: no 'time' column; header has {', '.join(repr(x) for x in hdr)}; "
                       "map it with columns={'time': 'your name'}", path=p, column="time", row=h + 1)
    # unknown extra columns: keep when numeric, else ignore with a warning
    notes: list[str] = []
    if first_stamp is not None:
        notes.append(f"time given as date-time stamps; t = 0 s at {first_stamp}")
    order = ["time"] + [c for c in SCHEMA[1:] if c in arrays] + [c for c in arrays if c not in SCHEMA]
    arrays = {c: arrays[c] for c in order}
    for j, nm in enumerate(names):
        if j in taken:
            continue
        label = nm or f"column {j + 1}"
        empty = (np.isnan(cols[j]).all() if isinstance(cols[j], np.ndarray)
                 else all(not c.strip() for c in cols[j]))
        if not nm and empty:  # trailing delimiter: an empty unnamed column
            continue
        if not _mostly_numeric(cols[j]):
            notes.append(f"column '{hdr[j]}' is not numeric; ignored")
            warnings.warn(f"`{p.name}`: column '{hdr[j]}' is not numeric; ignored", stacklevel=3)
            continue
        # a mostly numeric column: a bad cell is an error
        if label in arrays and label in columns:
            notes.append(f"column '{hdr[j]}' ignored: columns= maps '{label}' to '{columns[label]}'")
            continue
        if label in arrays:
            first = next(jj for jj, nn in enumerate(names) if jj in taken and (nn == label or colmap.get(label) == jj))
            raise LogError(f"`{p.name}` row {h + 1}: column '{label}' appears twice (columns {first + 1} and "
                           f"{j + 1} of the header); rename one, or pick one by number with "
                           f"columns={{'{label}': {first + 1}}}",
                           path=p, column=label, row=h + 1, value=hdr[j])
        a = _to_float(cols[j], label, label, where, decimal_comma=delim != ",")
        arrays[label] = a
        if parsed[j][1] is not None:
            header_units[label] = parsed[j][1]
            file_col[label] = label
    t, ch, units_in = _convert_units(arrays, units, header_units, where, file_col)
    return t, ch, where, units_in, notes, meta


def _find_col(theirs: str, hdr: list[str], names: list[str]) -> int | None:
    t = theirs.strip()
    for cands in (hdr, names):
        hits = [j for j, c in enumerate(cands) if c == t]
        if len(hits) == 1:
            return hits[0]
    hits = [j for j, c in enumerate(names) if c.lower() == t.lower()]
    return hits[0] if len(hits) == 1 else None


_NA_TOKENS = ["", "nan", "NaN", "NAN", "na", "NA", "n/a", "N/A", "null", "NULL", "Null", "none", "None", "NONE",
              "-nan", "-NaN"]


# pandas < 3 parses floats with "high" precision by default (last-digit differences possible);
# pandas 3 deprecates the argument and parses exactly by default
_EXACT_FLOATS = {"float_precision": "round_trip"} if int(pd.__version__.split(".")[0]) < 3 else {}


def _fast_table(lines: list[str], data_idx: list[int], delim: str, ncol: int):
    """Parse the data rows with pandas' C parser when that is unambiguous, else None.

    Used only when no cell is quoted, every row has ``ncol`` fields and every cell is a
    number or a missing-value token; any irregularity returns None and the careful
    row-by-row path (which names the offending row and value) takes over.  Values are
    parsed exactly as Python's ``float`` does (round-trip precision).
    Returns (table (n_rows, ncol) float, keep mask dropping all-blank rows).
    """
    if len(data_idx) < 50:
        return None
    body = [lines[k] for k in data_idx]
    text = "\n".join(body)
    if '"' in text or "'" in text:
        return None
    if delim == "whitespace":
        if any(len(b.split()) != ncol for b in body):
            return None
        sep = r"\s+"
    else:
        if any(b.count(delim) != ncol - 1 for b in body):
            return None
        sep = delim
    try:
        df = pd.read_csv(io.StringIO(text), sep=sep, header=None, names=list(range(ncol)), dtype=float,
                         na_values=_NA_TOKENS, keep_default_na=False, skip_blank_lines=False, engine="c",
                         **_EXACT_FLOATS)
    except (ValueError, TypeError, pd.errors.ParserError):
        return None
    if len(df) != len(body):
        return None
    table = df.to_numpy(dtype=float)
    keep = ~np.isnan(table).all(axis=1)
    return table[keep], keep


def _mostly_numeric(cells) -> bool:
    if isinstance(cells, np.ndarray):
        return True
    vals = [c.strip() for c in cells if c.strip().lower() not in _MISSING_TOKENS]
    if not vals:
        return True
    return sum(_is_number(c) for c in vals[:200]) >= 0.5 * min(len(vals), 200)


def _is_number(s: str) -> bool:
    try:
        float(s)
        return True
    except ValueError:
        return False


_ISO_RE = re.compile(r"^\d{4}-\d{2}-\d{2}[T ]\d{2}:\d{2}")
_DECIMAL_COMMA_RE = re.compile(r"^[-+]?\d*,\d+([eE][-+]?\d+)?$")


def _iso_seconds(cells: Sequence[str], col: str, where: _Where) -> np.ndarray:
    """ISO 8601 date-time stamps -> seconds after the first one."""
    stamps = pd.to_datetime(pd.Series([c.strip() for c in cells]), format="ISO8601", errors="coerce")
    bad = stamps.isna().to_numpy()
    if bad.any():
        i = int(np.argmax(bad))
        raise where.error(f"value {cells[i].strip()!r} is not a date-time stamp like the first one "
                          f"({cells[0].strip()!r}); fix the cell (every sample needs a time)", col, i,
                          value=cells[i].strip())
    if getattr(stamps.dt, "tz", None) is not None:
        stamps = stamps.dt.tz_convert("UTC")
    ns = stamps.to_numpy().astype("datetime64[ns]").astype(np.int64)
    return (ns - ns[0]) * 1e-9


def _to_float(cells: Sequence[str], ours: str, col: str, where: _Where, decimal_comma: bool = False) -> np.ndarray:
    if isinstance(cells, np.ndarray) and cells.dtype.kind == "f":
        return cells.copy()
    try:
        return np.asarray(cells, dtype=float)  # fast path: no blanks, all numbers
    except ValueError:
        pass
    out = np.empty(len(cells))
    for i, c in enumerate(cells):
        s = c.strip()
        if s.lower() in _MISSING_TOKENS:
            out[i] = np.nan
            continue
        try:
            out[i] = float(s)
        except ValueError:
            if decimal_comma and _DECIMAL_COMMA_RE.match(s):
                out[i] = float(s.replace(",", "."))
                continue
            hint = ""
            if re.fullmatch(r"[-+]?\d+,\d+", s):
                hint = " (decimal comma? save the file with decimal points)"
            raise LogError(f"{where.place(col, i)}: value {s!r} is not a number{hint}; fix the cell or leave it "
                           "blank for a missing sample", path=where.path, column=ours, row=where.row_of(i),
                           value=s) from None
    return out


# --- MARIN SIMMAN .dat ------------------------------------------------------------------

_MARIN_COLS = ("time", "x", "y", "phi", "psi", "u_e", "v_e", "p", "r", "delta", "n")
_MARIN_UNITS = {"time": "s", "x": "m", "y": "m", "phi": "deg", "psi": "deg", "u_e": "m/s", "v_e": "m/s",
                "p": "deg/s", "r": "deg/s", "delta": "deg", "n": "rpm"}


def _looks_marin(text: str) -> bool:
    return text.lstrip()[:200].upper().startswith("MARIN")


def _read_marin(text: str, p: Path, units: Mapping[str, str], marin_time: str):
    if units:
        raise ValueError("units= does not apply to MARIN .dat files (their units are fixed: degrees, rpm)")
    if marin_time not in ("uniform", "drop"):
        raise ValueError(f"marin_time={marin_time!r}: use 'uniform' or 'drop'")
    lines = text.splitlines()
    start = None
    for k, line in enumerate(lines):
        if k >= 2 and line.strip() and _is_number(line.split()[0]):
            start = k
            break
        if k > 10:
            break
    if start is None:
        raise LogError(f"`{p.name}`: no data rows after the MARIN title lines; expected two title lines, a blank "
                       "line and rows of 11 numbers", path=p)
    idx = [k for k in range(start, len(lines)) if lines[k].strip()]
    fast = _fast_table(lines, idx, "whitespace", 11)
    if fast is not None and fast[1].all():
        a = fast[0]
        rows = np.asarray(idx, dtype=np.int64) + 1
        where = _Where(p, p.stem, rows)
    else:
        a, rows, where = _marin_rows(lines, idx, p)
    notes: list[str] = []
    t = a[:, 0].copy()
    # --- repeated (rounded) time stamps ------------------------------------------------
    d = np.diff(t)
    if (d < 0).any():
        i = int(np.argmax(d < 0)) + 1
        raise where.error(f"time {_fmt_value(t[i])} goes back from {_fmt_value(t[i - 1])}; the file is not in time "
                          "order", "time", i, value=t[i])
    nrep = int(np.sum(d == 0))
    if nrep:
        if marin_time == "uniform":
            tu, dev = _uniform_time(t)
            if tu is not None:
                notes.append(f"time printed with 3 significant digits: {nrep} repeated stamps; time rebuilt as "
                             f"t0 + k dt (dt = {tu[1] - tu[0]:.6g} s), which rounds to every printed stamp "
                             f"(max deviation {dev:.2f} of the printed resolution)")
                t = tu
            else:
                warnings.warn(f"`{p.name}`: time stamps are not consistent with uniform sampling; "
                              f"dropping {nrep} repeated stamps instead", stacklevel=3)
                marin_time = "drop"
        if marin_time == "drop":
            keep = np.concatenate([[True], d != 0])
            a, t, rows = a[keep], t[keep], rows[keep]
            where.rows = rows
            notes.append(f"{nrep} samples with a repeated time stamp dropped (first of each kept)")
    ch_units = dict(_MARIN_UNITS)
    arrays = {c: a[:, j] for j, c in enumerate(_MARIN_COLS)}
    arrays["time"] = t
    t2, ch, units_in = _convert_units(arrays, ch_units, {}, where)
    # earth-fixed (dx0/dt, dy0/dt) -> body axes by the heading
    ue, ve = ch.pop("u_e"), ch.pop("v_e")
    c, s = np.cos(ch["psi"]), np.sin(ch["psi"])
    ch_out = {"x": ch["x"], "y": ch["y"], "psi": ch["psi"],
              "u": ue * c + ve * s, "v": -ue * s + ve * c,
              "r": ch["r"], "delta": ch["delta"], "n": ch["n"], "phi": ch["phi"], "p": ch["p"]}
    units_in = {k: units_in.get(k, "") for k in ("time", "x", "y", "psi", "r", "delta", "n", "phi", "p")}
    units_in["u"] = units_in["v"] = "m/s (earth-fixed)"
    notes.append("u, v in the file are earth-fixed (dx0/dt, dy0/dt); rotated into body axes by psi")
    return t2, ch_out, where, units_in, notes


def _marin_rows(lines: list[str], idx: list[int], p: Path):
    """Careful row-by-row parse of MARIN data lines (names the row of any irregularity)."""
    rows_l, vals = [], []
    for k in idx:
        parts = lines[k].split()
        if len(parts) != 11:
            raise LogError(f"`{p.name}` row {k + 1}: {len(parts)} number(s), a MARIN row has 11 (time x0 y0 phi psi "
                           "u v p r delta rev); fix or delete the row", path=p, row=k + 1, value=lines[k].strip()[:60])
        rows_l.append(k + 1)
        vals.append(parts)
    rows = np.asarray(rows_l, dtype=np.int64)
    where = _Where(p, p.stem, rows)
    try:
        a = np.asarray(vals, dtype=float)
    except ValueError:
        cols = list(zip(*vals))
        for j, c in enumerate(_MARIN_COLS):
            _to_float(cols[j], c, c, where)
        raise  # pragma: no cover (_to_float raised)
    return a, rows, where


def _uniform_time(t: np.ndarray) -> tuple[np.ndarray | None, float]:
    """Fit t0 + k dt to stamps rounded to 3 significant digits; None when inconsistent."""
    k = np.arange(t.size, dtype=float)
    ulp = np.where(t != 0, 10.0 ** (np.floor(np.log10(np.abs(np.where(t != 0, t, 1.0)))) - 2), 1e-3)
    w = 1.0 / ulp
    # two candidates: anchored at the first stamp (dt by weighted least squares), and t0, dt both
    # fitted; keep the one that deviates least from the printed stamps
    dt = float(np.sum(k * w * (t - t[0]) * w) / np.sum((k * w) ** 2))
    cands = [t[0] + k * dt]
    # weighted least squares for (t0, dt) in closed form (no BLAS: threaded BLAS stalls on a busy machine)
    w2 = w * w
    sw, sk, skk = np.sum(w2), np.sum(w2 * k), np.sum(w2 * k * k)
    st, skt = np.sum(w2 * t), np.sum(w2 * k * t)
    det = sw * skk - sk * sk
    dt_free = (sw * skt - sk * st) / det
    t0_free = (st - dt_free * sk) / sw
    cands.append(t0_free + k * dt_free)
    devs = [float(np.max(np.abs(c - t) / ulp)) for c in cands]
    j = int(np.argmin(devs))
    tu, dev = cands[j], devs[j]
    if not tu[-1] > tu[0] or dev > 1.0:
        return None, dev
    return tu, dev
    A = np.stack([np.ones_like(k), k], axis=1)
    coef = np.linalg.lstsq(A * w[:, None], t * w, rcond=None)[0]
    tu = A @ coef
    dev = float(np.max(np.abs(tu - t) / ulp))
    if not coef[1] > 0 or dev > 1.0:
        return None, dev
    return tu, dev
