"""Validate an identified model against measured manoeuvres.

For each trial log the model is **replayed** with the log's recorded inputs
(rudder ``delta``, propeller ``n``) from the log's initial state
(:func:`shipid.simulate.replay`), and compared with the measurement in two
ways:

* per-channel RMSE / NRMSE and the RMS track error
  (:func:`shipid.simulate.replay_errors`);
* the standard-manoeuvre metrics (ITTC 7.5-04-02-01 / IMO MSC.137(76)) of the
  measured run and of the replay, computed by the same function
  (:func:`shipid.manoeuvres.metrics`), and their differences.

The replay is *open loop*: the rudder moves when it moved in the log, so a
zigzag's predicted overshoot is the predicted heading peak minus the nominal
switch angle of the measured run (the rudder is not re-triggered by the
predicted heading).  That is what isolates the model error from the
helmsman's/autopilot's timing.  A closed-loop standard manoeuvre of the model
is :func:`shipid.manoeuvres.zigzag` / ``shipid simulate``.

Positions refer to the logged point for both the measurement and the replay
(the replay starts at the logged position).  Units in the output: SI and
radians for RMSE values, metrics as documented in :mod:`shipid.manoeuvres`
(lengths over L, angles in degrees).
"""
from __future__ import annotations

import math
import os
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from ..identify.result import model_from
from ..logs import read_log, TrialLog
from ..manoeuvres import metrics as manoeuvre_metrics, ship_info, standard_manoeuvre, steady_turn
from ..manoeuvres.run_metrics import reported_steady_turn
from ..models.base import Model
from ..results import ResultMixin
from ..simulate import SimulationResult, replay, replay_errors

__all__ = ["validate", "validate_logs", "validate_one", "LogValidation", "resolve_model", "load_logs", "DIFF_EXCLUDE",
           "DURATION_MULTIPLE", "STANDARD_METRICS"]

#: Metric keys not differenced (settings of the run rather than predictions).
DIFF_EXCLUDE = ("lpp", "execute_time", "rudder_deg", "switch_deg")
#: A closed-loop standard manoeuvre matching a measured run runs until its metrics exist -- a zigzag to its second
#: overshoot (the fifth rudder execute), a turn to 540 deg of heading -- for at most this many times the measured
#: run's duration after its execute (never less than the simulator's own limit: 80 L/U for a zigzag, 60 L/U for a
#: turn).  A model that needs longer is off by more than every goal; the metric is then missing with the reason
#: (``standard_missing``).  The rule of docs/choosing_a_model.md.
DURATION_MULTIPLE = 3.0
#: The metrics of a standard manoeuvre whose absence in the closed-loop prediction is reported (when measured).
STANDARD_METRICS = {"turning": ("advance_L", "tactical_diameter_L"), "zigzag": ("overshoot1_deg", "overshoot2_deg")}


