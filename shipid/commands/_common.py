"""Options and helpers shared by the sub-commands (one copy of each)."""
from __future__ import annotations

import warnings


def parse_pairs(items, option: str, convert=str) -> dict:
    """``["a=1,b=2", "c=3"]`` -> ``{"a": convert("1"), ...}``; ValueError naming the option otherwise
    (also for a name given twice, e.g. ``psi=deg,psi=rad``: which one was meant cannot be guessed)."""
    out: dict = {}
    for item in items or []:
        for part in item.split(","):
            if not part.strip():
                continue
            if "=" not in part:
                raise ValueError(f"{option} entry '{part}' must look like NAME=VALUE, e.g. psi=deg")
            k, v = part.split("=", 1)
            k = k.strip()
            if k in out:
                raise ValueError(f"{option}: '{k}' is given twice ({k}={out[k]} and {part.strip()}); give it once")
            try:
                out[k] = convert(v.strip())
            except ValueError:
                raise ValueError(f"{option} entry '{part}': '{v.strip()}' is not a valid value") from None
    return out


def add_log_options(p) -> None:
    """The options that say how to read trial logs: one copy for every command that reads logs
    (fit, log, metrics, validate, report); :func:`read_logs` applies them."""
    g = p.add_argument_group("reading the logs")
    g.add_argument("--lpp", type=float, default=None, help="ship length between perpendiculars [m]")
    g.add_argument("--ship", default=None, help="ship particulars file (JSON or YAML)")
    g.add_argument("--schema", default=None, metavar="FILE|PRESET",
                   help="how the file's columns map to channels: a preset (shipid, marin, esso-frt) or a JSON/YAML "
                        "schema file (columns, units, velocity_frame, rudder_sign, skip_rows, header, delimiter)")
    g.add_argument("--units", action="append", metavar="CH=UNIT", help="declare units, e.g. psi=deg,n=rpm")
    g.add_argument("--columns", "--column", dest="columns", action="append", metavar="CH=COLUMN",
                   help="map a channel to the file's column name (or 1-based number), e.g. psi=heading")
    g.add_argument("--delimiter", default=None, help="CSV delimiter if not a comma (';', tab or 'whitespace')")
    g.add_argument("--skip-rows", type=int, default=None, metavar="N",
                   help="skip N preamble lines before the header (or before the data with --no-header)")
    g.add_argument("--no-header", dest="header", action="store_false", default=None,
                   help="the file has no header line: map the channels by column number (--columns u=5)")
    g.add_argument("--velocity-frame", choices=["body", "earth"], default=None,
                   help="axes of the file's u, v: body (default) or earth-fixed dx/dt, dy/dt (rotated by psi)")
    g.add_argument("--rudder-sign", type=int, choices=[1, -1], default=None, metavar="{1,-1}",
                   help="-1 when the file's positive rudder turns the ship to port (flipped to shipid's "
                        "starboard-positive convention; the marin schema already does this)")
    g.add_argument("--format", dest="fmt", choices=["auto", "csv", "marin"], default="auto",
                   help="file format (default: auto)")
    g.add_argument("--interpolate-inputs", action="store_true", help="fill gaps in delta/n by interpolation")
    g.add_argument("--no-unit-checks", action="store_true",
                   help="skip the 'looks like degrees/rpm' heuristics (when a log trips them legitimately)")
    g.add_argument("--marin-time", choices=["uniform", "drop"], default="uniform",
                   help="MARIN .dat: rebuild the 3-digit time stamps (uniform, default) or drop repeats")
    g.add_argument("--no-consistency-checks", action="store_true",
                   help="skip the channel-consistency checks (r vs dpsi/dt, u, v vs the track, rudder sign vs the "
                        "first turn, n vs speed, GNSS freezes, glitches)")


def read_logs(paths, args) -> list:
    """Read ``paths`` with the options of :func:`add_log_options`; gap warnings are left to the caller
    (they are in each log's ``summary()``)."""
    from ..logs import read_log

    if args.skip_rows is not None and args.skip_rows < 0:
        raise ValueError(f"--skip-rows {args.skip_rows}: give a number of lines >= 0")
    kw = dict(units=parse_pairs(args.units, "--units") or None,
              columns=parse_pairs(args.columns, "--columns") or None,
              fmt=args.fmt, lpp=args.lpp, ship=args.ship, interpolate_inputs=args.interpolate_inputs,
              delimiter=args.delimiter, unit_checks=not args.no_unit_checks, marin_time=args.marin_time,
              schema=args.schema, skip_rows=args.skip_rows, header=args.header,
              velocity_frame=args.velocity_frame, rudder_sign=args.rudder_sign,
              consistency_checks=not args.no_consistency_checks)
    logs = []
    for path in paths:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)
            logs.append(read_log(path, **kw))
    return logs


def json_and_csv_outputs(output, force: bool):
    """``(out.json, out.csv)`` for commands that write a JSON summary with a CSV beside it.

    ValueError when the name does not end in .json, its folder is missing, or
    either file exists without ``--force``.
    """
    from pathlib import Path

    out = Path(output)
    if out.suffix.lower() != ".json":
        raise ValueError(f"{out}: the output must be a .json file (a CSV is written beside it)")
    csv = out.with_suffix(".csv")
    for f in (out, csv):
        if f.exists() and not force:
            raise ValueError(f"{f}: output exists; choose another name or pass --force to overwrite it")
    if not out.parent.exists():
        raise ValueError(f"{out}: folder {out.parent} does not exist; create it first")
    return out, csv
