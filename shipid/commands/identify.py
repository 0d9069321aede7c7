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
                                   "shipid schema, or MARIN .dat) with the augmented-state EKF.",
                       epilog="exit status: 0 fit consistent with its noise model; 1 the output-error refinement "
                              "failed; 2 bad input or option; 3 fit done but NOT consistent (a warning names the "
                              "channels and likely causes; the result JSON has diagnostics.consistency); "
                              "4 the filter diverged (result = start values, success false).")
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
    p.add_argument("--refine", action="store_true", help="refine with an output-error least-squares fit")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(handler=_fit)

    d = sub.add_parser("demo", help="fit the bundled synthetic KCS logs and print the results")
    d.add_argument("-o", "--output-dir", default=None, help="new folder for the outputs (default: shipid-demo-<time>)")
    d.add_argument("--passes", type=int, default=2, help="EKF passes (default 2)")
    d.set_defaults(handler=_demo)


def _start_model(args):
    from ..identify import model_from
    from ..models import get_model, model_class

    cls = model_class(args.model)
    opts = {"lpp": args.lpp} if (args.lpp is not None and "lpp" in cls.__init__.__code__.co_varnames) else {}
    if args.params is None:
        return cls(**opts)
    if args.params.endswith(".json"):
        return model_from(args.params, model=args.model)[0]
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


def _fit(args) -> int:
    from ..identify import EKFIdentifier

    out = Path(args.output)
    if out.exists() and not args.force:
        raise ValueError(f"{out}: output exists; choose another name or pass --force to overwrite it")
    if args.passes < 1:
        raise ValueError(f"--passes must be >= 1, got {args.passes}")
    model = _start_model(args)
    logs = read_logs(args.logs, args)
    for lg in logs:
        if lg.missing or lg.dropouts:
            print(f"note: {lg.summary()}", file=sys.stderr)
    ident = EKFIdentifier(model, estimate=_names(args.estimate) or None, fixed=_fixed(args, model),
                          n_passes=args.passes, tune_noise=args.tune_noise, progress=not args.no_progress)
    ident.fit(logs)
    result = ident.result()
    if args.refine:
        from ..identify.batch import OutputErrorRefiner

        result = OutputErrorRefiner(ident.to_model(), estimate=ident.estimated_).fit(logs, start=ident).result()
    result.to_json(out, force=args.force)
    _print_result(result)
    print(f"wrote {out}")
    if not ident.success_:
        return EXIT_DIVERGED
    verdict = ident.diagnostics_.get("consistency", {})
    if not verdict.get("consistent", True):
        print(_inconsistency_warning(verdict), file=sys.stderr)
    if not result.success:
        return 1
    return 0 if verdict.get("consistent", True) else EXIT_INCONSISTENT


#: ``shipid fit`` exit status of a fit that is not consistent with its noise model, and of a diverged filter.
EXIT_INCONSISTENT, EXIT_DIVERGED = 3, 4


def _inconsistency_warning(verdict: dict) -> str:
    """One plain warning for an inconsistent fit: the channels, the findings, the likely causes."""
    from ..identify.diagnostics import likely_causes

    reasons = verdict.get("reasons", [])
    chans = [c for c in verdict.get("channels", {}) if any(f"'{c}'" in r for r in reasons)]
    where = f" in channel(s) {', '.join(chans)}" if chans else ""
    causes = likely_causes(reasons)
    return (f"warning: the fit is not consistent with its noise model{where}: " + "; ".join(reasons)
            + (f". Likely causes: {causes}." if causes else ".") + " Do not use these coefficients before the cause "
            "is found (exit status 3).")


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
