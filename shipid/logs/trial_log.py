# Why one file: TrialLog and the checks every reader applies to a log (units, channels, heading) are one contract.
"""The :class:`TrialLog` object, :class:`LogError`, and the validation every reader shares.

Every reader (and :meth:`TrialLog.from_arrays`) converts its channels to SI with
:func:`_convert_units` and builds the log with :func:`_finish`, which checks time,
finiteness, plausibility and units ("looks like degrees"), fills input gaps when
asked, unwraps the heading and records missing samples and dropouts.
"""
from __future__ import annotations

import io
import json
import math
import os
import warnings
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np
import pandas as pd

from .._io import atomic_write_text
from ..results import ResultMixin, axes_column, in_degrees
from .consistency import check_consistency
from .sensors import check_sensors
from .errors import LogError, _fmt_value, _Where
from .ship import ShipParticulars, _as_ship
from .units import _UNKNOWN_DIMS, SCHEMA, SHIP_CHANNELS, SI_UNIT, UNITS, _units_for, unit_key

# physical plausibility limits (SI); see docs/logs.md
_ABSURD = {"speed": 100.0, "length": 1e8, "rate": 10.0, "revs": 1000.0, "time": 1e10, "angle": 1e6}
_GENERIC_ABSURD = 1e15
_CONTROL_ANGLES = ("delta", "fin")   # |value| > pi/2 rad looks like degrees
_ATTITUDE_ANGLES = ("phi", "theta")  # |value| > pi/2 rad looks like degrees
_RATE_DEG_LIMIT = 3.0                 # |rate| > 3 rad/s looks like deg/s
_RPM_SCORE = 200.0                    # n sqrt(Lpp) [rps m^0.5] above this looks like rpm


# --------------------------------------------------------------------------------------
# the log object
# --------------------------------------------------------------------------------------


