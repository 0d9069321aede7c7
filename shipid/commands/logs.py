"""``shipid log``: check trial logs (print what was read) and convert them to the SI CSV schema."""
from __future__ import annotations

import warnings


def register(sub) -> None:
    p = sub.add_parser(
        "log",
        help="check trial logs and print their summary; -o converts one to the SI CSV schema",
        description="Read and validate trial logs exactly as `shipid fit` would, print a summary of each "
                    "(samples, channels, units converted, missing samples with their rows, dropouts), "
                    "and optionally write one as a clean CSV in SI units and radians.",
    )
    p.add_argument("logs", nargs="+", metavar="LOG", help="trial log files (.csv, MARIN .dat)")
    p.add_argument("-o", "--output", default=None, metavar="OUT.csv",
                   help="write the (single) log as CSV in the default schema, SI units, radians")
    p.add_argument("--force", action="store_true", help="overwrite an existing output")
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
    p.set_defaults(handler=_log)


def _pairs(items, option: str) -> dict:
    out: dict = {}
    for item in items or []:
        for part in item.split(","):
            if not part.strip():
                continue
            if "=" not in part:
                raise ValueError(f"{option} entry '{part}' must look like CHANNEL=VALUE, e.g. psi=deg")
            k, v = part.split("=", 1)
            out[k.strip()] = v.strip()
    return out


def _log(args) -> int:
    from ..logs import read_log

    if args.output and len(args.logs) != 1:
        raise ValueError(f"-o/--output converts one log; got {len(args.logs)}: give one LOG with -o")
    kw = dict(units=_pairs(args.units, "--units") or None, columns=_pairs(args.columns, "--columns") or None,
              fmt=args.fmt, lpp=args.lpp, ship=args.ship, interpolate_inputs=args.interpolate_inputs,
              delimiter=args.delimiter, unit_checks=not args.no_unit_checks, marin_time=args.marin_time)
    for path in args.logs:
        with warnings.catch_warnings():  # gaps and dropouts are in the summary
            warnings.simplefilter("ignore", UserWarning)
            log = read_log(path, **kw)
        print(log.summary())
        if args.output:
            out = log.to_csv(args.output, force=args.force)
            print(f"wrote {out} ({len(log)} samples, SI units, radians, body-axis velocities)")
    return 0
