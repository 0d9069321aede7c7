"""``shipid sample`` (MCMC posterior of a fit) and ``shipid campaign`` (many fits and sweeps on Dask), plus the
``--draws`` helpers of ``shipid simulate`` / ``validate`` / ``report`` (the logic is in
:mod:`shipid.uncertainty`)."""
from __future__ import annotations

import json
import sys
from pathlib import Path

from ._common import add_log_options, add_progress_option, progress_on, read_logs_for_result, renamed_option


def _command(sub, name, handler, help, description, *, positional, output_help, output_metavar=None,
             force_help="overwrite an existing output"):
    """A sub-command of this module: its positional arguments (``(name, metavar, help[, nargs])``),
    the required ``-o/--output`` and ``--force``."""
    p = sub.add_parser(name, help=help, description=description)
    for dest, metavar, text, *nargs in positional:
        p.add_argument(dest, metavar=metavar, help=text, **({"nargs": nargs[0]} if nargs else {}))
    p.add_argument("-o", "--output", required=True, metavar=output_metavar, help=output_help)
    p.add_argument("--force", action="store_true", help=force_help)
    p.set_defaults(handler=handler)
    return p


def register(sub) -> None:
    p = _command(sub, "sample", _sample,
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

    c = _command(sub, "campaign", _campaign,
                 "run the fits and sweeps of a campaign file (JSON/YAML) on Dask workers",
                 "Run many fits, each with its own logs and settings, and sweeps (turning-diameter grids, glider "
                 "launch factorials) from a campaign file; an embedded LocalCluster of --workers processes by "
                 "default, an existing cluster with --scheduler, serially with --workers 1.  Writes "
                 "OUTDIR/<name>/result.json (+ predictions.json with draws) per fit, OUTDIR/<name>/sweep.csv per "
                 "sweep and OUTDIR/campaign.json.",
                 positional=[("campaign", "CAMPAIGN", "campaign file (.json, .yaml)")],
                 output_help="output folder (new or empty)", output_metavar="OUTDIR",
                 force_help="run every member again into a used output folder (removes the members' old files)")
    c.add_argument("--resume", action="store_true",
                   help="finish a campaign that was stopped: members OUTDIR/campaign.journal lists as finished "
                        "(files unchanged) are kept, the others run")
    c.epilog = ("exit status: 0 every member ok; 3 some fits flagged (`shipid fit` would exit 3 or 4 on them: not "
                "consistent with their noise model, or diverged) and none failed; 1 some members failed; 2 bad input")
    add_engine_options(c)


def _progress_option(p) -> None:
    add_progress_option(p)  # --progress / --no-progress, on at a terminal, as every long-running command


def add_engine_options(p) -> None:
    p.add_argument("--workers", type=int, default=None,
                   help="worker processes of the embedded Dask LocalCluster (default: CPUs; 1 = serial)")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS", help="existing Dask scheduler, e.g. tcp://host:8786")
    _progress_option(p)


def engine_from(args):
    from ..campaign import Engine

    return Engine(args.workers, scheduler=args.scheduler, progress=progress_on(args))


def add_draws_option(p) -> None:
    """``--draws N`` (+ ``--seed``, ``--samples``) for simulate / validate / report (``--draws-seed``: the old
    spelling of ``--seed``)."""
    p.add_argument("--draws", type=int, default=0, metavar="N",
                   help="propagate the fit's uncertainty: N parameter draws simulated as one batch (95 %% intervals, "
                        "IMO probabilities)")
    p.add_argument("--seed", type=int, default=0, help="random seed of the draws (default 0)")
    renamed_option(p, "--draws-seed", "--seed", dest="seed", type=int, metavar="SEED")
    p.add_argument("--samples", default=None, metavar="SAMPLES.json",
                   help="draw from MCMC samples (`shipid sample`) instead of the fit's Gaussian posterior")


def check_draws(args) -> int:
    n = int(getattr(args, "draws", 0) or 0)
    if n < 0:
        raise ValueError(f"--draws {n}: give a positive number of parameter draws (or 0 for none)")
    return n


def _sample(args) -> int:
    from ..uncertainty.posterior import sample_posterior

    from ._common import check_output_path

    out = check_output_path(args.output, force=args.force, inputs=[args.result, *args.logs], what="samples")
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
                             progress=progress_on(args))
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


