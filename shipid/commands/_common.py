"""Options and helpers shared by the sub-commands (one copy of each)."""
from __future__ import annotations

import argparse
import sys
import warnings

#: How long an old spelling keeps working (said in the notice it prints).
RENAMED_UNTIL = "the next release"


class _RenamedOption(argparse.Action):
    """A hidden old spelling of an option: stores into the new option's destination and says once, on stderr,
    what to use instead."""

    def __init__(self, option_strings, dest, *, new: str, note: str = "", **kwargs):
        self.new, self.note = new, note
        super().__init__(option_strings, dest, help=argparse.SUPPRESS, **kwargs)

    def __call__(self, parser, namespace, values, option_string=None):
        renamed_notice(parser.prog, option_string, self.new, self.note)
        setattr(namespace, self.dest, self.const if self.nargs == 0 else values)


def renamed_option(p, old: str, new: str, *, dest: str, note: str = "", flag: bool = False, **kwargs) -> None:
    """Add ``old`` to parser ``p`` as a hidden alias of the option ``new`` (same ``dest``): it works, is not
    listed in ``--help``, and prints one line on stderr naming ``new``.  ``flag``: an option without a value
    (stores True); ``kwargs`` (type, nargs, metavar) as the new option's."""
    if flag:
        kwargs = {"nargs": 0, "const": True}
    p.add_argument(old, dest=dest, action=_RenamedOption, new=new, note=note, default=argparse.SUPPRESS, **kwargs)


def renamed_notice(prog: str, old: str, new: str, note: str = "") -> None:
    """The one line an old spelling prints on stderr: what to use instead, and until when the old one works."""
    extra = f" ({note})" if note else ""
    print(f"{prog}: note: '{old}' is now '{new}'{extra}; '{old}' works until {RENAMED_UNTIL}", file=sys.stderr)