@dataclass
class LogValidation(ResultMixin):
    """Replay of one log and its comparison with the measurement.

    Attributes
    ----------
    log : TrialLog
    simulation : SimulationResult
        The replay (states on the log's time grid).
    errors : DataFrame
        :func:`shipid.simulate.replay_errors` (rows per channel and ``track``).
    measured, predicted : TurningMetrics, ZigzagMetrics or None
        None where the metrics could not be computed (reason in ``notes``).
    lpp : float or None
        Ship length [m] used for the metrics.
    rudder_sign : float
        Factor applied to the logged rudder angle before the replay.
    notes : list of str
    success : bool
        True when the replay stayed finite and both metric sets exist
        (or neither applies).
    """

    log: Any
    simulation: SimulationResult
    errors: pd.DataFrame
    measured: Any = None
    predicted: Any = None
    lpp: float | None = None
    rudder_sign: float = 1.0
    model_lpp: float | None = None
    standard: Any = None
    standard_settings: dict = field(default_factory=dict)
    notes: list = field(default_factory=list)
    steady_measured: Any = None
    steady_predicted: Any = None
    standard_missing: list = field(default_factory=list)

    @property
    def success(self) -> bool:
        return bool(self.simulation.success) and (self.measured is None) == (self.predicted is None)

    @property
    def message(self) -> str:
        """One line: the replay's outcome and the notes."""
        head = f"log '{getattr(self.log, 'name', 'log')}': " + (self.manoeuvre or "no standard manoeuvre") + "; "
        head += "replay finished" if self.simulation.success else f"replay failed: {self.simulation.message}"
        return "; ".join([head] + list(self.notes))

    @property
    def manoeuvre(self) -> str | None:
        return None if self.measured is None else self.measured.manoeuvre

    def summary(self) -> pd.DataFrame:
        """The manoeuvre metrics as logged (``measured``), in the replay of the logged inputs (``replay``)
        and in the model's own closed-loop manoeuvre (``closed_loop``), one row per metric, with
        ``replay - measured``; a log that is no standard manoeuvre gives its replay errors instead
        (:attr:`errors`: ``rmse``, ``nrmse``, ``n_samples`` per channel, SI units and radians)."""
        if self.measured is None:
            return self.errors.copy()
        cols = {"measured": self.measured, "replay": self.predicted, "closed_loop": self.standard}
        dicts = {k: (v.to_dict() if v is not None else {}) for k, v in cols.items()}
        keys = [k for k, v in dicts["measured"].items()
                if k not in DIFF_EXCLUDE and isinstance(v, (int, float)) and not isinstance(v, bool)]
        out = pd.DataFrame({c: [d.get(k) for k in keys] for c, d in dicts.items()}, index=pd.Index(keys, name="metric"),
                           dtype=float)
        out["replay - measured"] = out["replay"] - out["measured"]
        return out

    def _html_title(self) -> str:
        return f"Validation on '{getattr(self.log, 'name', 'log')}'"

    def _key_numbers(self) -> dict:
        k = {"model": self.simulation.model.name, "manoeuvre": self.manoeuvre or "none"}
        if "track" in self.errors.index:
            k["track RMSE [m]"] = float(self.errors.loc["track", "rmse"])
        return k

    def to_pandas(self) -> pd.DataFrame:
        """The replay's time series (states and inputs, indexed by time; see :meth:`SimulationResult.to_pandas`)."""
        return self.simulation.to_pandas()

    def plot(self, ax=None):
        """The measured log under the replay, one axes per state and input (angles in degrees); returns the axes."""
        return self.simulation.plot(ax=ax)

    def difference(self, other: str = "predicted") -> dict:
        """``predicted - measured`` (or ``standard - measured``) for every numeric metric both have
        (``None`` where either is missing)."""
        o = getattr(self, other)
        if self.measured is None or o is None:
            return {}
        m, p = self.measured.to_dict(), o.to_dict()
        out = {}
        for k, mv in m.items():
            if k in DIFF_EXCLUDE or isinstance(mv, (bool, str, dict)) or k not in p:
                continue
            pv = p[k]
            if (mv is None or isinstance(mv, (int, float))) and (pv is None or isinstance(pv, (int, float))):
                out[k] = None if (mv is None or pv is None) else float(pv) - float(mv)
        return out

    def steady_summary(self) -> dict:
        """The ``steady_turn`` entry: ``measured``, ``predicted`` (the replay's, over the same hold) and
        ``difference`` (predicted - measured of the diameter, speed and time per circle); empty when none."""
        if self.steady_measured is None:
            return {}
        m = self.steady_measured.to_dict()
        p = self.steady_predicted.to_dict() if self.steady_predicted is not None else {}
        keys = ("steady_diameter_L", "steady_speed", "time_360_s")
        diff = {k: (p[k] - m[k] if p.get(k) is not None and m.get(k) is not None else None) for k in keys} if p else {}
        return {"measured": m, "predicted": p, "difference": diff}

    def to_dict(self) -> dict:
        """JSON-able summary: ``file``, ``manoeuvre``, ``measured``, ``predicted``, ``difference``,
        ``rmse``, ``nrmse`` (per channel, SI units / radians), ``track_rmse_m``, ``replay`` and ``notes``."""
        err = self.errors
        chans = [c for c in err.index if c != "track"]
        rmse = {c: _num(err.loc[c, "rmse"]) for c in chans}
        nrmse = {c: _num(err.loc[c, "nrmse"]) for c in chans}
        track = _num(err.loc["track", "rmse"]) if "track" in err.index else None
        path = getattr(self.log, "path", None)
        return {
            "file": str(path) if path is not None else getattr(self.log, "name", "log"),
            "name": getattr(self.log, "name", None),
            "sha256": getattr(self.log, "sha256", None),
            "manoeuvre": self.manoeuvre,
            "lpp": self.lpp,
            "measured": self.measured.to_dict() if self.measured is not None else {},
            "predicted": self.predicted.to_dict() if self.predicted is not None else {},
            "difference": self.difference(),
            "rmse": rmse,
            "nrmse": nrmse,
            "rmse_units": {c: self.simulation.model.units.get(c, "") for c in chans},
            "track_rmse_m": track,
            "standard": ({**self.standard.to_dict(), "settings": dict(self.standard_settings)}
                         if self.standard is not None else {}),
            "standard_difference": self.difference("standard"),
            "steady_turn": self.steady_summary(),
            "standard_missing": [dict(m) for m in self.standard_missing],
            "replay": {"success": bool(self.simulation.success), "message": self.simulation.message,
                       "rudder_sign": self.rudder_sign, "model_lpp": self.model_lpp,
                       "n_samples": int(self.simulation.t.size)},
            "success": self.success,
            "notes": list(self.notes),
        }


