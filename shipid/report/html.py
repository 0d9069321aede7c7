"""One self-contained HTML validation report of an identified model.

The page is built with plain Python string formatting, every value passing
through :func:`html.escape` (log names, file paths and warnings come from
the user); images are PNG data URIs, the stylesheet is inline, there is no
script and no link to anything outside the file, so it opens offline and can
be mailed or archived as one file.
"""
from __future__ import annotations

import math
import os
import re
import sys
from datetime import datetime, timezone
from pathlib import Path

from .._io import OutputExistsError, atomic_write_text
from ..identify.result import software_versions
from ..identify.verdict import plain_message, verdict_of
from ..validation import LogValidation, load_logs, resolve_model, validate_one
from . import figures
from ._markup import _e, _f, _fig, _img, _table  # noqa: F401  (_img: the helpers as one set)
from .uncertainty import uncertainty_section

__all__ = ["render_report", "write_report"]

#: Metrics shown in the summary table, with their labels.
SUMMARY_METRICS = {
    "turning": (("advance_L", "advance [L]"), ("transfer_L", "transfer [L]"),
                ("tactical_diameter_L", "tactical diameter [L]"), ("steady_diameter_L", "steady diameter [L]"),
                ("speed_loss", "speed loss [-]")),
    "zigzag": (("overshoot1_deg", "1st overshoot [deg]"), ("overshoot2_deg", "2nd overshoot [deg]"),
               ("overshoot1_time", "1st overshoot time [s]"), ("time_second_execute", "time to 2nd execute [s]"),
               ("initial_turning_L", "initial turning [L]")),
}

_CSS = """
body{font-family:-apple-system,"Segoe UI",Helvetica,Arial,sans-serif;margin:24px auto;max-width:1100px;
color:#1d1d1f;line-height:1.4;padding:0 16px}
h1{font-size:1.6em;border-bottom:2px solid #234;padding-bottom:6px}
h2{font-size:1.25em;margin-top:1.8em;border-bottom:1px solid #bbb;padding-bottom:3px}
h3{font-size:1.05em;margin-top:1.4em}
table{border-collapse:collapse;margin:8px 0 14px 0;font-size:0.86em}
th,td{border:1px solid #ccc;padding:3px 7px;text-align:right;vertical-align:top}
th{background:#eef2f6}
td.l,th.l{text-align:left}
td.pass{background:#dff5df}td.fail{background:#f9dcdc;font-weight:bold}td.na{color:#888}
.warn{background:#fff6dc;border-left:4px solid #e0a800;padding:4px 10px;margin:4px 0}
.note{color:#444;font-size:0.9em}
.mono{font-family:Menlo,Consolas,monospace;font-size:0.85em;word-break:break-all}
img{max-width:100%;height:auto;display:block;margin:6px 0}
p.intro{background:#f3f6fa;border-left:4px solid #4a78a8;padding:6px 10px}
.figs{display:flex;flex-wrap:wrap;gap:12px;align-items:flex-start}
nav a{margin-right:12px}
"""


# ----------------------------------------------------------------------------- helpers
def _anchor(i: int) -> str:
    return f"log{i + 1}"


def _versions_now() -> dict:
    return software_versions()


# ----------------------------------------------------------------------------- sections
#: Banner colours per grade (background, border).
_BANNER = {"consistent": ("#eaf6ea", "#3a8a3a"), "model_error": ("#fdf6e3", "#b58900"),
           "defect": ("#fbeaea", "#b03030"), "diverged": ("#fbeaea", "#b03030")}


def verdict_banner(result) -> str:
    """The report's opening banner: the fit's grade, each reason as a sentence, and what to do."""
    v = verdict_of(result)
    bg, border = _BANNER[v.grade]
    items = "".join(f"<li>{_e(r)}</li>" for r in v.reasons)
    return (f"<div class=\"verdict\" id=\"verdict\" style=\"background:{bg};border-left:6px solid {border};"
            f"padding:6px 12px;margin:8px 0\"><p><b>Verdict: {_e(v.grade.replace('_', ' '))}.</b> {_e(v.advice)}</p>"
            + (f"<ul>{items}</ul>" if items else "") + "</div>")


_ROLE = re.compile(r":[a-z]+:`~?([^`]+)`")


def plain(text: str) -> str:
    """``text`` without reStructuredText markup: roles (``:func:`x```) and literals (````x````) as plain words."""
    text = _ROLE.sub(lambda m: m.group(1).rsplit(".", 1)[-1], str(text))
    return text.replace("``", "").replace("**", "")


