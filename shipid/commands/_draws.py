"""``--draws N`` of ``shipid simulate`` / ``validate`` / ``report``: the fit's uncertainty propagated to the
predictions (the logic is in :mod:`shipid.uncertainty`)."""
from __future__ import annotations

from pathlib import Path

from ._common import renamed_option


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
