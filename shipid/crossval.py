# Why one file: cross-validation and model choice share one fold loop, its scoring rule and its table.
"""How well will a model predict a run it has not seen?  Cross-validation over runs, and model choice.

:func:`cross_validate` fits a model on all runs but one (or one fold of runs) and predicts the runs left out,
for every fold, through the path ``shipid fit`` and ``shipid validate`` take: the fit is
:func:`shipid.identify.fit_logs` with the caller's options, the prediction
:func:`shipid.validation.validate_one` (replay, steady turn, the closed-loop standard manoeuvre with the run's
own rudder and check angles) and :func:`shipid.validation.horizon_prediction` (open loop from the
measured states every 5 s, 10/30/60 s ahead), from the fit's start current for a model with current states.

:func:`choose_model` cross-validates the candidate models (:func:`candidates_for`: the ones that apply to the
logs) and ranks them by :func:`score_runs` -- the rule of ``docs/choosing_a_model.md``, fixed there before it
scored any data set.

Folds are independent fits: they run on :class:`shipid.campaign.Engine` (Dask workers, an existing scheduler,
or serially), each fold a member; a fold that fails is reported and the others complete, and the numbers do
not depend on where a fold ran.

This module sits above :mod:`shipid.validation` (beside :mod:`shipid.campaign`): it uses fitting *and*
validation, so it cannot live in :mod:`shipid.identify`, which the validation floor itself builds on.
"""
from __future__ import annotations

import math
import os
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

import numpy as np
import pandas as pd

from .campaign import Engine
from .environment.cli import APPARENT_WIND, environment_model, true_wind_at_edge, wind_geometry
from .environment.model import WIND_INPUTS, takes_environment
from .identify import fit_logs, model_from
from .logs.overlap import drop_contained, repeated_samples
from .models import available_models, get_model, model_class
from .results import ResultMixin, verdict_grade
from .validation import horizon_prediction, load_logs, validate_one

__all__ = ["cross_validate", "CrossValidation", "choose_model", "ModelChoice", "Candidate", "candidates_for",
           "parse_candidates", "fold_groups", "assign_folds", "score_runs", "run_fold", "start_model",
           "GOALS", "CAP", "ASTERN_SHARE", "LOW_FROUDE", "LOW_SPEED_SHARE", "SHIP_MODELS", "LOW_SPEED_MODELS"]

#: Goal of each scored metric (the divisor of the score, docs/choosing_a_model.md): tactical diameter [%],
#: first / second overshoot [deg], median position error 30 s ahead [fraction of Lpp].
GOALS = {"tactical_diameter_pct": 5.0, "overshoot1_deg": 2.0, "overshoot2_deg": 3.0, "position_30s_L": 0.1}
#: What a missing prediction, a non-finite error or a failed fold counts in the score (times the goal), and the
#: cap of every normalised error.
CAP = 10.0
#: Candidate rule: ship models for every log set (simplest first), and the low-speed ones, which apply when a log
#: has its propeller astern on at least :data:`ASTERN_SHARE` of its samples or spends :data:`LOW_SPEED_SHARE` of
#: them below Froude number :data:`LOW_FROUDE`.
SHIP_MODELS = ("kcs-response", "response-nl", "mmg")
LOW_SPEED_MODELS = ("lowspeed",)
ASTERN_SHARE, LOW_FROUDE, LOW_SPEED_SHARE = 0.01, 0.05, 0.10
#: Metrics reported per left-out run: key -> (unit, what).
METRICS = {
    "tactical_diameter_pct": ("%", "tactical diameter, closed loop"),
    "advance_pct": ("%", "advance, closed loop"),
    "overshoot1_deg": ("deg", "first overshoot, closed loop"),
    "overshoot2_deg": ("deg", "second overshoot, closed loop"),
    "steady_diameter_pct": ("%", "steady-turn diameter, replay"),
    "time_360_pct": ("%", "time per circle of the steady turn, replay"),
}
_G = 9.80665


# ----------------------------------------------------------------------------- models
def start_model(name: str, params=None, lpp: float | None = None, *, say=None):
    """The start model of ``shipid fit --model NAME [--params SET|RESULT.json]`` at the logs' ship length ``lpp``:
    a named parameter set is Froude-scaled to it, an earlier result of another length too (said with ``say``)."""
    cls = model_class(name)
    opts = {"lpp": lpp} if (lpp is not None and "lpp" in cls.__init__.__code__.co_varnames) else {}
    if params is None:
        return cls(**opts)
    if str(params).endswith(".json") or Path(str(params)).is_file():
        model = model_from(params, model=name)[0]
        ml = getattr(model, "lpp", None)
        if lpp is not None and ml is not None and abs(ml / lpp - 1.0) > 1e-9 and hasattr(model, "scaled"):
            if say is not None:
                say(f"note: start values {params} (Lpp {ml:g} m) Froude-scaled to the logs' {lpp:g} m")
            model = model.scaled(lpp)
        return model
    return get_model(name, params, **opts)