def _options_text(opts) -> str:
    """Model options as ``key: value; ...`` (nested mappings in brackets), not a Python repr."""
    def one(v):
        if isinstance(v, dict):
            return "(" + ", ".join(f"{k} {one(x)}" for k, x in v.items()) + ")"
        if isinstance(v, (list, tuple)):
            return ", ".join(one(x) for x in v)
        if isinstance(v, float):
            return f"{v:.6g}"
        return "none" if v is None else str(v)
    return "; ".join(f"{k}: {one(v)}" for k, v in dict(opts).items())


def model_label(result, model) -> str:
    """The model in words: its registered name, or a ship model with wind and/or current named after its base."""
    base = getattr(model, "base", None)
    if base is None:
        return str(result.model)
    parts = [w for w, on in (("wind", getattr(model, "wind", None) is not None),
                             ("current", bool(getattr(model, "current", None)))) if on]
    return f"{base.name} with {' and '.join(parts)}" if parts else str(base.name)


def _section_model(result, model) -> str:
    mod = sys.modules.get(type(getattr(model, "base", None) or model).__module__)
    doc = plain((mod.__doc__ or "").strip().splitlines()[0]) if mod is not None and mod.__doc__ else ""
    s = result.settings or {}
    rows = [("registered model", _e(result.model)), ("description", _e(doc)),
            ("states", _e(", ".join(model.state_names))), ("inputs", _e(", ".join(model.input_names))),
            ("method", _e(result.method)), ("verdict", _e(verdict_of(result).grade.replace("_", " "))),
            ("optimiser", _e(("converged" if result.success else "did not converge") +
                             (f": {plain_message(result.message)}" if result.message else ""))),
            ("log-likelihood", _f(result.loglik, "{:.6g}")), ("created (UTC)", _e(result.created))]
    for key, label in (("n_passes", "EKF passes"), ("discretisation", "discretisation"), ("substeps", "RK4 substeps"),
                       ("param_walk", "parameter random walk")):
        if key in s:
            rows.append((label, _e(s[key])))
    opts = result.model_options
    if opts:
        rows.append(("model options", _e(_options_text(opts))))
    out = ("<h2 id=\"model\">Model and method</h2><p>Which equations were fitted, how, and the settings that "
           "reproduce the fit.</p>" + _table(["item", "value"], rows, left=2))
    for key, label in (("meas_std", "measurement noise std (SI units)"), ("process_std", "process noise std (SI units)")):
        d = s.get(key)
        if d:
            out += f"<p class=\"note\">{_e(label)}: " + ", ".join(f"{_e(k)} = {_f(v)}" for k, v in d.items()) + "</p>"
    return out


def _unit(model, name: str) -> str:
    """The unit of coefficient ``name`` of ``model`` (``model.units``): "&ndash;" for non-dimensional ones."""
    u = (getattr(model, "units", None) or {}).get(name)
    if u is None:
        return "?"
    return "&ndash;" if u in ("-", "1", "") else _e(u.replace("^2", "²").replace("^3", "³"))


def _section_coefficients(result, model=None) -> str:
    tab = result.summary()
    est = list(tab.index)
    rows = []
    for name, r in tab.iterrows():
        rows.append((_e(name), _unit(model, name), _f(r["value"], "{:.5g}"), _f(r["std"], "{:.3g}"),
                     _f(r["ci95_low"], "{:.5g}"), _f(r["ci95_high"], "{:.5g}"), _f(r["rel_std_%"], "{:.1f}")))
    out = ("<h2 id=\"coefficients\">Identified coefficients</h2><p>The estimated coefficients with their "
           "uncertainty; the unit column gives each one's SI unit (&ndash;: non-dimensional).</p>")
    fixed = {k: v for k, v in result.coef.items() if k not in est}
    if not est:
        return out + ("<p>No coefficient was estimated (the result carries no covariance, e.g. a published "
                      "parameter set): values used:</p>" +
                      _table(["coefficient", "unit", "value"],
                             [(_e(k), _unit(model, k), _f(v, "{:.5g}")) for k, v in fixed.items()], left=2))
    out += ("<p class=\"note\">95 % confidence interval = value &plusmn; 1.96 &sigma; (Gaussian approximation of the "
            "posterior); relative &sigma; = &sigma; / |value|.</p>")
    out += _table(["coefficient", "unit", "value", "&sigma;", "95 % CI low", "95 % CI high", "relative &sigma; [%]"],
                  rows, left=2)
    if fixed:
        out += ("<p class=\"note\">Held fixed (not estimated; units as above, &ndash; non-dimensional): " +
                ", ".join(f"{_e(k)} = {_f(v, '{:.5g}')}" + ("" if _unit(model, k) in ("&ndash;", "?") else
                                                             f" {_unit(model, k)}") for k, v in fixed.items()) + "</p>")
    return out