def split_model_option(args) -> None:
    """``--model MODEL[:SET]`` or ``--model RESULT.json`` of ``fit``/``crossval`` into the model name
    (``args.model``) and its start values (``args.params``: the set or the result file); ``auto[:...]`` is
    left as it is.  ValueError when the start values are named twice (with the old ``--params``)."""
    from pathlib import Path

    spec = str(args.model)
    if spec == "auto" or spec.startswith("auto:"):
        return
    if spec.lower().endswith(".json") or Path(spec).is_file():
        name, start = None, spec
    else:
        name, colon, start = spec.partition(":")
        if not colon:
            return
    if getattr(args, "params", None) is not None:
        raise ValueError(f"--model {spec} already names the start values; drop --params {args.params}")
    if name is None:
        from ..identify.result import load_result

        name = load_result(start).model
    args.model, args.params = name, start or None


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
    g.add_argument("--sign", action="append", metavar="CH=-1",
                   help="channels whose sign the file has opposite to shipid's, e.g. r=-1,v=-1 (negated on reading; "
                        "the rudder takes --rudder-sign)")
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
    (they are in each log's ``summary()``), consistency warnings are re-issued (one per finding)."""
    from ..logs import read_log

    if args.skip_rows is not None and args.skip_rows < 0:
        raise ValueError(f"--skip-rows {args.skip_rows}: give a number of lines >= 0")
    signs = parse_pairs(getattr(args, "sign", None), "--sign")
    for k, v in signs.items():
        if k == "delta":
            raise ValueError("--sign delta: give the rudder's sign with --rudder-sign -1")
        if v not in ("1", "+1", "-1"):
            raise ValueError(f"--sign {k}={v}: give +1 or -1 (the channel is negated for -1), e.g. --sign r=-1,v=-1")
        signs[k] = float(v)
    kw = dict(units=parse_pairs(args.units, "--units") or None, signs=signs or None,
              columns=parse_pairs(args.columns, "--columns") or None,
              fmt=args.fmt, lpp=args.lpp, ship=args.ship, interpolate_inputs=args.interpolate_inputs,
              delimiter=args.delimiter, unit_checks=not args.no_unit_checks, marin_time=args.marin_time,
              schema=args.schema, skip_rows=args.skip_rows, header=args.header,
              velocity_frame=args.velocity_frame, rudder_sign=args.rudder_sign,
              consistency_checks=not args.no_consistency_checks)
    from ..logs.sensors import SensorWarning

    logs = []
    by_check: dict = {}
    for path in paths:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("ignore", UserWarning)
            warnings.simplefilter("always", SensorWarning)
            logs.append(read_log(path, **kw))
        for w in caught:  # what the reader found without the channel checks (a cut last row, look-alikes)
            if issubclass(w.category, SensorWarning):
                warnings.warn(str(w.message), UserWarning, stacklevel=2)
        for f in (logs[-1].consistency.warnings if logs[-1].consistency is not None else []):
            by_check.setdefault(f.check, []).append((len(logs) - 1, f))
    # consistency warnings (GNSS freezes, a loose yaw rate, rpm?) matter to every command: a finding of one log
    # is said as it is; one that several logs share, once, with their count and the first log's words
    for check, found in by_check.items():
        n = len({i for i, _ in found})
        if n == 1:
            for _, f in found:
                warnings.warn(f.message, UserWarning, stacklevel=2)
        else:
            what = CHECK_WORDS.get(check, check.replace("_", " "))
            warnings.warn(f"{n} of {len(logs)} logs ({what}; `shipid log FILE` lists each), the first: "
                          f"{found[0][1].message}", UserWarning, stacklevel=2)
    return logs


#: Plain words for the consistency checks, for a finding that several logs share.
CHECK_WORDS = {
    "position_freeze": "GNSS positions freeze", "yaw_rate_scale": "gyro scale", "yaw_rate": "yaw rate against heading",
    "glitches": "single-sample spikes", "velocity_frame": "velocities against the track",
    "rudder_sign": "rudder sign", "propeller": "propeller rate", "propeller_dead": "propeller channel still",
    "truncated_row": "last row cut short",
    "header_lookalike": "look-alike header characters",
}



def read_logs_for_result(args, model=None) -> list:
    """The logs of ``args.logs`` for the fit result ``args.result`` (or its ``model``), read as ``shipid fit``
    reads them (``validate``, ``report``, ``sample``); for a wind-aware model (true-wind inputs) a log with only the
    apparent wind gets the true wind in memory, said once per log on stderr (as ``fit --wind``)."""
    from ..environment.cli import true_wind_at_edge
    from ..environment.model import WIND_INPUTS
    from ..validation import resolve_model

    logs = read_logs(args.logs, args)
    model = model if model is not None else resolve_model(args.result)[0]
    if set(WIND_INPUTS) <= set(model.input_names):
        true_wind_at_edge(logs, what="wind-aware model", say=True)
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
    """``--progress`` / ``--no-progress`` (bars on stderr; default: on when stderr is a terminal) and ``--quiet``
    (no bars, no stage lines, no notices: only the results)."""
    p.add_argument("--progress", dest="progress", action="store_true", default=None,
                   help="show progress bars (default: on when stderr is a terminal; otherwise one line per stage)")
    p.add_argument("--no-progress", dest="progress", action="store_false",
                   help="no progress bars (the stage lines stay)")
    p.add_argument("--quiet", action="store_true", help="print the results only: no progress bars, stage lines or notices")


def say(args, line: str) -> None:
    """Print a stage line (what starts now and how big it is) unless ``--quiet``."""
    if not getattr(args, "quiet", False):
        print(line, flush=True)


def progress_iter(items, args, desc: str):
    """``items`` wrapped in a tqdm bar when :func:`progress_on`; otherwise unchanged, after one stage line
    ("DESC (N) ...") unless ``--quiet``."""
    if not progress_on(args):
        items = list(items)
        say(args, f"{desc} ({len(items)}) ...")
        return items
    from tqdm.auto import tqdm

    return tqdm(items, desc=desc, leave=False)


def progress_on(args) -> bool:
    """Whether to show progress for ``args`` (see :func:`add_progress_option`)."""
    import sys

    if getattr(args, "quiet", False):
        return False
    value = getattr(args, "progress", None)
    if value is None:
        return bool(getattr(sys.stderr, "isatty", lambda: False)())
    return bool(value)


#: Units of the channels that appear in CSV outputs (SI, radians), for the headers.
CHANNEL_UNITS = {"time": "s", "t": "s", "x": "m", "y": "m", "psi": "rad", "u": "m/s", "v": "m/s", "r": "rad/s",
                 "p": "rad/s", "phi": "rad", "delta": "rad", "n": "rps", "T": "N", "phi_p": "rad"}


def units_header(frame, model=None, units=None):
    """``frame`` with ``name [unit]`` column (and index) names where the unit is known
    (``units`` first, then the model's ``units``, then :data:`CHANNEL_UNITS`); other names unchanged."""
    table = dict(CHANNEL_UNITS)
    if model is not None:
        table.update(getattr(model, "units", {}) or {})
    table.update(units or {})
    units = table

    def label(name):
        unit = units.get(str(name))
        return f"{name} [{unit}]" if unit and "[" not in str(name) else name

    out = frame.rename(columns=label)
    if out.index.name is not None:
        out.index = out.index.rename(label(out.index.name))
    return out


def output_command(sub, name, handler, help, description, *, positional, output_help, output_metavar=None,
                   force_help="overwrite an existing output"):
    """A sub-command that writes one output (``sample``, ``campaign``): its positional arguments
    (``(name, metavar, help[, nargs])``), the required ``-o/--output`` and ``--force``."""
    p = sub.add_parser(name, help=help, description=description)
    for dest, metavar, text, *nargs in positional:
        p.add_argument(dest, metavar=metavar, help=text, **({"nargs": nargs[0]} if nargs else {}))
    p.add_argument("-o", "--output", required=True, metavar=output_metavar, help=output_help)
    p.add_argument("--force", action="store_true", help=force_help)
    p.set_defaults(handler=handler)
    return p
