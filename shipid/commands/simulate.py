"""``shipid simulate``: a standard manoeuvre of a model, and the model helpers ``metrics`` and ``sweep`` share.

``MODEL`` arguments accept either a fit-result JSON (``{"model": name, "coef": {...}}``, optionally
``"model_options"`` passed to the model, e.g. MMG particulars) or a registered model name with an
optional parameter set, e.g. ``mmg``, ``mmg:kcs``, ``kcs-response:synthetic-truth``.
"""
from __future__ import annotations

import math
import sys

from ._common import check_output_path, parse_zigzag, renamed_option

#: Help text of a MODEL argument (one way to name a model in every command).
MODEL_HELP = "a registered model, optionally with a parameter set (MODEL[:SET], e.g. mmg:kvlcc2), or a fit RESULT.json"

#: Keys printed in the short metric summaries.
SUMMARY_KEYS = ("advance_L", "transfer_L", "tactical_diameter_L", "steady_diameter_L", "speed_loss",
                "overshoot1_deg", "overshoot2_deg", "time_second_execute", "initial_turning_L")


def register(sub) -> None:
    p = sub.add_parser("simulate", help="simulate a standard manoeuvre with a model (prints its metrics)",
                       description="Simulate a turning circle or a zigzag with a model (a fit result or a registered "
                                   "model with a parameter set) from a steady approach, and print its metrics with the "
                                   "IMO criteria; --draws propagates the fit's uncertainty to the metrics.")
    p.add_argument("model", metavar="MODEL", help=MODEL_HELP)
    g = p.add_mutually_exclusive_group(required=True)
    g.add_argument("--turning", type=float, metavar="DEG", help="turning circle with this rudder angle [deg]")
    g.add_argument("--zigzag", metavar="D/C", help="zigzag rudder/check (heading) angles [deg], e.g. 20/20 or 10/5")
    _common(p)
    p.add_argument("--side", choices=("both", "starboard", "port"), default="both",
                   help="turning side / side of the first zigzag execute")
    p.add_argument("-o", "--output", default=None,
                   help="CSV of the time series, units in the headers (with --side both: both turns, column 'run')")
    p.add_argument("--force", action="store_true", help="overwrite the output file")
    from ._draws import add_draws_option

    add_draws_option(p)
    p.add_argument("--metrics-output", default=None, metavar="FILE",
                   help="with --draws: JSON of the metrics with 95 %% intervals and IMO probabilities")
    p.set_defaults(handler=_simulate)


def _common(p):
    p.add_argument("--speed", type=float, default=None, help="approach speed [m/s] (default: design speed)")
    p.add_argument("--lpp", type=float, default=None,
                   help="ship length [m]: Froude-scale the model to this ship (default: the length it was fitted at)")
    p.add_argument("--rudder-rate", type=float, default=None, metavar="DEG_S", help="rudder rate [deg/s]")
    _integrator(p)


def _integrator(p):
    p.add_argument("--integrator", choices=("rk4", "dopri5"), default="rk4",
                   help="integrator: fixed-step RK4 (default) or adaptive Dormand-Prince 5(4) (faster at equal accuracy)")
    renamed_option(p, "--method", "--integrator", dest="integrator", choices=("rk4", "dopri5"))
    p.add_argument("--rtol", type=float, default=1e-6, help="relative tolerance of --integrator dopri5 (default 1e-6)")


def _rtol(args) -> float:
    if not (0.0 < args.rtol < 1.0):
        raise ValueError(f"--rtol {args.rtol!r}: give a relative tolerance between 0 and 1, e.g. 1e-6")
    return args.rtol


def load_model(spec: str, lpp: float | None = None):
    """Model from a fit-result JSON path or ``name[:parameter-set]`` (ValueError naming the problem), at
    the ship length it was fitted at, or Froude-scaled to ``lpp`` [m] when given and the model can be
    (``scaled``); a model that cannot be rescaled keeps its coefficients and ``lpp`` only sets the
    length of the manoeuvre (step, execute time, non-dimensional metrics), as before."""
    from ..identify.result import model_from

    model = model_from(spec)[0]
    ml = getattr(model, "lpp", None)
    if lpp is not None and ml is not None and abs(ml / lpp - 1.0) > 1e-12 and hasattr(model, "scaled"):
        print(f"note: {model.name} Froude-scaled from Lpp {ml:g} m to {lpp:g} m", file=sys.stderr)
        model = model.scaled(lpp)
    return model


