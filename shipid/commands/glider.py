"""``shipid glider launch`` and ``shipid glider optimise`` (the underwater-glider surface-launch study)."""
from __future__ import annotations

import math

from .._io import atomic_write_set, dumps_json

from ._common import add_progress_option, check_output_path, progress_on, renamed_option, units_header

MODEL_HELP = "the glider model: glider[:SET] (default glider, the paper's parameters) or a glider fit RESULT.json"


def register(sub) -> None:
    p = sub.add_parser("glider", help="underwater-glider launch simulation and launch optimisation",
                       description="Underwater-glider surface launches: simulate one (launch) or choose the launch "
                                   "speed, angle, fin incidence and CG by differential evolution (optimise).")
    gs = p.add_subparsers(dest="glider_command", metavar="SUBCOMMAND")

    lp = gs.add_parser("launch", help="simulate one surface launch until the glider returns to the surface",
                       description="Simulate one surface launch of the glider (speed and angle at entry, fin and CG "
                                   "settings) until it returns to the surface; writes the maximum depth, horizontal "
                                   "travel, exit angle and duration as JSON (and the trajectory as CSV on request).")
    lp.add_argument("--speed", type=float, required=True, help="launch speed [m/s]")
    lp.add_argument("--angle", type=float, required=True, help="launch angle from the vertical [deg]")
    lp.add_argument("--fin", type=float, default=0.0, help="fin incidence [deg], positive leading edge up (default 0)")
    lp.add_argument("--cg", type=float, default=0.0, help="CG offset from the centre of buoyancy [m], positive towards the nose (default 0)")
    lp.add_argument("--model", default=None, metavar="MODEL", help=MODEL_HELP)
    renamed_option(lp, "--params", "--model", dest="model", note="glider:SET or RESULT.json")
    lp.add_argument("--dt", type=float, default=None, help="RK4 step [s] (default: automatic, <= 0.01)")
    lp.add_argument("--trajectory", default=None, help="also write the trajectory as CSV to this file")
    lp.add_argument("-o", "--output", required=True, help="summary JSON to write")
    lp.add_argument("--force", action="store_true", help="overwrite existing output files")
    lp.set_defaults(handler=_launch)

    op = gs.add_parser("optimise", help="choose speed, angle, fin and CG by differential evolution (objective in docs/glider.md)",
                       description="Choose the launch speed, angle, fin incidence and CG within the given ranges by "
                                   "differential evolution, trading depth against horizontal travel (objective in "
                                   "docs/glider.md), and compare with the best launch of the paper's grid.")
    op.add_argument("--model", default=None, metavar="MODEL", help=MODEL_HELP)
    renamed_option(op, "--params", "--model", dest="model", note="glider:SET or RESULT.json")
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
    add_progress_option(op)
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
            raise ValueError(f"{spec}: result file not found; give a 'shipid fit' result JSON or glider[:SET]")
        return model_from(path, model="glider")[0]
    name, colon, pset = str(spec).partition(":")
    if not colon and name != "glider":  # a bare parameter-set name (the old --params SET)
        name, pset = "glider", name
    if name != "glider":
        raise ValueError(f"--model {spec}: the glider commands take the glider model; give glider[:SET] or a glider "
                         "fit RESULT.json")
    return get_model("glider", pset or None)


def _launch(args) -> int:
    from ..glider import launch

    inputs = [args.model]
    check_output_path(args.output, force=args.force, inputs=inputs)
    if args.trajectory:
        check_output_path(args.trajectory, force=args.force, inputs=inputs, what="trajectory")
        if str(args.trajectory) == str(args.output):
            raise ValueError(f"--trajectory {args.trajectory}: give a different file from -o")
    for opt, v in (("--speed", args.speed), ("--angle", args.angle), ("--fin", args.fin), ("--cg", args.cg),
                   ("--dt", args.dt)):
        if v is not None and not math.isfinite(v):
            raise ValueError(f"{opt} {v}: give a finite number")
    model = _model(args.model)
    res = launch(args.speed, args.angle, args.fin, args.cg, model=model, dt=args.dt)
    out = res.as_dict(0)
    out.update({"model": "glider", "params": {k: float(v) for k, v in res.model.params_series().items()},
                "dt_s": res.dt, "success": bool(res.success), "message": res.message})
    out["params"]["x_g"] = float(args.cg)
    files = [(args.output, dumps_json(out))]
    if args.trajectory:
        traj = units_header(res.to_pandas(0), res.model, units={"depth": "m (down)"})
        files.insert(0, (args.trajectory, traj.to_csv(float_format="%.10g")))
    atomic_write_set(files, force=args.force)  # trajectory and summary: both or neither
    print(f"max depth {out['max_depth_m']:.3f} m, horizontal {out['horizontal_m'] if out['horizontal_m'] is not None else float('nan'):.3f} m, "
          f"exit angle {out['exit_angle_deg'] if out['exit_angle_deg'] is not None else float('nan'):.1f} deg, "
          f"duration {out['duration_s'] if out['duration_s'] is not None else float('nan'):.2f} s -> {args.output}")
    return 0 if res.success else 1


def _optimise(args) -> int:
    from ..glider import optimise_launch

    check_output_path(args.output, force=args.force, inputs=[args.model])
    if args.popsize < 1 or args.maxiter < 1:
        raise ValueError(f"--popsize {args.popsize} / --maxiter {args.maxiter}: give whole numbers >= 1")
    if args.popsize * args.maxiter > 100_000:
        raise ValueError(f"--popsize {args.popsize} x --maxiter {args.maxiter}: over 100000 generations x members "
                         "would run for hours; the defaults are 10 and 30")
    model = _model(args.model)
    bounds = {k: tuple(v) for k, v in (("speed", args.speed), ("angle_deg", args.angle), ("fin_deg", args.fin), ("cg_m", args.cg)) if v is not None}
    res = optimise_launch(model=model, bounds=bounds, max_exit_angle_deg=args.max_exit_angle, popsize=args.popsize,
                          maxiter=args.maxiter, seed=args.seed, progress=progress_on(args))
    doc = res.as_dict()
    atomic_write_set([(args.output, dumps_json(doc))], force=args.force)
    x = res.x
    print(f"best: speed {x['speed']:.2f} m/s, angle {x['angle_deg']:.1f} deg, fin {x['fin_deg']:.1f} deg, "
          f"cg {x['cg_m']:.4f} m; "
          f"J = {res.objective:.3f} (depth {res.launch['max_depth_m']:.2f} m, horizontal {res.launch['horizontal_m']:.2f} m) -> {args.output}")
    return 0
