"""EKF fit time per sample with and without the environment terms (wind inputs and coefficients,
current states), as a ratio measured in the same run.

The same synthetic logs (shipid.environment.synthetic.environment_log, a known wind and current) are
fitted twice with the same settings: the plain ``lowspeed`` model estimating hydrodynamic coefficients,
and ``with_environment(lowspeed, wind, current="constant")`` estimating the same coefficients plus three
wind components and the two current states.

    python benchmarks/bench_environment.py            # 2 logs x 200 s at 1 Hz, 2 passes
    python benchmarks/bench_environment.py --seconds 600 --every 5
"""
from __future__ import annotations

import argparse
import time
import warnings

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
    t_plain, _ = _time_fit(plain, [lg[cols] for lg in logs], HYD, a.substeps, {})
    t_env, _ = _time_fit(truth, logs, HYD + WIND, a.substeps, truth.identifier_settings())
    print(f"{a.logs} logs x {a.seconds:g} s, {n} filtered samples ({a.substeps} RK4 substeps each)")
    print(f"{'model':42s} {'states':>6s} {'estimated':>9s} {'s total':>8s} {'ms/sample':>10s}")
    print(f"{'lowspeed (no environment)':42s} {plain.nx:6d} {len(HYD):9d} {t_plain:8.2f} {1e3 * t_plain / n:10.3f}")
    print(f"{'lowspeed + wind + current':42s} {truth.nx:6d} {len(HYD) + len(WIND):9d} {t_env:8.2f} "
          f"{1e3 * t_env / n:10.3f}")
    print(f"ratio (with / without environment): {t_env / t_plain:.2f}")


if __name__ == "__main__":
    main()