class TrialLog(ResultMixin):
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
                 fmt: str = "arrays", sources: dict | None = None, meas_std: dict | None = None):
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
        #: channel -> the file column it was read from (e.g. ``"column 7 'r_angvelo [rad/s]'"``)
        self.sources = dict(sources or {})
        #: channel -> the sensor's noise standard deviation [SI] declared by the log's format
        #: (:attr:`shipid.logs.Schema.meas_std`); empty when the format declares none
        self.meas_std = dict(meas_std or {})
        #: :class:`shipid.logs.consistency.ConsistencyResult` when read_log ran the checks, else None
        self.consistency = None

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
        consistency_checks: bool = True,
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
        consistency_checks : bool
            Run :func:`shipid.logs.check_consistency` as :func:`read_log` does (an error raises
            LogError, a warning is a ``UserWarning``; the result is ``log.consistency``).  False for
            arrays already checked (e.g. a checked log resampled) or made by a model.
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
        log = _finish(t, arrays, where=where, name=name, ship=_as_ship(ship, None), path=None, sha256=None,
                      inputs=inputs, interpolate_inputs=interpolate_inputs, required=required,
                      min_samples=min_samples, unit_checks=unit_checks, units_in=units_in, notes=[], fmt="arrays")
        if consistency_checks:
            _run_consistency(log, opt_out="pass consistency_checks=False")
        return log

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

    # --- derived logs (every channel travels, extra channels such as wind included) -----
    def _derived(self, data: pd.DataFrame, rows: np.ndarray, note: str) -> "TrialLog":
        missing = {}
        for c in data.columns:
            gap = np.isnan(data[c].to_numpy())
            if gap.any():
                missing[c] = [int(r) for r in rows[gap]]
        t = data["time"].to_numpy()
        d = np.diff(t)
        dropouts = []
        if t.size > 2:
            med = float(np.median(d))
            dropouts = [(float(t[k]), float(t[k + 1])) for k in np.flatnonzero(d > 3.0 * med)]
        return TrialLog(data.reset_index(drop=True), name=self.name, ship=self.ship, path=self.path,
                        sha256=self.sha256, rows=rows, missing=missing, dropouts=dropouts, units_in=self.units_in,
                        notes=[*self.notes, note], fmt=self.fmt, sources=self.sources, meas_std=self.meas_std)

    def window(self, t_start: float | None = None, t_end: float | None = None) -> "TrialLog":
        """The samples with ``t_start <= time <= t_end`` [s] (None = open end), every channel kept.

        Raises
        ------
        ValueError
            When fewer than 2 samples fall inside.
        """
        t = self.time
        keep = np.ones(t.size, dtype=bool)
        if t_start is not None:
            keep &= t >= float(t_start)
        if t_end is not None:
            keep &= t <= float(t_end)
        if keep.sum() < 2:
            raise ValueError(f"log '{self.name}': window {t_start}..{t_end} s holds {int(keep.sum())} sample(s) "
                             f"of t = {t[0]:g}..{t[-1]:g} s; choose a window with at least 2 samples")
        return self._derived(self.data[keep], self.rows[keep], f"window t = {t_start}..{t_end} s")

    def resample(self, dt: float) -> "TrialLog":
        """The log on a uniform time base ``t0 + k dt`` [s] by linear interpolation, every channel kept.

        Heading ``psi`` is continuous (unwrapped) and is interpolated as is;
        other angle channels (e.g. ``wind_dir_true``, wrapped to [0, 2 pi)) are
        interpolated on their unwrapped values and wrapped back into their
        range ([0, 2 pi) when no value is negative, else [-pi, pi)).  A sample whose
        neighbours are not both finite is NaN (gaps are not bridged).  ``rows``
        of the result hold the file row of the nearest earlier sample.
        """
        dt = float(dt)
        if not (math.isfinite(dt) and dt > 0):
            raise ValueError(f"resample: dt = {dt!r} s must be finite and > 0")
        t = self.time
        n = int(math.floor((t[-1] - t[0]) / dt + 1e-9)) + 1
        if n < 2:
            raise ValueError(f"resample: dt = {dt:g} s leaves fewer than 2 samples in t = {t[0]:g}..{t[-1]:g} s")
        tn = t[0] + np.arange(n) * dt
        j = np.clip(np.searchsorted(t, tn, side="right") - 1, 0, t.size - 2)
        w = (tn - t[j]) / (t[j + 1] - t[j])
        units = self.units()
        out = {"time": tn}
        for c in self.channels:
            a = self.data[c].to_numpy()
            wrapped = units.get(c) == "rad" and c not in SHIP_CHANNELS
            if wrapped:
                ok = np.isfinite(a)
                lo = 0.0 if ok.any() and a[ok].min() >= 0.0 else -math.pi   # [0, 2 pi) or [-pi, pi)
                a = a.copy()
                a[ok] = np.unwrap(a[ok])
            v = a[j] * (1.0 - w) + a[j + 1] * w
            v = np.where(w == 0.0, a[j], np.where(w == 1.0, a[j + 1], v))  # exact at old samples
            if wrapped:
                v = (v - lo) % (2 * math.pi) + lo
            out[c] = v
        return self._derived(pd.DataFrame(out), self.rows[j], f"resampled to dt = {dt:g} s (linear)")

    def to_pandas(self) -> pd.DataFrame:
        """A copy of :attr:`data` indexed by time [s]."""
        return self.data.set_index("time", drop=True).copy()

    def __repr__(self) -> str:
        src = self.path.name if self.path is not None else "arrays"
        return f"TrialLog(name={self.name!r}, source={src!r}, samples={len(self)}, channels={self.channels})"

    @property
    def success(self) -> bool:
        """False when the channel-consistency checks found an error (:attr:`consistency`)."""
        return self.consistency is None or bool(self.consistency.success)

    @property
    def message(self) -> str:
        """One line: samples, time span and the consistency status."""
        t = self.time
        span = f", t = {t[0]:g} .. {t[-1]:g} s" if len(t) else ""
        cons = f"; {self.consistency.message.split(': ', 1)[-1]}" if self.consistency is not None else ""
        return f"log '{self.name}': {len(self)} samples{span}{cons}"

    def summary(self) -> pd.DataFrame:
        """One row per channel (angles in degrees): unit, finite samples, missing samples, min, mean, max."""
        u = self.units()
        rows = {}
        for c in self.channels:
            y, unit = in_degrees(self[c], u.get(c, ""))
            y = np.asarray(y, dtype=float)
            fin = y[np.isfinite(y)]
            rows[c] = {"unit": unit, "samples": int(fin.size), "missing": len(self.missing.get(c, [])),
                       "min": fin.min() if fin.size else np.nan, "mean": fin.mean() if fin.size else np.nan,
                       "max": fin.max() if fin.size else np.nan}
        return pd.DataFrame.from_dict(rows, orient="index", columns=["unit", "samples", "missing", "min", "mean", "max"])

    def _html_title(self) -> str:
        src = self.path.name if self.path is not None else "arrays"
        return f"TrialLog '{self.name}' ({src})"

    def _key_numbers(self) -> dict:
        k = {"samples": len(self), "dt [s] (median)": self.dt if len(self) > 1 else float("nan"),
             "ship": str(self.ship) if self.ship is not None else "not given", "dropouts": len(self.dropouts)}
        return k

    def __str__(self) -> str:
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
        if self.consistency is not None:
            lines.append(f"  consistency: {self.consistency.status} ({', '.join(self.consistency.checks)} checked)")
            for f in self.consistency.findings:
                lines.append(f"  {f.level}: {f.message}")
        return "\n".join(lines)

    def plot(self, ax=None, channels: Sequence[str] | None = None):
        """Plot each channel against time (one axes per channel); returns the axes.

        Angles and rates are shown in degrees for readability.
        """
        import matplotlib.pyplot as plt  # only when plotting: pyplot takes ~1 s to import

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
        key = unit_key(unit)
        if key not in UNITS:
            col = (columns_in_file or {}).get(name, name)
            raise LogError(f"{where.label} column '{col}': unknown unit {unit!r}; use one of "
                           "s, ms, min, h, m, km, nm (nautical mile), rad, deg, m/s, knots (kn), km/h, rad/s, "
                           "deg/s, deg/min, rps, rpm, Hz",
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



#: Velocity channels a log may leave out when it logs the track and the heading (x, y, psi): the identifier's filter
#: infers them (e.g. sea trials with GNSS positions and a gyro heading but no sway velocity).
TRACK_VELOCITIES = ("u", "v", "r")


def required_channels(required: Sequence[str], present) -> tuple[list, list]:
    """``required`` less the :data:`TRACK_VELOCITIES` that ``present`` (channel names) lacks while it holds x, y and
    psi, and a note for each one left out."""
    have = set(present)
    if not {"x", "y", "psi"} <= have:
        return list(required), []
    drop = [c for c in TRACK_VELOCITIES if c in required and c not in have]
    return ([c for c in required if c not in drop],
            [f"'{c}' not logged: the filter infers it from the track and heading (x, y, psi)" for c in drop])


def _finish(t: np.ndarray, ch: dict[str, np.ndarray], *, where: _Where, name: str, ship, path, sha256,
            inputs: Sequence[str], interpolate_inputs: bool, required: Sequence[str], min_samples: int,
            unit_checks: bool, units_in: dict, notes: list, fmt: str) -> TrialLog:
    """Validate SI arrays and build the TrialLog (shared by every reader)."""
    n = t.shape[0]
    required, unlogged = required_channels(required, ch)
    notes = [*notes, *unlogged]
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
    if where.rows is not None and n > 1:
        t = _drop_repeated_rows(t, ch, where, notes)
        n = t.shape[0]
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
        _check_channel(c, a, where, unit_checks, units_in.get(c))
    if unit_checks and "psi" in ch:
        _check_heading(t, ch, where, psi_unit=units_in.get("psi"))
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
                    dropouts=dropouts, units_in=units_in, notes=notes, fmt=fmt, sources=where.sources)