@dataclass(frozen=True)
class Candidate:
    """One candidate model: registered ``model`` name, start parameter ``params`` (set name or result JSON;
    None: the model's default), ``wind`` geometry (``--wind``) and ``current`` (``--current``)."""

    model: str
    params: str | None = None
    wind: str | None = None
    current: str | None = None

    @property
    def label(self) -> str:
        s = self.model + (f":{self.params}" if self.params else "")
        if self.wind:
            s += " +wind"
        if self.current:
            s += " +current"
        return s


def parse_candidates(text: str) -> list[Candidate] | None:
    """``"auto"`` -> None (the rule of :func:`candidates_for`); ``"auto:mmg:kvlcc2,response-nl"`` -> those
    candidates in that order.  ValueError for an unknown model name."""
    text = str(text).strip()
    if text == "auto":
        return None
    if not text.startswith("auto:"):
        raise ValueError(f"--model {text}: not 'auto' or 'auto:MODEL[:SET],...'")
    out = []
    for part in text[5:].split(","):
        part = part.strip()
        if not part:
            continue
        name, _, pset = part.partition(":")
        if name not in available_models():
            raise ValueError(f"--model {text[:80]}: unknown model '{name}'; available: "
                             f"{', '.join(m for m in available_models() if m in SHIP_MODELS + LOW_SPEED_MODELS)}")
        out.append(Candidate(name, pset or None))
    if not out:
        raise ValueError(f"--model {text}: name at least one candidate after 'auto:', e.g. auto:mmg,response-nl")
    return out


def _has_wind(log) -> bool:
    cols = set(getattr(log, "data", log).columns)
    return set(WIND_INPUTS) <= cols or set(APPARENT_WIND) <= cols


def _low_speed_reason(logs, lpp) -> str | None:
    """Why the low-speed models apply to ``logs`` (docs/choosing_a_model.md), or None."""
    for lg in logs:
        cols = lg.data.columns
        if "n" in cols:
            n = np.asarray(lg.data["n"], dtype=float)
            n = n[np.isfinite(n)]
            if n.size and np.mean(n < 0) >= ASTERN_SHARE:
                return f"{lg.name} has its propeller astern on {np.mean(n < 0):.0%} of its samples"
        if lpp and "u" in cols:
            U = np.hypot(np.asarray(lg.data["u"], float), np.asarray(lg.data["v"], float) if "v" in cols else 0.0)
            U = U[np.isfinite(U)]
            share = float(np.mean(U / math.sqrt(_G * lpp) < LOW_FROUDE)) if U.size else 0.0
            if share >= LOW_SPEED_SHARE:
                return f"{lg.name} spends {share:.0%} of its samples below Froude number {LOW_FROUDE:g}"
    return None


def candidates_for(logs, *, lpp: float | None = None, wind: str | None = None, current: str | None = None,
                   given: Sequence[Candidate] | None = None) -> tuple[list[Candidate], list[str]]:
    """The candidate models for ``logs`` by the rule of docs/choosing_a_model.md, and one line per decision.

    ``given``: the user's candidates (``--model auto:...``), kept in their order; ``wind``, ``current``: the
    environment options given explicitly (applied to every candidate).  Without them, every candidate gets a wind
    part and a constant current when every log carries wind and a geometry is known (the logs' ship)."""
    why = []
    L = lpp or _lpp(logs)
    if given is None:
        names = list(SHIP_MODELS)
        reason = _low_speed_reason(logs, L)
        if reason:
            names += list(LOW_SPEED_MODELS)
            why.append(f"lowspeed is a candidate: {reason}")
        else:
            why.append("lowspeed is not a candidate: no log holds astern propeller or low speed")
        given = [Candidate(n) for n in names]
    if wind is None and current is None:
        if all(_has_wind(lg) for lg in logs):
            try:
                wind_geometry("auto", logs)
                wind, current = "auto", "constant"
                why.append("every candidate has a wind part and a constant current: every log carries wind")
            except ValueError:
                why.append("no wind part: the logs carry wind but their ship has no shipped above-water geometry "
                           "(give --wind FILE.json and --current)")
        else:
            why.append("no wind or current part: not every log carries wind")
    out = [Candidate(c.model, c.params, c.wind or wind, c.current or current) for c in given]
    cannot = [c.model for c in out if (c.wind or c.current) and not takes_environment(model_class(c.model))]
    if cannot:
        names = ", ".join(dict.fromkeys(cannot))
        out = [c for c in out if c.model not in cannot]
        if not out:
            raise ValueError(f"{names}: cannot take a wind or current part (only mmg and lowspeed can); leave out "
                             "--wind/--current or name mmg or lowspeed")
        are = "are not candidates" if ", " in names else "is not a candidate"
        why.append(f"{names} {are}: the candidates get wind and current parts, and these can be added to mmg and "
                   "lowspeed only")
    return out, why


