"""``shipid validate`` and ``shipid report``: check a fitted model against measured logs.

Both replay the model with each log's recorded rudder and propeller inputs
(:mod:`shipid.validation`); ``validate`` writes the comparison as a JSON list,
``report`` as one self-contained HTML page.
"""
from __future__ import annotations

import math
import sys
from pathlib import Path

from ._common import add_progress_option, progress_iter


def _common(p) -> None:
    p.add_argument("result", metavar="RESULT.json", help="fit result written by `shipid fit -o`")
    p.add_argument("logs", nargs="+", metavar="LOG", help="trial logs to replay (.csv, MARIN .dat)")
    p.add_argument("--lpp", type=float, default=None, help="ship length [m] (default: from the log, then the model)")
    p.add_argument("--rudder-sign", type=float, choices=(1.0, -1.0), default=1.0, metavar="{1,-1}",
                   help="multiply the logged rudder angle by this before the replay (-1 for the MARIN KVLCC2 files, "
                        "whose positive rudder turns to port)")
    p.add_argument("--no-closed-loop", action="store_true",
                   help="skip the model's own closed-loop standard manoeuvre matching each log (replay only)")
    p.add_argument("--force", action="store_true", help="overwrite an existing output")


def register(sub) -> None:
    p = sub.add_parser("validate", help="replay a fitted model on logs: RMSE and measured vs predicted metrics (JSON)",
                       description="Replay a fitted model with each log's recorded inputs from its initial state and "
                                   "compare with the measurement: per-channel RMSE/NRMSE, track error, and the "
                                   "ITTC/IMO manoeuvre metrics of the log and of the replay.")
    _common(p)
    p.add_argument("-o", "--output", required=True, help="JSON file to write (a list, one object per log)")
    p.set_defaults(handler=_validate)

    r = sub.add_parser("report", help="write a self-contained HTML validation report of a fitted model",
                       description="One HTML file (figures embedded, no network): coefficients with sigma and 95 % "
                                   "intervals, correlation heat-map, identifiability warnings, measured vs replayed "
                                   "time series and tracks, residuals, the IMO table, versions and input hashes.")
    _common(r)
    r.add_argument("-o", "--output", required=True, help="HTML file to write")
    r.add_argument("--title", default=None, help="report title")
    add_progress_option(r)
    r.set_defaults(handler=_report)


def _check(args) -> Path:
    from ._common import check_output_path

    out = check_output_path(args.output, force=args.force, inputs=[args.result, *args.logs])
    if args.lpp is not None and not (math.isfinite(args.lpp) and args.lpp > 0):
        raise ValueError(f"--lpp {args.lpp}: give the ship length in metres (a positive number)")
    return out


def _line(d: dict) -> str:
    rm = d["rmse"]
    parts = [f"{d['name']}: {d['manoeuvre'] or 'no standard manoeuvre'}"]
    for k in ("u", "v", "r"):
        if rm.get(k) is not None:
            parts.append(f"rmse_{k}={rm[k]:.3g}")
    if d.get("track_rmse_m") is not None:
        parts.append(f"track={d['track_rmse_m']:.3g} m")
    for k, v in d["difference"].items():
        if k in ("advance_L", "tactical_diameter_L", "overshoot1_deg", "overshoot2_deg") and v is not None:
            parts.append(f"d{k}={v:+.3f}")
    return " ".join(parts)


def _validate(args) -> int:
    from .._io import atomic_write_text, dumps_json
    from ..validation import validate

    out = _check(args)
    res = validate(args.result, args.logs, args.lpp, rudder_sign=args.rudder_sign,
                   closed_loop=not args.no_closed_loop)
    atomic_write_text(out, dumps_json(res), force=args.force)
    for d in res:
        print(_line(d))
        for n in d["notes"]:
            print(f"  note: {n}")
    print(f"wrote {out}")
    bad = [d["name"] for d in res if not d["replay"]["success"]]
    if bad:
        print(f"shipid validate: warning: replay diverged for {', '.join(bad)}", file=sys.stderr)
        return 1
    return 0


def _report(args) -> int:
    from .._io import atomic_write_text
    from ..report import render_report
    from ..validation import load_logs, resolve_model, validate_one

    out = _check(args)
    model, res = resolve_model(args.result)
    vals = [validate_one(model, lg, lpp=args.lpp, rudder_sign=args.rudder_sign, closed_loop=not args.no_closed_loop)
            for lg in progress_iter(load_logs(args.logs, lpp=args.lpp), args, "replaying logs")]
    text = render_report(res, args.logs, title=args.title, validations=vals)
    atomic_write_text(out, text, force=args.force)
    for v in vals:
        print(_line(v.to_dict()))
    print(f"wrote {out}")
    return 0 if all(v.simulation.success for v in vals) else 1