def _num(v) -> float | None:
    try:
        v = float(v)
    except (TypeError, ValueError):
        return None
    return v if math.isfinite(v) else None


# ----------------------------------------------------------------------------- inputs
def _check_substeps(substeps) -> None:
    if isinstance(substeps, bool) or not isinstance(substeps, (int, np.integer)) or substeps < 1:
        raise ValueError(f"substeps must be a whole number >= 1 (RK4 steps per log sample), got {substeps!r}")


def resolve_model(result_or_model) -> tuple[Model, Any]:
    """A model (and the fit result, if any) from a fit result, its JSON, a path to it, or a model.

    Parameters
    ----------
    result_or_model : FitResult, dict, str, os.PathLike or Model
        A result (or the path of its JSON), a model, or a registered model's name with an optional
        parameter set (``"mmg:kvlcc2"``).  A result JSON may carry ``"model_options"`` (keyword arguments of the model class, e.g.
        MMG particulars ``{"lpp": 320}``), at top level or under ``"extra"``.

    Returns
    -------
    (Model, FitResult or None)
    """
    looks_like_file = isinstance(result_or_model, (str, os.PathLike)) and (
        Path(result_or_model).suffix.lower() == ".json" or os.sep in str(result_or_model))
    if looks_like_file and not Path(result_or_model).is_file():  # else a registered model name[:set]
        raise FileNotFoundError(f"{result_or_model}: no such result file; run `shipid fit` first or check the path")
    return model_from(result_or_model)


def load_logs(logs, *, lpp: float | None = None) -> list:
    """TrialLogs from paths (read with :func:`shipid.logs.read_log`) or TrialLog objects."""
    if isinstance(logs, (str, os.PathLike, TrialLog)):
        logs = [logs]
    out = []
    for lg in logs:
        if isinstance(lg, (str, os.PathLike)):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", UserWarning)  # gap notes: the log summary reports them
                lg = read_log(lg, lpp=lpp)
        elif not hasattr(lg, "data"):
            raise ValueError(f"logs: expected file paths or TrialLog objects, got {type(lg).__name__}")
        out.append(lg)
    if not out:
        raise ValueError("no logs given: pass at least one trial log")
    return out


def _model_lpp(model: Model) -> float | None:
    return ship_info(model).get("lpp")


def _for_length(model: Model, lpp: float | None, notes: list) -> Model:
    """Froude-scale a model that knows its length (``scaled``) to the log's length."""
    ml = _model_lpp(model)
    if lpp is None or ml is None or abs(ml / lpp - 1.0) < 1e-9:
        return model
    if hasattr(model, "scaled"):
        notes.append(f"model Froude-scaled from Lpp {ml:g} m to the log's {lpp:g} m")
        return model.scaled(lpp)
    notes.append(f"model is for Lpp {ml:g} m but the log's ship has {lpp:g} m and the model cannot be rescaled; "
                 "replayed as it is")
    return model


