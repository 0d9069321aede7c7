"""Paper's steepest descent + LEPF vs BFGS + LEPF vs the direct method, side by side.

For each of seed 000's scenarios: iterations, wall time, final time reached and
largest (scaled) constraint violation; ratios are against the paper's method
measured in the same run.  Scenario 1 also prints the analytic answer.

    python benchmarks/bench_control.py            # scenarios 1-3 (minutes)
    python benchmarks/bench_control.py --quick    # scenario 1 only, coarse grid
"""
from __future__ import annotations

import argparse
import time

from shipid.control import bang_bang_straight, paper_problem, solve_direct, solve_indirect
from shipid.models import get_model


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="scenario 1 only, 12 intervals x 8 RK4 steps")
    ap.add_argument("--scenarios", default="1,2,3")
    args = ap.parse_args(argv)
    scen = [1] if args.quick else [int(s) for s in args.scenarios.split(",")]
    m = get_model("planing-boat")
    s = m.params_series()
    b = bang_bang_straight(m.resistance, s["m"] - s["X_udot"], 7500.0, 300.0, 0.5)
    print(f"scenario 1 analytic (switching curve): switch {b.switch_t:.2f} s at x = {b.switch_x:.1f} m, "
          f"u = {b.switch_u:.2f} m/s; final time {b.final_time:.2f} s")
    rows = []
    for k in scen:
        kw = {"n_intervals": 12, "substeps": 8} if args.quick else {}
        runs = {}
        for label, fn in (("steepest+LEPF (paper)", lambda pr: solve_indirect(pr, method="steepest")),
                          ("BFGS+LEPF", lambda pr: solve_indirect(pr, method="bfgs")),
                          ("direct SLSQP", lambda pr: solve_direct(pr))):
            pr = paper_problem(k, **kw)
            t0 = time.perf_counter()
            res = fn(pr)
            wall = time.perf_counter() - t0
            runs[label] = (res, wall)
        ref_wall = runs["steepest+LEPF (paper)"][1]
        for label, (res, wall) in runs.items():
            rows.append((k, label, res.nit, wall, wall / ref_wall, res.final_time,
                         res.switch_time, res.max_constraint_violation, res.success))
    print(f"{'sc':>2} {'method':<22} {'iter':>5} {'wall s':>8} {'ratio':>6} {'tf s':>8} {'switch s':>8} {'max viol':>9} ok")
    for k, label, nit, wall, ratio, tf, sw, mv, ok in rows:
        sw_s = "-" if sw is None else f"{sw:.2f}"
        extra = f"  (tf vs analytic {tf / b.final_time - 1:+.2%})" if k == 1 else ""
        print(f"{k:>2} {label:<22} {nit:>5} {wall:>8.1f} {ratio:>6.2f} {tf:>8.2f} {sw_s:>8} {mv:>9.2e} {ok}{extra}")


if __name__ == "__main__":
    main()
