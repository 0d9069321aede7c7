"""``shipid fit`` and ``shipid demo``: identification from the shell."""
from __future__ import annotations

import sys
from datetime import datetime
from pathlib import Path

import numpy as np

from ._common import add_log_options, read_logs


def _names(items) -> list[str]:
    return [p.strip() for item in items or [] for p in item.split(",") if p.strip()]


def register(sub) -> None:
    p = sub.add_parser("fit", help="identify model coefficients from trial logs (augmented-state EKF)",
                       description="Identify a model's coefficients from one or more trial logs (CSV in the "
                                   "shipid schema, or MARIN .dat) with the augmented-state EKF.")
    p.add_argument("logs", nargs="+", metavar="LOG", help="trial log files (.csv, MARIN .dat)")
    p.add_argument("--model", default="kcs-response", help="registered model (see `shipid models`)")
    p.add_argument("--params", default=None, metavar="SET|RESULT.json",
                   help="start values: a parameter set of the model or an earlier result JSON")
    p.add_argument("-o", "--output", required=True, help="result JSON to write")
    p.add_argument("--force", action="store_true", help="overwrite an existing output")
    add_log_options(p)
    p.add_argument("--estimate", action="append", metavar="NAMES", help="comma-separated parameters to estimate")
    p.add_argument("--fixed", action="append", metavar="NAME[=VALUE]", help="parameters to hold fixed")
    p.add_argument("--passes", type=int, default=2, help="EKF passes (default 2)")
    p.add_argument("--tune-noise", action="store_true", help="tune noise levels by innovation likelihood")
    p.add_argument("--refine", nargs="?", const="output-error", default="auto",
                   choices=("auto", "none", "output-error", "metrics"),
                   help="refinement after the EKF: 'output-error', 'metrics' (output error + the training runs' own "
                        "standard-manoeuvre metrics), 'none'; default 'auto' = output-error when the logs hold turning "
                        "circles and zigzags, else none; a bare --refine means output-error")
    p.add_argument("--max-nfev", type=int, default=60, help="evaluation limit of the refinement (default 60)")
    p.add_argument("--dt", default="auto", metavar="auto|K",
                   help="use every K-th sample; default auto: >= 25 steps per fastest time constant of the model")
    p.add_argument("--no-neutral", action="store_true",
                   help="do not take the rudder neutral angle (delta0) from the straight approaches of the logs")
    p.add_argument("--start", choices=("staged", "given"), default="staged",
                   help="staged start values (response-nl: the seed terms first) or the start model as given")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(handler=_fit)

    d = sub.add_parser("demo", help="fit the bundled synthetic KCS logs and print the results")
    d.add_argument("-o", "--output-dir", default=None, help="new folder for the outputs (default: shipid-demo-<time>)")
    d.add_argument("--passes", type=int, default=2, help="EKF passes (default 2)")
    d.set_defaults(handler=_demo)


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
    from ..identify import model_from
    from ..models import get_model, model_class

    cls = model_class(args.model)
    L = args.lpp if args.lpp is not None else lpp
    opts = {"lpp": L} if (L is not None and "lpp" in cls.__init__.__code__.co_varnames) else {}
    if args.params is None:
        return cls(**opts)
    if args.params.endswith(".json"):
        model = model_from(args.params, model=args.model)[0]
        ml = getattr(model, "lpp", None)
        if L is not None and ml is not None and abs(ml / L - 1.0) > 1e-9 and hasattr(model, "scaled"):
            print(f"note: start values {args.params} (Lpp {ml:g} m) Froude-scaled to the logs' {L:g} m", file=sys.stderr)
            model = model.scaled(L)
        return model
    return get_model(args.model, args.params, **opts)


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
                    raise ValueError(f"--fixed {part}: '{v}' is not a number") from None
            else:
                names.append(part)
    if values:
        for n in names:
            values[n] = float(model.params[model.param_index(n)])
        return values
    return names or None


def _dt(args):
    if args.dt == "auto":
        return "auto"
    try:
        k = int(args.dt)
    except ValueError:
        k = 0
    if k < 1:
        raise ValueError(f"--dt {args.dt}: give 'auto' or a positive whole number of samples, e.g. --dt 4")
    return k


def _fit(args) -> int:
    from ..identify.recipe import fit_logs

    out = Path(args.output)
    if out.exists() and not args.force:
        raise ValueError(f"{out}: output exists; choose another name or pass --force to overwrite it")
    if args.passes < 1:
        raise ValueError(f"--passes must be >= 1, got {args.passes}")
    if args.max_nfev < 1:
        raise ValueError(f"--max-nfev must be >= 1, got {args.max_nfev}")
    logs = read_logs(args.logs, args)
    model = _start_model(args, _logs_lpp(logs))
    for lg in logs:
        if lg.missing or lg.dropouts:
            print(f"note: {lg.summary()}", file=sys.stderr)
    fit = fit_logs(logs, model, lpp=args.lpp, estimate=_names(args.estimate) or None, fixed=_fixed(args, model),
                   start=args.start, neutral=not args.no_neutral, dt=_dt(args),
                   refine=None if args.refine == "none" else args.refine, n_passes=args.passes,
                   max_nfev=args.max_nfev, tune_noise=args.tune_noise, progress=not args.no_progress, log=print)
    result = fit.result()
    result.to_json(out, force=args.force)
    _print_result(result)
    print(f"wrote {out}")
    return 0 if result.success else 1