# ----------------------------------------------------------------------------- main
def validate_one(model: Model, log, *, lpp: float | None = None, rudder_sign: float = 1.0,
                 substeps: int = 2, closed_loop: bool = True, zigzag_angles=None,
                 initial: dict | None = None) -> LogValidation:
    """Replay ``model`` on one TrialLog and compare; see :func:`validate`."""
    notes: list[str] = []
    name = getattr(log, "name", "log")
    ship = getattr(log, "ship", None)
    L = lpp if lpp is not None else getattr(ship, "lpp", None)
    if L is None:
        L = _model_lpp(model)
        if L is not None:
            notes.append(f"ship length not in the log: used the model's Lpp {L:g} m")
    if L is not None and not L > 0:
        raise ValueError(f"lpp must be a positive length in metres, got {L}")
    m = _for_length(model, L, notes)
    if rudder_sign not in (1, -1, 1.0, -1.0):
        raise ValueError(f"rudder_sign must be +1 or -1, got {rudder_sign}")
    data = log.data
    if rudder_sign == -1 and "delta" in data.columns:
        data = data.assign(delta=-data["delta"])
        notes.append("logged rudder angle multiplied by -1 for the replay (opposite sign convention)")
    with warnings.catch_warnings():  # a diverging replay is reported in the notes and by success=False
        warnings.simplefilter("ignore", RuntimeWarning)
        sim = replay(m, data, substeps=substeps, initial=initial)
        errors = replay_errors(sim, data)
    if not sim.success:
        notes.append(f"replay: {sim.message}; no RMSE or predicted metrics")
        errors = errors.assign(rmse=np.nan, nrmse=np.nan)
    res = LogValidation(log=log, simulation=sim, errors=errors, lpp=L, rudder_sign=float(rudder_sign),
                        model_lpp=_model_lpp(m), notes=notes)
    if L is None:
        notes.append("no ship length (pass lpp= / --lpp): manoeuvre metrics skipped")
        return res
    try:
        rud, chk = zigzag_angles if zigzag_angles is not None else (None, None)
        res.measured = manoeuvre_metrics(log, lpp=L, name=name, rudder_deg=rud, check_deg=chk)
    except ValueError as exc:
        notes.append(f"measured metrics not available: {exc}")
        _steady(log, sim, L, rudder_sign, res)
        return res
    if closed_loop:
        _standard(m, log, res)
    if not sim.success:
        return res
    pred = sim.to_pandas().reset_index()
    if rudder_sign == -1:
        pred["delta"] = -pred["delta"]  # back to the log's convention: same rudder history as measured
    try:
        res.predicted = manoeuvre_metrics(
            pred, lpp=L, kind=res.measured.manoeuvre, name=f"replay of {name}",
            switch_deg=getattr(res.measured, "switch_deg", None) if res.measured.manoeuvre == "zigzag" else None)
    except ValueError as exc:
        notes.append(f"predicted metrics not available: {exc}")
        return res
    side_m = getattr(res.measured, "side", None) or getattr(res.measured, "first_side", None)
    side_p = getattr(res.predicted, "side", None) or getattr(res.predicted, "first_side", None)
    if side_m and side_p and side_m != side_p:
        notes.append(f"the replay turns to {side_p}, the log to {side_m}: the log's rudder sign convention is "
                     "probably opposite to the model's; use rudder_sign=-1 (--rudder-sign -1)")
    return res


def _steady(log, sim, L: float, rudder_sign: float, res: LogValidation) -> None:
    """A run that is not a standard manoeuvre but holds its rudder through a turn (a turning run started from rest):
    the steady turn of its longest hold (:func:`~shipid.manoeuvres.run_metrics.steady_turn`), measured and in the
    replay of the same inputs; nothing (and no note) when the run holds no turning rudder angle or its hold turns
    less than :data:`~shipid.manoeuvres.run_metrics.STEADY_REPORT_DEG`."""
    st = reported_steady_turn(log, lpp=L, name=getattr(log, "name", None))
    if st is None:  # no hold, or a brief one (random, berthing, zigzag runs): not a turn
        return
    res.steady_measured = st
    if not sim.success:
        return
    pred = sim.to_pandas().reset_index()
    if rudder_sign == -1:
        pred["delta"] = -pred["delta"]
    try:
        res.steady_predicted = steady_turn(pred, lpp=L, name=f"replay of {getattr(log, 'name', 'log')}")
    except ValueError as exc:
        res.notes.append(f"steady turn of the replay not available: {exc}")