def _section_identifiability(result) -> str:
    d = result.diagnostics or {}
    out = ("<h2 id=\"identifiability\">Identifiability</h2><p>Whether the logs determine each coefficient on its "
           "own, or only in combination with others.</p>")
    if not d:
        return out + "<p class=\"note\">The result carries no identifiability diagnostics.</p>"
    out += f"<p>Condition number of the scaled posterior covariance: <b>{_f(d.get('condition_number'), '{:.3g}')}</b>"
    if d.get("nis_mean") is not None and d.get("nis_expected") is not None:
        out += (f"; mean normalised innovation squared {_f(d['nis_mean'], '{:.3g}')} "
                f"(expected {_f(d['nis_expected'], '{:.3g}')} for a consistent filter)")
    out += ".</p>"
    warns = d.get("warnings") or []
    if warns:
        out += "<h3>Warnings</h3>" + "".join(f"<div class=\"warn\">{_e(w)}</div>" for w in warns)
    else:
        out += "<p>No identifiability warnings.</p>"
    poor = d.get("poorly_determined") or []
    if poor:
        out += f"<p>Poorly determined coefficients: {_e(', '.join(map(str, poor)))}.</p>"
    combos = d.get("unidentified_combinations") or []
    if combos:
        rows = [(_e(c.get("combination", c)) if isinstance(c, dict) else _e(c),
                 _f(c.get("variance_ratio") if isinstance(c, dict) else None, "{:.2f}")) for c in combos]
        out += "<h3>Combinations the data do not determine</h3>" + _table(
            ["combination (scaled coefficients)", "posterior / prior variance"], rows)
    corr = d.get("correlation") or {}
    names, mat = corr.get("names") or [], corr.get("matrix") or []
    if names and len(mat) == len(names):
        out += _fig(figures.correlation_figure(names, mat), "correlation heat-map")
    return out


def _summary_row(v: LogValidation, i: int) -> list:
    d = v.to_dict()
    kind = d["manoeuvre"]
    rm = d["rmse"]
    deg = 180 / math.pi
    cells = [f'<a href="#{_anchor(i)}">{_e(d["name"])}</a>', (_e(kind) if kind else "&ndash;")]
    cells += [_f(rm.get("u")), _f(rm.get("v")), _f(None if rm.get("r") is None else rm["r"] * deg),
              _f(None if rm.get("psi") is None else rm["psi"] * deg), _f(d["track_rmse_m"]),
              _f(None if d["track_rmse_m"] is None or not v.lpp else d["track_rmse_m"] / v.lpp, "{:.3f}")]
    return cells


def _section_summary(vals: list[LogValidation]) -> str:
    out = ("<h2 id=\"summary\">Replay of the logs</h2>"
           "<p class=\"note\">Each log is <b>replayed</b>: the model is simulated with the log's recorded rudder "
           "and propeller inputs from the log's initial state (mean of the first five samples). RMSE is taken "
           "over all samples against the measurement (measurement noise included). The <b>closed-loop</b> rows are "
           "the model's own standard manoeuvre matching the log (same side, rudder and switch angle, approach "
           "speed; propeller rps held at the value that gives that speed; zigzag rudder reversed by the "
           "model's heading): the free-running prediction. For a log whose propeller rate changes during "
           "the run only the replay is comparable.</p>")
    psi = [v.to_dict()["rmse"].get("psi") for v in vals]
    psi = [x * 180 / math.pi for x in psi if x is not None and math.isfinite(x)]
    if psi and max(psi) > 20.0:
        out += ("<p class=\"note\">The heading RMSE is over the whole replay, which runs open loop for the whole log: "
                "a small yaw-rate error integrates into a heading error that grows with time and never returns "
                f"(here up to {max(psi):.0f}&deg;), so on long runs it measures that drift more than the model's "
                "turning.  The yaw rate r and, where shown, the open-loop predictions over fixed horizons "
                "judge the turning better.</p>")
    rows = [_summary_row(v, i) for i, v in enumerate(vals)]
    out += _table(["log", "manoeuvre", "RMSE u [m/s]", "RMSE v [m/s]", "RMSE r [deg/s]", "RMSE &psi; [deg]",
                   "track RMSE [m]", "track RMSE [L]"], rows, left=2)
    for kind in ("turning", "zigzag"):
        sel = [(i, v) for i, v in enumerate(vals) if v.manoeuvre == kind and v.predicted is not None]
        if not sel:
            continue
        keys = SUMMARY_METRICS[kind]
        rows = []
        for i, v in sel:
            srcs = [("measured", v.measured.to_dict()), ("replay", v.predicted.to_dict()),
                    ("replay &minus; measured", v.difference())]
            if v.standard is not None:
                srcs += [("closed loop", v.standard.to_dict()), ("closed loop &minus; measured", v.difference("standard"))]
            for what, src in srcs:
                rows.append([_e(v.log.name) if what == "measured" else "", what] +
                            [_f(src.get(k), "{:+.3f}" if "minus" in what else "{:.3f}") for k, _ in keys])
        out += f"<h3>{'Turning circles' if kind == 'turning' else 'Zigzags'}: metrics measured vs predicted</h3>"
        out += _table(["log", ""] + [_e(lab) for _, lab in keys], rows, left=2)
    steady = [v for v in vals if v.steady_measured is not None]
    if steady:
        keys = (("steady_diameter_L", "steady diameter [L]"), ("steady_speed", "steady speed [m/s]"),
                ("time_360_s", "time per circle [s]"))
        rows = []
        for v in steady:
            st = v.steady_summary()
            m = st["measured"]
            for what, src in (("measured", m), ("replay", st["predicted"]), ("replay &minus; measured", st["difference"])):
                rows.append([_e(v.log.name) if what == "measured" else "",
                             f"{m['rudder_deg']:+.1f}&deg; from {m['hold_start']:.0f} s" if what == "measured" else "",
                             what] + [_f((src or {}).get(k), "{:+.3f}" if "minus" in what else "{:.3f}") for k, _ in keys])
        out += ("<h3>Steady turns of runs that are not standard manoeuvres</h3><p class=\"note\">The longest rudder "
                "hold of each run (propeller at one rate) taken as a turn from its start: the steady diameter and speed "
                "as for a turning circle, once the hold has turned 360&deg; (270&deg; when it turns less than 450&deg;); "
                "the replay over the same inputs. No approach quantities: the run has no steady approach.</p>")
        out += _table(["log", "hold", ""] + [_e(lab) for _, lab in keys], rows, left=3)
    return out


