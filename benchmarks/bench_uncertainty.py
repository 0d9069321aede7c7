"""Speed of the uncertainty machinery, as ratios measured in the same run.

1. 500 parameter draws of a 35 deg turning circle as ONE batch (``predict_manoeuvres``) against 500
   single-member ``turning_circle`` runs (goal >= 30x).
2. A campaign of 16 fits on 2 Dask worker processes (LocalCluster) against the same 16 fits serially
   (goal >= 1.7x on 2 free cores), with two member sizes: "light" (EKF only, two 60 s logs: ~0.1 CPU-s
   a member once warm) and "full" (EKF, output-error refinement and 200-draw predicted turn and zigzag
   on two whole bundled logs: ~3 CPU-s a member, what a campaign member with ``refine`` and ``draws``
   does).  The serial half runs in a fresh process; both halves are timed warm (after the warm-up the
   engine runs on each worker at start-up, ``shipid.campaign.warm_fits``, ~3 s per process) and cold
   (warm-up, and for Dask the cluster start, included).  Also printed: the ceiling (the same members on
   a pre-warmed ``ProcessPoolExecutor``), the per-worker warm-up, member durations, the idle tail, the
   CPU of the members, of the workers' other threads and of the main process, and the same Dask half
   with Dask's default configuration (``Engine(quiet=False)``).
3. MCMC effective samples per second: emcee with vectorised walkers (one batched simulation per half
   ensemble) against emcee calling the likelihood once per walker, same chain settings.
4. The MCMC column's problem (docs/uncertainty.md sect. 3: c1-c3 and six initial states, two 40 s logs):
   one batched likelihood call on the compiled replay against the numpy one, and effective samples per
   CPU-second of ``moves="independence"`` against ``moves="de"`` (same steps, same start).

Run: ``OPENBLAS_NUM_THREADS=1 python benchmarks/bench_uncertainty.py [--draws 500] [--fits 16] [--steps 300]``.
The numbers depend on the load of the machine: state it with the result.
"""
from __future__ import annotations

import argparse
import contextlib
import os
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

warnings.simplefilter("ignore", RuntimeWarning)
REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))  # measure this checkout (the Dask workers inherit the path), not an installed copy


def bench_draws(n: int) -> None:
    from shipid.identify import FitResult
    from shipid.manoeuvres import turning_circle
    from shipid.models import get_model
    from shipid.uncertainty import parameter_draws, predict_manoeuvres

    import pandas as pd

    m = get_model("kcs-response", "synthetic-truth")
    est = ["b1", "b2", "b3", "b4", "c1", "c2", "c3"]
    sd = 0.01 * np.abs(m.params_series()[est].to_numpy())
    res = FitResult("kcs-response", m.params_series().to_dict(), {}, pd.DataFrame(np.diag(sd**2), index=est, columns=est))
    t0 = time.perf_counter()
    pred = predict_manoeuvres(res, ["turning:35"], draws=n, seed=0)
    t_batch = time.perf_counter() - t0
    P = parameter_draws(res, n, seed=0)
    t0 = time.perf_counter()
    td = [turning_circle(m, 35, side="starboard", params=p).metrics[0].tactical_diameter_L for p in P]
    t_loop = time.perf_counter() - t0
    same = np.allclose(np.sort(td), np.sort([r.tactical_diameter_L for r in pred.runs["turning_35_starboard"].metrics[1:]]),
                       rtol=1e-6)
    print(f"[1] {n} draws of a 35 deg turn: one batch {t_batch:.2f} s, {n} single runs {t_loop:.2f} s -> "
          f"{t_loop / t_batch:.1f}x (goal >= 30x); same tactical diameters: {same}")


def _short_logs(tmp: Path) -> list[str]:
    out = []
    for name in ("kcs_tc_p35", "kcs_zz_m10", "kcs_zz_p20_rpm", "kcs_tc_m25_rpm"):
        lines = (REPO / "data" / f"{name}.csv").read_text().splitlines()
        p = tmp / f"{name}_60s.csv"
        p.write_text("\n".join(lines[:601]) + "\n")
        out.append(str(p))
    return out


_SERIAL_HALF = """
import json, sys, time
t0 = time.perf_counter()
sys.path.insert(0, sys.argv[1])
from shipid.campaign import Engine, load_campaign, run_campaign, warm_fits, warm_specs
camp = load_campaign(sys.argv[2])
warm_fits(warm_specs(camp["fits"]))
t1, c1 = time.perf_counter(), time.process_time()
run_campaign(camp, sys.argv[3], engine=Engine(1, progress=False))
print(json.dumps({"warm": t1 - t0, "run": time.perf_counter() - t1, "run_cpu": time.process_time() - c1}))
"""