def standard_time_limit(measured, log, lpp: float) -> tuple[float, float]:
    """``(t_max, duration)`` [s] of the closed-loop manoeuvre matching a measured run: the execute (2 L/U, the
    simulators' default) plus the larger of the simulator's own limit (80 L/U zigzag, 60 L/U turn) and
    :data:`DURATION_MULTIPLE` times the measured run's duration after its execute."""
    U = float(measured.approach_speed)
    t = np.asarray(getattr(log, "time", None) if hasattr(log, "time") else log["time"], dtype=float)
    te = float(getattr(measured, "execute_time", math.nan))
    duration = float(t[-1] - te) if (t.size and math.isfinite(te)) else float(t[-1] - t[0]) if t.size else 0.0
    own = (80.0 if measured.manoeuvre == "zigzag" else 60.0) * lpp / U
    return 2.0 * lpp / U + max(own, DURATION_MULTIPLE * duration), duration


def _missing_reason(kind: str, metric: str, met, t_max: float, duration: float, run_message: str) -> str:
    """Why the closed-loop manoeuvre has no ``metric`` (one line)."""
    within = f"within {t_max:.0f} s ({DURATION_MULTIPLE:g} times the measured run's {duration:.0f} s, or the simulator's limit)"
    if run_message and "t_max" not in run_message and "finished" not in run_message:
        return f"the prediction stopped: {run_message}"
    if kind == "turning":
        return f"the model's heading never changed by {90 if metric == 'advance_L' else 180} deg {within}"
    sw = getattr(met, "switch_deg", math.nan)
    msg = getattr(met, "message", "") or ""
    if "never reached the switch angle" in msg:
        return f"the model's heading deviation never reached the check angle {sw:g} deg {within}"
    if metric == "overshoot1_deg" or "third execute" in msg:
        return (f"the model's heading never came back through the check angle {sw:g} deg on the other side "
                f"{within}, so the zigzag has no {'first' if metric == 'overshoot1_deg' else 'second'} overshoot")
    return f"the model's heading never turned back after the third execute {within}, so there is no second overshoot"


def _standard(model: Model, log, res: LogValidation) -> None:
    """Closed-loop standard manoeuvre of the model matching the measured one (see :func:`validate`); a metric the
    run measured but the prediction does not reach is listed in ``res.standard_missing`` with the reason."""
    m = res.measured
    ship = getattr(log, "ship", None)
    rate = getattr(ship, "rudder_rate", None) or ship_info(model).get("rudder_rate")
    side = m.side if m.manoeuvre == "turning" else m.first_side
    settings = {"rudder_deg": abs(float(m.rudder_deg)), "speed": float(m.approach_speed), "side": side,
                "rudder_rate_deg_s": None if rate is None else math.degrees(rate), "lpp": res.lpp}
    if m.manoeuvre != "turning":
        settings["switch_deg"] = float(m.switch_deg)
    t_max, duration = math.nan, math.nan
    try:
        t_max, duration = standard_time_limit(m, log, res.lpp)
        settings["t_max_s"] = t_max
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            run = standard_manoeuvre(model, m, rudder_rate=rate, lpp=res.lpp,
                                     t_max=t_max if math.isfinite(t_max) and t_max > 0 else None)
    except ValueError as exc:
        res.notes.append(f"closed-loop manoeuvre not available: {exc}")
        md = m.to_dict()
        if "never changed by" in str(exc) and math.isfinite(t_max):
            why = (f"the model's heading never changed by half the check angle {float(m.switch_deg):g} deg within "
                   f"{t_max:.0f} s ({DURATION_MULTIPLE:g} times the measured run's {duration:.0f} s, or the "
                   "simulator's limit)")
        else:
            why = f"the closed-loop manoeuvre could not be run: {exc}"
        res.standard_missing += [{"metric": k, "reason": why} for k in STANDARD_METRICS.get(m.manoeuvre, ())
                                 if _num(md.get(k)) is not None]
        return
    settings["n_rps"] = float(run.settings["n"].iloc[0]) if "n" in run.settings else None
    if not run.success:
        res.notes.append(f"closed-loop manoeuvre: {run.message}")
    res.standard, res.standard_settings = run.metrics[0], settings
    md, sd = m.to_dict(), res.standard.to_dict()
    # metrics reached only after the simulators' own limit (the prediction ran longer for them, by the rule above)
    own = (80.0 if m.manoeuvre == "zigzag" else 60.0) * res.lpp / float(m.approach_speed)
    times = {"advance_L": "time_90", "tactical_diameter_L": "time_180", "overshoot1_deg": "overshoot1_time",
             "overshoot2_deg": "overshoot2_time"}
    late = [k for k in STANDARD_METRICS.get(m.manoeuvre, ())
            if _num(sd.get(k)) is not None and (_num(getattr(res.standard, times[k], None)) or 0.0) > own]
    if late:
        settings["reached_after_simulator_limit"] = late
    for k in STANDARD_METRICS.get(m.manoeuvre, ()):
        if _num(md.get(k)) is not None and _num(sd.get(k)) is None:
            res.standard_missing.append({"metric": k, "reason": _missing_reason(m.manoeuvre, k, res.standard, t_max,
                                                                                duration, run.message)})


