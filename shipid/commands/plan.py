"""``shipid plan``: time-optimal manoeuvres (Ghorbani et al.'s scenarios or a PROBLEM.json)."""
from __future__ import annotations

import numpy as np

from ._common import add_progress_option, json_and_csv_outputs, progress_on, renamed_option, units_header


def register(sub) -> None:
    p = sub.add_parser(
        "plan", help="compute a time-optimal manoeuvre (paper-1|paper-2|paper-3 or PROBLEM.json)",
        description="Solve a minimum-time optimal-control problem and write plan.json plus the trajectory "
                    "as CSV beside it (same name, .csv).",
    )
    p.add_argument("problem", metavar="PROBLEM",
                   help="a built-in problem, paper-1, paper-2 or paper-3 (the planing boat paper's scenarios), or a "
                        "PROBLEM.json file")
    p.add_argument("--method", choices=("indirect", "direct"), default="direct",
                   help="indirect: costates + LEPF (the paper's method); direct: multiple shooting (default)")
    optimizers = ("bfgs", "steepest", "slsqp", "trust-constr", "ipopt")
    p.add_argument("--optimizer", dest="optimizer", choices=optimizers, default=None,
                   help="inner optimiser (indirect: bfgs|steepest, default bfgs; direct: slsqp|trust-constr|ipopt, "
                        "default slsqp; ipopt needs `pip install shipid[casadi]`)")
    renamed_option(p, "--solver", "--optimizer", dest="optimizer", choices=optimizers)
    p.add_argument("--intervals", type=int, default=None, help="number of control intervals (overrides the problem)")
    p.add_argument("--substeps", type=int, default=None, help="RK4 steps per control interval (overrides the problem)")
    p.add_argument("--tol", type=float, default=1e-2, help="admissible scaled constraint violation (default 0.01)")
    p.add_argument("-o", "--output", required=True, help="output plan JSON (the CSV goes beside it)")
    p.add_argument("--force", action="store_true", help="overwrite existing outputs")
    add_progress_option(p)
    p.set_defaults(handler=_plan)


def _plan(args) -> int:
    from .._io import atomic_write_set, dumps_json
    from ..control import SCENARIOS, load_problem, paper_problem, solve_direct, solve_indirect

    out, csv = json_and_csv_outputs(args.output, args.force, inputs=[args.problem])
    if not (np.isfinite(args.tol) and args.tol > 0):
        raise ValueError(f"--tol {args.tol}: give the admissible scaled constraint violation, a positive number "
                         "(default 0.01)")
    if args.intervals is not None and args.intervals < 2:
        raise ValueError(f"--intervals must be >= 2, got {args.intervals}")
    if args.substeps is not None and args.substeps < 1:
        raise ValueError(f"--substeps must be >= 1, got {args.substeps}")
    if args.problem in SCENARIOS:
        problem = paper_problem(args.problem, n_intervals=args.intervals, substeps=args.substeps)
    else:
        problem = load_problem(args.problem)
        if args.intervals is not None:
            if problem.u_guess is not None and np.ndim(problem.u_guess) == 2:
                problem.u_guess = None  # a per-interval guess does not fit the new grid
            problem.n_intervals = args.intervals
        if args.substeps is not None:
            problem.substeps = args.substeps
    opt = args.optimizer
    if args.method == "indirect":
        if opt not in (None, "bfgs", "steepest"):
            raise ValueError(f"--optimizer {opt} is not available with --method indirect; use bfgs or steepest")
        res = solve_indirect(problem, method=opt or "bfgs", tol=args.tol, progress=progress_on(args))
    else:
        if opt not in (None, "slsqp", "trust-constr", "ipopt"):
            raise ValueError(f"--optimizer {opt} is not available with --method direct; use slsqp, trust-constr or ipopt")
        kw = {} if opt == "ipopt" else {"progress": progress_on(args)}
        res = solve_direct(problem, method=opt or "slsqp", tol=args.tol, **kw)
    doc = res.to_dict()
    doc["trajectory_csv"] = csv.name
    doc["tolerance"] = args.tol
    # the CSV and the JSON are published as a set (both or neither)
    atomic_write_set([(csv, units_header(res.to_pandas(), res.problem.model).to_csv(float_format="%.6g")),
                      (out, dumps_json(doc))], force=args.force)
    print(f"{problem.name}: {res.method} final time {res.final_time:.2f} s, switch "
          f"{'none' if res.switch_time is None else f'{res.switch_time:.2f} s'}, max violation "
          f"{res.max_constraint_violation:.2e}, {res.nit} iterations -> {out}")
    if not res.success:
        print(f"warning: {res.message}")
        return 1
    return 0