_IMO_VALUE = {"advance": ("advance_L", "L"), "tactical_diameter": ("tactical_diameter_L", "L"),
              "initial_turning": ("initial_turning_L", "L"), "overshoot1": ("overshoot1_deg", "deg"),
              "overshoot2": ("overshoot2_deg", "deg")}


def _pass_cell(v):
    if v is None:
        return ("n/a", "na")
    return ("pass", "pass") if v else ("FAIL", "fail")


def _section_imo(vals: list[LogValidation]) -> str:
    out = ("<h2 id=\"imo\">IMO MSC.137(76) manoeuvring criteria</h2>"
           "<p class=\"note\">Criteria that apply to each run (turning circle: advance &lt; 4.5 L, tactical "
           "diameter &lt; 5 L; 10/10 zigzag: overshoot limits depending on L/V, initial turning &le; 2.5 L; "
           "20/20 zigzag: first overshoot &le; 25&deg;). The standard applies to the full-scale ship in trial "
           "conditions; the L/V used here is the log's own (for a model-scale log it is smaller than the "
           "ship's by &radic;scale, which gives the strictest overshoot limits).</p>")
    rows = []
    for v in vals:
        na = ("n/a", "na")
        if v.measured is None:
            rows.append([_e(v.log.name), "not a standard manoeuvre: no criterion applies", "", "", na, "", na, "",
                         na])
            continue
        mi = v.measured.imo()
        pd_ = v.predicted.to_dict() if v.predicted is not None else {}
        sd_ = v.standard.to_dict() if v.standard is not None else {}
        md = v.measured.to_dict()
        crits = [k[:-5] for k in mi if k.endswith("_pass")]
        if not crits:
            rows.append([_e(v.log.name), _e(f"no IMO criterion for a {abs(v.measured.rudder_deg):g} deg "
                                            f"{v.manoeuvre}"), "", "", na, "", na, "", na])
        for c in crits:
            key, unit = _IMO_VALUE.get(c, (c, ""))
            lim = mi.get(f"{c}_limit_{unit}") if unit else None
            row = [_e(v.log.name), _e(c.replace("_", " ") + (f" [{unit}]" if unit else "")), _f(lim, "{:.3g}")]
            for d in (md, pd_, sd_):
                row += [_f(d.get(key), "{:.3f}"), _pass_cell(d.get("imo", {}).get(f"{c}_pass"))]
            rows.append(row)
    return out + _table(["log", "criterion", "limit", "measured", "", "replay", "", "closed loop", ""], rows, left=2)


def _innovations_for(identifier, name: str):
    if identifier is None:
        return None
    for inn in getattr(identifier, "innovations_", []) or []:
        if inn.attrs.get("name") == name:
            return inn
    return None


