"""``read_log``: open a log file, pick its format reader, validate into a :class:`TrialLog`."""
from __future__ import annotations

import hashlib
import os
import warnings
from importlib import resources
from pathlib import Path
from typing import Mapping, Sequence

from .._io import check_memory
from ._text import _check_path, _decode
from .marin import _looks_marin, _read_marin
from .schema import (OPTIONAL_CHANNELS, PRESETS, Schema, apply_conventions, check_frame, check_rudder_sign, check_signs,
                     load_schema, merged)
from .sensors import check_sensors, SensorWarning
from .ship import ShipParticulars, _as_ship, _bundled_ship, read_ship
from .shipid_csv import _read_csv
from .trial_log import LogError, TrialLog, _finish, _run_consistency
from .units import SCHEMA


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
    schema: "str | os.PathLike | Schema | Mapping | None" = None,
    velocity_frame: str | None = None,
    rudder_sign: float | None = None,
    signs: Mapping[str, float] | None = None,
    skip_rows: int | None = None,
    header: bool | None = None,
    consistency_checks: bool = True,
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
        deg, m/s, knots (kn), km/h, rad/s, deg/s, deg/min, rps, rpm, Hz.  Overrides a unit in
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
    schema : str, path, Schema or mapping, optional
        A preset (``"shipid"``, ``"marin"``, ``"esso-frt"``; see
        :data:`shipid.logs.schema.PRESETS`) or a schema file (JSON/YAML) that
        says which column holds which channel, units, velocity frame, rudder
        sign, rows to skip, header and delimiter.  The other arguments
        override it (``columns``/``units`` per channel).  Default: the
        ``shipid`` schema, or ``marin`` for an auto-detected MARIN file.
    velocity_frame : {"body", "earth"}, optional
        Axes of the file's u, v; ``"earth"`` (earth-fixed dx/dt, dy/dt) is
        rotated into body axes by the heading.  Default: the schema's.
    rudder_sign : {+1, -1}, optional
        Multiplies the file's rudder angle to give shipid's convention
        (positive delta turns to starboard).  Default: the schema's.
    signs : dict, optional
        Channel -> +1 or -1: channels whose sign the file has opposite to shipid's (e.g.
        ``{"r": -1, "v": -1}`` for a port-positive yaw rate and sway), merged into the schema's
        ``signs``; the rudder takes ``rudder_sign``.  CLI: ``--sign r=-1,v=-1``.
    skip_rows : int, optional
        Lines to skip before the header (or before the data without one).
    header : bool, optional
        False when the file has no header line; then ``columns`` gives
        1-based column numbers and unmapped columns are named ``col<k>``.
    consistency_checks : bool
        Run :func:`shipid.logs.check_consistency` on the log (yaw rate against
        dpsi/dt, velocities against the track, rudder sign against the first
        turn, propeller rate against speed, GNSS freezes, glitches): an error
        raises LogError, a warning is issued as ``UserWarning``; the result is
        ``log.consistency``.  CLI: ``--no-consistency-checks`` turns them off.

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
    check_log_memory(p)
    try:
        raw = p.read_bytes()
    except PermissionError:
        raise LogError(f"`{p}`: cannot read the file (permission denied); check its permissions", path=p) from None
    sha = hashlib.sha256(raw).hexdigest()
    if not raw or raw.isspace():  # (raw.strip() would copy the whole file)
        raise LogError(f"`{p.name}`: file is empty; give a log with a header line and data rows", path=p)
    text = _decode(raw, p)
    del raw  # the text is what is parsed; the bytes of a long log are not kept beside it
    if fmt not in ("auto", "csv", "marin"):
        raise ValueError(f"fmt={fmt!r}: use 'auto', 'csv' or 'marin'")
    if velocity_frame is not None:
        check_frame(velocity_frame)
    if rudder_sign is not None:
        check_rudder_sign(rudder_sign)
    if signs is not None:
        signs = check_signs(signs)
    if schema is not None:
        sch = load_schema(schema)
    elif fmt == "marin" or (fmt == "auto" and _looks_marin(text)):
        sch = PRESETS["marin"]
    else:
        sch = PRESETS["shipid"]
    sch = merged(sch, fmt=None if fmt == "auto" else fmt, columns=columns, units=units, delimiter=delimiter,
                 velocity_frame=velocity_frame, rudder_sign=rudder_sign, signs=signs, skip_rows=skip_rows,
                 header=header)
    ship_obj = _as_ship(ship, None)
    if sch.fmt == "marin":
        if columns:
            raise LogError(f"`{p.name}`: columns= (CLI: --columns) does not apply to a MARIN .dat file (its columns "
                           "are fixed); to read it as a table of your own, pass fmt='csv' (CLI: --format csv)", path=p)
        t, ch, where, units_in, notes = _read_marin(text, p, units or {}, marin_time)
        meta = {}
    else:
        # a schema's wind channels may be absent from a run (not those the caller maps by columns=)
        t, ch, where, units_in, notes, meta = _read_csv(text, p, sch.columns, sch.units, required, sch.delimiter,
                                                        skip_rows=sch.skip_rows, header=sch.header,
                                                        optional=set(OPTIONAL_CHANNELS) - set(columns or ()))
        if ship_obj is None and isinstance(meta.get("ship"), Mapping):
            ship_obj = ShipParticulars.from_dict(meta["ship"], source=f"`{p.name}` shipid-ship line")
    unknown = sorted(set(signs or ()) - set(ch))
    if unknown:
        raise LogError(f"`{p.name}`: signs for {unknown}, but the log has no such channel; its channels are "
                       f"{sorted(c for c in ch if c != 'time')}", path=p, column=unknown[0])
    for key, given in (("signs", sch.signs), ("meas_std", sch.meas_std)):  # the schema's own, as the options
        known = set(ch) | set(sch.columns or ()) | set(SCHEMA) | set(OPTIONAL_CHANNELS)
        unknown = sorted(str(c) for c in set(given or ()) - known)
        if unknown:
            raise LogError(f"`{p.name}`: schema '{sch.name}' gives {key} for {', '.join(unknown[:3])}, but the log has "
                           f"no such channel; its channels are {sorted(c for c in ch if c != 'time')}; fix the "
                           "schema's keys", path=p, column=unknown[0])
    apply_conventions(ch, units_in, notes, sch, where)
    if ship_obj is None and sch.ship is not None:
        ship_obj = _schema_ship(sch.ship)
        notes.append(f"ship particulars: bundled {ship_obj} (schema '{sch.name}'); pass ship= or lpp= to override")
    ship_obj = _as_ship(ship_obj, lpp)
    if name is None:
        name = (meta.get("log") or {}).get("name") if isinstance(meta.get("log"), Mapping) else None
        name = name or p.stem
    where.name = name
    log = _finish(t, ch, where=where, name=name, ship=ship_obj, path=p, sha256=sha, inputs=inputs,
                   interpolate_inputs=interpolate_inputs, required=required, min_samples=min_samples,
                   unit_checks=unit_checks, units_in=units_in, notes=notes, fmt=sch.fmt)
    log.meas_std = dict(sch.meas_std)
    reader_notes = {"truncated": meta.get("_truncated"), "lookalike": meta.get("_lookalike", [])}
    if consistency_checks:
        _run_consistency(log, reader_notes=reader_notes)
    else:  # the reader's own findings are said even without the channel checks
        for f in check_sensors(log, reader_notes=reader_notes):
            if f.check in ("truncated_row", "header_lookalike"):
                warnings.warn(f.message, SensorWarning, stacklevel=2)
    return log