def _lpp(logs) -> float | None:
    lpps = {float(lg.ship.lpp) for lg in logs if getattr(lg, "ship", None) is not None and lg.ship.lpp}
    if len(lpps) > 1:
        raise ValueError(f"the logs belong to ships of different lengths {sorted(lpps)} m; cross-validate one ship "
                         "at a time (or pass --lpp)")
    return lpps.pop() if lpps else None


# ----------------------------------------------------------------------------- folds
def fold_groups(logs) -> tuple[list[list[int]], list[dict]]:
    """Groups of ``logs`` that must stay on one side of a fold, and the logs left out as copies.

    A log whose every sample is a sample of another log (a trimmed copy, :func:`shipid.logs.overlap.drop_contained`)
    is left out of the cross-validation (the fit would drop it as a repeat; predicting it would count its run
    twice); logs that share samples (overlapping segments, :func:`~shipid.logs.overlap.repeated_samples`) form one
    group.  Returns ``(groups as lists of indices into logs, in the order of their first log; copies)``."""
    rows = repeated_samples(logs) if len(logs) > 1 else []
    kept, gone = drop_contained(logs, rows)
    keep = [i for i, lg in enumerate(logs) if any(lg is k for k in kept)]
    parent = {i: i for i in keep}

    def find(i):
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for r in rows:
        a, b = r["index"], r["in_index"]
        if a in parent and b in parent:
            ra, rb = find(a), find(b)
            if ra != rb:
                parent[max(ra, rb)] = min(ra, rb)
    groups: dict[int, list[int]] = {}
    for i in keep:
        groups.setdefault(find(i), []).append(i)
    return [groups[k] for k in sorted(groups)], gone


def assign_folds(n_groups: int, folds="loro") -> list[int]:
    """Fold of each group: ``"loro"`` one fold per group; an integer K: group i in fold i mod K."""
    if folds in ("loro", None):
        return list(range(n_groups))
    try:
        k = int(folds)
    except (TypeError, ValueError):
        k = 0
    if not 2 <= k <= n_groups:
        raise ValueError(f"folds={folds!r}: give 'loro' or a number of folds from 2 to the number of runs "
                         f"({n_groups})")
    return [i % k for i in range(n_groups)]


# ----------------------------------------------------------------------------- one fold (runs on a worker)
def _finite(v):
    try:
        v = float(v)
    except (TypeError, ValueError):
        return None
    return v if math.isfinite(v) else None


def _pct(pred, meas):
    p, m = _finite(pred), _finite(meas)
    return None if p is None or m is None or m == 0 else 100.0 * (p - m) / m


def _run_entry(v, h, L, fold: int) -> dict:
    """The per-run entry of a left-out run from its :class:`~shipid.validation.LogValidation` ``v`` and
    :class:`~shipid.validation.HorizonResult` ``h``."""
    log = v.log
    path = getattr(log, "path", None)
    e = {"run": getattr(log, "name", "log"), "file": str(path) if path is not None else None,
         "folder": Path(path).parent.name if path is not None else "", "fold": int(fold),
         "manoeuvre": v.manoeuvre, "lpp": _finite(L), "errors": {}, "measured": {}, "predicted": {},
         "missing": [], "blowups": 0, "n_starts": 0, "notes": list(v.notes)}
    err, meas, pred, miss = e["errors"], e["measured"], e["predicted"], e["missing"]
    m = v.measured.to_dict() if v.measured is not None else {}
    s = v.standard.to_dict() if v.standard is not None else {}
    std_msg = (s.get("message") or "") if s else ""
    closed_note = next((n for n in v.notes if n.startswith("closed-loop manoeuvre")), "")
    pairs = {"turning": [("tactical_diameter_pct", "tactical_diameter_L", True), ("advance_pct", "advance_L", True)],
             "zigzag": [("overshoot1_deg", "overshoot1_deg", False), ("overshoot2_deg", "overshoot2_deg", False)]}
    for key, mk, pct in pairs.get(v.manoeuvre, []):
        mv = _finite(m.get(mk))
        if mv is None:
            continue
        meas[key] = mv
        pv = _finite(s.get(mk))
        pred[key] = pv
        if pv is None:
            why = {x["metric"]: x["reason"] for x in v.standard_missing}
            reason = why.get(mk) or "; ".join(x for x in (closed_note, std_msg) if x and x != "ok") or "not reached"
            miss.append({"metric": key, "reason": reason})
            err[key] = None
        else:
            err[key] = _pct(pv, mv) if pct else pv - mv
    e["reached_after_simulator_limit"] = list(v.standard_settings.get("reached_after_simulator_limit", []))
    st = v.steady_summary()
    if st:
        sm, sp = st["measured"], st["predicted"] or {}
        for key, k in (("steady_diameter_pct", "steady_diameter_L"), ("time_360_pct", "time_360_s")):
            mv = _finite(sm.get(k))
            if mv is None:
                continue
            meas[key] = mv
            pred[key] = _finite(sp.get(k))
            err[key] = _pct(sp.get(k), mv)
            if err[key] is None:
                miss.append({"metric": key, "reason": "the replay holds no steady turn over the measured hold"})
    if h is not None:
        e["horizons"] = []
        for j, H in enumerate(h.horizons):
            pe = h.position_error[:, j]
            ok = ~np.isnan(pe)
            n, blown = int(ok.sum()), int(np.isinf(pe[ok]).sum())
            med = float(np.median(pe[ok])) if n else None  # inf when more than half blew up
            e["horizons"].append({"seconds": float(H), "n_starts": n, "n_blowups": blown,
                                  "position_error_median_m": _finite(med),
                                  "errors_m": [float(x) if math.isfinite(x) else None for x in pe[ok]]})
            err[f"position_{H:g}s_m"] = _finite(med)
            if n and med is not None and not math.isfinite(med):
                miss.append({"metric": f"position_{H:g}s_m",
                             "reason": f"{blown} of {n} starts blew up before {H:g} s"})
        e["blowups"] = int(h.blowup.sum())
        e["n_starts"] = int(h.start_times.size)
    return e