def _pool_ceiling(camp: dict, workers: int) -> float:
    """Wall seconds of the campaign's members on a pre-warmed ProcessPoolExecutor (no Dask, nothing written)."""
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor
    from functools import partial

    from shipid.campaign import member_seeds, run_member, warm_fits, warm_specs

    specs = [{**f, "seed": s} for f, s in zip(camp["fits"], member_seeds(camp["seed"], len(camp["fits"])))]
    with ProcessPoolExecutor(workers, mp_context=mp.get_context("spawn"),
                             initializer=partial(warm_fits, warm_specs(specs))) as ex:
        while len({f.result() for f in [ex.submit(_pid_after, 0.5) for _ in range(workers)]}) < workers:
            pass  # every worker process is up and warm
        t0 = time.perf_counter()
        list(ex.map(run_member, specs))
        return time.perf_counter() - t0


def _pid_after(seconds: float) -> int:
    time.sleep(seconds)
    return os.getpid()


def bench_campaign(n_fits: int, workers: int, members: str = "light", ceiling: bool = True,
                   compare: bool = True) -> None:
    """Campaign of ``n_fits`` members: serial (a fresh process) against ``workers`` Dask workers.

    Both halves are timed warm (after the same warm-up, :func:`shipid.campaign.warm_fits`, that the
    engine runs on each worker at start-up) and cold (warm-up included; for Dask also the cluster start).
    ``ceiling``: also the same members on a pre-warmed ProcessPoolExecutor; ``compare``: also a Dask half
    with Dask's default configuration (``Engine(quiet=False)``).
    """
    import json
    import pickle
    import subprocess
    from functools import partial

    from shipid.campaign import WORKER_ENV, Engine, load_campaign, run_campaign, warm_fits, warm_specs

    threads = {k: os.environ.get(k) for k in WORKER_ENV}
    env = {**os.environ, **WORKER_ENV}  # the serial half runs with the workers' thread settings
    if any(v != "1" for v in threads.values()):
        print(f"[2] note: this process runs with {threads}; the serial half and the workers with {WORKER_ENV}")
    load0 = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        if members == "light":
            logs = _short_logs(tmp)
            extra = {}
        else:
            logs = [str(REPO / "data" / f"{n}.csv") for n in ("kcs_tc_p35", "kcs_zz_m10", "kcs_zz_p20_rpm", "kcs_tc_m25_rpm")]
            extra = {"refine": True, "draws": 200, "manoeuvres": ["turning:35", "zigzag:10/10"]}
        fits = [{"name": f"fit{i:02d}", "logs": [logs[i % 4], logs[(i + 1) % 4]], "passes": 2, **extra}
                for i in range(n_fits)]
        camp_path = tmp / "c.json"
        camp_path.write_text(json.dumps({"seed": 1, "fits": fits}))
        camp = load_campaign(camp_path)
        # what travels to a worker per member: the member's settings and file paths, not the logs' arrays
        payload = max(len(pickle.dumps(f)) for f in camp["fits"])
        ser = json.loads(subprocess.run([sys.executable, "-c", _SERIAL_HALF, str(REPO), str(camp_path),
                                         str(tmp / "serial")], env=env, capture_output=True, text=True,
                                        check=True).stdout.strip().splitlines()[-1])
        member_s = [m["seconds"] for m in json.loads((tmp / "serial" / "campaign.json").read_text())["members"]]
        runs = {}
        for quiet in (True, False) if compare else (True,):
            with Engine(workers, progress=False, quiet=quiet) as eng:
                eng._start()
                t0 = time.perf_counter()
                eng.warm(partial(warm_fits, warm_specs(camp["fits"])))  # what run_campaign asks for: not repeated
                t_warm = time.perf_counter() - t0
                t0 = time.perf_counter()
                run_campaign(camp, tmp / f"dask{int(quiet)}", engine=eng)
                runs[quiet] = (t_warm, time.perf_counter() - t0, dict(eng.stats))
        t_warm, t_dask, st = runs[True]
        same = all(json.loads((tmp / "serial" / f["name"] / "result.json").read_text()) ==
                   json.loads((tmp / f"dask{int(q)}" / f["name"] / "result.json").read_text()) for f in fits for q in runs)
        t_pool = _pool_ceiling(camp, workers) if ceiling else float("nan")
    cold_s, cold_d = ser["warm"] + ser["run"], st["start"] + t_warm + t_dask
    member_cpu = sum(st["member_cpu"])
    ends = sorted(st["worker_end"].values())
    print(f"[2] campaign of {n_fits} {members} fits, serial (fresh process) against {workers} Dask workers; load "
          f"average {load0:.1f} before, {os.getloadavg()[0]:.1f} after (1-min, incl. this run) on {os.cpu_count()} CPUs\n"
          f"    warm: serial {ser['run']:.1f} s, Dask {t_dask:.1f} s -> {ser['run'] / t_dask:.2f}x (goal >= 1.7x); "
          f"ceiling, pre-warmed ProcessPoolExecutor({workers}) {t_pool:.1f} s -> {ser['run'] / t_pool:.2f}x\n"
          f"    cold: serial {cold_s:.1f} s (warm-up {ser['warm']:.1f} s), Dask {cold_d:.1f} s (cluster start "
          f"{st['start']:.1f} s, warm-up {t_warm:.1f} s; per worker {', '.join(f'{v:.1f}' for v in st['warm'].values())} s)"
          f" -> {cold_s / cold_d:.2f}x\n"
          f"    members: serial {min(member_s):.2f}-{max(member_s):.2f} s (median {np.median(member_s):.2f}); on Dask "
          f"{min(st['member_seconds']):.2f}-{max(st['member_seconds']):.2f} s; workers' last member ends at "
          f"{', '.join(f'{e:.1f}' for e in ends)} s (idle tail {ends[-1] - ends[0]:.1f} s)\n"
          f"    CPU during the Dask run: members {member_cpu:.1f} s, the workers' other threads "
          f"{sum(st['worker_cpu'].values()) - member_cpu:.2f} s, main process (client, scheduler, nannies) "
          f"{st['main_cpu']:.2f} s; identical results: {same}; largest member payload {payload} bytes\n"
          f"    CPU-time projection for free cores (serial CPU / (busiest worker's CPU + main process CPU / "
          f"{workers})): {_cpu_projection(ser, st, workers):.2f}x -- a model that ignores waiting; the wall ratios "
          "on an idle machine are the measurement")
    if False in runs:  # the same Dask half with Dask's default configuration (``Engine(quiet=False)``)
        t_warm, t_dask, st = runs[False]
        member_cpu = sum(st["member_cpu"])
        print(f"    Dask's default configuration (Engine(quiet=False)): warm {t_dask:.1f} s -> {ser['run'] / t_dask:.2f}x, "
              f"cold {cold_s / (st['start'] + t_warm + t_dask):.2f}x; CPU: members {member_cpu:.1f} s, the workers' "
              f"other threads {sum(st['worker_cpu'].values()) - member_cpu:.2f} s, main process {st['main_cpu']:.2f} s; "
              f"CPU-time projection {_cpu_projection(ser, st, workers):.2f}x")


