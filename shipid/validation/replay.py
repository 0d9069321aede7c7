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
from ..simulate import SimulationResult, replay, replay_errors

__all__ = ["validate", "validate_logs", "validate_one", "LogValidation", "resolve_model", "load_logs", "DIFF_EXCLUDE"]

#: Metric keys not differenced (settings of the run rather than predictions).
DIFF_EXCLUDE = ("lpp", "execute_time", "rudder_deg", "switch_deg")


@dataclass
class LogValidation:
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

    @property
    def success(self) -> bool:
        return bool(self.simulation.success) and (self.measured is None) == (self.predicted is None)

    @property
    def manoeuvre(self) -> str | None:
        return None if self.measured is None else self.measured.manoeuvre

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
def resolve_model(result_or_model) -> tuple[Model, Any]:
    """A model (and the fit result, if any) from a fit result, its JSON, a path to it, or a model.

    Parameters
    ----------
    result_or_model : FitResult, dict, str, os.PathLike or Model
        A result JSON may carry ``"model_options"`` (keyword arguments of the model class, e.g.
        MMG particulars ``{"lpp": 320}``), at top level or under ``"extra"``.

    Returns
    -------
    (Model, FitResult or None)
    """
    if isinstance(result_or_model, (str, os.PathLike)) and not Path(result_or_model).is_file():
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


def _standard(model: Model, log, res: LogValidation) -> None:
    """Closed-loop standard manoeuvre of the model matching the measured one (see :func:`validate`)."""
    m = res.measured
    ship = getattr(log, "ship", None)
    rate = getattr(ship, "rudder_rate", None) or ship_info(model).get("rudder_rate")
    side = m.side if m.manoeuvre == "turning" else m.first_side
    settings = {"rudder_deg": abs(float(m.rudder_deg)), "speed": float(m.approach_speed), "side": side,
                "rudder_rate_deg_s": None if rate is None else math.degrees(rate), "lpp": res.lpp}
    if m.manoeuvre != "turning":
        settings["switch_deg"] = float(m.switch_deg)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            run = standard_manoeuvre(model, m, rudder_rate=rate, lpp=res.lpp)
    except ValueError as exc:
        res.notes.append(f"closed-loop manoeuvre not available: {exc}")
        return
    settings["n_rps"] = float(run.settings["n"].iloc[0]) if "n" in run.settings else None
    if not run.success:
        res.notes.append(f"closed-loop manoeuvre: {run.message}")
    res.standard, res.standard_settings = run.metrics[0], settings


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
    return [v.to_dict() for v in validate_logs(result_or_model, logs, lpp, rudder_sign=rudder_sign,
                                               substeps=substeps, closed_loop=closed_loop,
                                               zigzag_angles=zigzag_angles, initial=initial)]
