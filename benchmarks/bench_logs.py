"""Reading speed of shipid.read_log against plain pandas parsing of the same files.

Prints, for a 12 000-row CSV in the default schema and for a MARIN SIMMAN .dat file
(when ../shared/data/kvlcc2_marin is present), the time of ``read_log`` (parse +
validation + unit conversion + unwrapping + MARIN time rebuild and rotation +
channel-consistency checks), of ``read_log(..., consistency_checks=False)`` and of
``pandas.read_csv`` (parse only), the ratio to pandas and the share the checks add (best CPU times,
with and without the checks measured alternately).  Run:

    python benchmarks/bench_logs.py
"""
from __future__ import annotations

import tempfile
import time
import warnings
from pathlib import Path

import numpy as np
import pandas as pd

import sys as _sys
from pathlib import Path as _Path

_sys.path.insert(0, str(_Path(__file__).resolve().parents[1]))  # measure this checkout, not an installed copy

from shipid import TrialLog, read_log

MARIN = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "kvlcc2_marin"


def best_of(fn, repeat: int = 5) -> float:
    """Best CPU time of ``fn`` [s] (process time: on a shared machine other processes' load does not count)."""
    best = float("inf")
    for _ in range(repeat):
        t0 = time.process_time()
        fn()
        best = min(best, time.process_time() - t0)
    return best


def best_of_pair(fa, fb, repeat: int = 15) -> tuple[float, float]:
    """Best times of ``fa`` and ``fb`` run alternately (a shared machine's load hits both alike)."""
    ba = bb = float("inf")
    for _ in range(repeat):
        ba = min(ba, best_of(fa, 1))
        bb = min(bb, best_of(fb, 1))
    return ba, bb


def main() -> None:
    n = 12_000
    t = np.arange(n) * 0.1
    rng = np.random.default_rng(0)
    psi = np.cumsum(rng.normal(0, 1e-3, n))
    log = TrialLog.from_arrays(t, consistency_checks=False, x=np.cumsum(np.cos(psi)) * 0.15, y=np.cumsum(np.sin(psi)) * 0.15, psi=psi,
                               u=1.5 + rng.normal(0, 0.01, n), v=rng.normal(0, 0.01, n),
                               r=np.gradient(psi, t), delta=np.full(n, 0.2), n=np.full(n, 10.0))
    rows = []
    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "log12k.csv"
        log.to_csv(p)
        t_ours, t_bare = best_of_pair(lambda: read_log(p), lambda: read_log(p, consistency_checks=False))
        t_pd = best_of(lambda: pd.read_csv(p, comment="#"))
        rows.append(("CSV 12000 rows x 9", t_ours, t_bare, t_pd))
    f = MARIN / "MARIN_FREE_KVLCC2_tc_35_m.dat"
    if f.exists():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            t_ours, t_bare = best_of_pair(lambda: read_log(f), lambda: read_log(f, consistency_checks=False))
        t_pd = best_of(lambda: pd.read_csv(f, sep=r"\s+", skiprows=3, header=None))
        rows.append((f"MARIN {f.name} ({len(read_log(f))} rows x 11)", t_ours, t_bare, t_pd))
    else:
        print(f"(MARIN data not found at {MARIN}; skipped)")
    print(f"{'file':55s} {'read_log [ms]':>14s} {'no checks [ms]':>15s} {'pandas [ms]':>12s} {'ratio':>7s} "
          f"{'checks':>7s}")
    for name, a, c, b in rows:
        print(f"{name:55s} {a * 1e3:14.1f} {c * 1e3:15.1f} {b * 1e3:12.1f} {a / b:7.2f} {a / c - 1:+7.0%}")


if __name__ == "__main__":
    main()