def _cpu_projection(ser: dict, st: dict, workers: int) -> float:
    """Serial run's CPU over the parallel run's critical CPU (busiest worker process + its share of the main
    process): the ratio free cores would give if nothing ever waited (load-independent, a model)."""
    return ser["run_cpu"] / (max(st["worker_cpu"].values()) + st["main_cpu"] / workers)


def bench_mcmc(steps: int) -> None:
    from shipid.identify import EKFIdentifier
    from shipid.uncertainty.posterior import sample_posterior
    from shipid.models import get_model
    from shipid.synthetic import TrialRecipe, make_trial

    m = get_model("kcs-response", "synthetic-truth")
    log = make_trial(m, TrialRecipe("short_tc", "turning", 25.0, 20.0, dt_s=0.2, execute_s=2.0), np.random.default_rng(5))[0]
    res = EKFIdentifier(m, estimate=["c2", "c3"], init="model").fit(log).result()
    out, chains = {}, {}
    for vec in (True, False):
        t0 = time.perf_counter()
        s = sample_posterior(res, log, walkers=32, steps=steps, burn=steps // 4, seed=3, vectorize=vec)
        dt = time.perf_counter() - t0
        chains[vec] = s.samples
        out[vec] = (s.diagnostics["ess_min"] / dt, dt, s.diagnostics["ess_min"], s.diagnostics["n_likelihood_calls"])
    v, n = out[True], out[False]
    # same seed and moves: the two samplers produce the same chain, so the ESS is the same and the ESS/s
    # ratio is the wall-time ratio (the ESS of a short chain is itself rough: it is printed, not compared)
    same = np.allclose(chains[True], chains[False], rtol=1e-10, atol=0)
    print(f"[3] MCMC (2 coefficients, 32 walkers, {steps} steps): vectorised {v[1]:.1f} s ({v[3]} batched calls), "
          f"per walker {n[1]:.1f} s ({n[3]} calls); identical chains: {same}; ESS_min {v[2]:.0f} -> "
          f"{v[0]:.1f} vs {n[0]:.1f} ESS/s = {v[0] / n[0]:.1f}x")


def bench_mcmc_study(steps: int) -> None:
    from shipid import _jit
    from shipid._kernel import filter_functions
    from shipid.identify import EKFIdentifier
    from studies.coverage import COVERAGE_RECIPES
    from shipid.uncertainty.posterior import OutputErrorLikelihood, sample_posterior
    from shipid.models import get_model
    from shipid.synthetic import KCS_NOISE_STD, make_trial

    m = get_model("kcs-response", "synthetic-truth")
    rng = np.random.default_rng(2026)
    logs = [make_trial(m, r, rng, KCS_NOISE_STD)[0] for r in COVERAGE_RECIPES]
    est = ["c1", "c2", "c3"]
    res = EKFIdentifier(m, estimate=est, n_passes=2).fit(logs).result()
    like = OutputErrorLikelihood(m, logs, est, meas_std=res.settings["meas_std"], x0_states=True)
    th = np.hstack([[res.coef[n] for n in est], np.zeros(like.n_x0)]) + 1e-5 * np.random.default_rng(0).standard_normal((36, 9))
    per = {}
    for mode in ("compiled", "numpy"):
        with (_jit.disabled() if mode == "numpy" else contextlib.nullcontext()):
            like(th)
            t0, n = time.process_time(), 0
            while time.process_time() - t0 < 2.0:
                like(th)
                n += 1
            per[mode] = (time.process_time() - t0) / n
    print(f"[4] likelihood of 36 walkers x 2 logs x 401 samples: compiled replay {per['compiled'] * 1e3:.1f} ms "
          f"(kernel available: {filter_functions(m, notice=False) is not None}), numpy {per['numpy'] * 1e3:.1f} ms "
          f"= {per['numpy'] / per['compiled']:.1f}x")
    out = {}
    for mv in ("independence", "de"):
        t0 = time.process_time()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            s = sample_posterior(res, logs, walkers=36, steps=steps, burn=300, seed=3, moves=mv, sample_x0=True)
        cpu = time.process_time() - t0
        d = s.diagnostics
        out[mv] = d["ess_min"] / cpu
        print(f"[4] {mv:12s} {steps} steps (300 burn-in): {cpu:.1f} CPU-s, tau_max {d['tau_max']:.1f}, ESS_min "
              f"{d['ess_min']:.0f}, split-R-hat {d['rhat_max']:.4f}, converged {s.converged} -> {out[mv]:.1f} ESS/CPU-s")
    print(f"[4] independence / de: {out['independence'] / out['de']:.1f}x ESS per CPU-second")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--draws", type=int, default=500)
    ap.add_argument("--fits", type=int, default=16)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--steps", type=int, default=300)
    ap.add_argument("--only", choices=("draws", "campaign", "mcmc", "mcmc-study"), default=None)
    ap.add_argument("--members", choices=("light", "full", "both"), default="both",
                    help="campaign member size (module docstring, item 2)")
    ap.add_argument("--study-steps", type=int, default=1000)
    ap.add_argument("--no-ceiling", action="store_true", help="campaign: skip the ProcessPoolExecutor ceiling")
    ap.add_argument("--no-compare", action="store_true",
                    help="campaign: skip the Dask half with Dask's default configuration")
    a = ap.parse_args()
    if a.only in (None, "draws"):
        bench_draws(a.draws)
    if a.only in (None, "campaign"):
        for members in (("light", "full") if a.members == "both" else (a.members,)):
            bench_campaign(a.fits, a.workers, members, ceiling=not a.no_ceiling, compare=not a.no_compare)
    if a.only in (None, "mcmc"):
        bench_mcmc(a.steps)
    if a.only in (None, "mcmc-study"):
        bench_mcmc_study(a.study_steps)


if __name__ == "__main__":
    main()
