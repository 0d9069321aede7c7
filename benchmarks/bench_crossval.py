"""Speed of cross-validation and model choice, as ratios measured in the same run.

1. The folds x candidates of a model choice (``shipid fit --model auto``'s cross-validation,
   :func:`shipid.crossval.choose_model`) on 2 Dask worker processes against the same members serially
   (goal >= 1.7x on 2 free cores).  Cold: the Dask half includes the cluster start and each worker's first
   calls (imports, loading the compiled kernels from numba's cache); the serial half runs first, in this
   process, after a warm-up that runs every candidate once.  The two halves' numbers are compared to the bit.
2. The share of each stage of a fold in the serial half (CPU seconds, this process): the EKF stage, the
   output-error refinement (its residuals and Jacobian columns: one batched simulation of the nominal and all
   perturbed parameter sets per Jacobian, the closed-loop metric residuals one batch of parameter sets per
   manoeuvre), the closed-loop standard manoeuvres of the left-out runs, and their open-loop horizon
   predictions; the rest (reading, replays, metrics, the physical-damping check) is "other".

Data (``--data``): ``marin`` -- the four MARIN KVLCC2 training runs (tc+-35, zz+-10; the zz+-20 runs are not
read) with the candidates of ``--model auto`` (kcs-response, response-nl, mmg); ``esso`` -- the Esso Osaka runs
with ``lowspeed`` + wind + current (``--folds`` K of them); ``bundled`` -- the synthetic KCS logs in data/ with
kcs-response and mmg (EKF stage only; a quick check).

Run: ``OPENBLAS_NUM_THREADS=1 python benchmarks/bench_crossval.py --data marin``.  The numbers depend on the
load of the machine: state it (``uptime``) with the result.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
import warnings
from pathlib import Path

warnings.simplefilter("ignore")
REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))  # measure this checkout (the Dask workers inherit the path), not an installed copy
SHARED = REPO.parent / "shared" / "data"


def _setup(data: str, folds):
    from shipid.crossval import Candidate
    from shipid.logs import read_log

    if data == "marin":
        d = SHARED / "kvlcc2_marin"
        logs = [read_log(d / f"MARIN_FREE_KVLCC2_{k}_m.dat") for k in ("tc_35", "tc_-35", "zz_10", "zz_-10")]
        return logs, None, {}, folds
    if data == "esso":
        files = sorted((SHARED / "esso_osaka_frt").glob("*/*.csv"))
        logs = [read_log(f, schema="esso-frt") for f in files]
        return logs, [Candidate("lowspeed", None, "esso-osaka-3m", "constant")], {}, folds
    logs = [read_log(p) for p in sorted((REPO / "data").glob("kcs_*.csv"))]
    return logs, [Candidate("kcs-response"), Candidate("mmg", "kcs")], {"refine": None}, folds


class _Stages:
    """CPU seconds spent inside each stage (wrapping the functions a fold calls)."""

    def __init__(self):
        self.cpu = {"ekf": 0.0, "refinement": 0.0, "closed-loop manoeuvres": 0.0, "horizon predictions": 0.0}

    def wrap(self, owner, name, stage):
        fn = getattr(owner, name)

        def timed(*a, **k):
            c0 = time.process_time()
            try:
                return fn(*a, **k)
            finally:
                self.cpu[stage] += time.process_time() - c0

        setattr(owner, name, timed)

    def install(self):
        import shipid.crossval as hz  # (a fold calls the name crossval imported)
        import shipid.validation.replay as val
        from shipid.identify.batch import OutputErrorRefiner
        from shipid.identify.identifier import EKFIdentifier

        self.wrap(EKFIdentifier, "fit", "ekf")
        self.wrap(OutputErrorRefiner, "fit", "refinement")
        self.wrap(val, "_standard", "closed-loop manoeuvres")
        self.wrap(hz, "horizon_prediction", "horizon predictions")


def _strip(choice) -> str:
    return json.dumps({cv.candidate: {k: v for k, v in cv.to_dict().items() if k not in ("folds", "settings")}
                       for cv in choice.results}, sort_keys=True, default=str)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", choices=("marin", "esso", "bundled"), default="marin")
    ap.add_argument("--folds", default="loro", help="'loro' or K (default loro)")
    ap.add_argument("--workers", type=int, default=2)
    a = ap.parse_args(argv)
    from shipid.campaign import Engine
    from shipid.crossval import choose_model

    folds = a.folds if a.folds == "loro" else int(a.folds)
    logs, cands, fit_options, folds = _setup(a.data, folds)
    print(f"load before: {os.getloadavg()[0]:.2f} (1 min), {os.cpu_count()} CPUs; data {a.data}, {len(logs)} logs")
    kw = dict(folds=folds, fit_options=fit_options)
    # warm-up of this process: every candidate on two logs (imports, compiled kernels of each model), not timed
    choose_model(logs[:2], cands, folds="loro", fit_options=fit_options)
    stages = _Stages()
    stages.install()
    t0, c0 = time.perf_counter(), time.process_time()
    serial = choose_model(logs, cands, **kw)
    t_serial, c_serial = time.perf_counter() - t0, time.process_time() - c0
    t0 = time.perf_counter()
    with Engine(a.workers, progress=False) as eng:
        par = choose_model(logs, cands, engine=eng, **kw)
        t_par = time.perf_counter() - t0
        t_start = eng.stats.get("start", float("nan"))
        member_cpu = sum(eng.stats.get("member_cpu") or [float("nan")])
    n = sum(len(cv.folds) for cv in serial.results)
    print(f"members (folds x candidates): {n}; chosen: {serial.best.candidate if serial.success else 'none'}")
    print(f"serial:            {t_serial:8.1f} s wall, {c_serial:8.1f} s CPU")
    print(f"{a.workers} Dask workers (cold): {t_par:8.1f} s wall (cluster start {t_start:.1f} s)")
    print(f"ratio serial / {a.workers} workers: {t_serial / t_par:.2f}x (goal 1.7x on 2 free cores)")
    print(f"identical to the bit: {_strip(serial) == _strip(par)}")
    # what bounds the ratio: members running side by side each take more CPU than one alone (shared caches and
    # memory bandwidth; on a virtual machine, whatever else its host runs), plus each worker's first calls
    print(f"members' CPU on the workers / serial CPU: {member_cpu / c_serial:.2f}x (each worker's first calls "
          f"included; the ratio cannot exceed {a.workers * c_serial / member_cpu:.2f}x)")
    total = sum(stages.cpu.values())
    print("share of the serial CPU per stage:")
    for k, v in stages.cpu.items():
        print(f"  {k:24s} {v:8.1f} s  {v / c_serial:6.1%}")
    print(f"  {'other':24s} {c_serial - total:8.1f} s  {(c_serial - total) / c_serial:6.1%}")
    print(f"load after: {os.getloadavg()[0]:.2f} (1 min)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
