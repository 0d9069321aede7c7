"""``shipid crossval``: how well will a model predict runs it has not seen (cross-validation over runs)."""
from __future__ import annotations

import sys

from ._common import add_progress_option, check_output_path, progress_on, read_logs, split_model_option


def register(sub) -> None:
    from .fit import add_engine_options, add_fit_options

    p = sub.add_parser("crossval", help="cross-validate a model over runs: fit on all runs but one, predict the one left out",
                       description="Leave-one-run-out (or K-fold over runs) cross-validation through the path of "
                                   "`shipid fit` and `shipid validate`: per left-out run the closed-loop standard-"
                                   "manoeuvre errors, steady-turn errors and open-loop position errors 10/30/60 s "
                                   "ahead; per model the median and the worst (docs/choosing_a_model.md).",
                       epilog="exit status: 0 every fold fitted and predicted; 1 some fold failed (reported, the others "
                              "completed); 2 bad input or option.")
    p.add_argument("logs", nargs="+", metavar="LOG", help="trial log files (.csv, MARIN .dat); at least two runs")
    p.add_argument("--model", default="kcs-response", metavar="MODEL",
                   help="the model and its start values: MODEL[:SET] (see `shipid models`) or a fit RESULT.json; or "
                        "'auto' / 'auto:MODEL[:SET],...' to cross-validate every candidate and rank them by the rule of "
                        "docs/choosing_a_model.md")
    p.add_argument("-o", "--output", required=True, help="JSON file to write (every fold and left-out run)")
    p.add_argument("--force", action="store_true", help="overwrite an existing output")
    add_fit_options(p)
    add_engine_options(p)
    p.add_argument("--horizon", default="10,30,60", metavar="SECONDS",
                   help="open-loop prediction horizons [s], comma-separated (default 10,30,60, as `shipid validate`)")
    p.add_argument("--start-every", type=float, default=5.0, help="spacing of the horizon starts [s] (default 5)")
    add_progress_option(p)
    p.set_defaults(handler=_crossval)


def _crossval(args) -> int:
    import math

    from .._io import atomic_write_text, dumps_json
    from ..crossval import choose_model, cross_validate, parse_candidates
    from .fit import _folds, _lib_errors, _logs_lpp, _start_model, check_fit_args, fit_options, print_choice
    from .validate import _horizons

    split_model_option(args)
    out = check_output_path(args.output, force=args.force, inputs=[*args.logs, args.params, args.ship])
    check_fit_args(args)
    horizons = _horizons(args.horizon)
    if not (math.isfinite(args.start_every) and args.start_every > 0):
        raise ValueError(f"--start-every {args.start_every}: give a positive number of seconds (default 5)")
    logs = read_logs(args.logs, args)
    common = dict(folds=_folds(args), lpp=args.lpp, wind=args.wind, current=args.current, horizons=horizons,
                  start_every=args.start_every, workers=args.workers, scheduler=args.scheduler,
                  progress=progress_on(args))
    if args.model == "auto" or args.model.startswith("auto:"):
        given = parse_candidates(args.model)
        if args.params is not None or args.fixed:
            raise ValueError("start values and --fixed cannot be combined with --model auto; name start sets per "
                             "candidate, e.g. --model auto:mmg:kvlcc2,response-nl")
        choice = _lib_errors(lambda: choose_model(logs, given, fit_options=fit_options(args, None), **common))
        for line in choice.why:
            print(f"model choice: {line}")
        for cv in choice.results:
            print(cv.text())
        print_choice(choice)
        atomic_write_text(out, dumps_json({"model_choice": choice.to_dict(),
                                           "crossval": [cv.to_dict() for cv in choice.results]}), force=args.force)
        results = choice.results
    else:
        model = _start_model(args, _logs_lpp(logs))
        cv = _lib_errors(lambda: cross_validate(logs, args.model, args.params, fit_options=fit_options(args, model),
                                                **common))
        print(cv.text())
        by = cv.by_folder()
        if len(by) > 1:
            print("  median position error 30 s ahead over all starts, by folder: "
                  + ", ".join(f"{k} {row['median_m']:.3g} m ({int(row['runs'])} runs)" for k, row in by.iterrows()))
        atomic_write_text(out, dumps_json(cv.to_dict()), force=args.force)
        results = [cv]
    for cv in results:
        for c in cv.copies:
            print(f"note: {c['log']} left out: every sample of it is in {c['copy_of']} (a copy of that run)",
                  file=sys.stderr)
        for f in cv.failed:
            print(f"warning: {cv.candidate}: fold {f['fold']} (left out {', '.join(f['left_out'])}) failed: "
                  f"{f['error']}"[:300], file=sys.stderr)
    print(f"wrote {out}")
    return 0 if all(cv.success for cv in results) else 1
