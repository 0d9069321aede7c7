"""Glider launch study: the paper's full factorial (7 speeds x 4 angles x 5 fins x 4 CG
offsets = 560 launches) as ONE vectorised batch vs a loop of single launches.

Three ways, same model (shipid.models.glider), same surface-return event:

* batch  -- ``shipid.glider.sweep()``: all 560 launches in one RK4 batch;
* loop   -- ``shipid.glider.launch()`` called once per launch (same RK4, same step);
* ivp    -- ``scipy.integrate.solve_ivp`` (RK45, rtol 1e-6, terminal event z = 0)
            per launch, calling ``model.rhs``: what a MATLAB ode45 study like the
            paper's does.

The loops are timed on ``--sample`` launches spread over the grid (default 28) and
scaled to 560 (``--sample 560`` runs them all).  Prints wall times, ratios and the
largest differences in max depth / horizontal travel between the methods.

    python benchmarks/bench_glider.py [--sample N]
"""
from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from shipid.glider import launch, launch_state, sweep  # noqa: E402
from shipid.models import get_model  # noqa: E402


def ivp_launch(model, speed, angle, fin, cg):
    m = model.with_params({"x_g": cg})
    u = np.array([np.deg2rad(fin)])

    def surface(t, x):
        return x[1]
    surface.terminal = True
    surface.direction = -1
    x0 = launch_state(speed, angle)
    # start just below the surface so the event does not fire at t = 0
    f0 = m.rhs(0.0, x0, u)
    t0 = 1e-6
    x0 = x0 + t0 * f0
    sol = solve_ivp(lambda t, x: m.rhs(t, x, u), (t0, 60.0), x0, method="RK45", rtol=1e-6, atol=1e-9,
                    events=surface, dense_output=False, max_step=0.05)
    xe = sol.y_events[0][0] if sol.t_events[0].size else sol.y[:, -1]
    return float(np.max(sol.y[1])), float(xe[0]), float(sol.t_events[0][0]) if sol.t_events[0].size else np.nan


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sample", type=int, default=28, help="launches timed in the loops (560 = all)")
    ap.add_argument("--dt", type=float, default=0.01, help="RK4 step for batch and loop [s]")
    args = ap.parse_args(argv)
    model = get_model("glider")
    warnings.simplefilter("ignore", RuntimeWarning)

    sweep([5.0], [45.0], [0.0], [0.0], dt=args.dt)           # warm-up
    t0 = time.perf_counter()
    res = sweep(dt=args.dt)
    t_batch = time.perf_counter() - t0
    df = res.summary()
    n = len(df)
    idx = np.unique(np.linspace(0, n - 1, min(args.sample, n)).round().astype(int))

    t0 = time.perf_counter()
    loop = []
    for i in idx:
        r = df.iloc[i]
        s = launch(r.speed_m_s, r.angle_deg, r.fin_deg, r.cg_m, dt=args.dt, keep_trajectories=False)
        loop.append((s.max_depth_m, s.horizontal_m))
    t_loop = (time.perf_counter() - t0) * n / idx.size

    t0 = time.perf_counter()
    ivp = []
    for i in idx:
        r = df.iloc[i]
        ivp.append(ivp_launch(model, r.speed_m_s, r.angle_deg, r.fin_deg, r.cg_m)[:2])
    t_ivp = (time.perf_counter() - t0) * n / idx.size

    b = df[["max_depth_m", "horizontal_m"]].to_numpy()[idx]
    loop, ivp = np.array(loop), np.array(ivp)
    print(f"glider launch study: {n} launches (7 x 4 x 5 x 4), RK4 dt = {args.dt:g} s, "
          f"loops timed on {idx.size} launches and scaled to {n}")
    print(f"{'method':<34}{'wall [s]':>10}{'x batch':>10}")
    print(f"{'batch  (one vectorised RK4 run)':<34}{t_batch:>10.2f}{1.0:>10.1f}")
    print(f"{'loop   (launch() per launch)':<34}{t_loop:>10.2f}{t_loop / t_batch:>10.1f}")
    print(f"{'ivp    (solve_ivp RK45 + event)':<34}{t_ivp:>10.2f}{t_ivp / t_batch:>10.1f}")
    print(f"max |batch - loop| depth {np.abs(b[:, 0] - loop[:, 0]).max():.1e} m, horizontal {np.abs(b[:, 1] - loop[:, 1]).max():.1e} m")
    print(f"max |batch - ivp|  depth {np.abs(b[:, 0] - ivp[:, 0]).max():.1e} m, horizontal {np.abs(b[:, 1] - ivp[:, 1]).max():.1e} m")
    print(f"batch goal < 2 s: {'met' if t_batch < 2.0 else 'NOT met'} ({t_batch:.2f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