def _grade(fit, result) -> tuple[str, list]:
    """The fit's grade: the result's verdict where it has one, else diverged / consistent / not consistent."""
    grade = verdict_grade(result)
    if grade is not None:
        return grade, list(getattr(getattr(result, "verdict", None), "reasons", None) or [])
    if not fit.ekf.success_:
        return "diverged", [str(fit.ekf.message_)]
    cons = result.diagnostics.get("consistency") or {}
    return ("consistent" if cons.get("consistent", True) else "model_error"), list(cons.get("reasons", []))


def run_fold(spec: dict) -> dict:
    """One fold (runs on a worker): fit ``spec["candidate"]`` on ``spec["train"]`` with ``spec["fit_options"]``
    (keyword arguments of :func:`shipid.identify.fit_logs`), then predict each log of ``spec["test"]`` as
    ``shipid validate`` does.  Returns the fold record and one entry per left-out run (JSON-able)."""
    t0 = time.perf_counter()
    cand: Candidate = spec["candidate"]
    train, test = spec["train"], spec["test"]
    lpp = spec.get("lpp")
    L = lpp if lpp is not None else _lpp(train)
    model = start_model(cand.model, cand.params, L)
    extra = None
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        if cand.wind or cand.current:
            model, extra = environment_model(model, train, wind=cand.wind, current=cand.current)
        opts = dict(spec.get("fit_options") or {})
        fit = fit_logs(train, model, lpp=lpp, ekf_options=extra, start_defaults=cand.params is None, **opts)
        result = fit.result()
    fit_seconds = time.perf_counter() - t0
    grade, reasons = _grade(fit, result)
    record = {"fold": int(spec["fold"]), "candidate": cand.label, "train": [lg.name for lg in train],
              "left_out": [lg.name for lg in test], "success": bool(result.success), "grade": grade,
              "reasons": reasons, "message": str(result.message), "fit_seconds": fit_seconds, "error": None}
    runs = []
    if grade == "diverged":  # the result is the start values: nothing to predict with
        record["error"] = f"the filter diverged ({result.message})"
        return {"fold": record, "runs": runs}
    model, res = model_from(result)  # what `shipid validate` reads from the result file
    start = (res.settings or {}).get("current_start") if res is not None else None
    initial = {"cx": float(start["cx"]), "cy": float(start["cy"])} if (start and "cx" in model.state_names) else None
    horizons = tuple(spec.get("horizons") or ())
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for lg in test:
            v = validate_one(model, lg, lpp=lpp, initial=initial)
            h = None
            if horizons and {"x", "y", "psi"} <= set(lg.data.columns):
                h = horizon_prediction(model, lg, horizons=horizons, start_every=float(spec.get("start_every", 5.0)),
                                       initial=initial)
            runs.append(_run_entry(v, h, v.lpp, spec["fold"]))
    record["seconds"] = time.perf_counter() - t0
    return {"fold": record, "runs": runs}


# ----------------------------------------------------------------------------- scoring
def _normalised(run: dict) -> dict:
    """The run's scored errors over their goals (:data:`GOALS`), capped at :data:`CAP`; a missing prediction
    or a non-finite error counts :data:`CAP`."""
    out = {}
    err, meas = run.get("errors", {}), run.get("measured", {})
    for key in ("tactical_diameter_pct", "overshoot1_deg", "overshoot2_deg"):
        if key in meas:
            v = err.get(key)
            out[key] = CAP if v is None else min(abs(v) / GOALS[key], CAP)
    for hz in run.get("horizons") or []:
        if abs(hz["seconds"] - 30.0) < 1e-9 and hz["n_starts"]:
            v, L = hz["position_error_median_m"], run.get("lpp")
            if L:
                out["position_30s_L"] = CAP if v is None else min(v / (GOALS["position_30s_L"] * L), CAP)
    return out


