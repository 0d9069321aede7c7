"""``shipid validate``: check a fitted model against measured logs (and the options ``shipid report`` shares).

``validate`` and ``report`` both replay the model with each log's recorded rudder and propeller inputs
(:mod:`shipid.validation`); ``validate`` writes the comparison as a JSON list,
``report`` as one self-contained HTML page.
"""
from __future__ import annotations

import math
import sys
from pathlib import Path

from ._common import add_log_options, add_progress_option, progress_iter, read_logs_for_result


def _common(p, model: bool = False) -> None:
    if model:
        p.add_argument("result", metavar="MODEL", help="the model to validate: a fit RESULT.json (written by `shipid "
                                                       "fit -o`) or a registered model MODEL[:SET], e.g. mmg:kvlcc2")
    else:
        p.add_argument("result", metavar="RESULT.json", help="fit result written by `shipid fit -o`")
    p.add_argument("logs", nargs="+", metavar="LOG", help="trial logs to replay (.csv, MARIN .dat)")
    # --lpp (default: from the log, then the model), --rudder-sign (-1: the file's rudder is positive to port;
    # the MARIN reader flips by itself), --schema, --units, ...: read exactly as `shipid fit` reads
    add_log_options(p)
    p.add_argument("--zigzag", metavar="D/C", default=None,
                   help="nominal rudder/check angles [deg] of the zigzag logs, e.g. 10/5 (default: read from each log)")
    p.add_argument("--no-closed-loop", action="store_true",
                   help="skip the model's own closed-loop standard manoeuvre matching each log (replay only)")
    p.add_argument("--force", action="store_true", help="overwrite an existing output")
    p.add_argument("--horizon", default="10,30,60", metavar="SECONDS",
                   help="multi-start open-loop prediction horizons [s], comma-separated (default 10,30,60; "
                        "'none' to skip): per log median/p90 position and median heading errors from starts "
                        "every --start-every s")
    p.add_argument("--start-every", type=float, default=5.0, help="spacing of the horizon starts [s] (default 5)")
    add_progress_option(p)


def register(sub) -> None:
    p = sub.add_parser("validate", help="replay a fitted model on logs: RMSE and measured vs predicted metrics (JSON)",
                       description="Replay a fitted model with each log's recorded inputs from its initial state and "
                                   "compare with the measurement: per-channel RMSE/NRMSE, track error, and the "
                                   "ITTC/IMO manoeuvre metrics of the log and of the replay.")
    _common(p, model=True)
    p.add_argument("-o", "--output", required=True, help="JSON file to write (a list, one object per log)")
    from ._draws import add_draws_option

    add_draws_option(p)
    p.set_defaults(handler=_validate)


def _check(args) -> Path:
    from ._common import check_output_path

    out = check_output_path(args.output, force=args.force, inputs=[args.result, *args.logs])
    if args.lpp is not None and not (math.isfinite(args.lpp) and args.lpp > 0):
        raise ValueError(f"--lpp {args.lpp}: give the ship length in metres (a positive number)")
    return out


def _zigzag(args):
    from ._common import parse_zigzag

    return parse_zigzag(args.zigzag) if args.zigzag else None


def _line(d: dict) -> str:
    rm = d["rmse"]
    parts = [f"{d['name']}: {d['manoeuvre'] or 'no standard manoeuvre'}"]
    for k in ("u", "v", "r"):
        if rm.get(k) is not None:
            parts.append(f"rmse_{k}={rm[k]:.3g}")
    if d.get("track_rmse_m") is not None:
        parts.append(f"track={d['track_rmse_m']:.3g} m")
    # predicted - measured: of the replay (the logged rudder), and of the model's own closed-loop standard
    # manoeuvre (its rudder law; what the ITTC/IMO goals judge) -- labelled, so the two are not confused
    for label, key in (("replay", "difference"), ("closed-loop", "standard_difference")):
        diffs = [f"d{k}={v:+.3f}" for k, v in (d.get(key) or {}).items()
                 if k in ("advance_L", "tactical_diameter_L", "overshoot1_deg", "overshoot2_deg") and v is not None]
        if diffs:
            parts.append(f"{label}: " + " ".join(diffs))
    st = d.get("steady_turn") or {}
    m, p = st.get("measured") or {}, st.get("predicted") or {}
    if m:
        txt = (f"steady turn (rudder {m['rudder_deg']:+.1f} deg held from t = {m['hold_start']:.0f} s): "
               + (f"D/L {m['steady_diameter_L']:.3g}" if m.get("steady_diameter_L") is not None else m["message"]))
        if m.get("steady_diameter_L") is not None and p.get("steady_diameter_L") is not None:
            txt += f", replay {p['steady_diameter_L']:.3g}"
        parts.append(txt)
    return " ".join(parts)


