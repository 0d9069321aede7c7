"""The 16-coefficient MCMC coverage column (docs/uncertainty.md sect. 3), resumable.

Settings fixed before the run (chosen by the convergence checks of one trial chain, never by coverage):
all 16 coefficients and the 6 initial states sampled (22 dimensions, 48 walkers), moves="independence" with
the proposal from each replicate's output-error Laplace approximation, walkers started from the EKF posterior,
800 steps of which the first 100 are discarded; flat prior (``use_prior=False``): the result does not record its
prior's centre, and the default Gaussian prior centred on the EKF estimate uses the data twice -- on a trial replicate
it pulled the posterior means of a2-a7 by 0.37-0.41 sigma towards the EKF estimate (without it: within 0.06 sigma of
the output-error maximum-likelihood estimate).  Re-running the same command skips the replicates already in
the checkpoint; ``--table`` only tabulates it.

    OPENBLAS_NUM_THREADS=1 nice python -m studies.run_mcmc16_coverage CHECKPOINT.jsonl [--n 100] [--table]
"""
import argparse
import warnings

from studies.coverage import coverage_study

MCMC16 = dict(steps=800, burn=100, walkers=48, moves="independence", sample_x0=True, proposal="output-error",
              use_prior=False)

if __name__ == "__main__":
    ap = argparse.ArgumentParser()
    ap.add_argument("checkpoint")
    ap.add_argument("--n", type=int, default=100)
    ap.add_argument("--table", action="store_true", help="tabulate the checkpoint, run nothing")
    a = ap.parse_args()
    warnings.simplefilter("ignore", RuntimeWarning)
    r = coverage_study(n_replicates=a.n, draws=100, seed=2026, refine="output-error", mcmc_replicates=a.n,
                       mcmc_kwargs=MCMC16, checkpoint=a.checkpoint, run=not a.table)
    import pandas as pd

    with pd.option_context("display.width", 200, "display.max_rows", 100):
        print(r.table.to_string())
    print(r.message)
    print({k: r.settings[k] for k in ("n_done", "cpu_s_per_replicate")})
    mc = [g["mcmc"] for g in r.replicates if "mcmc" in g]
    if mc:
        import numpy as np

        print("chains: rhat_max <= %.4f, ess_min >= %.0f, tau_max <= %.2f, acceptance %.2f-%.2f, converged %d/%d" % (
            max(m["rhat_max"] for m in mc), min(m["ess_min"] for m in mc), max(m["tau_max"] for m in mc),
            min(m["acceptance"] for m in mc), max(m["acceptance"] for m in mc), sum(m["converged"] for m in mc), len(mc)))
        for m in mc:
            if not m["converged"]:
                print("refused:", m["message"])
