"""``shipid fit``: identification from the shell."""
from __future__ import annotations

import sys

import numpy as np

from ._common import (add_log_options, add_progress_option, check_output_path, parse_pairs, progress_on, read_logs,
                      renamed_option, split_model_option)


def _names(items) -> list[str]:
    return [p.strip() for item in items or [] for p in item.split(",") if p.strip()]


def register(sub) -> None:
    p = sub.add_parser("fit", help="identify model coefficients from trial logs (augmented-state EKF)",
                       description="Identify a model's coefficients from one or more trial logs (CSV in the "
                                   "shipid schema, or MARIN .dat) with the augmented-state EKF.",
                       epilog="exit status: 0 the fit's verdict is 'consistent' (the model explains the logs to "
                              "their noise) or 'model_error' (no data defect; the model misses the logs by more than "
                              "their noise: one warning line says how much); 2 bad input or option; 3 'defect' (a data or set-up defect is likely: the warning "
                              "names it, the channel and the option that fixes it); 4 'diverged' (no estimate). The "
                              "result JSON's 'verdict' holds the grade, the reasons and the numbers.")
    p.add_argument("logs", nargs="+", metavar="LOG", help="trial log files (.csv, MARIN .dat)")
    p.add_argument("--model", default="kcs-response", metavar="MODEL",
                   help=FIT_MODEL_HELP)
    p.add_argument("-o", "--output", required=True, help="result JSON to write")
    p.add_argument("--force", action="store_true", help="overwrite an existing output")
    add_fit_options(p)
    p.add_argument("--cross-validate", action="store_true",
                   help="also cross-validate the fit over the runs (leave-one-run-out, as `shipid crossval`) and store "
                        "the block in the result (extra.crossval); `shipid report` shows it")
    add_engine_options(p)
    add_progress_option(p)
    p.set_defaults(handler=_fit)


def add_engine_options(p) -> None:
    """``--folds``, ``--workers``, ``--scheduler``: how a cross-validation is split and where its folds run."""
    p.add_argument("--folds", default="loro", metavar="loro|K",
                   help="cross-validation folds: leave-one-run-out (default) or K folds of runs")
    p.add_argument("--workers", type=int, default=None, metavar="N",
                   help="run the folds on N local Dask worker processes (default: serially)")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="run the folds on an existing Dask scheduler, e.g. tcp://host:8786")


#: ``--model`` of ``shipid fit`` and ``shipid crossval``: the model and its start values, or the choice.
FIT_MODEL_HELP = ("the model and its start values: MODEL[:SET] (a registered model, see `shipid models`, with a "
                  "parameter set), an earlier fit RESULT.json, or 'auto' to choose among the models that apply by "
                  "cross-validation ('auto:mmg:kvlcc2,response-nl' to choose among those; docs/choosing_a_model.md)")