def _validate(args) -> int:
    from .._io import atomic_write_text, dumps_json
    from ..validation import resolve_model, validate_one
    from ._draws import check_draws, validate_draws

    out = _check(args)
    horizons = _horizons(args.horizon)
    model, result = resolve_model(args.result)  # read once
    if result is None and check_draws(args):
        raise ValueError(f"--draws needs a fit RESULT.json (the draws come from its covariance); {args.result} is a model")
    _print_grade(result)
    logs = read_logs_for_result(args, model)
    initial = _current_start(model, result)  # the replay and the horizon predictions start with it
    vals = [validate_one(model, lg, lpp=args.lpp, closed_loop=not args.no_closed_loop, zigzag_angles=_zigzag(args),
                         initial=initial) for lg in progress_iter(logs, args, "replaying logs")]
    res = [v.to_dict() for v in vals]
    validate_draws(args, args.result, vals, res)  # --draws N: intervals inside each "predicted" block
    if horizons:
        for d, (h, _) in zip(res, _horizon_results(args, horizons, logs, model, initial)):
            if h is None:
                continue
            d["horizon"] = h.to_records()
            print(f"{d['name']}: horizon " + ", ".join(
                f"{e['seconds']:g} s median {e['position_error_median_m']:.3g} m ({e['n_starts']} starts"
                f"{', %d blow-ups' % e['n_blowups'] if e['n_blowups'] else ''})"
                for e in d["horizon"] if e["position_error_median_m"] is not None))
    atomic_write_text(out, dumps_json(res), force=args.force)
    for d in res:
        print(_line(d))
        for n in d["notes"]:
            print(f"  note: {n}")
        miss = d.get("standard_missing") or []
        if miss:
            print(f"  closed-loop: {len(miss)} measured metric(s) not predicted: "
                  + "; ".join(f"{x['metric']}: {x['reason']}" for x in miss))
    n_miss = sum(len(d.get("standard_missing") or []) for d in res)
    if n_miss:
        print(f"closed-loop: {n_miss} measured metric(s) not predicted on "
              f"{sum(1 for d in res if d.get('standard_missing'))} of {len(res)} logs (standard_missing in the JSON)")
    print(f"wrote {out}")
    bad = [d["name"] for d in res if not d["replay"]["success"]]
    if bad:
        print(f"shipid validate: warning: replay diverged for {', '.join(bad)}", file=sys.stderr)
        return 1
    return 0


def _print_grade(result) -> None:
    """First line of ``validate`` and ``report``: the fit's verdict (for a defect, what it is; the coefficients
    are not to be trusted before it is fixed)."""
    if result is None:
        return
    from ..identify.verdict import verdict_of

    v = verdict_of(result)
    if v.grade in ("defect", "diverged"):
        first = v.reasons[0] if v.reasons else ""
        line = f"warning: this fit's verdict is {v.grade}: {first}" if first else f"warning: this fit's verdict is {v.grade}"
        print(line if len(line) <= 300 else line[:296].rsplit(" ", 1)[0] + " ...")
    else:
        print(f"fit verdict: {v.grade.replace('_', ' ')}")


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


def _horizon_results(args, horizons, logs, model, initial) -> list:
    """``(HorizonResult, log)`` per log for ``--horizon``, each prediction started with ``initial`` (the
    fit's start current, :func:`_current_start`)."""
    from ..validation.horizon import horizon_prediction

    out = []
    for lg in progress_iter(logs, args, f"open-loop predictions over {', '.join(f'{h:g}' for h in horizons)} s, "
                                        "logs"):
        if not {"x", "y", "psi"} <= set(getattr(lg, "data", lg).columns):
            print(f"note: {getattr(lg, 'name', 'log')}: no x, y, psi channels; horizon prediction skipped",
                  file=sys.stderr)
            out.append((None, lg))
            continue
        out.append((horizon_prediction(model, lg, horizons=horizons, start_every=args.start_every,
                                       initial=initial), lg))
    return out


def _current_start(model, result):
    """The start current of the replay and the predictions of a model with current states: the fit's
    ``current_start`` (the mean of its logs' estimated currents; said on stderr), else zero (said too); None for
    other models."""
    if "cx" not in model.state_names:
        return None
    start = (getattr(result, "settings", None) or {}).get("current_start")
    if start is None:
        print("note: the result carries no start current; the predictions start with no current", file=sys.stderr)
        return None
    print(f"note: the replay and the predictions start with the fit's current cx = {start['cx']:.4g}, cy = {start['cy']:.4g} m/s "
          f"({start.get('reason', 'from the fit')})", file=sys.stderr)
    return {"cx": float(start["cx"]), "cy": float(start["cy"])}


