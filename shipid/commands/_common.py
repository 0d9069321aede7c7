"""Options and helpers shared by the sub-commands (one copy of each)."""
from __future__ import annotations

import warnings


def parse_pairs(items, option: str, convert=str) -> dict:
    """``["a=1,b=2", "c=3"]`` -> ``{"a": convert("1"), ...}``; ValueError naming the option otherwise."""
    out: dict = {}
    for item in items or []:
        for part in item.split(","):
            if not part.strip():
                continue
            if "=" not in part:
                raise ValueError(f"{option} entry '{part}' must look like NAME=VALUE, e.g. psi=deg")
            k, v = part.split("=", 1)
            try:
                out[k.strip()] = convert(v.strip())
            except ValueError:
                raise ValueError(f"{option} entry '{part}': '{v.strip()}' is not a valid value") from None
    return out


def parse_zigzag(text: str, option: str = "--zigzag") -> tuple[float, float]:
    """``"10/5"`` -> ``(10.0, 5.0)``: a zigzag's rudder and check (heading) angles [deg], both positive;
    ``"10"`` means 10/10.  ValueError naming the option otherwise."""
    parts = str(text).split("/")
    try:
        vals = [float(v) for v in parts]
    except ValueError:
        vals = []
    if len(vals) == 1:
        vals = vals * 2
    if len(vals) != 2 or not all(v > 0 for v in vals):
        raise ValueError(f"{option} '{text}': give rudder/heading angles in degrees (rudder/check), e.g. 20/20 or 10/5")
    return vals[0], vals[1]


def add_log_options(p) -> None:
    """The options that say how to read trial logs (same for every command that reads logs)."""
    p.add_argument("--lpp", type=float, default=None, help="ship length between perpendiculars [m]")
    p.add_argument("--ship", default=None, help="ship particulars file (JSON or YAML)")
    p.add_argument("--units", action="append", metavar="CH=UNIT", help="declare units, e.g. psi=deg,n=rpm")
    p.add_argument("--columns", "--column", dest="columns", action="append", metavar="CH=COLUMN",
                   help="map a channel to the file's column name (or 1-based number), e.g. psi=heading")
    p.add_argument("--delimiter", default=None, help="CSV delimiter if not a comma (';', tab or 'whitespace')")
    p.add_argument("--format", dest="fmt", choices=["auto", "csv", "marin"], default="auto",
                   help="file format (default: auto)")
    p.add_argument("--interpolate-inputs", action="store_true", help="fill gaps in delta/n by interpolation")
    p.add_argument("--no-unit-checks", action="store_true",
                   help="skip the 'looks like degrees/rpm' heuristics (when a log trips them legitimately)")
    p.add_argument("--marin-time", choices=["uniform", "drop"], default="uniform",
                   help="MARIN .dat: rebuild the 3-digit time stamps (uniform, default) or drop repeats")


def read_logs(paths, args) -> list:
    """Read ``paths`` with the options of :func:`add_log_options`; gap warnings are left to the caller
    (they are in each log's ``summary()``)."""
    from ..logs import read_log

    kw = dict(units=parse_pairs(args.units, "--units") or None,
              columns=parse_pairs(args.columns, "--columns") or None,
              fmt=args.fmt, lpp=args.lpp, ship=args.ship, interpolate_inputs=args.interpolate_inputs,
              delimiter=args.delimiter, unit_checks=not args.no_unit_checks, marin_time=args.marin_time)
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