def add_fit_options(p) -> None:
    """The options of ``shipid fit`` that say how to fit (one copy: ``shipid crossval`` takes them too)."""
    p.set_defaults(params=None)
    renamed_option(p, "--params", "--model", dest="params", metavar="SET|RESULT.json",
                   note="MODEL:SET or --model RESULT.json")
    add_log_options(p)
    p.add_argument("--estimate", action="append", metavar="NAMES", help="comma-separated parameters to estimate")
    p.add_argument("--fixed", action="append", metavar="NAME[=VALUE]", help="parameters to hold fixed")
    p.add_argument("--passes", type=int, default=2, help="EKF passes (default 2)")
    p.add_argument("--tune-noise", action="store_true", help="tune noise levels by innovation likelihood")
    p.add_argument("--refine", nargs="?", const="output-error", default="auto",
                   choices=("auto", "none", "output-error", "metrics"),
                   help="refinement after the EKF: 'output-error', 'metrics' (output error + the training runs' own "
                        "standard-manoeuvre metrics), 'none'; default 'auto' = metrics when the logs hold turning "
                        "circles and zigzags, else none (lowspeed and models with --wind/--current: none; they cannot "
                        "be refined yet); a bare --refine means output-error")
    p.add_argument("--metric-weight", type=float, default=None, metavar="W",
                   help="weight of the metric residuals of the 'metrics' refinement (default 0.1, chosen by "
                        "leave-one-run-out on the KVLCC2 training runs)")
    p.add_argument("--max-nfev", type=int, default=60, help="evaluation limit of the refinement (default 60)")
    p.add_argument("--refine-all", action="store_true",
                   help="refine every estimated coefficient (default: hold at their EKF values those the refinement "
                        "cannot resolve: singular values of its scaled Jacobian below sqrt(2 ftol cost))")
    p.add_argument("--sign-bounds", action="store_true",
                   help="keep the model's dissipative coefficients (pure sway and yaw damping, e.g. response-nl b1 b5 "
                        "b6 c2 c5 c7) <= 0 in the refinement (default: off; the fit's diagnostics.damping reports the "
                        "fitted model's own damping either way)")
    p.add_argument("--no-physical-damping", action="store_true",
                   help="do not constrain the refinement when the refined model's own sway or yaw damping is positive "
                        "along the logged states (default: solve again with d(dv/dt)/dv, d(dr/dt)/dr <= -0.02 U/L there)")
    p.add_argument("--every", default="auto", metavar="auto|K",
                   help="use every K-th sample; default auto: >= 25 steps per fastest time constant of the model (mmg: 50; "
                        "lowspeed: 2 s at 3 m, Froude-scaled)")
    renamed_option(p, "--dt", "--every", dest="every", metavar="auto|K", note="the sample stride K")
    p.add_argument("--max-drift", default="auto", metavar="auto|DEG|none",
                   help="models linear in v and r (kcs-response): use each log until its drift angle first exceeds "
                        "DEG (default auto: 10 deg for such models, every sample for the others; none: every sample)")
    p.add_argument("--keep-repeated", action="store_true",
                   help="fit a log even when every sample of it is in another log (a trimmed copy of the same run; "
                        "default: dropped, as it would count that run twice)")
    p.add_argument("--no-neutral", action="store_true",
                   help="do not take the rudder neutral angle (delta0) from the straight approaches of the logs")
    p.add_argument("--start", choices=("staged", "given"), default="staged",
                   help="staged start values (response-nl: the seed terms first) or the start model as given")
    p.add_argument("--wind", nargs="?", const="auto", default=None, metavar="GEOMETRY",
                   help="add wind forces (Fujiwara) with the logs' true wind as inputs: 'esso-osaka-3m' or a JSON "
                        "file of shipid.environment.WindForce fields (bare --wind: from the logs' ship)")
    p.add_argument("--current", nargs="?", const="constant", default=None, choices=("constant", "random-walk"),
                   help="estimate a uniform earth-fixed current as two extra states (bare --current: constant)")
    p.add_argument("--meas-std", action="append", metavar="CH=STD",
                   help="measurement noise standard deviation per channel in SI units (m, rad, m/s, rad/s), "
                        "e.g. psi=0.002,r=0.0005; default: the sensor noise the logs' schema declares (esso-frt does), "
                        "else estimated from the data")


def _logs_lpp(logs):
    """The one ship length [m] of the logs' particulars (None when unknown; ValueError when they differ)."""
    lpps = {float(lg.ship.lpp) for lg in logs if getattr(lg, "ship", None) is not None and lg.ship.lpp}
    if len(lpps) > 1:
        raise ValueError(f"the logs belong to ships of different lengths {sorted(lpps)} m; fit one ship at a time "
                         "(or pass --lpp)")
    return lpps.pop() if lpps else None


def _start_model(args, lpp=None):
    """The start model at the logs' ship length ``lpp`` (a named parameter set is Froude-scaled to it, an
    earlier result of another length too): a start never comes from another ship's scale."""
    from ..crossval import start_model

    L = args.lpp if args.lpp is not None else lpp
    return start_model(args.model, args.params, L, say=lambda m: print(m, file=sys.stderr))


def _fixed(args, model):
    names, values = [], {}
    for item in args.fixed or []:
        for part in item.split(","):
            part = part.strip()
            if not part:
                continue
            if "=" in part:
                k, v = part.split("=", 1)
                try:
                    values[k.strip()] = float(v)
                except ValueError:
                    raise ValueError(f"--fixed {part[:60]}: '{v[:30]}' is not a number; give NAME=VALUE, "
                                     "e.g. --fixed a8=0") from None
                if not np.isfinite(values[k.strip()]):
                    raise ValueError(f"--fixed {part[:60]}: give a finite value (or NAME alone to hold the "
                                     "start value)")
            else:
                names.append(part)
    if values:
        for n in names:
            values[n] = float(model.params[model.param_index(n)])
        return values
    return names or None


def _dt(args):
    if args.every == "auto":
        return "auto"
    try:
        k = int(args.every)
    except ValueError:
        k = 0
    if k < 1:
        raise ValueError(f"--every {args.every}: give 'auto' or a positive whole number of samples, e.g. --every 4")
    return k


def _max_drift(args):
    text = str(args.max_drift).strip().lower()
    if text in ("auto", "none"):
        return None if text == "none" else "auto"
    try:
        deg = float(text)
    except ValueError:
        deg = float("nan")
    if not 0 < deg < 90:
        raise ValueError(f"--max-drift {args.max_drift}: give 'auto', 'none' or a drift angle in degrees between 0 "
                         "and 90, e.g. --max-drift 10")
    return deg


