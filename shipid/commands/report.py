"""``shipid report``: one self-contained HTML validation report of a fitted model (replays as ``shipid validate``)."""
from __future__ import annotations

from ._common import progress_iter, read_logs_for_result
from ._draws import add_draws_option, check_draws
from .validate import _check, _common, _current_start, _horizon_results, _horizons, _line, _print_grade, _zigzag


def register(sub) -> None:
    r = sub.add_parser("report", help="write a self-contained HTML validation report of a fitted model",
                       description="One HTML file (figures embedded, no network): coefficients with sigma and 95 % "
                                   "intervals, correlation heat-map, identifiability warnings, measured vs replayed "
                                   "time series and tracks, residuals, the IMO table, versions and input hashes.")
    _common(r)
    r.add_argument("-o", "--output", required=True, help="HTML file to write")
    r.add_argument("--title", default=None, help="report title")
    add_draws_option(r)
    r.set_defaults(handler=_report)


def _report(args) -> int:
    from .._io import atomic_write_text
    from ..report import render_report
    from ..validation import resolve_model, validate_one

    out = _check(args)
    model, res = resolve_model(args.result)
    _print_grade(res)
    logs = read_logs_for_result(args, model)
    initial = _current_start(model, res)
    vals = [validate_one(model, lg, lpp=args.lpp, closed_loop=not args.no_closed_loop,
                         zigzag_angles=_zigzag(args), initial=initial)
            for lg in progress_iter(logs, args, "replaying logs")]
    unc = {"draws": check_draws(args), "seed": args.seed, "samples": args.samples} if check_draws(args) else None
    horizons = _horizons(args.horizon)
    hz = [h for h in _horizon_results(args, horizons, logs, model, initial) if h[0] is not None] if horizons else None
    text = render_report(res, args.logs, title=args.title, validations=vals, uncertainty=unc, horizons=hz)
    atomic_write_text(out, text, force=args.force)
    for v in vals:
        print(_line(v.to_dict()))
    print(f"wrote {out}")
    return 0 if all(v.simulation.success for v in vals) else 1
