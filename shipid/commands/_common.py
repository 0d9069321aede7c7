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


def json_and_csv_outputs(output, force: bool, inputs=()):
    """``(out.json, out.csv)`` for commands that write a JSON summary with a CSV beside it.

    ValueError when the name does not end in .json, its folder is missing or
    not writable, either file is one of ``inputs``, or either exists without
    ``--force`` (checked before any computation).
    """
    from pathlib import Path

    out = Path(output)
    if out.suffix.lower() != ".json":
        raise ValueError(f"{out}: the output must be a .json file (a CSV is written beside it)")
    csv = out.with_suffix(".csv")
    for f in (out, csv):
        check_output_path(f, force=force, inputs=inputs)
    return out, csv


def check_output_path(path, *, force: bool, inputs=(), what: str = "output"):
    """The output checks of :func:`shipid._io.check_output_path` (before a long computation)."""
    from .._io import check_output_path as check

    return check(path, force=force, inputs=inputs, what=what)


def add_progress_option(p) -> None:
    """``--progress`` / ``--no-progress``; default: on when stderr is a terminal."""
    p.add_argument("--progress", dest="progress", action="store_true", default=None,
                   help="show progress (default: on when stderr is a terminal)")
    p.add_argument("--no-progress", dest="progress", action="store_false", help="no progress output")


def progress_iter(items, args, desc: str):
    """``items`` wrapped in a tqdm bar when :func:`progress_on` (else unchanged)."""
    if not progress_on(args):
        return items
    from tqdm.auto import tqdm

    return tqdm(items, desc=desc, leave=False)


def progress_on(args) -> bool:
    """Whether to show progress for ``args`` (see :func:`add_progress_option`)."""
    import sys

    value = getattr(args, "progress", None)
    if value is None:
        return bool(getattr(sys.stderr, "isatty", lambda: False)())
    return bool(value)


#: Units of the channels that appear in CSV outputs (SI, radians), for the headers.
CHANNEL_UNITS = {"time": "s", "t": "s", "x": "m", "y": "m", "psi": "rad", "u": "m/s", "v": "m/s", "r": "rad/s",
                 "p": "rad/s", "phi": "rad", "delta": "rad", "n": "rps", "T": "N", "phi_p": "rad"}


def units_header(frame, model=None):
    """``frame`` with ``name [unit]`` column (and index) names where the unit is known
    (the model's ``units`` first, then :data:`CHANNEL_UNITS`); other names unchanged."""
    units = dict(CHANNEL_UNITS)
    if model is not None:
        units.update(getattr(model, "units", {}) or {})

    def label(name):
        unit = units.get(str(name))
        return f"{name} [{unit}]" if unit and "[" not in str(name) else name

    out = frame.rename(columns=label)
    if out.index.name is not None:
        out.index = out.index.rename(label(out.index.name))
    return out
