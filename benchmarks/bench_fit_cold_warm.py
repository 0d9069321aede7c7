"""The README's KVLCC2 fit as a new user meets it: compiled path cold and warm, numpy path, in one run.

    nice -n 10 python benchmarks/bench_fit_cold_warm.py [--skip-numpy] [--numpy-twice]

Runs ``shipid fit`` on the MARIN tc+-35 and zz+-10 runs with ``--model mmg`` (the README's command;
``../shared/data/kvlcc2_marin``) as fresh child processes, in this order:

1. compiled, cold: ``NUMBA_CACHE_DIR`` an empty folder (what the first run after ``pip install .`` does:
   numba compiles the filter, ~30 s, and stores it there);
2. compiled, warm: the same folder again (numba loads the compiled filter from it);
3. numpy path: ``SHIPID_JIT=0`` (nothing to compile or cache; ``--numpy-twice`` runs it twice to show that).

For each run it prints the wall time, the child's CPU time (user + system, the fairer clock on a shared
machine), the longest stretch without a line of output (stdout and stderr; the user's "silent" time) and
the exit status, then the ratios numpy/cold, numpy/warm and cold/warm, all measured in this run.  The
coefficients of the three fits are compared too (the compiled and numpy paths should agree to rounding).
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
MARIN = ROOT / ".." / "shared" / "data" / "kvlcc2_marin"
RUNS = ["MARIN_FREE_KVLCC2_tc_35_m.dat", "MARIN_FREE_KVLCC2_tc_-35_m.dat",
        "MARIN_FREE_KVLCC2_zz_10_m.dat", "MARIN_FREE_KVLCC2_zz_-10_m.dat"]


def run_fit(out: Path, env_extra: dict):
    """One ``python -m shipid fit`` child: dict of wall, cpu, longest silence [s], exit status, first lines,
    coefficients."""
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1",
           "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""), **env_extra}
    cmd = [sys.executable, "-u", "-m", "shipid", "fit", *(str(MARIN / r) for r in RUNS), "--model", "mmg",
           "-o", str(out), "--force"]
    r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, env=env, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            bufsize=1)
    stamps, lines = [t0], []

    def read():
        for line in proc.stdout:
            stamps.append(time.perf_counter())
            lines.append(line.rstrip("\n"))

    th = threading.Thread(target=read)
    th.start()
    rc = proc.wait()
    th.join()
    wall = time.perf_counter() - t0
    stamps.append(t0 + wall)
    r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime)
    silent = max(b - a for a, b in zip(stamps[:-1], stamps[1:]))
    if rc not in (0, 1, 3) or not out.exists():
        raise RuntimeError(f"shipid fit failed ({rc}): {' | '.join(lines[-5:])}")
    coef = json.loads(out.read_text())["coef"]
    return {"wall": wall, "cpu": cpu, "silent": silent, "rc": rc, "lines": lines, "coef": coef}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--skip-numpy", action="store_true", help="only the compiled path (cold, warm)")
    ap.add_argument("--numpy-twice", action="store_true", help="run the numpy path twice (cold = warm there)")
    args = ap.parse_args(argv)
    if not all((MARIN / r).exists() for r in RUNS):
        print(f"MARIN KVLCC2 runs not found in {MARIN.resolve()}: nothing to measure")
        return 0
    res = {}
    print(f"shipid fit (README KVLCC2 command: {len(RUNS)} MARIN runs, --model mmg), one child process each")
    print(f"{'run':<20}{'wall s':>9}{'CPU s':>9}{'silent s':>10}{'exit':>6}  compile notice", flush=True)

    def one(label, out, env):
        r = res[label] = run_fit(out, env)
        notice = next((ln for ln in r["lines"] if "compiling" in ln), "none")
        print(f"{label:<20}{r['wall']:9.1f}{r['cpu']:9.1f}{r['silent']:10.1f}{r['rc']:6d}  {notice[:70]}", flush=True)

    with tempfile.TemporaryDirectory() as tmp:
        cache = Path(tmp) / "numba_cache"
        cache.mkdir()
        env = {"SHIPID_JIT": "1", "NUMBA_CACHE_DIR": str(cache)}
        one("compiled, cold", Path(tmp) / "cold.json", env)
        one("compiled, warm", Path(tmp) / "warm.json", env)
        if not args.skip_numpy:
            one("numpy path", Path(tmp) / "numpy.json", {"SHIPID_JIT": "0"})
            if args.numpy_twice:
                one("numpy path, again", Path(tmp) / "numpy2.json", {"SHIPID_JIT": "0"})
    cold, warm = res["compiled, cold"], res["compiled, warm"]
    print(f"cold / warm (compiled): wall {cold['wall'] / warm['wall']:.2f}x, CPU {cold['cpu'] / warm['cpu']:.2f}x; "
          f"compilation ~{cold['wall'] - warm['wall']:.0f} s wall")
    if "numpy path" in res:
        npy = res["numpy path"]
        print(f"numpy / compiled cold: wall {npy['wall'] / cold['wall']:.2f}x, CPU {npy['cpu'] / cold['cpu']:.2f}x")
        print(f"numpy / compiled warm: wall {npy['wall'] / warm['wall']:.2f}x, CPU {npy['cpu'] / warm['cpu']:.2f}x")
    ref = cold["coef"]
    for k, r in res.items():
        dev = max(abs(r["coef"][n] - ref[n]) / max(abs(ref[n]), 1e-12) for n in ref)
        print(f"coefficients of '{k}' vs compiled cold: largest relative difference {dev:.1e}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