def score_runs(runs: Sequence[dict], failed_runs: Sequence[str] = ()) -> dict:
    """The score of docs/choosing_a_model.md: each run's mean normalised error (:func:`_normalised`), a run of a
    failed fold :data:`CAP`; the mean over runs (``score``), the worst run (``worst``, ``worst_run``) and each
    run's score (``runs``)."""
    per = {}
    for r in runs:
        nz = _normalised(r)
        if nz:
            per[r["run"]] = float(np.mean(list(nz.values())))
    for name in failed_runs:
        per[name] = CAP
    if not per:
        return {"score": None, "worst": None, "worst_run": None, "runs": {}}
    worst = max(per, key=lambda k: per[k])
    return {"score": float(np.mean(list(per.values()))), "worst": per[worst], "worst_run": worst, "runs": per}


# ----------------------------------------------------------------------------- results
@dataclass
class CrossValidation(ResultMixin):
    """Result of :func:`cross_validate` for one model.

    Attributes
    ----------
    candidate : str  the model cross-validated (name, start set, environment parts)
    runs : list of dict  one entry per left-out run: ``errors`` (predicted - measured: % for lengths, deg for
        overshoots; the run's median position error [m] at each horizon), ``measured``, ``predicted``,
        ``missing`` (metric and reason), ``blowups``, ``horizons`` and ``notes``
    folds : list of dict  one per fold: training and left-out runs, ``grade``, ``success``, ``error``
    copies : list of dict  logs left out as copies of another log
    score : dict  :func:`score_runs`
    settings : dict  folds, horizons, fit options
    """

    candidate: str
    runs: list = field(default_factory=list)
    folds: list = field(default_factory=list)
    copies: list = field(default_factory=list)
    score: dict = field(default_factory=dict)
    settings: dict = field(default_factory=dict)

    @property
    def failed(self) -> list[dict]:
        return [f for f in self.folds if f.get("error")]

    @property
    def success(self) -> bool:
        """True when every fold's fit was made and its runs predicted."""
        return bool(self.folds) and not self.failed

    @property
    def message(self) -> str:
        n = len(self.folds)
        if not self.failed:
            return f"{n} folds, {len(self.runs)} left-out runs predicted"
        return (f"{len(self.failed)} of {n} folds failed: "
                + "; ".join(f"fold {f['fold']} ({', '.join(f['left_out'])}): {f['error']}" for f in self.failed))

    def to_pandas(self) -> pd.DataFrame:
        """One row per left-out run: its fold, manoeuvre, every error, blow-ups, missing predictions, run score."""
        rows = []
        for r in self.runs:
            row = {"run": r["run"], "folder": r.get("folder", ""), "fold": r["fold"], "manoeuvre": r["manoeuvre"]}
            row.update({k: v for k, v in r["errors"].items()})
            row["blowups"] = r["blowups"]
            row["missing"] = len(r["missing"])
            row["score"] = self.score.get("runs", {}).get(r["run"])
            rows.append(row)
        return pd.DataFrame(rows).set_index("run") if rows else pd.DataFrame()

    def summary(self) -> pd.DataFrame:
        """Per metric: ``n`` runs, ``median`` of the absolute errors, ``worst`` (signed) and ``worst_run``,
        ``unit``; plus rows ``blowups`` (total), ``missing`` (predictions) and ``failed_folds``."""
        metrics = {k: v[0] for k, v in METRICS.items()}
        hz = sorted({h["seconds"] for r in self.runs for h in (r.get("horizons") or [])})
        metrics.update({f"position_{H:g}s_m": "m" for H in hz})
        rows = []
        for k, unit in metrics.items():
            vals = [(r["run"], r["errors"][k]) for r in self.runs if k in r["errors"]]
            if not vals:
                continue
            fin = [(n, v) for n, v in vals if v is not None]
            miss = len(vals) - len(fin)
            if fin:
                worst = max(fin, key=lambda t: abs(t[1]))
                rows.append({"metric": k, "unit": unit, "n": len(fin), "missing": miss,
                             "median": float(np.median([abs(v) for _, v in fin])), "worst": worst[1],
                             "worst_run": worst[0]})
            else:
                rows.append({"metric": k, "unit": unit, "n": 0, "missing": miss, "median": None, "worst": None,
                             "worst_run": None})
        rows.append({"metric": "blowups", "unit": "starts", "n": len(self.runs), "missing": 0,
                     "median": None, "worst": float(sum(r["blowups"] for r in self.runs)), "worst_run": None})
        rows.append({"metric": "failed_folds", "unit": "folds", "n": len(self.folds), "missing": 0, "median": None,
                     "worst": float(len(self.failed)), "worst_run": None})
        return pd.DataFrame(rows).set_index("metric")

    def by_folder(self, seconds: float = 30.0) -> pd.DataFrame:
        """Median position error [m] ``seconds`` ahead over all starts of the runs of each folder (run type),
        with the number of runs, starts and blow-ups."""
        groups: dict = {}
        for r in self.runs:
            for h in r.get("horizons") or []:
                if abs(h["seconds"] - seconds) < 1e-9:
                    g = groups.setdefault(r.get("folder", ""), {"runs": 0, "e": [], "blowups": 0})
                    g["runs"] += 1
                    g["e"] += [np.inf if x is None else x for x in h["errors_m"]]
                    g["blowups"] += h["n_blowups"]
        rows = [{"folder": k, "runs": g["runs"], "starts": len(g["e"]), "blowups": g["blowups"],
                 "median_m": float(np.median(g["e"])) if g["e"] else None} for k, g in groups.items()]
        return pd.DataFrame(rows).set_index("folder") if rows else pd.DataFrame()

    def worst_runs(self, n: int = 3) -> list[tuple[str, float]]:
        """The ``n`` runs with the highest run score (:func:`score_runs`)."""
        per = self.score.get("runs", {})
        return sorted(per.items(), key=lambda t: -t[1])[:n]

    def plot(self, ax=None):
        """Bar chart of the run scores (1 = at the goals), worst first; returns the axes."""
        import matplotlib.pyplot as plt  # only when plotting: pyplot takes ~1 s to import

        if ax is None:
            _, ax = plt.subplots(figsize=(6, 3))
        items = sorted(self.score.get("runs", {}).items(), key=lambda t: -t[1])
        ax.bar(range(len(items)), [v for _, v in items])
        ax.set_xticks(range(len(items)))
        ax.set_xticklabels([k for k, _ in items], rotation=60, ha="right", fontsize=7)
        ax.axhline(1.0, color="k", lw=0.8, ls="--")
        ax.set_ylabel("run score (1 = at the goals)")
        ax.set_title(f"{self.candidate}: left-out runs")
        return ax

    def _html_title(self) -> str:
        return f"cross-validation of {self.candidate}"

    def _key_numbers(self) -> dict:
        sc = self.score
        out = {"folds": len(self.folds), "left-out runs": len(self.runs)}
        if sc.get("score") is not None:
            out.update({"score": f"{sc['score']:.3g}", "worst run": f"{sc['worst_run']} ({sc['worst']:.3g})"})
        return out

    def to_dict(self, *, starts: bool = True) -> dict:
        """JSON-able: ``candidate``, ``success``, ``message``, ``score``, ``summary`` (list of rows), ``runs``,
        ``folds``, ``copies``, ``settings``; ``starts=False`` leaves out every start's error (a compact block for
        a fit result)."""
        runs = self.runs
        if not starts:
            runs = [{**r, "horizons": [{k: v for k, v in h.items() if k != "errors_m"} for h in r.get("horizons") or []]}
                    for r in runs]
        summ = self.summary().reset_index()
        return {"candidate": self.candidate, "success": self.success, "message": self.message,
                "score": self.score, "summary": [{k: (None if isinstance(v, float) and not math.isfinite(v) else v)
                                                  for k, v in row.items()} for row in summ.to_dict("records")],
                "by_folder_30s": self.by_folder().reset_index().to_dict("records") if self.runs else [],
                "runs": runs, "folds": self.folds, "copies": self.copies, "settings": self.settings}

    def text(self) -> str:
        """The summary a user quotes, as lines."""
        lines = [f"cross-validation of {self.candidate}: {self.message}"]
        for k, row in self.summary().iterrows():
            if k in ("blowups", "failed_folds"):
                lines.append(f"  {k}: {int(row['worst'])}")
                continue
            if row["n"]:
                lines.append(f"  {k} [{row['unit']}]: median |error| {row['median']:.3g}, worst {row['worst']:+.3g} "
                             f"({row['worst_run']}), {int(row['n'])} runs" + (f", {int(row['missing'])} not predicted"
                                                                                if row["missing"] else ""))
            else:
                lines.append(f"  {k}: not predicted on any of {int(row['missing'])} runs")
        if self.score.get("score") is not None:
            lines.append(f"  score {self.score['score']:.3g} (1 = at the goals); worst runs: "
                         + ", ".join(f"{k} {v:.3g}" for k, v in self.worst_runs()))
        return "\n".join(lines)