def _member_line(m: dict) -> str:
    if m["status"] == "failed":
        return f"{m['name']}: FAILED: {m['error']}"
    if m["status"] == "flagged":
        why = "; ".join(m.get("reasons") or [])
        return f"{m['name']}: flagged: {why[:200]}{'...' if len(why) > 200 else ''}"
    note = "" if m.get("success", True) else " (did not converge)"
    return f"{m['name']}: ok{note}"


def _campaign(args) -> int:
    from ..campaign import campaign_exit_status, load_campaign, run_campaign

    if args.force and args.resume:
        raise ValueError("--force and --resume: give one (--resume keeps finished members, --force runs them again)")
    camp = load_campaign(args.campaign)  # validate before starting any worker
    with engine_from(args) as eng:
        summary = run_campaign(camp, args.output, engine=eng, force=args.force, resume=args.resume,
                               on_member=lambda m: print(_member_line(m), flush=True))
    for m in summary["members"]:
        for w in m.get("warnings", [])[:3]:
            print(f"{m['name']}: warning: {w}", file=sys.stderr)
    resumed = f", {summary['n_resumed']} kept from the earlier run" if summary.get("n_resumed") else ""
    print(f"{summary['n_members']} members: {summary['n_ok']} ok, {summary['n_flagged']} flagged, "
          f"{summary['n_failed']} failed{resumed} ({summary['engine']}); wrote {Path(args.output) / 'campaign.json'}")
    return campaign_exit_status(summary)


# ----------------------------------------------------------------------------- --draws hunks
def simulate_draws(args, model_spec: str) -> int:
    """``shipid simulate RESULT.json --turning 35 --draws N [--metrics-output FILE]``."""
    from ..uncertainty import predict_manoeuvres

    if not (model_spec.lower().endswith(".json") and Path(model_spec).is_file()):
        raise ValueError(f"--draws needs a fit result JSON (with a covariance), got '{model_spec}'")
    if args.output:
        raise ValueError("-o/--output (time series CSV) is not written with --draws; use --metrics-output FILE")
    if args.turning is not None:
        specs = [f"turning:{args.turning:g}:{s}" for s in _sides(args.side)]
    else:
        d, _, p = args.zigzag.partition("/")
        specs = [f"zigzag:{d}/{p or d}:{s}" for s in _sides(args.side)]
    import math

    pred = predict_manoeuvres(model_spec, specs, draws=check_draws(args), seed=args.seed, samples=args.samples,
                              speed=args.speed, lpp=args.lpp, method=args.integrator,
                              rudder_rate=math.radians(args.rudder_rate) if args.rudder_rate is not None else None)
    tab = pred.summary()
    print(tab[["manoeuvre", "metric", "nominal", "median", "low", "high", "n_nonfinite"]].to_string(
        index=False, float_format=lambda v: f"{v:.4g}"))
    for lab, blk in pred.imo.items():
        for crit, v in blk.items():
            print(f"{lab}: IMO {crit} met with probability {v['probability']:.3f} "
                  f"({v['n_met']}/{pred.draws}; {v['n_not_evaluated']} not evaluated)")
    print(pred.message)
    if getattr(args, "metrics_output", None):
        pred.to_json(args.metrics_output, force=args.force)
        print(f"wrote {args.metrics_output}")
    return 0 if pred.status == 0 else 1


def _sides(side: str) -> list[str]:
    return ["starboard", "port"] if side == "both" else [side]


def validate_draws(args, result_path, vals: list, out: list) -> None:
    """Add ``"<metric>_ci"`` / ``"imo_probability"`` / ``"draws"`` to each log's ``predicted`` block."""
    from ..uncertainty import parameter_draws, replay_draws
    from ..validation.replay import _for_length, resolve_model

    n = check_draws(args)
    if n == 0:
        return
    model, res = resolve_model(result_path)
    if res is None:
        raise ValueError("--draws needs a fit result (with a covariance), not a model name")
    P = parameter_draws(res, n, seed=args.seed, samples=args.samples)
    for v, d in zip(vals, out):
        if v.measured is None or v.lpp is None or not d.get("predicted"):
            continue
        m = _for_length(model, v.lpp, [])
        blk = replay_draws(m, v.log, P, lpp=v.lpp, kind=v.measured.manoeuvre,
                           switch_deg=getattr(v.measured, "switch_deg", None), rudder_sign=v.rudder_sign)
        blk.pop("simulation")
        d["predicted"].update(blk)


def write_json(path, obj, force) -> None:
    from .._io import atomic_write_text

    atomic_write_text(path, json.dumps(obj, indent=2, allow_nan=False) + "\n", force=force)


def warn(msg: str) -> None:
    print(msg, file=sys.stderr)
