"""``shipid sweep``: turning circles of a model over rudder angle x approach speed, as one batch."""
from __future__ import annotations

import math

from .simulate import MODEL_HELP, _check_common, _floats, _integrator, _rtol, _write_or_print, load_model


def register(sub) -> None:
    p = sub.add_parser("sweep", help="turning-diameter sweep over rudder angle x approach speed (one batch)",
                       description="Turning circles of a model over every rudder angle x approach speed, simulated "
                                   "as one batch; prints (or writes) one CSV row per turn with its metrics.")
    p.add_argument("model", metavar="MODEL", help=MODEL_HELP)
    p.add_argument("--rudder", default="10,15,25", help="rudder angles [deg], comma separated")
    p.add_argument("--speed", default=None, help="approach speeds [m/s], comma separated (default: design speed)")
    p.add_argument("--side", choices=("both", "starboard", "port"), default="starboard",
                   help="turning side (default starboard; both: each angle to either side)")
    p.add_argument("--lpp", type=float, default=None,
                   help="ship length [m]: Froude-scale the model to this ship (default: the length it was fitted at)")
    p.add_argument("--rudder-rate", type=float, default=None, metavar="DEG_S", help="rudder rate [deg/s]")
    _integrator(p)
    p.add_argument("-o", "--output", default=None, help="CSV to write (default: print)")
    p.add_argument("--force", action="store_true", help="overwrite the output file")
    p.set_defaults(handler=_sweep)


#: Units of the ``sweep`` CSV columns (``_L``: lengths divided by Lpp; speed loss: 1 - U_steady / U_approach).
SWEEP_UNITS = {"rudder_deg": "deg", "speed": "m/s", "n": "rps", "advance_L": "Lpp", "transfer_L": "Lpp",
               "tactical_diameter_L": "Lpp", "steady_diameter_L": "Lpp", "tactical_diameter": "m",
               "steady_diameter": "m", "speed_loss": "-"}


def _sweep(args) -> int:
    from ..manoeuvres import ship_info, turning_sweep

    _check_common(args)
    model = load_model(args.model, args.lpp)
    rud = _floats(args.rudder, "--rudder")
    if args.speed is None:
        u0 = ship_info(model).get("design_speed")
        if u0 is None:
            raise ValueError(f"model '{model.name}' has no design speed; pass --speed")
        speeds = [u0]
    else:
        speeds = _floats(args.speed, "--speed")
    if any(r <= 0 for r in rud) or any(s <= 0 for s in speeds):
        raise ValueError("--rudder and --speed values must be positive (use --side for port)")
    rate = math.radians(args.rudder_rate) if args.rudder_rate is not None else None
    df = turning_sweep(model, rud, speeds, side=args.side, rudder_rate=rate, lpp=args.lpp,
                       method=args.integrator, rtol=_rtol(args))
    from ._common import units_header

    table = units_header(df, units=SWEEP_UNITS)
    _write_or_print(table.to_csv(index=False, float_format="%.10g"), args.output, args.force)
    if args.output:
        print(df[["rudder_deg", "speed", "n", "tactical_diameter_L", "steady_diameter_L"]].to_string(index=False))
    return 0 if bool(df["success"].all()) else 1