def _drop_repeated_rows(t: np.ndarray, ch: dict[str, np.ndarray], where: _Where, notes: list) -> np.ndarray:
    """A file row that repeats the row before it exactly (time and every channel; loggers that write a buffer
    twice) carries nothing new: it is dropped, with a note naming its rows (``ch`` and ``where.rows`` are
    updated in place).  A repeated time with any other value changed stays, for the time check to refuse."""
    rep = np.flatnonzero(np.diff(t) == 0) + 1
    if rep.size == 0:
        return t
    same = np.ones(rep.size, dtype=bool)
    for a in ch.values():
        same &= (a[rep] == a[rep - 1]) | (np.isnan(a[rep]) & np.isnan(a[rep - 1]))
    if not same.any():
        return t
    keep = np.ones(t.size, dtype=bool)
    keep[rep[same]] = False
    dropped = [int(r) for r in where.rows[~keep]]
    notes.append(f"{len(dropped)} row(s) repeating the row above exactly dropped (rows {_short_list(dropped)})")
    for c in ch:
        ch[c] = ch[c][keep]
    where.rows = where.rows[keep]
    return t[keep]


def _deg_hint(c: str, unit: str) -> str:
    return f"pass units={{'{c}': '{unit}'}} (CLI: --units {c}={unit}) or convert"