def _collect(cand: Candidate, outcomes, specs, copies, settings) -> CrossValidation:
    runs, folds, failed = [], [], []
    for o, spec in zip(outcomes, specs):
        if o.ok:
            folds.append({**o.value["fold"], "worker_seconds": o.seconds})
            runs += o.value["runs"]
            if o.value["fold"].get("error"):
                failed += [lg.name for lg in spec["test"]]
        else:
            folds.append({"fold": spec["fold"], "candidate": cand.label, "train": [lg.name for lg in spec["train"]],
                          "left_out": [lg.name for lg in spec["test"]], "success": False, "grade": None,
                          "reasons": [], "message": "", "error": o.error})
            failed += [lg.name for lg in spec["test"]]
    order = {lg: i for i, lg in enumerate(settings.get("runs", []))}
    runs.sort(key=lambda r: order.get(r["run"], len(order)))
    return CrossValidation(cand.label, runs, folds, copies, score_runs(runs, failed), settings)


def _prepare(logs, lpp, folds):
    logs = load_logs(logs, lpp=lpp)
    groups, gone = fold_groups(logs)
    if len(groups) < 2:
        raise ValueError(f"cross-validation needs at least two distinct runs; got {len(groups)} "
                         f"({', '.join(lg.name for lg in logs)})")
    fold_of = assign_folds(len(groups), folds)
    k = max(fold_of) + 1
    plan = []
    for f in range(k):
        test = [logs[i] for g, fg in zip(groups, fold_of) if fg == f for i in g]
        train = [logs[i] for g, fg in zip(groups, fold_of) if fg != f for i in g]
        plan.append((f, train, test))
    copies = [{"log": r["log"], "copy_of": r["in"]} for r in gone]
    names = [logs[i].name for g in groups for i in g]
    return logs, plan, copies, names