def _section_log(v: LogValidation, i: int, identifier) -> str:
    log = v.log
    d = v.to_dict()
    title = f"{log.name}"
    out = f"<h3 id=\"{_anchor(i)}\">{i + 1}. {_e(title)} ({_e(d['manoeuvre'] or 'no standard manoeuvre')})</h3>"
    out += f"<p class=\"note\">file <span class=\"mono\">{_e(d['file'])}</span>"
    if v.lpp:
        out += f"; Lpp {_f(v.lpp, '{:.4g}')} m"
    if v.measured is not None:
        out += f"; positions: {_e(v.measured.reference)}; rudder execute at t = {_f(v.measured.execute_time, '{:.2f}')} s"
    out += "</p>"
    for n in v.notes:
        out += f"<div class=\"warn\">{_e(n)}</div>"
    for what, m in (("measured", v.measured), ("predicted", v.predicted)):
        if m is not None and m.message and m.message != "ok":
            out += f"<p class=\"note\">{_e(what)} metrics: {_e(m.message)}</p>"
    lf = log.data
    sf = v.simulation.to_pandas().reset_index()
    if v.rudder_sign == -1:
        sf["delta"] = -sf["delta"]
    out += _fig(figures.time_series_figure(lf, sf, f"{log.name}: measured vs replay"), f"time series {log.name}")
    out += "<div class=\"figs\">"
    out += _fig(figures.track_figure(lf, sf, f"{log.name}: track"), f"track {log.name}")
    out += "</div>"
    out += _fig(figures.residual_figure(lf, sf, f"{log.name}: replay residual (measured - replay)"),
                f"residuals {log.name}")
    inn = _innovations_for(identifier, log.name)
    if inn is not None:
        out += ("<p class=\"note\">Innovations: each measurement minus the filter's one-step prediction "
                "(final pass). For a consistent filter about 95 % of them lie inside the shaded band of "
                "&plusmn;2 predicted standard deviations.</p>")
        out += _fig(figures.innovation_figure(inn, f"{log.name}: EKF innovations (final pass)"),
                    f"innovations {log.name}")
    elif identifier is not None:
        out += "<p class=\"note\">This log was not part of the identifier's fit: no innovations.</p>"
    return out


def _section_inputs(result, vals: list[LogValidation]) -> str:
    out = ("<h2 id=\"inputs\">Input files</h2><p>The files behind this report, with checksums to show they are the "
           "ones named.</p><h3>Logs the model was fitted to</h3>")
    rows = [(_e(m.get("name")), f"<span class=\"mono\">{_e(m.get('path'))}</span>",
             f"<span class=\"mono\">{_e(m.get('sha256'))}</span>") for m in (result.inputs or [])]
    out += _table(["log", "path", "sha256"], rows, left=3) if rows else "<p class=\"note\">not recorded</p>"
    out += "<h3>Logs validated in this report</h3>"
    rows = [(_e(v.log.name), f"<span class=\"mono\">{_e(getattr(v.log, 'path', None) or '(in memory)')}</span>",
             f"<span class=\"mono\">{_e(getattr(v.log, 'sha256', None) or '-')}</span>") for v in vals]
    fitted = {m.get("sha256") for m in (result.inputs or []) if m.get("sha256")}
    out += _table(["log", "path", "sha256"], rows, left=3)
    held = [v.log.name for v in vals if getattr(v.log, "sha256", None) and v.log.sha256 not in fitted]
    if fitted:
        out += (f"<p>Held out (not among the fitted logs, by sha256): {_e(', '.join(held)) if held else 'none'}.</p>")
    return out


def _section_versions(result) -> str:
    fit = result.versions or {}
    now = _versions_now()
    keys = list(dict.fromkeys(list(fit) + list(now)))
    rows = [(_e(k), _e(fit.get(k, "–")), _e(now.get(k, "–"))) for k in keys]
    return ("<h2 id=\"versions\">Software</h2><p>The versions that made the fit and this report.</p>" +
            _table(["package", "at the fit", "at this report"], rows, left=3))


# ----------------------------------------------------------------------------- public
#: Units of the cross-validated metrics (``shipid crossval``).
_CV_UNITS = {"tactical_diameter_pct": "%", "advance_pct": "%", "overshoot1_deg": "deg", "overshoot2_deg": "deg",
             "steady_diameter_pct": "%", "time_360_pct": "%"}