def _declared_misfit(c: str, a: np.ndarray, i: int, where: _Where, declared: str, why: str) -> LogError:
    """The unit a column was declared in (not SI) gives implausible values: say so, not "looks like deg"."""
    dim = SHIP_CHANNELS[c]
    tip = " (a marine rate of turn is in deg/min)" if dim == "rate" else ""
    return where.error(f"value {_fmt_value(a[i])} {SI_UNIT[dim]}, read as {declared}, is not plausible ({why}); "
                       f"check the unit declared for '{c}'{tip} (or unit_checks=False)", c, i, value=a[i])


def _check_channel(c: str, a: np.ndarray, where: _Where, unit_checks: bool, declared: str | None = None) -> None:
    """Finiteness and plausibility of one SI channel; ``declared``: the unit it was read in (when that is not
    SI, an implausible value blames that unit rather than suggesting degrees)."""
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
    if declared is not None and unit_key(declared) == unit_key(SI_UNIT[dim]):
        declared = None
    if unit_checks and dim == "rate" and _RATE_DEG_LIMIT < mx <= _RATE_DEG_LIMIT * 180 / math.pi:
        i = int(np.argmax(absa > _RATE_DEG_LIMIT))
        if declared:
            raise _declared_misfit(c, a, i, where, declared, f"|{c}| > {_RATE_DEG_LIMIT:g} rad/s is not a ship's "
                                   "turn rate")
        raise where.error(f"value {_fmt_value(a[i])} looks like deg/s (|{c}| > {_RATE_DEG_LIMIT:g} rad/s = "
                          f"{math.degrees(_RATE_DEG_LIMIT):.0f} deg/s is not a ship's turn rate); "
                          + _deg_hint(c, "deg/s") + " (or unit_checks=False if it really is rad/s)", c, i, value=a[i])
    if unit_checks and c in _CONTROL_ANGLES + _ATTITUDE_ANGLES and math.pi / 2 < mx <= 180.0:
        i = int(np.argmax(absa > math.pi / 2))
        kind = "rudder/fin angle" if c in _CONTROL_ANGLES else "roll/pitch angle"
        if declared:
            raise _declared_misfit(c, a, i, where, declared, f"a {kind} beyond 90 deg")
        raise where.error(f"value {_fmt_value(a[i])} looks like degrees (a {kind} beyond 90 deg = 1.571 rad); "
                          + _deg_hint(c, "deg") + " (or unit_checks=False if it really is radians)", c, i, value=a[i])
    limit = _ABSURD[dim]
    if dim == "angle" and c in _CONTROL_ANGLES + _ATTITUDE_ANGLES:
        limit = 180.0 if unit_checks else _ABSURD["angle"]
    if mx > limit:
        i = int(np.argmax(absa > limit))
        raise where.error(f"value {_fmt_value(a[i])} {SI_UNIT[dim]} is absurd for '{c}' (|value| > {limit:g} "
                          f"{SI_UNIT[dim]}); check the column and its unit", c, i, value=a[i])


def _psi_r_slope(t: np.ndarray, ch: dict[str, np.ndarray], ok: np.ndarray):
    """Regression slope of the heading increments on the integrated yaw rate (1 when both are in radians) over
    contiguous valid samples (no dropout, no 2 pi wrap): ``(slope, its standard error)``, or None when r is
    absent or the ship turns less than 0.2 rad in total (too little to judge)."""
    if "r" not in ch:
        return None
    psi, r = ch["psi"], ch["r"]
    dt = np.diff(t)
    med = float(np.median(dt))
    a, b = ok[:-1], ok[1:]
    contiguous = (b - a == 1) & (dt[a] <= 3 * med)
    jump = psi[b] - psi[a]
    good = contiguous & np.isfinite(r[a]) & np.isfinite(r[b]) & (np.abs(jump) <= math.pi)
    if good.sum() < 10:
        return None
    rdt = 0.5 * (r[a] + r[b])[good] * dt[a][good]
    dpsi = jump[good]
    turned = float(np.sum(np.abs(rdt)))
    den = float(np.sum(rdt * rdt))
    if not (turned > 0.2 and den > 0):  # at least ~11 deg of turning to judge
        return None
    slope = float(np.sum(dpsi * rdt) / den)
    m = int(good.sum())
    se = math.sqrt(max(float(np.sum((dpsi - slope * rdt) ** 2)) / (m - 1), 0.0) / den)
    return slope, se


