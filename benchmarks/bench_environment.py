"""EKF fit time per sample with and without the environment terms (wind inputs and coefficients,
current states), on the compiled EKF kernel and on the numpy path, as ratios measured in the same run.

The same synthetic logs (shipid.environment.synthetic.environment_log, a known wind and current) are
fitted twice with the same settings: the plain ``lowspeed`` model estimating hydrodynamic coefficients,
and ``with_environment(lowspeed, wind, current="constant")`` estimating the same coefficients plus three
wind components and the two current states; each once compiled (numba; a warm-up fit
compiles first and is not timed) and once on the numpy path (``shipid._jit.disabled()``: the path every
fit took before the models declared their equations to the kernel).

    python benchmarks/bench_environment.py            # 2 logs x 200 s at 1 Hz, 2 passes
    (with an editable install elsewhere, run it as PYTHONPATH=. python benchmarks/... from the worktree)
    python benchmarks/bench_environment.py --seconds 600 --every 5
"""
from __future__ import annotations

import argparse
import contextlib
import time
import warnings

import sys as _sys
from pathlib import Path as _Path

_sys.path.insert(0, str(_Path(__file__).resolve().parents[1]))  # measure this checkout, not an installed copy

from shipid import _jit
from shipid.environment import with_environment
from shipid.environment.synthetic import NOISE_STD, environment_log
from shipid.identify import EKFIdentifier
from shipid.models import get_model

HYD = ["X0F", "Yv", "Yr", "Nv", "Nr", "CD"]
WIND = ["wX1", "wY1", "wN2"]


def _time_fit(model, logs, estimate, substeps, extra):
    ident = EKFIdentifier(model, estimate=estimate, init="model", meas_std=NOISE_STD, n_passes=2, substeps=substeps,
                          input_hold="zoh", **extra)
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        ident.fit(logs)
    return time.perf_counter() - t0, ident


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=200.0, help="duration of each synthetic log [s]")
    ap.add_argument("--logs", type=int, default=2, help="number of logs")
    ap.add_argument("--every", type=int, default=10, help="decimation of the 10 Hz logs for the fit")
    ap.add_argument("--substeps", type=int, default=2, help="RK4 substeps per interval")
    a = ap.parse_args(argv)
    truth = with_environment(get_model("lowspeed"), wind="esso-osaka-3m", current="constant")
    logs = [environment_log(truth, seed=s, duration=a.seconds, current=(0.03, -0.02)).iloc[::a.every]
            for s in range(1, a.logs + 1)]
    n = sum(len(lg) for lg in logs) * 2  # samples filtered (2 passes)
    plain = get_model("lowspeed")
    cols = ["time", "x", "y", "psi", "u", "v", "r", "delta", "n"]
    cases = {"lowspeed (no environment)": (plain, [lg[cols] for lg in logs], HYD, {}),
             "lowspeed + wind + current": (truth, logs, HYD + WIND, truth.identifier_settings())}
    paths = {"compiled": contextlib.nullcontext} if _jit.enabled() else {}
    paths["numpy"] = _jit.disabled
    times = {}
    for path, ctx in paths.items():
        for name, (model, lgs, est, extra) in cases.items():
            with ctx():
                if path == "compiled":  # compile (or load the numba cache) outside the timing
                    _time_fit(model, lgs, est, a.substeps, extra)
                times[path, name] = _time_fit(model, lgs, est, a.substeps, extra)[0]
    print(f"{a.logs} logs x {a.seconds:g} s, {n} filtered samples ({a.substeps} RK4 substeps each)")
    print(f"{'path':9s} {'model':30s} {'states':>6s} {'estimated':>9s} {'s total':>8s} {'ms/sample':>10s}")
    for (path, name), t in times.items():
        model, _, est, _ = cases[name]
        print(f"{path:9s} {name:30s} {model.nx:6d} {len(est):9d} {t:8.2f} {1e3 * t / n:10.3f}")
    for path in paths:
        print(f"ratio {path} (with / without environment): "
              f"{times[path, 'lowspeed + wind + current'] / times[path, 'lowspeed (no environment)']:.2f}")
    if "compiled" in paths:
        for name in cases:
            print(f"speed-up compiled / numpy, {name}: {times['numpy', name] / times['compiled', name]:.1f}x")

if __name__ == "__main__":
    main()