def _print_result(result) -> None:
    import pandas as pd

    tab = result.summary()
    with pd.option_context("display.float_format", "{:.5g}".format, "display.width", 120):
        print(f"model {result.model} ({result.method}): {result.message}")
        print(tab.to_string())
    d = result.diagnostics
    if d:
        print(f"condition number of the scaled covariance: {d.get('condition_number', float('nan')):.3g}")
        for w in d.get("warnings", []):
            print(f"warning: {w}")


def _new_dir(base: str | None) -> Path:
    if base is not None:
        p = Path(base)
        if p.exists():
            raise ValueError(f"{p}: output folder exists; choose a new name (the demo never overwrites)")
        p.mkdir(parents=True)
        return p
    stamp = datetime.now().strftime("%Y%m%d-%H%M%S")
    p = Path(f"shipid-demo-{stamp}")
    i = 1
    while p.exists():
        i += 1
        p = Path(f"shipid-demo-{stamp}-{i}")
    p.mkdir()
    return p


def _demo(args) -> int:
    import pandas as pd

    from ..datasets import bundled_data_dir, bundled_kcs_logs
    from ..identify import EKFIdentifier
    from ..logs import read_log
    from ..models import get_model
    from ..simulate import replay, replay_errors

    paths = bundled_kcs_logs()
    if not paths:
        raise ValueError(f"no bundled logs found in {bundled_data_dir()}; reinstall shipid")
    outdir = _new_dir(args.output_dir)
    print(f"shipid demo: fitting kcs-response to {len(paths)} bundled synthetic logs ({bundled_data_dir()})")
    logs = [read_log(p) for p in paths]
    truth = get_model("kcs-response", "synthetic-truth")
    # start far from the truth: every coefficient off by a seeded random 30 %
    rng = np.random.default_rng(0)
    start = truth.with_params(truth.params * (1 + 0.3 * rng.standard_normal(truth.np)))
    ident = EKFIdentifier(start, n_passes=args.passes, init="equation-error", progress=True).fit(logs)
    result = ident.result()
    result.to_json(outdir / "result.json")
    _print_result(result)
    tab = result.summary()
    tab["truth"] = truth.params_series()[tab.index]
    tab["error_sigma"] = (tab["value"] - tab["truth"]) / tab["std"]
    (outdir / "coefficients.csv").write_text(tab.to_csv())
    inside = int((tab["error_sigma"].abs() < 3).sum())
    print(f"\nagainst the known truth: {inside}/{len(tab)} coefficients within 3 sigma")
    rows = []
    fitted = ident.to_model()
    for lg in logs:
        err = replay_errors(replay(fitted, lg), lg)
        rows.append(pd.Series({f"{ch}_rmse": err.loc[ch, "rmse"] for ch in ("u", "v", "r") if ch in err.index}, name=lg.name))
    rep = pd.DataFrame(rows)
    print("\nreplay of each log with its recorded inputs (RMSE against the noisy log):")
    print(rep.to_string(float_format=lambda v: f"{v:.4g}"))
    (outdir / "replay_rmse.csv").write_text(rep.to_csv())
    _demo_figure(ident, logs, fitted, outdir)
    _demo_mmg(args, outdir)
    print(f"\noutputs in {outdir}/: result.json, coefficients.csv, replay_rmse.csv, replay.png, "
          "mmg_result.json, report.html")
    return 0


def _demo_mmg(args, outdir: Path) -> None:
    """Part 2: logs from the MMG model (structurally different, as real data are):
    fit on four, validate on all five (one held out), write the HTML report."""
    from ..datasets import bundled_kcs_logs
    from ..identify import EKFIdentifier
    from ..logs import read_log
    from ..models import get_model
    from ..report import write_report

    paths = bundled_kcs_logs("mmg")
    if not paths:
        return
    logs = [read_log(p) for p in paths]
    held_out = [lg for lg in logs if lg.name.endswith("zz_p10")]
    train = [lg for lg in logs if lg not in held_out]
    print(f"\npart 2: kcs-response fitted to {len(train)} logs generated by the MMG model "
          f"(held out: {', '.join(lg.name for lg in held_out)})")
    ident = EKFIdentifier(get_model("kcs-response"), n_passes=args.passes, progress=True).fit(train)
    res = ident.result()
    res.to_json(outdir / "mmg_result.json")
    _print_result(res)
    write_report(res, logs, outdir / "report.html", identifier=ident,
                 title="shipid demo: kcs-response identified from MMG-generated KCS logs")


def _demo_figure(ident, logs, fitted, outdir: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..simulate import replay

    fig, axs = plt.subplots(1, len(logs), figsize=(4 * len(logs), 4))
    for ax, lg in zip(np.atleast_1d(axs), logs):
        sim = replay(fitted, lg)
        ax.plot(lg["y"], lg["x"], ".", ms=1, label="log")
        ax.plot(sim.state("y"), sim.state("x"), "-", label="fitted model")
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_title(lg.name, fontsize=9)
        ax.set_xlabel("y [m]")
    np.atleast_1d(axs)[0].set_ylabel("x [m]")
    np.atleast_1d(axs)[0].legend()
    fig.tight_layout()
    fig.savefig(outdir / "replay.png", dpi=90)
    plt.close(fig)