def validate_logs(result_or_model, logs, lpp: float | None = None, *, rudder_sign: float = 1.0,
                  substeps: int = 2, closed_loop: bool = True, zigzag_angles=None,
                  initial: dict | None = None) -> list[LogValidation]:
    """Replay a model on each log and compare; returns :class:`LogValidation` objects (see :func:`validate`)."""
    model, _ = resolve_model(result_or_model)
    return [validate_one(model, lg, lpp=lpp, rudder_sign=rudder_sign, substeps=substeps, closed_loop=closed_loop,
                         zigzag_angles=zigzag_angles, initial=initial) for lg in load_logs(logs, lpp=lpp)]


def validate(result_or_model, logs, lpp: float | None = None, *, rudder_sign: float = 1.0,
             substeps: int = 2, closed_loop: bool = True, zigzag_angles=None,
             initial: dict | None = None) -> list[dict]:
    """Validate a model against measured logs by replaying their recorded inputs.

    Parameters
    ----------
    result_or_model : FitResult, result JSON (dict or path) or Model
    logs : sequence of paths or TrialLogs (one path or log is accepted too)
    lpp : float, optional
        Ship length [m] for the metrics; default: each log's ship particulars, then the model's.
        A model with a ``scaled`` method (``mmg``) of another length is Froude-scaled to it.
    rudder_sign : {1, -1}
        Multiply the logged rudder angle by this before the replay (the MARIN KVLCC2 files use the
        opposite sign to the shipped models: pass -1).
    substeps : int
        RK4 steps per log sample interval.
    closed_loop : bool
        Also simulate the model's own standard manoeuvre matching the log (same side, rudder angle,
        switch angle, approach speed, the log's rudder rate when known; propeller rps solved for
        the approach speed; rudder reversed by the model's own heading) with
        :func:`shipid.manoeuvres.turning_circle` / :func:`~shipid.manoeuvres.zigzag`.  Its metrics are
        the ``standard`` entry -- the free-running prediction a trial would compare with.
    zigzag_angles : (rudder_deg, check_deg), optional
        Nominal rudder and check angles [deg] of the zigzag logs; either may be None.  By default both
        come from each log (the check angle from the heading deviation at its rudder reversals,
        :func:`shipid.manoeuvres.zigzag.infer_check_angle`), and the closed-loop zigzag is run with them.
    initial : dict, optional
        Start values of states no log carries, for the replay (:func:`shipid.simulate.replay`): e.g. a fit's
        ``settings["current_start"]`` for a model with current states (``shipid validate`` passes it).

    Returns
    -------
    list of dict, one per log, with keys ``file``, ``manoeuvre`` ("turning"/"zigzag"/None),
    ``measured`` and ``predicted`` (metric dicts of :mod:`shipid.manoeuvres`, including ``imo``),
    ``difference`` (predicted - measured per metric), ``standard`` and ``standard_difference``
    (closed-loop manoeuvre, see ``closed_loop``; ``standard.settings`` records how it was run), ``rmse`` / ``nrmse`` (per channel; SI units
    and radians, NRMSE relative to the measured range), ``track_rmse_m``, ``replay`` (success,
    message), ``success`` and ``notes``.
    """
    _check_substeps(substeps)
    return [v.to_dict() for v in validate_logs(result_or_model, logs, lpp, rudder_sign=rudder_sign,
                                               substeps=substeps, closed_loop=closed_loop,
                                               zigzag_angles=zigzag_angles, initial=initial)]