#: Peak memory of reading a text log per row [bytes], with a margin: ``benchmarks/bench_log_memory.py``
#: measures 454 bytes a row above the imports on a 500 000-row, 9-column log of 71-byte rows (6.3 x the 72 bytes
#: a row of the finished log; 671 bytes, 9.3 x, before the table was parsed from bytes rather than a
#: 4-byte-a-character StringIO and the file's bytes were dropped once decoded).
LOG_BYTES_PER_ROW = 700


def check_log_memory(p: Path) -> None:
    """Refuse, before reading it, a log whose rows (estimated from the file's size and its first 64 kB) would
    need more memory than :func:`shipid._io.memory_limit_bytes`; one line with the estimate and the limit."""
    size = p.stat().st_size
    if size < 2**26:  # below 64 MiB no log can come near the limit
        return
    with open(p, "rb") as fh:
        head = fh.read(1 << 16)
    row = max(len(head) / max(head.count(b"\n"), 1), 8.0)
    rows = size / row
    check_memory(size + rows * LOG_BYTES_PER_ROW, f"`{p.name}`: reading about {rows:.3g} rows ({size / 2**20:.0f} MiB)",
                 "split the log into shorter runs, or raise the limit if the machine has the memory")


def _schema_ship(spec: str) -> ShipParticulars:
    """A schema's ship: a bundled ship name (``shipid/data_ships/NAME.json``) or a ship file path."""
    if resources.files("shipid").joinpath("data_ships", f"{spec}.json").is_file():
        return _bundled_ship(spec)
    return read_ship(spec)
