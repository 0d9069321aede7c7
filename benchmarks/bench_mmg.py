"""Benchmark: shipid's MMG model vs the shipmmg package (same KVLCC2 L7 coefficients, same run).

Goals: one 35 deg turning circle >= 5x faster than shipmmg at equal accuracy; a sweep of
100 manoeuvres as one shipid batch >= 50x faster than looping shipmmg at equal accuracy.

1. One 35 deg turning circle (rudder step at t = 0, 250 s at L7 scale, > 700 deg of heading change):
   each code at several accuracy settings; accuracy = largest position error over 501 output times
   (in ship lengths) against that code's own converged solution (shipid dopri5 rtol 1e-11, shipmmg
   rtol 1e-10).  shipid runs `shipid.simulate.simulate` with method="dopri5" (outputs from the dense
   output, as shipmmg's solve_ivp `sol`) and with method="rk4" (fixed step, linear interpolation
   to the output times).
2. A sweep of 100 turning circles (10 rudder angles x 5 speeds x 2 sides, same approach, rudder rate
   and duration for both codes) as ONE shipid batch (`shipid.manoeuvres.turning_circle`, metrics
   included) vs looping shipmmg (solve_ivp per case, metrics by shipid's turning_metrics); accuracy
   = largest tactical-diameter error over the sweep against each code's own converged sweep.

The speed ratio is taken at equal accuracy: for each shipmmg setting, the fastest shipid setting that
is at least as accurate.  Times are CPU times of this process (best of several repeats for part 1),
so other load on a shared machine does not count.

Run:  python benchmarks/bench_mmg.py [--quick]      (SHIPID_JIT=0 for shipid's pure numpy/Python path)
shipmmg is not shipid's model: it differs in the wake and U/beta formulas (tests/test_mmg.py), so the
two converged solutions differ by ~0.1 L in position and 1-2 % in the turning diameter; accuracy is
measured per code.
"""
from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parents[1]))


def _best_time(fn, repeat):
    best = math.inf
    out = None
    for _ in range(repeat):
        t0 = time.process_time()
        out = fn()
        best = min(best, time.process_time() - t0)
    return best, out


def _equal_accuracy(rows, ref_code="shipmmg"):
    """[(shipmmg setting, its error, its time, best shipid setting, its error, its time, ratio)]."""
    out = []
    for code, st, e, tm in rows:
        if code != ref_code:
            continue
        ok = [(t2, s2, e2) for c2, s2, e2, t2 in rows if c2 != ref_code and np.isfinite(e) and e2 <= e]
        if ok:
            t2, s2, e2 = min(ok)
            out.append((st, e, tm, s2, e2, t2, tm / t2))
        else:
            out.append((st, e, tm, None, math.nan, math.nan, math.nan))
    return out