def _section_crossval(result) -> str:
    """The cross-validation stored in the result (``shipid fit --cross-validate`` or ``--model auto``): the
    candidates' scores when the model was chosen, the per-metric median and worst error on left-out runs."""
    extra = getattr(result, "extra", None) or {}
    cv, choice = extra.get("crossval"), extra.get("model_choice")
    if not cv and not choice:
        return ""
    out = ['<h2 id="crossval">Expected error on runs not used for fitting (cross-validation)</h2>']
    if choice:
        rows = [[_e(r["candidate"]), _f(r.get("score"), "{:.3g}"), _e(r.get("worst_run") or ""),
                 _f(r.get("worst"), "{:.3g}"), _f(r.get("failed_folds"), "{:.0f}"), _f(r.get("blowups"), "{:.0f}"),
                 _f(r.get("missing"), "{:.0f}")] for r in choice.get("table", [])]
        out.append(f"<p>Model chosen by cross-validation ({_e(choice.get('message', ''))}; score: mean over the "
                   "left-out runs of the errors over their goals, TD 5 %, overshoots 2 and 3 deg, 30 s position "
                   "0.1 L; 1 = at the goals).</p>")
        out.append(_table(["candidate", "score", "worst run", "its score", "failed folds", "blow-ups",
                           "not predicted"], rows))
    if cv:
        rows = []
        for r in cv.get("summary", []):
            unit = _CV_UNITS.get(r["metric"], "m" if r["metric"].startswith("position_") else "")
            if r["metric"] in ("blowups", "failed_folds"):
                rows.append([_e(r["metric"].replace("_", " ")), "", _f(r.get("worst"), "{:.0f}"), "", ""])
                continue
            rows.append([_e(f"{r['metric']} [{unit}]"), _f(r.get("median"), "{:.3g}"), _f(r.get("worst"), "{:+.3g}"),
                         _e(r.get("worst_run") or ""), _f(r.get("n"), "{:.0f}")])
        out.append(f"<p>{_e(cv.get('candidate', ''))}: {_e(cv.get('message', ''))}. Each run was predicted by a fit "
                   "on the other runs (closed-loop standard manoeuvres with the run's own rudder and check angles; "
                   "open-loop position errors from the measured state); errors are predicted minus measured.</p>")
        out.append(_table(["metric", "median |error|", "worst", "worst run", "runs"], rows))
    return "".join(out)


def _section_horizon(horizons) -> str:
    """Multi-start open-loop prediction errors (:func:`shipid.validation.horizon.horizon_prediction`) and
    predicted-vs-measured track overlays; ``horizons`` is a list of ``(HorizonResult, log)``."""
    if not horizons:
        return ""
    rows, figs = [], []
    for h, log in horizons:
        for e in h.to_records():
            rows.append([_e(h.name), _f(e["seconds"], "{:g}"), _f(e["position_error_median_m"], "{:.3f}"),
                         _f(e["position_error_p90_m"], "{:.3f}"), _f(e["heading_error_median_deg"], "{:.2f}"),
                         _f(e["n_starts"], "{:.0f}"), (_f(e["n_blowups"], "{:.0f}"), "bad" if e["n_blowups"] else "")])
        fig = figures._figure(4.6, 5.0)
        ax = h.plot(ax=fig.add_subplot(), log=log, every=max(1, len(h.start_times) // 12))
        ax.set_title(f"{h.name}\npredictions over {h.horizons.max():g} s", fontsize=10)
        ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.12), ncol=2, frameon=False)  # off the tracks
        fig.subplots_adjust(left=0.17, right=0.97, bottom=0.2, top=0.9)
        figs.append(_fig(fig, f"predicted vs measured tracks, {h.name}"))
    return ('<h2 id="horizon">Open-loop prediction from the measured state</h2><p>How far ahead the model can be '
            "trusted: from starts every few seconds it runs open loop with the measured inputs, and the table gives "
            "its position and heading errors at each horizon (blow-ups count with infinite error).</p>"
            + _table(["log", "horizon [s]", "median position error [m]", "p90 [m]", "median heading error [deg]",
                      "starts", "blow-ups"], rows)
            + '<div class="figs">' + "".join(figs) + "</div>")


def _ship_name(validations) -> str | None:
    for v in validations:
        name = getattr(getattr(v.log, "ship", None), "name", None)
        if name:
            return str(name)
    return None


def _data_set(validations) -> str:
    """The logs' folder (their common parent's name), or their names when they have no files."""
    paths = [getattr(v.log, "path", None) for v in validations]
    if paths and all(paths):
        parents = {Path(p).resolve().parent for p in paths}
        common = Path(os.path.commonpath([str(q) for q in parents]))
        return f"{len(paths)} log(s) from {common.name or common}"
    return f"{len(validations)} log(s)"


def default_title(result, model, validations) -> str:
    """"SHIP — MODEL model on N log(s) from FOLDER" (the ship from the logs' particulars, else its length)."""
    ship = _ship_name(validations)
    if ship is None:
        L = next((v.lpp for v in validations if v.lpp), None) or getattr(model, "lpp", None)
        ship = f"ship of Lpp {L:.4g} m" if L else "ship"
    return f"{ship} — {model_label(result, model)} model on {_data_set(validations)}"