def _floats(text: str, what: str) -> list[float]:
    try:
        vals = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise ValueError(f"{what} '{text}': give comma-separated numbers, e.g. 10,15,25") from None
    if not vals:
        raise ValueError(f"{what}: no values given")
    if not all(math.isfinite(v) for v in vals):
        raise ValueError(f"{what} '{text}': give finite numbers, e.g. 10,15,25")
    return vals


def _write_or_print(text: str, output, force: bool):
    from .._io import atomic_write_text

    if output:
        atomic_write_text(output, text, force=force)
    else:
        sys.stdout.write(text)


def _summary(label, d) -> str:
    if d["manoeuvre"] is None:
        return f"{label}: no standard manoeuvre"
    parts = [f"{k}={d[k]:.3f}" for k in SUMMARY_KEYS + ("time_360_s",) if isinstance(d.get(k), float)]
    if d["manoeuvre"] == "steady turn":
        parts.insert(0, f"hold {d['rudder_deg']:+.1f} deg from t = {d['hold_start']:.0f} s, "
                        f"{d['heading_change_deg']:.0f} deg" + ("" if d["success"] else f" ({d['message']})"))
    side = d.get("side") or d.get("first_side")
    return f"{label}: {d['manoeuvre']} ({side}) " + " ".join(parts)


def _positive_lpp(lpp) -> None:
    if lpp is not None and not (math.isfinite(lpp) and lpp > 0):
        raise ValueError(f"--lpp {lpp}: give the ship length between perpendiculars in metres (a positive number)")


def _check_common(args) -> None:
    if args.output:
        check_output_path(args.output, force=args.force, inputs=[args.model])
    _positive_lpp(args.lpp)
    if args.speed is not None and not isinstance(args.speed, str) and not (math.isfinite(args.speed) and args.speed > 0):
        raise ValueError(f"--speed {args.speed}: give the approach speed in m/s (a positive number)")
    if args.rudder_rate is not None and not (math.isfinite(args.rudder_rate) and args.rudder_rate > 0):
        raise ValueError(f"--rudder-rate {args.rudder_rate}: give the rudder rate in deg/s (a positive number)")


def _simulate(args) -> int:
    from ..manoeuvres import turning_circle, zigzag
    from ._draws import check_draws, simulate_draws

    _check_common(args)
    if check_draws(args):
        return simulate_draws(args, args.model)
    if args.metrics_output:
        raise ValueError("--metrics-output needs --draws N (the intervals of N parameter draws)")
    model = load_model(args.model, args.lpp)
    rate = math.radians(args.rudder_rate) if args.rudder_rate is not None else None
    if args.turning is not None:
        if not (math.isfinite(args.turning) and 0 < args.turning <= 90):
            raise ValueError(f"--turning {args.turning}: give the rudder angle in degrees, 0 < angle <= 90 (use --side)")
        res = turning_circle(model, args.turning, speed=args.speed, side=args.side, rudder_rate=rate, lpp=args.lpp,
                             method=args.integrator, rtol=_rtol(args))
    else:
        d, p = parse_zigzag(args.zigzag)
        res = zigzag(model, d, p, speed=args.speed, first=args.side, rudder_rate=rate, lpp=args.lpp,
                     method=args.integrator, rtol=_rtol(args))
    for m in res.metrics:
        print(_summary(model.name, m.to_dict()))
    if args.output:
        import pandas as pd

        from ._common import units_header

        frames = []
        for i in range(res.simulation.x.shape[0]):
            df = res.member(i).reset_index()
            df.insert(0, "run", i)
            frames.append(df)
        table = units_header(pd.concat(frames), model)
        _write_or_print(table.to_csv(index=False, float_format="%.10g"), args.output, args.force)
    if not res.success:
        print(f"shipid simulate: warning: {res.message}", file=sys.stderr)
        return 1
    return 0


