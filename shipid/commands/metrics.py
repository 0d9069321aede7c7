"""``shipid metrics``: standard-manoeuvre metrics (ITTC/IMO) of measured logs."""
from __future__ import annotations

import math
import sys
from pathlib import Path

from ._common import add_log_options, check_output_path, parse_zigzag, read_logs
from .simulate import _positive_lpp, _summary, _write_or_print


def register(sub) -> None:
    p = sub.add_parser("metrics", help="standard-manoeuvre metrics (ITTC/IMO) of measured logs -> JSON list",
                       description="Standard-manoeuvre metrics of measured logs (turning circle: advance, transfer, "
                                   "tactical and steady diameter; zigzag: overshoots, initial turning; ITTC 7.5-04-02-01 "
                                   "and the IMO MSC.137(76) criteria); a run that is no standard manoeuvre gives its "
                                   "steady turn when it holds one.  Prints a JSON list, one object per log.")
    p.add_argument("logs", nargs="+", metavar="LOG", help="trial logs (CSV or MARIN .dat)")
    add_log_options(p)   # --lpp (default: from the log's particulars), --schema, --units, ...
    p.add_argument("--kind", choices=("auto", "turning", "zigzag"), default="auto",
                   help="manoeuvre in the log: turning circle, zigzag, or auto (detected from the rudder "
                        "history, default)")
    p.add_argument("--zigzag", metavar="D/C", default=None,
                   help="nominal rudder/check angles [deg] of zigzag logs, e.g. 10/5 (default: read from each log, "
                        "the check angle from the heading deviation at the rudder reversals)")
    p.add_argument("--reference-offset", type=float, default=None, metavar="M",
                   help="logged point's distance forward of midship [m]; positions are moved to midship")
    p.add_argument("-o", "--output", default=None, help="JSON file to write (default: print)")
    p.add_argument("--force", action="store_true", help="overwrite the output file")
    p.set_defaults(handler=_metrics)


def _metrics(args) -> int:
    from .._io import dumps_json
    from ..manoeuvres import NotStandardManoeuvre, metrics

    if args.output:
        check_output_path(args.output, force=args.force, inputs=args.logs)
    _positive_lpp(args.lpp)
    if args.reference_offset is not None and not math.isfinite(args.reference_offset):
        raise ValueError(f"--reference-offset {args.reference_offset}: give the logged point's distance forward "
                         "of midship in metres (a finite number)")
    out = []
    rud, chk = parse_zigzag(args.zigzag) if args.zigzag else (None, None)
    logs = read_logs(args.logs, args)
    for f, log in zip(args.logs, logs):  # the logged point lies on the ship (bow sensors reach past the FP)
        L = args.lpp or getattr(getattr(log, "ship", None), "lpp", None)
        off = args.reference_offset
        if off is not None and abs(off) > (0.6 * L if L else 500.0):
            lim = f"within +/-0.6 Lpp = +/-{0.6 * L:.3g} m of midship" if L else "within 500 m of midship"
            raise ValueError(f"--reference-offset {off:.3g}: {Path(f).name}: the logged point must lie on the ship "
                             f"({lim}); give its distance forward of midship in metres")
    for f, log in zip(args.logs, logs):
        try:
            m = metrics(log, lpp=args.lpp, kind=args.kind, reference_offset=args.reference_offset, name=Path(f).name,
                        rudder_deg=rud, check_deg=chk)
        except NotStandardManoeuvre as exc:  # a run, not a bad input: its steady turn if it turns, else the reason
            out.append(_not_standard(f, log, args.lpp, exc))
            continue
        out.append({"file": str(f), **m.to_dict()})
    _write_or_print(dumps_json(out), args.output, args.force)
    if args.output:
        for d in out:
            print(_summary(d["file"], d))
    bad = [Path(d["file"]).name for d in out
           if d["manoeuvre"] is None or (d["manoeuvre"] == "steady turn" and not d["success"])]
    if bad:
        print(f"shipid metrics: warning: no standard-manoeuvre metrics or steady turn for {', '.join(bad)} (see "
              "their notes; judge such runs by shipid validate --horizon)", file=sys.stderr)
        return 1
    return 0


def _not_standard(f, log, lpp, exc) -> dict:
    """The entry of a run that is not a standard manoeuvre: the steady turn of its rudder hold when the hold turns
    at least STEADY_REPORT_DEG (manoeuvre "steady turn"), else no metrics (manoeuvre None); the reason in "note"."""
    from ..manoeuvres.run_metrics import reported_steady_turn

    print(f"note: {exc}", file=sys.stderr)
    st = reported_steady_turn(log, lpp=lpp, name=Path(f).name)
    if st is None:
        return {"file": str(f), "manoeuvre": None, "note": str(exc)}
    return {"file": str(f), "manoeuvre": "steady turn", **st.to_dict(), "note": str(exc)}
