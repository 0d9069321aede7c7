"""``shipid route``: Zermelo time-optimal routes and PSO energy-optimal USV plans.

    shipid route paper-zermelo -o route.json        # the Zermelo paper's example (nm, kn, h)
    shipid route paper-pso -o plan.json             # the USV paper's scenario (our obstacles, see docs)
    shipid route PROBLEM.json -o route.json         # your problem (shipid/routing/spec.py)

Writes the JSON summary and the route as CSV beside it (same name, ``.csv``).
"""
from __future__ import annotations

import numpy as np

from .._io import atomic_write_set, dumps_json

from ._common import (add_progress_option, json_and_csv_outputs, progress_iter, progress_on, renamed_notice,
                      renamed_option, units_header)

#: Built-in problems (the papers' examples), named as ``shipid plan``'s: ``paper-<which>``.
BUILTIN = ("paper-zermelo", "paper-pso")
#: Old names of the built-in problems (they work, with a note naming the new one).
OLD_BUILTIN = {"zermelo-paper": "paper-zermelo", "pso-paper": "paper-pso"}

#: Units of the route CSV columns, by the problem's unit system (``units`` of a Zermelo problem; PSO is SI).
ROUTE_UNITS = {
    "nautical": {"t": "h", "x": "nm", "y": "nm", "heading_deg": "deg", "course_deg": "deg"},
    "si": {"t": "s", "x": "m", "y": "m", "heading_deg": "deg", "course_deg": "deg",
           "lon": "deg", "lat": "deg"},
}


#: What ``route paper-pso`` prints under its numbers (docs/routing.md has the 64-case table).
PSO_FRAMING = ("the paper gives obstacles and current directions only in figures, so these are ours; this default "
               "(current towards E, then N, then W) turned out to be the worst of the 64 direction combinations "
               "in docs/routing.md (savings -50.4 % .. +9.2 %, median 0.0 %); the paper reports +10.37 %")
PSO_PAPER_NOTE = ("Li et al. scenario: start/goal, wind (from east, 7 m/s) and current speed (1.2 m/s) from the paper; "
                  "obstacles and current directions (towards 90, 0, 270 deg) are ours; events at 48 s and 192 s "
                  "(the paper's minutes 8 and 32 scaled by 0.1, since its own speed model finishes the 305 m in ~4 min). "
                  + PSO_FRAMING[0].upper() + PSO_FRAMING[1:] + ".")


def register(sub) -> None:
    p = sub.add_parser("route", help="time-optimal (Zermelo) or energy-optimal (PSO) routes in currents",
                       description="Solve a routing problem and write a JSON summary plus the route as CSV beside it.")
    p.add_argument("problem", metavar="PROBLEM",
                   help="a built-in problem, paper-zermelo (time-optimal route in a shear current) or paper-pso "
                        "(energy-optimal USV path), or a PROBLEM.json file")
    p.add_argument("-o", "--output", required=True, help="output JSON; the route CSV gets the same name with .csv")
    p.add_argument("--force", action="store_true", help="overwrite existing outputs")
    p.add_argument("--seed", type=int, default=None, help="PSO random seed (default: the problem's 'seed' or 0)")
    p.add_argument("--method", choices=["pmp", "transcription", "both"], default=None,
                   help="Zermelo solution method: Pontryagin shooting, direct transcription, or both (default: the "
                        "problem's 'solver' or both)")
    renamed_option(p, "--solver", "--method", dest="method", choices=["pmp", "transcription", "both"])
    p.add_argument("--kinematics", choices=["paper", "crab"], default=None,
                   help="PSO leg kinematics for paper-pso (default 'paper')")
    add_progress_option(p)
    p.set_defaults(handler=_route)


def _outputs(args):
    if args.problem in OLD_BUILTIN:
        renamed_notice("shipid route", args.problem, OLD_BUILTIN[args.problem])
        args.problem = OLD_BUILTIN[args.problem]
    inputs = [] if args.problem in BUILTIN else [args.problem]
    return json_and_csv_outputs(args.output, args.force, inputs=inputs)


def _route(args) -> int:
    from ..routing.spec import load_problem_spec

    out, csv = _outputs(args)
    if args.problem == "paper-zermelo":
        return _zermelo(args, {"type": "zermelo", "paper": True, "units": "nautical"}, None, out, csv)
    if args.problem == "paper-pso":
        return _pso(args, {"type": "pso", "paper": True}, None, out, csv)
    spec, base = load_problem_spec(args.problem)
    if spec["type"] == "zermelo":
        return _zermelo(args, spec, base, out, csv)
    return _pso(args, spec, base, out, csv)


def _write(out, csv, doc, frame, force, units="si"):
    # the CSV (units in its header) and the JSON are published as a set (both or neither)
    table = units_header(frame, units=ROUTE_UNITS[units])
    atomic_write_set([(csv, table.to_csv(index=False, float_format="%.10g")), (out, dumps_json(doc))], force=force)
    print(f"wrote {out} and {csv}")