def _print_pairs(pairs, unit):
    print(f"{'shipmmg':>14s} {'error':>9s} {'time':>8s} | {'shipid (equal accuracy)':>24s} {'error':>9s} {'time':>8s} | speed-up")
    for st, e, tm, s2, e2, t2, ratio in pairs:
        if s2 is None:
            print(f"{st:>14s} {e:9.2e} {tm * 1e3:8.1f} | {'(none as accurate)':>24s}")
        else:
            print(f"{st:>14s} {e:9.2e} {tm * 1e3:8.1f} | {s2:>24s} {e2:9.2e} {t2 * 1e3:8.1f} | {ratio:7.1f}x")
    print(f"(errors in {unit}, times in ms)")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer settings and a 20-case sweep (development)")
    args = ap.parse_args(argv)

    from scipy.optimize import brentq
    from shipmmg.mmg_3dof import simulate_mmg_3dof

    from shipid.manoeuvres import steady_rps, turning_circle, turning_metrics
    from shipid.models import get_model
    from shipid.simulate import simulate

    sys.path.insert(0, str(Path(__file__).parents[1] / "tests"))
    from test_mmg import _shipmmg_args  # the same parameter mapping the cross-check test uses

    model = get_model("mmg")
    L, U0 = model.lpp, 1.179
    n0 = brentq(lambda n: model.rhs(0.0, [0, 0, 0, U0, 0, 0], [0.0, n])[3], 1, 60)
    T, delta = 250.0, math.radians(35)
    t_out = np.linspace(0, T, 501)
    basic, man = _shipmmg_args(model)
    x0 = np.array([0, 0, 0, U0, 0, 0.0])
    U_out = np.tile([delta, n0], (t_out.size, 1))

    def run_rk4(dt):
        t = np.linspace(0, T, int(round(T / dt)) + 1)
        res = simulate(model, x0, t, np.tile([delta, n0], (t.size, 1)))
        return np.stack([np.interp(t_out, t, res.x[:, i]) for i in (0, 1)], axis=-1)

    def run_dopri5(rtol):
        return simulate(model, x0, t_out, U_out, method="dopri5", rtol=rtol).x[:, :2]

    def run_shipmmg(rtol):
        sol = simulate_mmg_3dof(basic, man, [0.0, T], [delta, delta], [n0, n0], u0=U0, ρ=model.particulars.rho,
                                rtol=rtol, atol=rtol * 1e-3)
        y = sol.sol(t_out)
        return np.stack([y[3], y[4]], axis=-1)

    from shipid import _jit

    print("shipid MMG equations: " + ("compiled by numba (extra 'fast')" if _jit.enabled() else
                                      "pure numpy/Python (numba not installed or SHIPID_JIT=0)"))
    ref_id = run_dopri5(1e-11)
    ref_sm = run_shipmmg(1e-10)
    err = lambda a, ref: float(np.hypot(*(a - ref).T).max() / L)  # noqa: E731
    print(f"converged solutions differ by {err(ref_id, ref_sm):.3e} L (shipmmg's own wake/U formulas)")
    print(f"converged shipid rk4 (dt = L/U/400) vs dopri5 (rtol 1e-11): {err(run_rk4(L / U0 / 400), ref_id):.1e} L")
    print("\n1. one 35 deg turning circle, 250 s at L7 scale")
    print(f"{'code':8s} {'setting':>16s} {'error [L]':>11s} {'time [ms]':>10s}")
    rep = 3 if args.quick else 7
    rows1 = []
    for f in ((0.2, 0.1) if args.quick else (0.4, 0.2, 0.1, 0.05)):
        tm, X = _best_time(lambda: run_rk4(f * L / U0), rep)
        rows1.append(("shipid", f"rk4 dt={f:g} L/U", err(X, ref_id), tm))
    for rtol in ((1e-3, 1e-5) if args.quick else (3e-3, 1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9)):
        tm, X = _best_time(lambda: run_dopri5(rtol), rep)
        rows1.append(("shipid", f"dopri5 rtol={rtol:g}", err(X, ref_id), tm))
    for rtol in ((1e-3, 1e-5) if args.quick else (1e-3, 1e-4, 1e-5, 1e-6, 1e-7)):
        tm, X = _best_time(lambda: run_shipmmg(rtol), rep)
        rows1.append(("shipmmg", f"rtol={rtol:g}", err(X, ref_sm), tm))
    for code, st, e, tm in rows1:
        print(f"{code:8s} {st:>20s} {e:11.2e} {1e3 * tm:10.1f}")
    pairs1 = _equal_accuracy(rows1)
    print()
    _print_pairs(pairs1, "L of track position")

    # ---------------------------------------------------------------- sweep of 100 manoeuvres
    n_rud = 5 if args.quick else 10
    rudders = np.linspace(10, 35, n_rud)
    speeds = [1.0, 1.179] if args.quick else [0.9, 1.0, 1.1, 1.179, 1.3]
    cases = len(rudders) * len(speeds) * 2
    print(f"\n2. sweep of {cases} turning circles (rudder {rudders[0]:g}..{rudders[-1]:g} deg x {len(speeds)} speeds "
          "x 2 sides; approach 2 L/U, rudder rate 15.8 deg/s, 540 deg)")
    print("accuracy = largest tactical-diameter error over the sweep [L], each code against its own converged run")

    def shipid_sweep(setting):
        kind, val = setting
        if kind == "rk4":
            return turning_circle(model, rudders, speed=speeds, side="both", heading_change_deg=540,
                                  dt=val * L / max(speeds))
        return turning_circle(model, rudders, speed=speeds, side="both", heading_change_deg=540,
                              method="dopri5", rtol=val)

    ref = shipid_sweep(("dopri5", 1e-10))
    td_ref = np.array([m.tactical_diameter_L for m in ref.metrics])
    ref_rk4 = shipid_sweep(("rk4", 0.0125))
    print(f"converged shipid rk4 (dt = L/U/80) vs dopri5 (rtol 1e-10): "
          f"{np.max(np.abs(np.array([m.tactical_diameter_L for m in ref_rk4.metrics]) - td_ref)):.1e} L")
    t_end = float(ref.simulation.t[-1])
    te = float(ref.metrics[0].execute_time)
    ns = dict(zip(speeds, steady_rps(model, speeds)))
    rate = model.rudder_rate
    # shipmmg starts AT the execute from the steady approach state (no approach phase: with one its adaptive
    # steps jump over the short rudder ramp at rtol 1e-3..1e-5 and the ship never turns); this favours shipmmg
    tl = np.arange(0.0, t_end - te, 0.05)

    def shipmmg_sweep(rtol):
        tds = []
        for r in rudders:
            for U in speeds:
                for sgn in (1, -1):
                    dl = sgn * np.clip(rate * tl, 0, math.radians(r))
                    sol = simulate_mmg_3dof(basic, man, tl, dl, np.full(tl.size, ns[U]), u0=U, ρ=model.particulars.rho,
                                            rtol=rtol, atol=rtol * 1e-3)
                    y = sol.sol(tl)
                    m = turning_metrics(tl, y[3], y[4], y[5], y[0], dl, lpp=L, v=y[1], execute_time=0.0)
                    tds.append(m.tactical_diameter_L)
        return np.array(tds)

    sm_ref = shipmmg_sweep(1e-9)
    rows2 = []
    for f in ((0.1,) if args.quick else (0.05, 0.1, 0.2)):
        tm, res = _best_time(lambda: shipid_sweep(("rk4", f)), 1)
        e = float(np.max(np.abs(np.array([m.tactical_diameter_L for m in res.metrics]) - td_ref)))
        rows2.append(("shipid", f"rk4 dt={f:g} L/U", e, tm))
    for rtol in ((1e-3, 1e-5) if args.quick else (1e-3, 1e-4, 1e-5, 1e-6, 1e-7)):
        tm, res = _best_time(lambda: shipid_sweep(("dopri5", rtol)), 2)
        e = float(np.max(np.abs(np.array([m.tactical_diameter_L for m in res.metrics]) - td_ref)))
        rows2.append(("shipid", f"dopri5 rtol={rtol:g}", e, tm))
    for rtol in ((1e-3, 1e-5) if args.quick else (1e-3, 1e-4, 1e-5, 1e-6)):
        tm, tds = _best_time(lambda: shipmmg_sweep(rtol), 1)
        failed = int(np.sum(~np.isfinite(tds)))
        e = float(np.max(np.abs(tds - sm_ref))) if not failed else math.inf
        rows2.append(("shipmmg", f"rtol={rtol:g}", e, tm))
        if failed:
            print(f"shipmmg rtol={rtol:g}: {failed} of {cases} runs have no tactical diameter")
    print(f"{'code':8s} {'setting':>20s} {'TD error [L]':>13s} {'time [s]':>9s}")
    for code, st, e, tm in rows2:
        print(f"{code:8s} {st:>20s} {e:13.2e} {tm:9.3f}")
    pairs2 = _equal_accuracy(rows2)
    print()
    _print_pairs(pairs2, "L of tactical diameter")

    # ---------------------------------------------------------------- both goals side by side
    print("\nGOALS (same run; ratio = shipmmg time / fastest shipid time at least as accurate)")
    print(f"{'shipmmg setting':>16s} | {'1: one turn (goal >= 5x)':>26s} | {f'2: {cases}-case sweep (goal >= 50x)':>34s}")
    by1 = {p[0]: p for p in pairs1}
    by2 = {p[0]: p for p in pairs2}
    for st in sorted(set(by1) | set(by2), key=lambda s: -float(s.split("=")[1])):
        cells = []
        for by, goal in ((by1, 5.0), (by2, 50.0)):
            p = by.get(st)
            if p is None or p[3] is None:
                cells.append("n/a" if p is None else "no shipid setting as accurate")
            else:
                cells.append(f"{p[6]:6.1f}x ({p[3]}) {'met' if p[6] >= goal else 'NOT met'}")
        print(f"{st:>16s} | {cells[0]:>26s} | {cells[1]:>34s}")


if __name__ == "__main__":
    main()