def _lib_errors(call):
    """Run ``call()``; the library's advice re-worded for the CLI."""
    try:
        return call()
    except ValueError as exc:
        msg = str(exc)
        if "give meas_std=" in msg:  # the library's advice in the CLI's words
            msg = msg.replace("give meas_std={...}", "pass --meas-std CH=STD, e.g. --meas-std psi=0.002")
        elif "not finite in the initial point" in msg:
            msg = (f"the model cannot be evaluated at the start values ({msg.rstrip('.')}); check --fixed "
                   "and --params values")
        raise ValueError(msg) from None


def check_fit_args(args) -> None:
    """The checks of the fit options (before reading any log)."""
    if not 1 <= args.passes <= 100:
        raise ValueError(f"--passes {args.passes if abs(args.passes) < 10**6 else f'{args.passes:.3g}'}: "
                         "give a number of EKF passes from 1 to 100 (default 2)")
    if args.lpp is not None and not (np.isfinite(args.lpp) and args.lpp > 0):
        raise ValueError(f"--lpp {args.lpp}: give the ship length between perpendiculars in metres (a positive number)")
    if args.metric_weight is not None and not (np.isfinite(args.metric_weight) and args.metric_weight >= 0):
        raise ValueError(f"--metric-weight {args.metric_weight}: give a finite weight >= 0 (default 0.1)")
    if args.max_nfev < 1:
        raise ValueError(f"--max-nfev must be >= 1, got {args.max_nfev}")
    if getattr(args, "workers", None) is not None and args.workers < 1:
        raise ValueError(f"--workers {args.workers}: give a number of worker processes >= 1")
    folds = getattr(args, "folds", "loro")
    if folds != "loro" and not (str(folds).isdigit() and int(folds) >= 2):
        raise ValueError(f"--folds {folds}: give 'loro' or a number of folds >= 2, e.g. --folds 8")


def fit_options(args, model) -> dict:
    """Keyword arguments of :func:`shipid.identify.fit_logs` from the fit options (the same for ``shipid fit``
    and every fold of ``shipid crossval``); ``model`` is the start model (for ``--fixed NAME``)."""
    meas_std = parse_pairs(args.meas_std, "--meas-std", float) or None
    for k, v in (meas_std or {}).items():
        if not (np.isfinite(v) and v > 0):
            raise ValueError(f"--meas-std {k}={v}: give a positive standard deviation in SI units, e.g. psi=0.002")
    return dict(estimate=_names(args.estimate) or None, fixed=_fixed(args, model), start=args.start,
                neutral=not args.no_neutral, dt=_dt(args), max_drift_deg=_max_drift(args),
                refine=None if args.refine == "none" else args.refine, metric_weight=args.metric_weight,
                n_passes=args.passes, max_nfev=args.max_nfev, hold_unresolved=not args.refine_all,
                sign_bounds=args.sign_bounds, physical_damping=not args.no_physical_damping, tune_noise=args.tune_noise,
                meas_std=meas_std, drop_repeated=not args.keep_repeated)


def _folds(args):
    return "loro" if args.folds == "loro" else int(args.folds)


def _choose(args, logs) -> tuple:
    """``--model auto[:...]``: cross-validate the candidates, print the table, return (chosen candidate, choice)."""
    from ..crossval import choose_model, parse_candidates

    given = parse_candidates(args.model)
    if args.params is not None:
        raise ValueError("--params cannot be combined with --model auto; name start sets per candidate, e.g. "
                         "--model auto:mmg:kvlcc2,response-nl")
    if args.fixed:
        raise ValueError("--fixed cannot be combined with --model auto (the candidates have different parameters); "
                         "name a model with --model")
    choice = _lib_errors(lambda: choose_model(
        logs, given, folds=_folds(args), lpp=args.lpp, wind=args.wind, current=args.current,
        fit_options=fit_options(args, None), workers=args.workers, scheduler=args.scheduler,
        progress=progress_on(args)))
    for line in choice.why:
        print(f"model choice: {line}")
    print_choice(choice)
    if not choice.success:
        raise ValueError("--model auto: no candidate model could be cross-validated on these logs (every fold failed); "
                         "see the table above, or name a model with --model")
    return choice


def print_choice(choice) -> None:
    import pandas as pd

    with pd.option_context("display.float_format", "{:.3g}".format, "display.width", 160):
        print("cross-validated candidates (score: mean over left-out runs of the errors over their goals, "
              "docs/choosing_a_model.md):")
        print(choice.summary().to_string(na_rep="-"))  # "-": no left-out run measures that metric
    print(f"model choice: {choice.message}")