def _median(xs):
    xs = sorted(x for x in xs if x is not None and math.isfinite(x))
    if not xs:
        return None
    n = len(xs)
    return xs[n // 2] if n % 2 else 0.5 * (xs[n // 2 - 1] + xs[n // 2])


def plain_summary(result, model, validations, horizons=None) -> str:
    """One paragraph in plain words: what was fitted, on what, the verdict, how well it predicts."""
    n_fit = len(result.inputs or [])
    names = [m.get("name") for m in (result.inputs or []) if m.get("name")]
    k = len(list(result.cov.index)) if getattr(result, "cov", None) is not None else 0
    n_par = len(result.coef or {})
    m = str(result.method)
    method = ("an extended Kalman filter" if m == "ekf" else
              f"an extended Kalman filter, then refined by {m} fitting of the replays" if m == "output-error" else
              f"the {m} method")
    fitted = (f"fitted by {method} to {n_fit} log(s) ({', '.join(names[:6])}{', ...' if len(names) > 6 else ''})"
              if n_fit else "with no fitted logs recorded")
    label = model_label(result, model)
    article = "an" if label[:1].lower() in "aeiou" or label.lower().startswith("mmg") else "a"
    out = [f"This report checks {article} {label} model {fitted}, estimating {k} of its {n_par} coefficients."]
    try:
        grade = verdict_of(result).grade
    except (AttributeError, KeyError, TypeError, ValueError):  # a result the verdict cannot read: consistency only
        grade = None
    cons = (result.diagnostics or {}).get("consistency") or {}
    if grade:
        out.append(f"Its verdict is {grade.replace('_', ' ')} (box above).")
    elif cons:
        out.append("The filter's innovations are consistent with its noise model." if cons.get("consistent", True)
                   else "The filter's innovations are not consistent with its noise model, so the stated "
                        "uncertainties are likely too small (Identifiability section).")
    if not result.success:
        out.append(f"The fit did not succeed: {result.message}.")
    fitted_sha = {m.get("sha256") for m in (result.inputs or []) if m.get("sha256")}
    held = [v for v in validations if getattr(v.log, "sha256", None) and fitted_sha
            and v.log.sha256 not in fitted_sha]
    track = _median([v.to_dict()["track_rmse_m"] for v in validations])
    Ls = [v.lpp for v in validations if v.lpp]
    if track is not None:
        rel = f" ({track / Ls[0]:.2f} ship lengths)" if Ls else ""
        out.append(f"Replayed open loop with each log's own rudder and propeller inputs, it follows the "
                   f"{len(validations)} log(s) ({f'{len(held)} not used in the fit' if held else 'all used in the fit'}) "
                   "with a median track error of "
                   f"{track:.3g} m{rel}.")
    td = [abs(v.difference("standard").get("tactical_diameter_L") or math.nan) / v.measured.to_dict()
          ["tactical_diameter_L"] * 100 for v in validations if v.manoeuvre == "turning" and v.standard is not None
          and v.measured.to_dict().get("tactical_diameter_L")]
    os1 = [abs(v.difference("standard").get("overshoot1_deg") or math.nan) for v in validations
           if v.manoeuvre == "zigzag" and v.standard is not None]
    parts = []
    if _median(td) is not None:
        parts.append(f"tactical diameter within {max(x for x in td if math.isfinite(x)):.1f} %")
    if _median(os1) is not None:
        parts.append(f"first overshoot within {max(x for x in os1 if math.isfinite(x)):.1f}&deg;".replace("&deg;", "°"))
    if parts:
        out.append("Sailing its own standard manoeuvres (closed loop), it predicts the measured " + " and ".join(parts)
                   + ".")
    by_h: dict = {}
    for h, _log in horizons or []:
        for e in h.to_records():
            by_h.setdefault(float(e["seconds"]), []).append(e.get("position_error_median_m"))
    if by_h:
        sec = 30.0 if 30.0 in by_h else sorted(by_h)[len(by_h) // 2]
        med = _median(by_h[sec])
        if med is not None:
            out.append(f"Predicting {sec:g} s ahead from measured states, its position error is {med:.2f} m "
                       f"(median over {len(by_h[sec])} log(s)).")
    return " ".join(out)


def render_report(result, logs, *, identifier=None, title: str | None = None, lpp: float | None = None,
                  rudder_sign: float = 1.0, closed_loop: bool = True,
                  validations: list[LogValidation] | None = None, uncertainty: dict | None = None,
                  intro: str | None = None, horizons=None) -> str:
    """The report as an HTML string (see :func:`write_report`).

    ``intro`` is plain text shown under the title (what the report demonstrates); blank
    lines separate paragraphs.

    ``validations`` (from :func:`shipid.validation.validate_logs`) reuses replays already computed;
    ``logs``, ``lpp``, ``rudder_sign`` and ``closed_loop`` are then ignored.  ``uncertainty``
    (``{"draws": N, "seed": s, "samples": None}``) adds the prediction-uncertainty section
    (:func:`shipid.report.uncertainty.uncertainty_section`).  ``horizons``: a list of
    ``(HorizonResult, log)`` adds the open-loop prediction section.
    """
    if result is None:
        if identifier is None:
            raise ValueError("render_report: give a fit result (or an identifier to take it from)")
        result = identifier.result()
    model, res = resolve_model(result)
    if res is None:
        raise ValueError("render_report: needs a fit result (FitResult or its JSON), not a bare model")
    if validations is None:
        validations = [validate_one(model, lg, lpp=lpp, rudder_sign=rudder_sign, closed_loop=closed_loop)
                       for lg in load_logs(logs, lpp=lpp)]
    extra = []
    if uncertainty:
        extra.append(uncertainty_section(res, validations, **uncertainty))
    title = title or default_title(res, model, validations)
    stamp = datetime.now(timezone.utc).isoformat(timespec="seconds")
    n_ok = sum(v.success for v in validations)
    nav = " ".join(f'<a href="#{a}">{t}</a>' for a, t in (
        ("summary", "Replay"), ("imo", "IMO criteria"), ("coefficients", "Coefficients"),
        ("identifiability", "Identifiability"), ("model", "Model"), ("logs", "Logs"), ("inputs", "Inputs"),
        ("versions", "Software")))
    body = [f"<h1>{_e(title)}</h1>",
            verdict_banner(res),
            f"<p class=\"intro\">{_e(plain_summary(res, model, validations, horizons))}</p>",
            f"<p class=\"note\">Model <b>{_e(model_label(res, model))}</b> ({_e(res.method)}; "
            f"{'fitted to ' + str(len(res.inputs)) + ' log(s)' if res.inputs else 'no fitted logs recorded'}), "
            f"validated on {len(validations)} log(s) "
            f"({n_ok} replayed with both metric sets). Report written {_e(stamp)} by shipid "
            f"{_e(_versions_now().get('shipid'))}.</p>",
            *[f"<p class=\"intro\">{_e(par.strip())}</p>" for par in (intro or "").split("\n\n") if par.strip()],
            f"<nav>{nav}</nav>",
            _section_summary(validations), _section_horizon(horizons), _section_imo(validations),
            _section_crossval(res), *extra,
            _section_coefficients(res, model),
            _section_identifiability(res), _section_model(res, model),
            "<h2 id=\"logs\">Measured vs simulated, per log</h2><p>For each log: the measured channels against the "
            "replay, the track, the replay's residuals and, for the fitted logs, the filter's innovations.</p>",
            *[_section_log(v, i, identifier) for i, v in enumerate(validations)],
            _section_inputs(res, validations), _section_versions(res)]
    return ("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
            f"<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\"><title>{_e(title)}</title>"
            f"<style>{_CSS}</style></head><body>\n" + "\n".join(body) + "\n</body></html>\n")


def write_report(result, logs, path: str | os.PathLike, *, force: bool = False, identifier=None,
                 title: str | None = None, lpp: float | None = None, rudder_sign: float = 1.0,
                 closed_loop: bool = True, intro: str | None = None) -> Path:
    """Write a self-contained HTML validation report.

    Parameters
    ----------
    result : FitResult, result JSON (dict or path), or None with ``identifier``
    logs : sequence of paths or TrialLogs
        Logs to replay (training and/or held-out runs).
    path : str or path-like
        Output ``.html`` file; written atomically, never overwritten unless ``force``.
    identifier : EKFIdentifier, optional
        The fitted identifier; adds innovation plots for the logs it was fitted to.
    title : str, optional
    intro : str, optional
        Plain text under the title saying what the report shows (paragraphs separated by blank lines).
    lpp : float, optional
        Ship length [m] for the metrics (default: from each log, then the model).
    rudder_sign : {1, -1}
        Sign applied to the logged rudder before replay (see :func:`shipid.validation.validate`).
    closed_loop : bool
        Also simulate the model's own standard manoeuvre matching each log (see :func:`shipid.validation.validate`).

    Returns
    -------
    pathlib.Path of the written file.
    """
    p = Path(path)
    if p.exists() and not force:  # fail before the (slow) replays and figures
        raise OutputExistsError(f"{p}: output exists; choose another name or pass --force (force=True) to overwrite it")
    text = render_report(result, logs, identifier=identifier, title=title, lpp=lpp, rudder_sign=rudder_sign,
                         closed_loop=closed_loop, intro=intro)
    return atomic_write_text(p, text, force=force)
