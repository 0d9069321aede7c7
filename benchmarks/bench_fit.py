"""End-to-end fit speed: the ``shipid fit`` CLI on the MARIN KVLCC2 runs, numpy path vs compiled path.

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_fit.py [--repeat 3] [--models mmg,kcs-response]

Each fit runs as a fresh ``python -m shipid fit`` process on the six MARIN
full-scale runs (``../shared/data/kvlcc2_marin``; the default recipe of each
model, 2 EKF passes), once with ``SHIPID_JIT=0`` ("before": the numpy path) and
once with the compiled path ("after", numba's cache filled by a warm-up run),
interleaved, best of ``--repeat``.  The clock is the child process's CPU time
(user + system), the fair one on a shared machine; wall time is printed too.
The ratio before/after is measured in the same run; absolute times on a
shared machine are noisy.
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
MARIN = ROOT / ".." / "shared" / "data" / "kvlcc2_marin"

#: The fits measured: label -> (model, extra CLI options).  "mmg" is the default recipe (all 39
#: coefficients from the model-scale KVLCC2 set); "mmg-hull" the recipe docs/identification.md advises for
#: full-scale data (the set Froude-scaled to 320 m, hull derivatives and resistance estimated).
FITS = {"mmg": ("mmg", []),
        "mmg-hull": ("mmg", ["--lpp", "320", "--estimate", "R0,Xvv,Xrr,Yv,Yr,Yvvv,Yvvr,Yvrr,Nv,Nr,Nvvv,Nvvr,Nvrr"]),
        "kcs-response": ("kcs-response", ["--fixed", "a8=0"])}


def run_fit(label: str, files, jit: bool, out: Path):
    """(CPU s, wall s, result dict) of one ``shipid fit`` child process (exit 1, a diverged filter, and
    exit 3, a fit the consistency verdict flags, are results too: the JSON is written)."""
    model, options = FITS[label]
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "SHIPID_JIT": "1" if jit else "0",
           "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    cmd = [sys.executable, "-m", "shipid", "fit", *map(str, files), "--model", model, *options,
           "-o", str(out), "--force", "--no-progress"]
    r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    w0 = time.perf_counter()
    proc = subprocess.run(cmd, env=env, capture_output=True, text=True, cwd=ROOT)
    wall = time.perf_counter() - w0
    r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    if proc.returncode not in (0, 1, 3) or not out.exists():
        raise RuntimeError(f"shipid fit --model {model} failed ({proc.returncode}): {proc.stderr.strip()[-500:]}")
    cpu = (r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime)
    return cpu, wall, json.loads(out.read_text())


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--repeat", type=int, default=3, help="best of N (the machine may be shared)")
    ap.add_argument("--fits", default=",".join(FITS), help=f"comma-separated fits of {list(FITS)}")
    args = ap.parse_args(argv)
    files = sorted(MARIN.glob("MARIN_FREE_KVLCC2_*_m.dat"))
    if not files:
        print(f"MARIN data not found in {MARIN.resolve()}: nothing to measure")
        return 1
    from shipid import _jit

    if not _jit.available():
        print("numba not installed (extra 'fast'): only the numpy path exists; nothing to compare")
        return 1
    print(f"shipid fit on {len(files)} MARIN KVLCC2 runs; CPU time of the child process, best of {args.repeat}; "
          "before = numpy path (SHIPID_JIT=0), after = compiled path (numba cache warm)")
    print(f"{'fit':14s}{'before CPU s':>14s}{'after CPU s':>13s}{'ratio':>9s}{'before wall':>13s}{'after wall':>12s}"
          f"{'max |coef diff| / std':>23s}")
    with tempfile.TemporaryDirectory() as tmp:
        for model in args.fits.split(","):
            out = Path(tmp) / f"{model}.json"
            out.unlink(missing_ok=True)
            run_fit(model, files, True, out)  # warm-up: fills numba's cache (compile time is bench_ekf's)
            best = {True: [float("inf")] * 2, False: [float("inf")] * 2}
            res = {}
            for _ in range(args.repeat):
                for jit in (False, True):
                    out.unlink(missing_ok=True)
                    c, w, r = run_fit(model, files, jit, out)
                    best[jit] = [min(best[jit][0], c), min(best[jit][1], w)]
                    res[jit] = r
            diff = _coef_diff(res[False], res[True])
            print(f"{model:14s}{best[False][0]:14.1f}{best[True][0]:13.1f}{best[False][0] / best[True][0]:8.1f}x"
                  f"{best[False][1]:13.1f}{best[True][1]:12.1f}{diff:23.2e}"
                  f"   success before/after: {res[False].get('success')}/{res[True].get('success')}")
    print("  (coefficient agreement: largest |before - after| over the estimated coefficients, in units of their std)")
    return 0


def _coef_diff(a: dict, b: dict) -> float:
    """Largest difference of the two results' coefficients relative to their standard deviations."""
    ca, cb = a.get("coef", {}), b.get("coef", {})
    sd = a.get("coef_std", {})
    vals = [abs(ca[k] - cb[k]) / sd[k] for k in ca if k in cb and sd.get(k, 0) > 0]
    return max(vals) if vals else float("nan")


if __name__ == "__main__":
    raise SystemExit(main())
