"""``shipid glider launch`` and ``shipid glider optimise`` (seed 004 launch study)."""
from __future__ import annotations

import json

from .._io import atomic_write_text


def register(sub) -> None:
    p = sub.add_parser("glider", help="underwater-glider launch simulation and launch optimisation")
    gs = p.add_subparsers(dest="glider_command", metavar="SUBCOMMAND")

    lp = gs.add_parser("launch", help="simulate one surface launch until the glider returns to the surface")
    lp.add_argument("--speed", type=float, required=True, help="launch speed [m/s]")
    lp.add_argument("--angle", type=float, required=True, help="launch angle from the vertical [deg]")
    lp.add_argument("--fin", type=float, default=0.0, help="fin incidence [deg], positive leading edge up (default 0)")
    lp.add_argument("--cg", type=float, default=0.0, help="CG offset from the centre of buoyancy [m], positive towards the nose (default 0)")
    lp.add_argument("--params", default=None, help="result JSON of 'shipid fit' for the glider model, or a parameter-set name (default: paper)")
    lp.add_argument("--dt", type=float, default=None, help="RK4 step [s] (default: automatic, <= 0.01)")
    lp.add_argument("--trajectory", default=None, help="also write the trajectory as CSV to this file")
    lp.add_argument("-o", "--output", required=True, help="summary JSON to write")
    lp.add_argument("--force", action="store_true", help="overwrite existing output files")
    lp.set_defaults(handler=_launch)

    op = gs.add_parser("optimise", help="choose speed, angle, fin and CG by differential evolution (objective in docs/glider.md)")
    op.add_argument("--params", default=None, help="result JSON of 'shipid fit' or a parameter-set name (default: paper)")
    op.add_argument("--speed", type=float, nargs=2, metavar=("LO", "HI"), default=None, help="speed range [m/s] (default 0.5 5)")
    op.add_argument("--angle", type=float, nargs=2, metavar=("LO", "HI"), default=None, help="angle range [deg] (default 15 60)")
    op.add_argument("--fin", type=float, nargs=2, metavar=("LO", "HI"), default=None, help="fin range [deg] (default 0 20)")
    op.add_argument("--cg", type=float, nargs=2, metavar=("LO", "HI"), default=None, help="CG range [m] (default -0.05 0)")
    op.add_argument("--max-exit-angle", type=float, default=75.0, help="exit angle above which the objective is penalised [deg] (default 75)")
    op.add_argument("--popsize", type=int, default=10, help="DE population per free variable (default 10)")
    op.add_argument("--maxiter", type=int, default=30, help="DE generations (default 30)")
    op.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    op.add_argument("-o", "--output", required=True, help="JSON to write")
    op.add_argument("--force", action="store_true", help="overwrite an existing output file")
    op.add_argument("--progress", action="store_true", help="show a progress bar over generations")
    op.set_defaults(handler=_optimise)
    p.set_defaults(handler=lambda args: (p.print_help(), 2)[1])


def _model(spec):
    from pathlib import Path

    from ..identify.result import model_from
    from ..models import get_model

    if spec is None:
        return get_model("glider")
    path = Path(spec)
    if path.suffix.lower() == ".json" or path.exists():
        if not path.is_file():
            raise ValueError(f"{spec}: parameter file not found; give a 'shipid fit' result JSON or a parameter-set name")
        return model_from(path, model="glider")[0]
    return get_model("glider", spec)


def _launch(args) -> int:
    from ..glider import launch

    model = _model(args.params)
    res = launch(args.speed, args.angle, args.fin, args.cg, model=model, dt=args.dt)
    out = res.as_dict(0)
    out.update({"model": "glider", "params": {k: float(v) for k, v in res.model.params_series().items()},
                "dt_s": res.dt, "success": bool(res.success), "message": res.message})
    out["params"]["x_g"] = float(args.cg)
    if args.trajectory:
        atomic_write_text(args.trajectory, res.to_pandas(0).to_csv(), force=args.force)
    atomic_write_text(args.output, json.dumps(out, indent=2) + "\n", force=args.force)
    print(f"max depth {out['max_depth_m']:.3f} m, horizontal {out['horizontal_m'] if out['horizontal_m'] is not None else float('nan'):.3f} m, "
          f"exit angle {out['exit_angle_deg'] if out['exit_angle_deg'] is not None else float('nan'):.1f} deg, "
          f"duration {out['duration_s'] if out['duration_s'] is not None else float('nan'):.2f} s -> {args.output}")
    return 0 if res.success else 1


def _optimise(args) -> int:
    from ..glider import optimise_launch

    model = _model(args.params)
    bounds = {k: tuple(v) for k, v in (("speed", args.speed), ("angle_deg", args.angle), ("fin_deg", args.fin), ("cg_m", args.cg)) if v is not None}
    res = optimise_launch(model=model, bounds=bounds, max_exit_angle_deg=args.max_exit_angle, popsize=args.popsize,
                          maxiter=args.maxiter, seed=args.seed, progress=args.progress)
    doc = res.as_dict()
    atomic_write_text(args.output, json.dumps(doc, indent=2) + "\n", force=args.force)
    x = res.x
    print(f"best: {x['speed']:.2f} m/s, {x['angle_deg']:.1f} deg, fin {x['fin_deg']:.1f} deg, cg {x['cg_m'] * 100:.2f} cm; "
          f"J = {res.objective:.3f} (depth {res.launch['max_depth_m']:.2f} m, horizontal {res.launch['horizontal_m']:.2f} m) -> {args.output}")
    return 0