def _zermelo(args, spec, base, out, csv) -> int:
    from ..routing.spec import zermelo_from_spec
    from ..routing.zermelo import paper_problem, solve_pmp, solve_transcription

    problem = paper_problem() if spec.get("paper") else zermelo_from_spec(spec, str(args.problem), base)
    units = spec.get("units", "si")
    to_h = 1.0 if units == "nautical" else 1.0 / 3600.0
    solver = args.method or spec.get("solver", "both")
    if solver not in ("pmp", "transcription", "both"):
        raise ValueError(f"{args.problem}: 'solver' must be pmp, transcription or both, got {solver!r}")
    if solver in ("pmp", "both") and problem.field.time_dependent:
        if solver == "pmp":
            raise ValueError(f"{args.problem}: the current is time dependent; the PMP solver needs a steady one -- use --method transcription")
        solver = "transcription"
    results = {}
    stages = ["pmp", "transcription"] if solver == "both" else [solver]
    for stage in progress_iter(stages, args, desc="route (Zermelo solvers)"):
        if stage == "pmp":
            results["pmp"] = solve_pmp(problem)
        else:
            guess = results.get("pmp")
            results["transcription"] = solve_transcription(problem, n=int(spec.get("n", 40)),
                                                           guess=guess if guess is not None and guess.reached else None)
    best = min((r for r in results.values() if r.reached), key=lambda r: r.time, default=next(iter(results.values())))
    doc = {
        "problem": str(args.problem), "type": "zermelo", "units": units,
        "time_h": best.time * to_h, "reached": bool(best.reached), "success": bool(best.success),
        "method": best.method, "message": best.message,
        "initial_course_deg": float(np.degrees(best.course[0])), "final_course_deg": float(np.degrees(best.course[-1])),
        "solvers": {k: {"time_h": r.time * to_h, "reached": bool(r.reached), "success": bool(r.success),
                        "message": r.message, "initial_course_deg": float(np.degrees(r.course[0]))}
                    for k, r in results.items()},
        "route_csv": csv.name,
        "columns": ("t, x (east), y (north), heading_deg (math, from east ccw), course_deg (nautical); "
                    + ("h, nm, nm, deg, deg" if units == "nautical" else "s, m, m, deg, deg")),
    }
    if spec.get("paper"):
        doc["note"] = ("Zwierzewicz example in nm, kn, h; the paper's 10.93 h is 4(1+sqrt 3) = 10.928 h of the extremal "
                       "with the rounded angles u(0) = 345, u(tf) = 210 deg, which starts 0.004 nm from the printed A")
    _write(out, csv, doc, best.to_pandas(), args.force, "nautical" if units == "nautical" else "si")
    print(f"time {best.time * to_h:.6f} h ({best.method}); reached: {best.reached}")
    return 0 if best.reached else 1


def _pso(args, spec, base, out, csv) -> int:
    import pandas as pd

    from ..routing.pso import compare_planners, local_to_lonlat, paper_scenario
    from ..routing.spec import usv_from_spec

    if spec.get("paper"):
        problem = paper_scenario(kinematics=args.kinematics or "paper")
    else:
        problem = usv_from_spec(spec, str(args.problem), base)
        if args.kinematics:
            problem.kinematics = args.kinematics
    from ..routing.spec import check_pso_settings

    settings = check_pso_settings(spec, str(args.problem))
    if args.seed is not None and args.seed < 0:
        raise ValueError(f"--seed {args.seed}: give a whole number >= 0")
    seed = args.seed if args.seed is not None else settings.get("seed", 0)
    kw = {k: settings[k] for k in ("n_particles", "max_iter", "replan_times") if k in settings}
    res = compare_planners(problem, rng=seed, progress=progress_on(args), **kw)
    oc, do, eo = res["ocpso"], res["dopso"], res["eopso"]
    rows = []
    for name, pts in (("ocpso", oc.points), ("dopso", do.points), ("eopso", eo.points)):
        for i, p in enumerate(pts):
            row = {"planner": name, "point": i, "x": p[0], "y": p[1]}
            if problem.origin is not None:
                ll = local_to_lonlat(p, *problem.origin)
                row["lon"], row["lat"] = ll[0], ll[1]
            rows.append(row)
    vd = res["dopso_voyage"]
    doc = {
        "problem": str(args.problem), "type": "pso", "seed": seed, "kinematics": problem.kinematics,
        "energy_J": oc.energy, "distance_m": oc.length, "time_s": oc.voyage.duration,
        "saving_vs_distance_optimal": res["saving_vs_distance_optimal"], "success": res["success"],
        "dopso": {"energy_J": vd.total_energy, "distance_m": do.length, "time_s": vd.duration},
        "eopso_static": {"energy_J": res["eopso_voyage"].total_energy, "distance_m": eo.length,
                         "predicted_energy_J": eo.energy},
        "replanning": oc.events,
        "obstacles": [{"x": o.x, "y": o.y, "radius": o.radius} for o in problem.obstacles],
        "route_csv": csv.name,
    }
    if spec.get("paper"):
        doc["note"] = PSO_PAPER_NOTE
    _write(out, csv, doc, pd.DataFrame(rows), args.force)
    print(f"OCPSO energy {oc.energy:.6g} J over {oc.length:.1f} m; DOPSO {vd.total_energy:.6g} J; "
          f"saving {100 * res['saving_vs_distance_optimal']:.2f} %")
    if spec.get("paper"):
        print(f"note: {PSO_FRAMING}")
    return 0 if res["success"] else 1