def _check_heading(t: np.ndarray, ch: dict[str, np.ndarray], where: _Where, psi_unit: str | None = None) -> None:
    """Heuristics for a heading in degrees declared as radians (see docs/logs.md), and for one in radians
    declared as degrees (``psi_unit``: the unit the file declared)."""
    psi = ch["psi"]
    ok = np.flatnonzero(np.isfinite(psi))
    if ok.size < 2:
        return
    hint = _deg_hint("psi", "deg") + " (or unit_checks=False if it really is radians)"
    fit = _psi_r_slope(t, ch, ok)
    # (1) first valid heading outside +-2 pi: a log normally starts within one turn -- unless the yaw rate
    # confirms radians (d psi = integral of r within 20 %): an unwrapped heading after turns
    i0 = int(ok[0])
    radians = fit is not None and abs(fit[0] - 1.0) < 0.2 and abs(fit[0]) > 5 * fit[1]
    if abs(psi[i0]) > 2 * math.pi + 0.01 and not radians:
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
    if fit is not None:
        r = ch["r"]
        slope, se = fit
        # standard error of the slope: flag only slopes clearly away from both 0 (noise) and 1
        clear = abs(slope) > 5 * se and abs(abs(slope) - 1.0) > 5 * se
        if clear and 20.0 < abs(slope) < 200.0:
            i = int(ok[np.nanargmax(np.abs(psi[ok]))])
            raise where.error(f"value {_fmt_value(psi[i])} looks like degrees (heading changes "
                              f"{abs(slope):.1f} x faster than the integral of r; 57.3 = deg/rad); "
                              + hint, "psi", i, value=psi[i])
        if clear and 1 / 200.0 < abs(slope) < 1 / 20.0 and psi_unit is not None and \
                unit_key(psi_unit) in ("deg", "degree", "degrees") and \
                float(np.nanmax(np.abs(np.degrees(psi[ok])))) <= 2 * math.pi + 0.1:
            # declared degrees, yet the file's numbers never leave +-2 pi: the heading is in radians (r is not
            # to blame: it agrees with the heading read as radians)
            i = int(ok[np.nanargmax(np.abs(psi[ok]))])
            raise where.error(f"value {_fmt_value(math.degrees(psi[i]))} declared in deg looks like radians (the "
                              f"file's headings stay within +-2 pi and the integral of r changes {1 / abs(slope):.1f} "
                              "x faster than them read as degrees); declare units={'psi': 'rad'} (CLI: --units "
                              "psi=rad) or fix the header's unit", "psi", i, value=math.degrees(psi[i]))
        if clear and 1 / 200.0 < abs(slope) < 1 / 20.0:
            i = int(np.nanargmax(np.abs(r)))
            raise where.error(f"value {_fmt_value(r[i])} looks like deg/s (the integral of r changes "
                              f"{1 / abs(slope):.1f} x faster than the heading; 57.3 = deg/rad); "
                              + _deg_hint("r", "deg/s") + " (or unit_checks=False)", "r", i, value=r[i])
        if slope < -0.5 and clear:
            warnings.warn(f"{where.label}: heading psi and yaw rate r have opposite signs "
                          f"(d psi/dt = {slope:.2f} r); check the sign conventions", stacklevel=4)


def _run_consistency(log: TrialLog, opt_out: str = "or --no-consistency-checks", *,
                     reader_notes: dict | None = None) -> None:
    """Check the channels and the sensors (:mod:`shipid.logs.sensors`, with what the reader found in
    ``reader_notes``); errors raise LogError (all named, first in full, then ``opt_out``: how to skip the
    checks), warnings warn."""
    res = check_consistency(log)
    res.findings.extend(check_sensors(log, reader_notes=reader_notes))  # sensor faults, in the same structure
    order = {"error": 0, "warning": 1, "info": 2}
    res.findings.sort(key=lambda f: order.get(f.level, 3))
    log.consistency = res
    for f in res.warnings:
        warnings.warn(f.message, stacklevel=3)
    if res.errors:
        more = len(res.errors) - 1
        tail = f" (and {more} more consistency error(s))" if more else ""
        e = res.errors[0]
        raise LogError(e.message + tail + "; " + opt_out,
                       path=log.path, column=e.channels[0] if e.channels else None)