def _specs(cand, plan, lpp, fit_options, horizons, start_every):
    return [{"candidate": cand, "fold": f, "train": train, "test": test, "lpp": lpp,
             "fit_options": dict(fit_options or {}), "horizons": tuple(horizons or ()), "start_every": start_every}
            for f, train, test in plan]


def _engine(engine, workers, scheduler, progress):
    if engine is not None:
        return engine, False
    return Engine(workers if workers is not None else 1, scheduler=scheduler, progress=progress), True


def _map(eng, specs, desc):
    """The folds on the engine, longest first; Dask's note that the members' logs make a large task graph is
    not shown (the logs are the members' input: a fold needs them on its worker)."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="Sending large graph")
        return eng.map(run_fold, specs, desc=desc, cost=[_fold_cost(s) for s in specs])


def _fold_cost(spec) -> float:
    return float(sum(lg.data.shape[0] for lg in spec["train"]))


def cross_validate(logs, model: str = "mmg", params=None, *, folds="loro", lpp: float | None = None,
                   wind: str | None = None, current: str | None = None, fit_options: dict | None = None,
                   horizons=(10.0, 30.0, 60.0), start_every: float = 5.0, workers: int | None = 1,
                   scheduler: str | None = None, engine=None, progress: bool = False) -> CrossValidation:
    """Cross-validate a model over runs: fit on the training runs of each fold, predict its left-out runs.

    Parameters
    ----------
    logs : sequence of paths or TrialLogs  the runs (one ship); copies of a run are left out, overlapping runs
        stay in one fold (:func:`fold_groups`)
    model, params : the model and its start values, as ``shipid fit --model NAME --params SET``
    folds : "loro" or int  leave-one-run-out (default) or K folds of run groups
    lpp : float, optional  ship length [m] (default: the logs' particulars)
    wind, current : optional  the environment parts of ``shipid fit --wind GEOMETRY --current KIND``
    fit_options : dict, optional  further keyword arguments of :func:`shipid.identify.fit_logs` (``shipid fit``'s
        options), the same in every fold
    horizons, start_every : open-loop prediction horizons [s] and start spacing [s] (``shipid validate``'s defaults)
    workers, scheduler, engine : where the folds run (:class:`shipid.campaign.Engine`; default serial)
    progress : bool  a bar over the folds

    Returns
    -------
    CrossValidation
    """
    logs, plan, copies, names = _prepare(logs, lpp, folds)
    cand = Candidate(model, params, wind, current)
    if wind:
        true_wind_at_edge(logs, what="--wind")
    specs = _specs(cand, plan, lpp, fit_options, horizons, start_every)
    eng, own = _engine(engine, workers, scheduler, progress)
    try:
        outs = _map(eng, specs, f"folds of {cand.label}")
    finally:
        if own:
            eng.close()
    settings = {"folds": folds, "n_folds": len(plan), "horizons": list(horizons or ()), "start_every": start_every,
                "fit_options": _jsonable(fit_options), "runs": names, "engine": eng.describe()}
    return _collect(cand, outs, specs, copies, settings)


def _jsonable(d):
    return {k: (v if isinstance(v, (str, int, float, bool, type(None), list)) else str(v)) for k, v in (d or {}).items()}


@dataclass
class ModelChoice(ResultMixin):
    """Result of :func:`choose_model`: every candidate's :class:`CrossValidation`, the ranking and the winner."""

    results: list
    candidates: list = field(default_factory=list)
    why: list = field(default_factory=list)

    @property
    def chosen(self):
        """The :class:`Candidate` of the best cross-validated model (None when none could be scored)."""
        if not self.success:
            return None
        return next(c for c in self.candidates if c.label == self.best.candidate)

    @property
    def ranking(self) -> list:
        """Candidates in the order of the rule (docs/choosing_a_model.md): score to 3 significant digits, then
        the worst run, then the candidate's place in the list; candidates without a score last."""
        def key(item):
            i, cv = item
            s = cv.score.get("score")
            if s is None:
                return (1, math.inf, math.inf, i)
            return (0, float(f"{s:.3g}"), cv.score["worst"], i)

        return [cv for _, cv in sorted(enumerate(self.results), key=key)]

    @property
    def best(self):
        return self.ranking[0] if self.results else None

    @property
    def success(self) -> bool:
        return self.best is not None and self.best.score.get("score") is not None

    @property
    def message(self) -> str:
        if not self.success:
            return "no candidate could be scored"
        r = self.ranking
        gap = (f", {r[1].score['score'] - r[0].score['score']:.3g} below {r[1].candidate}"
               if len(r) > 1 and r[1].score.get("score") is not None else "")
        return f"chose {r[0].candidate}: score {r[0].score['score']:.3g}{gap}"

    def summary(self) -> pd.DataFrame:
        """One row per candidate in ranking order: score, worst run and its score, failed folds, blow-ups,
        missing predictions and the median absolute error of each scored metric."""
        rows = []
        for cv in self.ranking:
            s = cv.summary()
            row = {"candidate": cv.candidate, "score": cv.score.get("score"), "worst_run": cv.score.get("worst_run"),
                   "worst": cv.score.get("worst"), "failed_folds": len(cv.failed),
                   "blowups": int(sum(r["blowups"] for r in cv.runs)),
                   "missing": int(sum(len(r["missing"]) for r in cv.runs))}
            for k in ("tactical_diameter_pct", "overshoot1_deg", "overshoot2_deg", "position_30s_m"):
                m = s.loc[k, "median"] if k in s.index else None
                row[k] = float(m) if m is not None else math.nan  # NaN: no run measures it
            rows.append(row)
        return pd.DataFrame(rows).set_index("candidate")

    def to_pandas(self) -> pd.DataFrame:
        return self.summary()

    def plot(self, ax=None):
        import matplotlib.pyplot as plt  # only when plotting: pyplot takes ~1 s to import

        if ax is None:
            _, ax = plt.subplots(figsize=(5, 3))
        tab = self.summary()
        ax.barh(range(len(tab)), tab["score"].fillna(CAP).to_numpy())
        ax.set_yticks(range(len(tab)))
        ax.set_yticklabels(tab.index)
        ax.invert_yaxis()
        ax.set_xlabel("cross-validated score (1 = at the goals)")
        return ax

    def _html_title(self) -> str:
        return "model choice by cross-validation"

    def _key_numbers(self) -> dict:
        return {"candidates": len(self.results), "chosen": self.best.candidate if self.success else "none"}

    def to_dict(self) -> dict:
        tab = self.summary().reset_index()
        return {"success": self.success, "message": self.message, "chosen": self.best.candidate if self.best else None,
                "rule": "docs/choosing_a_model.md", "why": list(self.why),
                "table": [{k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in row.items()}
                          for row in tab.to_dict("records")],
                "candidates": {cv.candidate: cv.to_dict(starts=False) for cv in self.results}}


def choose_model(logs, candidates: Sequence[Candidate] | None = None, *, folds="loro", lpp: float | None = None,
                 wind: str | None = None, current: str | None = None, fit_options: dict | None = None,
                 horizons=(10.0, 30.0, 60.0), start_every: float = 5.0, workers: int | None = 1,
                 scheduler: str | None = None, engine=None, progress: bool = False) -> ModelChoice:
    """Cross-validate every candidate (default :func:`candidates_for` the logs) and rank them by the rule of
    docs/choosing_a_model.md.  All folds of all candidates are members of one map over the engine."""
    logs, plan, copies, names = _prepare(logs, lpp, folds)
    cands, why = candidates_for(logs, lpp=lpp, wind=wind, current=current, given=candidates)
    if any(c.wind for c in cands):
        true_wind_at_edge(logs, what="--wind")
    per = [_specs(c, plan, lpp, fit_options, horizons, start_every) for c in cands]
    flat = [s for ss in per for s in ss]
    eng, own = _engine(engine, workers, scheduler, progress)
    try:
        outs = _map(eng, flat, "folds x candidates")
    finally:
        if own:
            eng.close()
    settings = {"folds": folds, "n_folds": len(plan), "horizons": list(horizons or ()), "start_every": start_every,
                "fit_options": _jsonable(fit_options), "runs": names, "engine": eng.describe()}
    results, i = [], 0
    for c, ss in zip(cands, per):
        results.append(_collect(c, outs[i:i + len(ss)], ss, copies, settings))
        i += len(ss)
    return ModelChoice(results, list(cands), why)
