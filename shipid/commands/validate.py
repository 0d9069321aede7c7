"""``shipid validate`` and ``shipid report``: check a fitted model against measured logs.

Both replay the model with each log's recorded rudder and propeller inputs
(:mod:`shipid.validation`); ``validate`` writes the comparison as a JSON list,
``report`` as one self-contained HTML page.
"""
from __future__ import annotations

import json
import math
import sys
from pathlib import Path


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
    p.add_argument("--schema", default=None, metavar="PRESET|FILE", help="log schema (e.g. esso-frt)")
    p.add_argument("--horizon", default="10,30,60", metavar="SECONDS",
                   help="multi-start open-loop prediction horizons [s], comma-separated (default 10,30,60; "
                        "'none' to skip): per log median/p90 position and median heading errors from starts "
                        "every --start-every s")
    p.add_argument("--start-every", type=float, default=5.0, help="spacing of the horizon starts [s] (default 5)")


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
    r.set_defaults(handler=_report)


def _check(args) -> Path:
    out = Path(args.output)
    if out.exists() and not args.force:
        raise ValueError(f"{out}: output exists; choose another name or pass --force to overwrite it")
    if out.resolve() in {Path(p).resolve() for p in [args.result, *args.logs]}:
        raise ValueError(f"{out}: the output would replace an input file; choose another name")
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
    from .._io import atomic_write_text
    from ..validation import validate

    out = _check(args)
    horizons = _horizons(args.horizon)
    logs = _read(args)
    res = validate(args.result, logs, args.lpp, rudder_sign=args.rudder_sign, closed_loop=not args.no_closed_loop)
    if horizons:
        for d, (h, _) in zip(res, _horizon_results(args, horizons, logs)):
            if h is None:
                continue
            d["horizon"] = h.summary()
            print(f"{d['name']}: horizon " + ", ".join(
                f"{e['seconds']:g} s median {e['position_error_median_m']:.3g} m ({e['n_starts']} starts"
                f"{', %d blow-ups' % e['n_blowups'] if e['n_blowups'] else ''})"
                for e in d["horizon"] if e["position_error_median_m"] is not None))
    atomic_write_text(out, json.dumps(res, indent=2, allow_nan=False) + "\n", force=args.force)
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


def _horizons(text: str) -> list[float]:
    if text is None or text.strip().lower() in ("", "none", "off", "0"):
        return []
    try:
        out = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise ValueError(f"--horizon {text}: give comma-separated seconds, e.g. 10,30,60") from None
    if not out or not all(math.isfinite(v) and v > 0 for v in out):
        raise ValueError(f"--horizon {text}: horizons must be positive numbers of seconds, e.g. 10,30,60")
    return out


def _horizon_results(args, horizons, logs) -> list:
    """``(HorizonResult, log)`` per log for ``--horizon``."""
    from ..validation import resolve_model
    from ..validation_horizon import horizon_prediction

    model, _ = resolve_model(args.result)
    out = []
    for lg in logs:
        if not {"x", "y", "psi"} <= set(getattr(lg, "data", lg).columns):
            print(f"note: {getattr(lg, 'name', 'log')}: no x, y, psi channels; horizon prediction skipped",
                  file=sys.stderr)
            out.append((None, lg))
            continue
        out.append((horizon_prediction(model, lg, horizons=horizons, start_every=args.start_every,
                                       rudder_sign=args.rudder_sign), lg))
    return out


def _read(args) -> list:
    """The logs, read with ``--schema`` when given (else by :func:`shipid.validation.load_logs`)."""
    from ..validation import load_logs

    if not getattr(args, "schema", None):
        return load_logs(args.logs, lpp=args.lpp)
    import warnings

    from ..logs import read_log

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        return [read_log(p, schema=args.schema, lpp=args.lpp) for p in args.logs]


def _report(args) -> int:
    from .._io import atomic_write_text
    from ..report import render_report
    from ..validation import resolve_model, validate_one

    out = _check(args)
    model, res = resolve_model(args.result)
    logs = _read(args)
    vals = [validate_one(model, lg, lpp=args.lpp, rudder_sign=args.rudder_sign, closed_loop=not args.no_closed_loop)
            for lg in logs]
    horizons = _horizons(args.horizon)
    hz = [h for h in _horizon_results(args, horizons, logs) if h[0] is not None] if horizons else None
    text = render_report(res, args.logs, title=args.title, validations=vals, horizons=hz)
    atomic_write_text(out, text, force=args.force)
    for v in vals:
        print(_line(v.to_dict()))
    print(f"wrote {out}")
    return 0 if all(v.simulation.success for v in vals) else 1