def _fit(args) -> int:
    from ..identify.recipe import fit_logs

    split_model_option(args)
    out = check_output_path(args.output, force=args.force, inputs=[*args.logs, args.params, args.ship],
                            what="result")
    check_fit_args(args)
    logs = read_logs(args.logs, args)
    choice = None
    if args.model == "auto" or args.model.startswith("auto:"):
        choice = _choose(args, logs)
        best = choice.chosen
        args.model, args.params = best.model, best.params
        args.wind, args.current = best.wind, best.current
    model = _start_model(args, _logs_lpp(logs))
    for lg in logs:
        if lg.missing or lg.dropouts:
            print(f"note: {lg}", file=sys.stderr)
    extra = None
    if args.wind or args.current:
        # wind/current parts around the ship model: the recipe with the base model's defaults, not refined
        from ..environment.cli import environment_model

        model, extra = environment_model(model, logs, wind=args.wind, current=args.current)
    opts = fit_options(args, model)
    recipe = _lib_errors(lambda: fit_logs(
        logs, model, lpp=args.lpp, progress=progress_on(args), ekf_options=extra, start_defaults=args.params is None,
        log=None if getattr(args, "quiet", False) else _print_step, **opts))
    fit, ident = recipe, recipe.ekf
    result = fit.result()
    if choice is not None:
        result.extra["model_choice"] = choice.to_dict()
        result.extra["crossval"] = choice.best.to_dict(starts=False)
    elif args.cross_validate:
        from ..crossval import cross_validate

        cv = _lib_errors(lambda: cross_validate(
            logs, args.model, args.params, folds=_folds(args), lpp=args.lpp, wind=args.wind, current=args.current,
            fit_options=opts, workers=args.workers, scheduler=args.scheduler, progress=progress_on(args)))
        print(cv.text())
        result.extra["crossval"] = cv.to_dict(starts=False)
    result.to_json(out, force=args.force)
    _print_result(result)
    print(f"wrote {out}")
    return _report_verdict(result)


def _print_step(line: str) -> None:
    """A recipe step, one line of at most ~300 characters (the full reason is in the result's settings)."""
    from ..identify.verdict import clip, plain_message

    print(clip(plain_message(line)))


def _print_verdict(result) -> None:
    """The verdict's grade and, unless consistent, its one line (the demo's parts)."""
    from ..identify.verdict import verdict_of, warning_line

    v = verdict_of(result)
    print(f"verdict: {v.grade}")
    line = warning_line(v)
    if line:
        print(line)


def _report_verdict(result) -> int:
    """Print the verdict's one line (stderr; nothing for a consistent fit) and return the exit status."""
    from ..identify.verdict import exit_status, verdict_of, warning_line

    v = verdict_of(result)
    print(f"verdict: {v.grade}", file=sys.stdout)
    line = warning_line(v)
    if line:
        print(line, file=sys.stderr)
    return exit_status(v)


def _print_result(result) -> None:
    import pandas as pd

    from ..identify.verdict import plain_message

    tab = result.summary()
    with pd.option_context("display.float_format", "{:.5g}".format, "display.width", 120):
        print(f"model {result.model} ({result.method}): {plain_message(result.message)}")
        print(tab.to_string())
    d = result.diagnostics
    if d:
        print(f"condition number of the scaled covariance: {d.get('condition_number', float('nan')):.3g}")
        for w in identifiability_lines(d):
            print(w)


def identifiability_lines(d: dict) -> list[str]:
    """The identifiability findings of a fit's diagnostics, one line per kind (at most ~300 characters; every
    pair and combination is in the result JSON under diagnostics)."""
    from ..identify.verdict import clip

    out = []
    pairs = d.get("correlated_pairs") or []
    if pairs:
        shown = ", ".join(f"{a}-{b} ({r:+.2f})" for a, b, r in pairs)
        out.append(clip(f"note: {len(pairs)} strongly correlated pair(s) (the logs determine a combination better "
                        f"than each; manoeuvres that excite them differently separate them): {shown}"))
    combos = d.get("unidentified_combinations") or []
    if combos:
        shown = "; ".join(c["combination"] for c in combos)
        out.append(clip(f"note: {len(combos)} combination(s) of scaled coefficients the data do not determine (the "
                        f"result along them is the prior): {shown}"))
    if d.get("poorly_determined"):
        out.append(clip("note: poorly determined (posterior std above half the prior std): "
                        + ", ".join(d["poorly_determined"])))
    generic = ("are strongly correlated (rho", "the data do not determine the combination", "poorly determined (")
    for w in d.get("warnings", []):
        if not any(g in w for g in generic):
            out.append(clip(f"warning: {w}"))
    return out


