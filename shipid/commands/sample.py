"""``shipid sample``: the MCMC posterior of a fit's coefficients (the logic is in :mod:`shipid.uncertainty`)."""
from __future__ import annotations

from ._common import add_log_options, add_progress_option, output_command, progress_on, read_logs_for_result


def register(sub) -> None:
    p = output_command(sub, "sample", _sample,
                 "sample the posterior of a fit's coefficients by MCMC (emcee) -> samples JSON",
                 "Sample the posterior of the estimated coefficients of RESULT.json over the output-error likelihood "
                 "of the logs (noise levels and the EKF's prior from the fit), started from the EKF posterior; reports "
                 "acceptance, autocorrelation time, effective sample size and split-R-hat, and exits 1 when the "
                 "chain has not converged.",
                 positional=[("result", "RESULT.json", "fit result written by `shipid fit -o`"),
                             ("logs", "LOG", "trial logs of the likelihood (usually the fit's)", "+")],
                 output_help="samples JSON to write")
    p.add_argument("--walkers", type=int, default=None, help="ensemble size (default max(4 x n_coef, 32))")
    p.add_argument("--steps", type=int, default=2000, help="steps per walker (default 2000)")
    p.add_argument("--burn", type=int, default=None, help="steps discarded (default steps/3)")
    p.add_argument("--thin", type=int, default=1, help="keep every THIN-th step")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--channels", default=None, help="output-error channels, comma separated (default u,v,r)")
    p.add_argument("--no-vectorize", action="store_true", help="one simulation per walker (slow; for comparison)")
    p.add_argument("--moves", choices=("de", "stretch", "independence"), default="de",
                   help="proposal: differential evolution (default), stretch, or DE burn-in then independence "
                        "Metropolis-Hastings from a Student-t fitted to it (docs/uncertainty.md)")
    p.add_argument("--sample-x0", action="store_true",
                   help="also sample each log's initial u, v, r (nuisance parameters; the exact posterior)")
    p.add_argument("--no-prior", action="store_true",
                   help="flat prior: sample the likelihood alone (default: the Gaussian prior the EKF started from, "
                        "as the result records it; flat with a warning for results that do not; docs/uncertainty.md "
                        "sect. 2)")
    _progress_option(p)
    add_log_options(p)


def _progress_option(p) -> None:
    add_progress_option(p)  # --progress / --no-progress, on at a terminal, as every long-running command


def _sample(args) -> int:
    from ..uncertainty.posterior import sample_posterior

    from ._common import check_output_path

    out = check_output_path(args.output, force=args.force, inputs=[args.result, *args.logs], what="samples file")
    for opt, v, low in (("--walkers", args.walkers, 2), ("--steps", args.steps, 10), ("--thin", args.thin, 1)):
        if v is not None and v < low:
            raise ValueError(f"{opt} {v}: give a whole number >= {low}")
    logs = read_logs_for_result(args)  # as validate reads them (a wind-aware fit: true wind from apparent-only logs)
    chans = [c.strip() for c in args.channels.split(",") if c.strip()] if args.channels else None
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        s = sample_posterior(args.result, logs, walkers=args.walkers, steps=args.steps, burn=args.burn, thin=args.thin,
                             seed=args.seed, vectorize=not args.no_vectorize, channels=chans, moves=args.moves,
                             sample_x0=args.sample_x0, use_prior=not args.no_prior,
                             progress=progress_on(args), log=None if getattr(args, "quiet", False) else print)
    s.to_json(out, force=args.force)
    import pandas as pd

    with pd.option_context("display.float_format", "{:.5g}".format, "display.width", 140):
        print(s.summary().to_string())
    d = s.diagnostics
    print(f"acceptance {d['acceptance_mean']:.3f}, tau_max {d['tau_max']:.1f} steps, ESS_min {d['ess_min']:.0f}, "
          f"split-R-hat_max {d['rhat_max']:.4f}")
    print(s.message)
    print(f"wrote {out}")
    return 0 if s.converged else 1


