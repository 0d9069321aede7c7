"""Paper's steepest descent + LEPF vs BFGS + LEPF vs the direct method (SLSQP, and IPOPT when
CasADi is installed), side by side on Ghorbani et al.'s scenarios.

For each scenario: iterations, wall time, its ratio to the reference method measured in the same
run (the paper's steepest descent), final time reached (and its difference to the analytic answer
for scenario 1, to direct SLSQP for scenarios 2-3), largest scaled constraint violation and which
constraint it is.

    python benchmarks/bench_control.py              # scenarios 1-3 on the default grids (tens of minutes)
    python benchmarks/bench_control.py --quick      # scenario 1 only, 8 intervals x 8 RK4 steps (minutes)
    python benchmarks/bench_control.py --scenarios 2,3 --methods bfgs,slsqp,ipopt
"""
from __future__ import annotations

import argparse
import time
import warnings

import sys as _sys
from pathlib import Path as _Path

_sys.path.insert(0, str(_Path(__file__).resolve().parents[1]))  # measure this checkout, not an installed copy

from shipid.control import bang_bang_straight, paper_problem, solve_direct, solve_indirect
from shipid.control.ipopt import have_casadi
from shipid.models import get_model

METHODS = {
    "steepest": ("steepest+LEPF (paper)", lambda pr, a: solve_indirect(pr, method="steepest", r0=a.r0, n_penalty=a.stages)),
    "bfgs": ("BFGS+LEPF", lambda pr, a: solve_indirect(pr, method="bfgs", r0=a.r0, n_penalty=a.stages)),
    "slsqp": ("direct SLSQP", lambda pr, a: solve_direct(pr, method="slsqp")),
    "ipopt": ("direct IPOPT (CasADi)", lambda pr, a: solve_direct(pr, method="ipopt")),
}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="scenario 1 only, 8 intervals x 8 RK4 steps")
    ap.add_argument("--scenarios", default="1,2,3", help="comma-separated scenario numbers (default 1,2,3)")
    ap.add_argument("--methods", default="steepest,bfgs,slsqp,ipopt",
                    help="comma-separated subset of steepest,bfgs,slsqp,ipopt (ipopt is skipped without CasADi); "
                         "the first one is the reference of the time ratios")
    ap.add_argument("--r0", type=float, default=1.0, help="first LEPF penalty parameter of the indirect methods")
    ap.add_argument("--stages", type=int, default=10, help="LEPF stages of the indirect methods")
    args = ap.parse_args(argv)
    scen = [1] if args.quick else [int(s) for s in args.scenarios.split(",")]
    methods = [m.strip() for m in args.methods.split(",") if m.strip()]
    unknown = sorted(set(methods) - set(METHODS))
    if unknown:
        ap.error(f"unknown method(s) {unknown}; choose from {sorted(METHODS)}")
    if "ipopt" in methods and not have_casadi():
        print("CasADi not installed: direct IPOPT skipped (pip install shipid[casadi])")
        methods.remove("ipopt")
    m = get_model("planing-boat")
    s = m.params_series()
    b = bang_bang_straight(m.resistance, s["m"] - s["X_udot"], 7500.0, 300.0, 0.5)
    print(f"scenario 1 analytic (switching curve): switch {b.switch_t:.2f} s at x = {b.switch_x:.1f} m, "
          f"u = {b.switch_u:.2f} m/s; final time {b.final_time:.2f} s")
    print(f"LEPF schedule of the indirect methods: r0 = {args.r0:g}, {args.stages} stages, c' = 0.2")
    rows = []
    for k in scen:
        kw = {"n_intervals": 8, "substeps": 8} if args.quick else {}
        runs = {}
        for key in methods:
            label, fn = METHODS[key]
            pr = paper_problem(k, **kw)
            t0 = time.perf_counter()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                res = fn(pr, args)
            runs[key] = (label, res, time.perf_counter() - t0, pr)
            worst = max(res.violations, key=res.violations.get)
            print(f"  scenario {k}: {label} done in {runs[key][2]:.1f} s: {res.nit} iterations, tf {res.final_time:.3f} s, "
                  f"max violation {res.max_constraint_violation:.2e} ({worst}), success {res.success}", flush=True)
        ref_wall = runs[methods[0]][2]
        tf_ref = b.final_time if k == 1 else (runs["slsqp"][1].final_time if "slsqp" in runs else None)
        for key, (label, res, wall, pr) in runs.items():
            worst = max(res.violations, key=res.violations.get)
            rows.append((k, f"{pr.n_intervals}x{pr.substeps}", label, res.nit, wall, wall / ref_wall, res.final_time,
                         None if tf_ref is None else res.final_time / tf_ref - 1, res.switch_time,
                         res.max_constraint_violation, worst, res.success))
    print(f"\nreference of the time ratios: {METHODS[methods[0]][0]}; dtf: scenario 1 vs analytic, 2-3 vs direct SLSQP")
    print(f"{'sc':>2} {'grid':>5} {'method':<22} {'iter':>5} {'wall s':>8} {'ratio':>6} {'tf s':>8} {'dtf':>8} "
          f"{'switch s':>8} {'max viol':>9} {'ok':<5} worst constraint")
    for k, grid, label, nit, wall, ratio, tf, dtf, sw, mv, worst, ok in rows:
        sw_s = "-" if sw is None else f"{sw:.2f}"
        dtf_s = "-" if dtf is None else f"{dtf:+.2%}"
        print(f"{k:>2} {grid:>5} {label:<22} {nit:>5} {wall:>8.1f} {ratio:>6.2f} {tf:>8.2f} {dtf_s:>8} {sw_s:>8} "
              f"{mv:>9.2e} {str(ok):<5} {worst}")


if __name__ == "__main__":
    main()
