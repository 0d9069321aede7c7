"""The fit recipe: what the project's studies learned, as the default path from logs to a model.

:func:`fit_logs` fits any registered ship model to trial logs of any ship and scale in reported,
switchable steps (each one recorded in the result's ``settings["recipe"]``, with the reason):

0. **Repeated runs** (``drop_repeated=True``) -- a log whose every sample is a sample of another log (a trimmed
   copy of the same run: :func:`shipid.logs.overlap.repeated_samples`) is dropped, as it would count that run
   twice; logs that share only part of their samples are kept with a warning.  Recorded only when found.
   A fit whose logs never get under way (:data:`FN_UNDER_WAY`) stops here with the reason.
1. **Ship** -- the logs' particulars (one ship; its Lpp) fix the scale of everything below; the start
   model is built at that length (a named parameter set is Froude-scaled to it), so a start never
   comes from another ship's scale.
2. **Sampling step** (``dt="auto"``) -- every k-th sample, k the largest with ``k * dt_log`` at most
   1/:data:`SAMPLES_PER_TAU` of the fastest time constant of the start model's sway-yaw-surge
   dynamics linearised at the logs' approach speed (the eigenvalues of ``jac_x``); never finer than
   the log; a model may set its own rate (``recipe_defaults.samples_per_tau``: ``mmg`` 1/50, chosen by
   leave-one-run-out within the KVLCC2 training runs).  (For the MARIN KVLCC2 runs: tau = 13.7 s,
   dt_log = 0.135 s -> k = 2 for ``mmg`` (4 at 25), every 3rd sample for ``response-nl``
   (tau = 10.7 s); for the 4.36 m KCS logs: tau = 0.83 s -> every sample.)
2b. **Linear range** (``max_drift_deg="auto"``) -- a model whose sway and yaw equations are linear in
   ``v`` and ``r`` (:func:`linear_sway_yaw`: ``kcs-response``) holds for small drift only: linear hull
   derivatives describe the forces up to drift angles of about :data:`LINEAR_DRIFT_DEG`, beyond which
   cross-flow drag (``v|v|``, ``r|r|``) dominates.  Each log is then used until its drift angle
   ``atan2(|v|, u)`` first exceeds that (:func:`linear_window`).  On the MARIN KVLCC2 training runs
   (tc+-35 reach 23-25 deg of drift, zz+-10 stay below 9 deg) the whole turning circles turn the linear
   yaw equation over (c2 > 0, c3 < 0, at every sampling step, input hold, gate and start tried), the
   window gives c2 = -0.055, c3 = +0.00063 (docs/identification.md).
3. **Rudder neutral angle** (``neutral=True``, models with a ``delta0`` parameter) -- the mean rudder
   of the straight approach segments of all logs (:func:`neutral_rudder_angle`: from each log's start
   until the rudder first departs, kept only when the heading changed by less than
   ``max_heading_change_deg`` over it), fixed in the EKF stage and freed in the refinement.
4. **Staged start values** (``start="staged"``) -- ``response-nl``: first the seed's 16 terms (a
   ``kcs-response`` EKF fit at the same scale, equation-error started), then all terms with the
   non-linear ones started at 0; ``kcs-response`` and ``mmg``: the (scaled) parameter set.  A propeller
   rate that is constant over all logs makes ``a1, a8, a9`` collinear: ``a8`` is then fixed at 0
   (the identifier's own identifiability note says why).
5. **EKF stage** -- :class:`~shipid.identify.identifier.EKFIdentifier` on the sampled logs.
6. **Refinement** (``refine="auto" | "metrics" | "output-error" | None``) -- an output-error fit of the
   same parameters started from the EKF (:class:`~shipid.identify.batch.OutputErrorRefiner`) on the
   logs resampled to one grid of twice the EKF step (:func:`common_grid`; the runs replay as one batch),
   each channel divided by its spread over the logs and each log weighted by 1/(its samples), so every
   run counts once.  ``"metrics"`` adds the training logs' own standard-manoeuvre errors of the model's
   closed-loop manoeuvres (:func:`metric_residuals`: tactical diameter of turns, first/second overshoot
   of zigzags, over :data:`METRIC_TOL`, times :data:`METRIC_WEIGHT`).  Stopping: ``scipy.optimize.least_squares``' tolerance tests
   (``xtol = ftol = 1e-8``) within ``max_nfev`` evaluations; a refinement that stops on the limit says
   so (``success`` False).  ``"auto"``: :data:`AUTO_REFINE` (``"metrics"`` at weight 0.1, chosen by
   leave-one-run-out within the KVLCC2 training runs -- one hull: a choice made on one data set) when the
   logs hold turning circles and zigzags, else no refinement.
6b. **Physical damping** (``physical_damping=True``) -- when the refined model's own sway or yaw damping,
   ``d(dv/dt)/dv`` and ``d(dr/dt)/dr`` from its Jacobian, is positive on more than 1 % of the logged states
   or at rest (:func:`~shipid.identify.diagnostics.damping_check`), the refinement is solved again from the
   start with both kept below ``-DAMPING_MARGIN * U/L`` there, as an exterior penalty
   (:func:`~shipid.identify.diagnostics.damping_penalty`).  Scaling a logged motion's u, v, r together
   towards rest keeps the drift angle and the turning radius; for the response models the own damping is
   linear in that scale, so the logged states and the rest state cover every slower copy of the logged
   motions.  A fit whose own damping is negative is not touched.  On the MARIN KVLCC2 training runs the
   unconstrained ``response-nl`` refinement had b1 +0.0177 and positive sway damping on 17 % of the
   states (self-excited sway in the slow part of the turns); constrained: b1 < 0, 0 % (docs/validation.md).

Only the logs passed in enter any step: held-out runs never do.
"""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from .._blas import one_blas_thread
from ..logs.overlap import drop_contained, repeated_samples
from ..models import get_model, Model, model_class
from ..results import ResultMixin, coefficient_table, plot_coefficients, verdict_grade
from .diagnostics import damping_check
from .identifier import EKFIdentifier
from .refine import AUTO_REFINE, METRIC_TOL, METRIC_WEIGHT, REFINE_MODES, _kinds, metric_residuals, refine_fit
from .sampling import (LINEAR_DRIFT_DEG, MIN_WINDOW_SAMPLES, SAMPLES_PER_TAU, _every, _log_step, every_kth,
                       fastest_time_constant,
                       _lpp_of, choose_sampling, common_grid, linear_sway_yaw, linear_window)
from .verdict import verdict_from_recipe

__all__ = ["fit_logs", "RecipeFit", "neutral_rudder_angle", "approach_segment", "choose_sampling", "common_grid",
           "linear_sway_yaw", "linear_window", "LINEAR_DRIFT_DEG",
           "metric_residuals", "refine_fit", "METRIC_TOL", "METRIC_WEIGHT", "SAMPLES_PER_TAU", "REFINE_MODES", "AUTO_REFINE"]

#: Froude exponents of the process noise per state (std per sqrt(s)) when a model's recipe default is scaled to
#: the logs' Lpp: x, y as L^0.75, psi as L^-0.25, u, v as L^0.25, r as L^-0.75 (a velocity per sqrt of a time).
_FROUDE_EXP = {"x": 0.75, "y": 0.75, "psi": -0.25, "u": 0.25, "v": 0.25, "r": -0.75}


@dataclass
class RecipeFit(ResultMixin):
    """What :func:`fit_logs` did and made.

    Attributes
    ----------
    ekf : EKFIdentifier  the fitted EKF stage
    refiner : OutputErrorRefiner or None  the refinement (None when not refined)
    steps : list of dict  one per recipe step: ``step``, ``value``, ``reason``
    logs : list of TrialLog  the logs as the EKF used them (sampled)
    free_in_refine : list of str  parameters fixed in the EKF stage and freed in the refinement
    lpp : float  the ship length the fit is at [m]
    metric_weight : float or None  weight of the metric residuals of a ``"metrics"`` refinement (else None)
    """

    ekf: object
    refiner: object = None
    steps: list = field(default_factory=list)
    logs: list = field(default_factory=list)
    free_in_refine: list = field(default_factory=list)
    lpp: float | None = None
    metric_weight: float | None = None
    #: the logs as given (before the recipe's stride and linear range): the verdict checks their channels
    source_logs: list = field(default_factory=list)
    #: ``{"log_step": s, "time_constant": s}`` of the logs and the start model (the verdict's sampling rule)
    sampling: dict = field(default_factory=dict)

    @property
    def final(self):
        """The last stage that ran (the refiner, else the EKF)."""
        return self.refiner if self.refiner is not None else self.ekf

    def __getattr__(self, key):
        # the fitted attributes of the last stage (coef_, coef_std_, success_, message_, logs_, ...)
        if key.endswith("_") and not key.startswith("_"):
            return getattr(self.final, key)
        raise AttributeError(f"RecipeFit has no attribute {key!r}")

    @property
    def success(self) -> bool:
        """True when the EKF stage and the refinement (when run) both succeeded; the result JSON says the same."""
        return bool(self.ekf.success_) and (self.refiner is None or bool(self.refiner.success_))

    @property
    def success_(self) -> bool:
        """The same as :attr:`success` (one truth for the whole recipe, not only its last stage)."""
        return self.success

    @property
    def message(self) -> str:
        """The last stage's message; when the EKF stage failed under a refinement, that first."""
        if self.refiner is not None and not self.ekf.success_:
            return f"EKF stage failed ({self.ekf.message_}); refinement: {self.refiner.message_}"
        return self.final.message_

    @property
    def message_(self) -> str:
        return self.message

    @property
    def verdict(self):
        """The fit's graded verdict (:func:`shipid.identify.verdict.verdict_from_recipe`), as its result carries it."""
        v = self.__dict__.get("_verdict")
        return v if v is not None else self.result().verdict

    def summary(self) -> pd.DataFrame:
        """The last stage's coefficient table (value, std, relative std, 95 % interval; ``attrs["verdict"]``
        the verdict grade when there is one)."""
        f = self.final
        tab = self.ekf.summary() if self.refiner is None else coefficient_table(f.coef_[f.estimated_], f.coef_std_[f.estimated_])
        grade = verdict_grade(self)
        if grade is not None:
            tab.attrs["verdict"] = grade
        return tab

    def recipe(self) -> pd.DataFrame:
        """The recipe's steps, one row each: ``step``, ``value``, ``reason``."""
        return pd.DataFrame([{"step": s["step"], "value": s["value"], "reason": s["reason"]} for s in self.steps],
                            columns=["step", "value", "reason"])

    def to_pandas(self) -> pd.DataFrame:
        """The EKF stage's smoothed states of every log (see :meth:`EKFIdentifier.to_pandas`)."""
        return self.ekf.to_pandas()

    def plot(self, ax=None):
        """Each estimated coefficient's 95 % interval relative to its value (last stage); returns the axes."""
        return plot_coefficients(self.summary(), ax, title=f"{self.ekf.model.name} (recipe)")

    def _html_title(self) -> str:
        return f"Recipe fit of '{self.ekf.model.name}'" + (" (EKF + refinement)" if self.refiner is not None else "")

    def _key_numbers(self) -> dict:
        return {"logs": len(self.logs) or len(getattr(self.final, "logs_", [])), "Lpp [m]": self.lpp,
                "recipe steps": len(self.steps)}

    def to_model(self):
        return self.final.to_model()

    def result(self):
        """The :class:`~shipid.identify.result.FitResult` of the last stage, its settings holding the recipe."""
        res = self.final.result()
        res.settings["recipe"] = [dict(s) for s in self.steps]
        start = current_start(self.ekf)
        if start is not None:
            res.settings["current_start"] = start
        if self.metric_weight is not None:
            res.settings["metric_weight"] = float(self.metric_weight)
        if self.refiner is not None:
            res.settings["ekf_stage"] = {"success": bool(self.ekf.success_), "message": self.ekf.message_,
                                         "coef": {k: float(v) for k, v in self.ekf.coef_.items()}}
            # the verdict `shipid fit` exits on is the EKF stage's (the refiner has no innovations): the result
            # JSON carries it where the CLI's epilog says, marked as that stage's
            verdict = getattr(self.ekf, "diagnostics_", {}).get("consistency")
            if verdict is not None and "consistency" not in res.diagnostics:
                res.diagnostics["consistency"] = {**verdict, "stage": "ekf"}
            if not self.ekf.success_:
                res.success = False
                res.message = f"EKF stage failed ({self.ekf.message_}); refinement: {res.message}"
        if self.logs:
            res.diagnostics["damping"] = damping_check(self.final.to_model(), self.logs)
        res.verdict = self.__dict__["_verdict"] = verdict_from_recipe(self, res)
        return res

    def __str__(self) -> str:
        """The recipe's steps as text, one ``recipe: step: value -- reason`` line each."""
        return "\n".join(f"recipe: {s['step']}: {s['value']} -- {s['reason']}" for s in self.steps)


def _sampling_check(model, logs) -> dict:
    """The logs' sample interval and the start model's fastest time constant at their speed (empty when
    unknown): the verdict calls a log that samples the ship's fastest motion fewer than twice decimated."""
    try:
        tau = fastest_time_constant(model, logs)[0]
        return {"log_step": float(_log_step(logs)), "time_constant": float(tau)}
    except (ValueError, np.linalg.LinAlgError, ZeroDivisionError):
        return {}


def current_start(ekf):
    """The start current for predictions of a log the fit has not seen: the mean of the fitted logs' smoothed
    current at their first sample (``{"cx", "cy", "n_logs", "reason"}``), or None for a model without current
    states.  As the Esso Osaka study predicts its held-out runs (``current_start="mean"``)."""
    states = getattr(ekf, "states_", None)
    if not states or "cx" not in getattr(ekf.model, "state_names", ()):
        return None
    c = np.array([[float(st["cx"].iloc[0]), float(st["cy"].iloc[0])] for st in states])
    c = c[np.all(np.isfinite(c), axis=1)]
    if not c.size:
        return None
    return {"cx": float(c[:, 0].mean()), "cy": float(c[:, 1].mean()), "n_logs": int(len(c)),
            "reason": f"mean of the {len(c)} fitted logs' estimated current at their start: the start current of "
                      "an open-loop prediction of a log the fit has not seen"}


# ----------------------------------------------------------------------------- the steps
def approach_segment(log, departure_deg: float = 1.0, min_samples: int = 3,
                     max_heading_change_deg: float = 2.0) -> slice | None:
    """The straight approach of a log: from its start until the rudder first departs by more than
    ``departure_deg`` from its first value, if at least ``min_samples`` long and the heading changed by
    less than ``max_heading_change_deg`` over it (else None)."""
    d = np.asarray(log["delta"], dtype=float)
    moved = np.flatnonzero(np.abs(d - d[0]) > math.radians(departure_deg))
    end = int(moved[0]) if moved.size else d.size
    if end < min_samples:
        return None
    if "psi" in log.channels:
        psi = np.unwrap(np.asarray(log["psi"], dtype=float)[:end])
        ok = psi[np.isfinite(psi)]
        if ok.size and np.ptp(ok) > math.radians(max_heading_change_deg):
            return None
    return slice(0, end)


def neutral_rudder_angle(logs, departure_deg: float = 1.0, min_samples: int = 3,
                         max_heading_change_deg: float = 2.0) -> tuple[float, int]:
    """Rudder angle [rad] that holds the ship straight: the mean rudder over the straight approach
    segments (:func:`approach_segment`) of all ``logs``, pooled sample by sample; and how many logs had
    one.  ValueError when none has."""
    vals = []
    for lg in logs:
        seg = approach_segment(lg, departure_deg, min_samples, max_heading_change_deg)
        if seg is not None:
            vals.append(np.asarray(lg["delta"], dtype=float)[seg])
    if not vals:
        raise ValueError("no log has a straight approach of at least "
                         f"{min_samples} samples before the rudder moves: the neutral rudder angle is unknown")
    v = np.concatenate(vals)
    return float(np.nanmean(v)), len(vals)




FN_UNDER_WAY = 0.01


def _check_under_way(logs, L: float) -> None:
    """ValueError when no log's ship gets under way (its largest speed below :data:`FN_UNDER_WAY`): there is no
    manoeuvre to identify (a moored or drifting ship), and the filter would only diverge.  The speed is
    hypot(u, v), else the track's (whose position noise can only make it larger: no false refusal)."""
    top = 0.0
    for lg in logs:
        d = lg.data
        if "u" in d.columns:
            U = np.hypot(d["u"].to_numpy(float), d["v"].to_numpy(float) if "v" in d.columns else 0.0)
        elif {"x", "y"} <= set(d.columns) and len(d) > 1:
            U = np.hypot(np.diff(d["x"].to_numpy(float)), np.diff(d["y"].to_numpy(float))) / np.diff(
                d["time"].to_numpy(float))
        else:
            return  # nothing to judge by
        if np.isfinite(U).any():
            top = max(top, float(np.nanmax(U)))
    fn = top / math.sqrt(9.81 * L)
    if fn < FN_UNDER_WAY:
        raise ValueError(f"the ship is not under way in any log: its largest speed is {top:.3g} m/s (Froude number "
                         f"{fn:.2g} at Lpp {L:g} m, below {FN_UNDER_WAY:g}); there is no manoeuvre to identify -- give "
                         "logs in which the ship moves (check the speed channel's unit and the ship length)")




# ----------------------------------------------------------------------------- the recipe
def _start_model(model, params, L):
    if isinstance(model, Model):
        m = model
        ml = getattr(m, "lpp", None)
        if ml is not None and abs(ml / L - 1.0) > 1e-9 and hasattr(m, "scaled"):
            return m.scaled(L), f"the given model Froude-scaled from Lpp {ml:g} m to the logs' {L:g} m"
        return m, "the given model"
    cls = model_class(model)
    takes_lpp = "lpp" in cls.__init__.__code__.co_varnames
    m = get_model(model, params, **({"lpp": L} if takes_lpp else {}))
    what = f"parameter set '{params}'" if isinstance(params, str) else ("the default parameter set" if params is None
                                                                         else "the given coefficients")
    return m, f"{model}: {what}" + (f" at the logs' Lpp {L:g} m (Froude-scaled)" if takes_lpp else "")


def fit_logs(logs, model="mmg", params=None, *, lpp: float | None = None, estimate=None, fixed=None,
             start: str = "staged", neutral: bool = True, free_neutral: bool = True, estimate_neutral: bool = False,
             dt="auto",
             max_drift_deg="auto", refine: str | None = "auto", metric_weight: float | None = None,
             n_passes: int = 2, max_nfev: int = 60, tune_noise: bool = False, progress: bool = False,
             meas_std=None, ekf_options=None, hold_unresolved: bool = True, sign_bounds: bool = False,
             physical_damping: bool = True, start_defaults: bool | None = None, drop_repeated: bool = True,
             log=None) -> RecipeFit:
    """Fit ``model`` to ``logs`` with the project's recipe (module docstring: steps 0-6).

    Parameters
    ----------
    logs : sequence of TrialLog  the training logs (one ship); nothing else enters the fit
    model : str or Model  registered model name (or a model: its parameters are the start)
    params : str, mapping or None  start parameter set or coefficients (default: the model's default set)
    lpp : float, optional  ship length [m] (default: the logs' particulars)
    estimate, fixed : optional  as :class:`~shipid.identify.identifier.EKFIdentifier`; default
        the model's ``recipe_defaults`` (estimate / fixed) (plus ``a8`` at constant rpm, ``delta0`` below)
    start : {"staged", "given"}  staged start values (step 4) or the start model as it is
    neutral : bool  rudder neutral angle from the straight approaches (step 3), where the model has ``delta0``
    free_neutral : bool  free that angle again in the refinement (default) or keep it fixed
    estimate_neutral : bool  start from that angle and estimate it in the EKF stage too (default False: fixed there)
    dt : "auto", int or None  step 2: ``"auto"``; an int k: every k-th sample; None: every sample
    max_drift_deg : "auto", float or None  step 2b: ``"auto"`` = :data:`LINEAR_DRIFT_DEG` for models linear in
        v and r (:func:`linear_sway_yaw`), else every sample; a number [deg]: that window for any model; None: off
    refine : {"auto", "metrics", "output-error", None}  step 6
    n_passes, tune_noise, progress, meas_std : passed to the EKF
    ekf_options : dict, optional  further keyword arguments of the EKF identifier (e.g. ``input_hold``, ``gate``)
    max_nfev : int  evaluation limit of the refinement
    metric_weight : float, optional  weight of the metric residuals of ``refine="metrics"`` (:func:`refine_fit`)
    hold_unresolved : bool  step 6's identifiable subset (:func:`refine_fit`; default True)
    sign_bounds : bool  step 6 keeps the model's dissipative coefficients <= 0 (:func:`refine_fit`; default False)
    physical_damping : bool  step 6 keeps the model's own sway and yaw damping negative along the logs
        (:func:`refine_fit`; default True)
    start_defaults : bool, optional  apply the model's ``recipe_defaults.start`` to the start model; default: when ``model`` is
        a name and ``params`` None (a model object or given parameters are the start the caller wants; ``shipid
        fit`` passes True unless ``--params`` is given)
    log : callable, optional  called with one line per step as it happens (e.g. ``print``)

    Models with wind and/or current (:func:`shipid.environment.with_environment`) take the defaults of their
    base model (estimate list, start, sampling, noise) plus the wind model's ``recipe_estimate`` for a wind part; their
    EKF stage is not refined.  Measurement noise: ``meas_std``, else the sensor noise the logs' format declares
    (``TrialLog.meas_std``, e.g. the ``esso-frt`` schema's), else the identifier's estimate from the data.

    Returns
    -------
    RecipeFit  (``.result()`` is the FitResult with ``settings["recipe"]``)

    Runs with one BLAS thread (:func:`shipid._blas.one_blas_thread`): the equation-error starts, the EKF and the
    refinement then give the same answer whatever the machine's thread setting (on the MARIN ``response-nl``
    fit, 1 and 2 OpenBLAS threads had ended the refinement in different minima).
    """
    with one_blas_thread():
        return _fit_logs(logs, model, params, lpp=lpp, estimate=estimate, fixed=fixed, start=start, neutral=neutral,
                         free_neutral=free_neutral, estimate_neutral=estimate_neutral, dt=dt,
                         max_drift_deg=max_drift_deg, refine=refine, metric_weight=metric_weight, n_passes=n_passes,
                         max_nfev=max_nfev, tune_noise=tune_noise, progress=progress, meas_std=meas_std,
                         ekf_options=ekf_options, hold_unresolved=hold_unresolved, sign_bounds=sign_bounds,
                         physical_damping=physical_damping, start_defaults=start_defaults,
                         drop_repeated=drop_repeated, log=log)


def _froude_process_std(defaults, L: float):
    """A model's recipe process noise (``RecipeDefaults.process_std``) Froude-scaled to length ``L`` (None: no
    default)."""
    if defaults.process_std is None:
        return None
    L0, std = defaults.process_std
    return {k: v * (L / L0) ** _FROUDE_EXP[k] for k, v in std.items()}


def _declared_meas_std(logs):
    """The sensor noise the logs' format declares (``TrialLog.meas_std``) when every log declares the same, else
    None (the identifier then estimates it from the data)."""
    decl = [dict(getattr(lg, "meas_std", None) or {}) for lg in logs]
    if not decl or not decl[0] or any(d != decl[0] for d in decl[1:]):
        return None
    return decl[0]


def _repeated_runs(logs, drop: bool, step) -> list:
    """Step 0: a log whose every sample is a sample of another (a trimmed copy of the same run) is dropped when
    ``drop`` (it would count that run twice), else kept with a warning; logs that share part of their samples
    (overlapping segments) are kept with a warning.  A step is recorded only when something was found."""
    if len(logs) < 2:
        return logs
    rows = repeated_samples(logs)  # (one comparison of the samples for both kinds of finding)
    kept, gone = drop_contained(logs, rows)
    copies = "; ".join(f"all {r['samples']} samples of {r['log']} are samples of {r['in']}" for r in gone)
    if gone and drop:
        step("repeated runs", {"dropped": [r["log"] for r in gone]},
             f"{copies}: a copy of a run would count that run twice (drop_repeated=False / --keep-repeated keeps it)")
        logs = kept
    elif gone:
        step("repeated runs", {"kept": [r["log"] for r in gone]}, f"asked to keep them: {copies}")
        warnings.warn(f"fit_logs: logs repeating another log are fitted twice: {copies}", UserWarning, stacklevel=4)
    names = {lg.name for lg in logs}  # (indices of ``rows`` refer to the logs as given; names to the kept ones)
    full = {frozenset((r["index"], r["in_index"])) for r in rows if r["share"] == 1.0}  # (copies: said above)
    part = [r for r in rows if r["index"] < r["in_index"] and frozenset((r["index"], r["in_index"])) not in full
            and r["log"] in names and r["in"] in names]
    if part:
        shared = "; ".join(f"{r['log']} and {r['in']} share {r['shared']} samples ({r['share']:.0%} of {r['log']})"
                           for r in part)
        step("overlapping runs", {"kept": [r["log"] for r in part]}, f"{shared}: those samples count twice")
        warnings.warn(f"fit_logs: logs share samples (overlapping segments of one run?): {shared}", UserWarning,
                      stacklevel=4)
    return logs


def _fit_logs(logs, model, params, *, lpp, estimate, fixed, start, neutral, free_neutral, estimate_neutral, dt,
              max_drift_deg, refine, metric_weight, n_passes, max_nfev, tune_noise, progress, meas_std, ekf_options,
              hold_unresolved, sign_bounds, physical_damping, start_defaults, drop_repeated, log) -> RecipeFit:
    logs = list(logs)
    if not logs:
        raise ValueError("fit_logs: no logs given")
    if refine not in ("auto", None, "none") + REFINE_MODES:
        raise ValueError(f"refine={refine!r}: use 'auto', 'metrics', 'output-error' or None")
    if start not in ("staged", "given"):
        raise ValueError(f"start={start!r}: use 'staged' or 'given'")
    steps: list[dict] = []

    def step(name, value, reason):
        steps.append({"step": name, "value": value, "reason": reason})
        if log is not None:
            shown = f"{value:.4g}" if isinstance(value, float) else value  # a line for people: 4 digits
            log(f"recipe: {name}: {shown} -- {reason}")

    logs = _repeated_runs(logs, drop_repeated, step)
    L = _lpp_of(logs, lpp)
    _check_under_way(logs, L)
    m0, why = _start_model(model, params, L)
    sampling_check = _sampling_check(m0, logs)  # the start model as built, before any start values from the logs
    # a model with wind/current parts takes its base ship model's defaults
    env = getattr(m0, "base", None) is not None and hasattr(m0, "identifier_settings")
    name = m0.base.name if env else m0.name
    wind_part = env and getattr(m0, "wind", None) is not None
    defaults = (m0.base if env else m0).recipe_defaults  # the model's own (shipid.models.RecipeDefaults)
    if env and refine not in (None, "none", "auto"):
        raise ValueError(f"refine={refine!r}: the refinement is not available for models with wind or current "
                         "parts yet; use refine=None (shipid fit: --refine none)")
    step("ship", {"lpp": L}, f"the logs' particulars; start: {why}")
    if start_defaults is None:
        start_defaults = isinstance(model, str) and params is None
    if start_defaults and defaults.start:
        m0 = m0.with_params(dict(defaults.start))
        step("start values (model default)", dict(defaults.start), f"{name}'s recipe default (chosen by "
             "cross-validation, see the model's recipe_defaults)")
    ekf_opts = dict(ekf_options or {})
    # sampling step
    if dt == "auto" and defaults.sampling is not None:
        dt_log = _log_step(logs)
        L0, h0 = defaults.sampling
        h = h0 * math.sqrt(L / L0)
        k = max(1, int(round(h / dt_log)))
        reason = (f"{every_kth(k)} ({k * dt_log:.3g} s): {name}'s recipe step {h0:g} s at Lpp {L0:g} m"
                  f", Froude-scaled to {h:.3g} s at {L:g} m, log step {dt_log:.3g} s")
        if defaults.substeps is not None and "substeps" not in ekf_opts:
            ekf_opts["substeps"] = defaults.substeps
            reason += f", {defaults.substeps} RK4 substeps per interval"
    elif dt == "auto":
        k, reason = choose_sampling(m0, logs)
    elif dt is None:
        k, reason = 1, "every sample (asked)"
    else:
        k = int(dt)
        if k < 1:
            raise ValueError(f"dt={dt!r}: give 'auto', None or a positive integer sample stride")
        reason = f"{every_kth(k)} (asked)"
    step("sampling", k, reason)
    used = [_every(lg, k) for lg in logs]
    if max_drift_deg == "auto":
        drift = LINEAR_DRIFT_DEG if linear_sway_yaw(m0) else None
        why_drift = (f"{name}'s sway and yaw equations are linear in v and r: linear derivatives hold for small "
                     "drift only") if drift is not None else f"{name} has non-linear sway/yaw terms: every sample"
    elif max_drift_deg is None:
        drift, why_drift = None, "off (asked)"
    else:
        drift = float(max_drift_deg)
        if not 0 < drift < 90:
            raise ValueError(f"max_drift_deg={max_drift_deg!r}: give 'auto', None or an angle in degrees "
                             "between 0 and 90, e.g. 10")
        why_drift = "asked"
    if drift is not None:
        windows = [linear_window(lg, drift) for lg in used]
        short = [lg.name for lg in windows if len(lg) < MIN_WINDOW_SAMPLES]
        if len(short) == len(windows):
            msg = (f"no log stays below {drift:g} deg of drift for {MIN_WINDOW_SAMPLES} samples from its start: "
                   f"{name} is linear in v and r and holds for small drift only; fit a model with non-linear "
                   "terms (response-nl, mmg, lowspeed) or pass max_drift_deg=None (--max-drift none)")
            if max_drift_deg != "auto":
                raise ValueError(msg)
            # the default: fit every sample rather than refuse, and say that the model is used beyond its range
            warnings.warn(msg.split(": ", 1)[0] + f"; fitting {name} to every sample, beyond its linear range "
                          "(its coefficients absorb the large-drift motion; a model with non-linear terms fits "
                          "these logs better)", UserWarning, stacklevel=2)
            step("linear range", None, why_drift + f"; but no log stays below {drift:g} deg for "
                 f"{MIN_WINDOW_SAMPLES} samples: every sample used (beyond the linear range, warned)")
            drift = None
    if drift is not None:
        used = [lg for lg in windows if len(lg) >= MIN_WINDOW_SAMPLES]
        kept = ", ".join(f"{lg.name} {lg.time[-1] - lg.time[0]:.4g} s" for lg in used)
        why_drift += f"; each log until its drift angle first exceeds {drift:g} deg ({kept})"
        if short:
            why_drift += (f"; left out (fewer than {MIN_WINDOW_SAMPLES} samples below it from the start): "
                          + ", ".join(short))
        step("linear range", drift, why_drift)
    elif max_drift_deg != "auto" or not linear_sway_yaw(m0):
        step("linear range", drift, why_drift)
    # estimated / fixed
    est = list(estimate) if estimate is not None else (
        list(defaults.estimate) if defaults.estimate is not None else None)
    if estimate is None and est is not None:
        if wind_part:
            est = est + [w for w in m0.wind.recipe_estimate if w in m0.param_names]
        step("estimated", list(est), f"{name}'s recipe default"
             + (" and the wind model's leading Fourier components" if wind_part else ""))
    fix: dict = {}
    if isinstance(fixed, dict):
        fix.update({k2: float(v) for k2, v in fixed.items()})
    elif fixed is not None:
        fix.update({k2: float(m0.params[m0.param_index(k2)]) for k2 in fixed})
    for k2 in defaults.fixed:
        if k2 not in fix and (estimate is None or k2 not in estimate):
            fix[k2] = float(m0.params[m0.param_index(k2)])
    if "a8" in m0.param_names and "a8" not in fix and (est is None or "a8" in est):
        n_all = np.concatenate([np.asarray(lg["n"], dtype=float) for lg in used if "n" in lg.channels])
        n_all = n_all[np.isfinite(n_all)]
        if n_all.size and np.ptp(n_all) <= 0.01 * max(abs(float(np.mean(n_all))), 1e-9):
            fix["a8"] = 0.0
            step("a8", 0.0, f"the propeller rate is constant ({np.mean(n_all):.4g} rps) in every log: "
                            "a1, a8, a9 are collinear, a8 fixed at 0")
    free_in_refine: list[str] = []
    if "delta0" in m0.param_names and neutral and not defaults.neutral and "delta0" not in fix:
        neutral = False
        step("neutral rudder angle", None, f"off for {name} (its recipe default: not kept by cross-validation)")
    if "delta0" in m0.param_names and neutral and "delta0" not in fix:
        try:
            d0, n_logs = neutral_rudder_angle(used)
            if estimate_neutral:
                m0 = m0.with_params({"delta0": d0})
                if est is not None and "delta0" not in est:
                    est = list(est) + ["delta0"]
                step("neutral rudder angle", math.degrees(d0),
                     f"deg, mean rudder of the straight approaches of {n_logs} of {len(used)} logs; the start of "
                     "delta0, estimated in the EKF stage and the refinement")
            else:
                fix["delta0"] = d0
                if free_neutral:
                    free_in_refine.append("delta0")
                step("neutral rudder angle", math.degrees(d0),
                     f"deg, mean rudder of the straight approaches of {n_logs} of {len(used)} logs; fixed in the "
                     "EKF stage, " + ("freed in the refinement" if free_neutral else "and in the refinement"))
        except ValueError as exc:
            step("neutral rudder angle", None, str(exc))
    if est is not None:
        est = [p for p in est if p not in fix]
    # staged start
    if start == "staged" and defaults.seed_model is not None:
        seed_model = get_model(defaults.seed_model, lpp=L)
        seed_fix = {k2: v for k2, v in fix.items() if k2 in seed_model.param_names}
        # the seed is linear in v and r: fitted on the linear range (step 2b) unless that is switched off
        seed_drift = LINEAR_DRIFT_DEG if max_drift_deg == "auto" else drift
        seed_logs = [linear_window(lg, seed_drift) for lg in used] if seed_drift is not None else used
        seed_logs = [lg for lg in seed_logs if len(lg) >= MIN_WINDOW_SAMPLES] or used  # none in range: all
        if log is not None:
            log(f"recipe: start values: fitting kcs-response to {len(seed_logs)} log(s) first ...")
        seed = EKFIdentifier(seed_model, fixed=seed_fix or None, n_passes=n_passes, progress=progress,
                             meas_std=meas_std, **(ekf_options or {})).fit(seed_logs)
        vals = {k2: float(seed.coef_.get(k2, 0.0)) for k2 in m0.param_names}
        vals.update({k2: v for k2, v in fix.items()})
        m0 = m0.with_params(vals)
        step("start values", "staged", "kcs-response (the seed's 16 terms) fitted at the logs' scale"
             + (f" up to {seed_drift:g} deg of drift" if seed_drift is not None else "")
             + f" ({seed.message_}); the non-linear terms start at 0")
    else:
        step("start values", "as built", why)
    if defaults.init is not None and "init" not in ekf_opts:
        ekf_opts["init"] = defaults.init
        step("EKF start", defaults.init, f"{name}'s recipe default: the start model's values")
    # noise levels: measurement (given > the logs' declared sensor noise > the identifier's estimate), process
    if meas_std is None:
        meas_std = _declared_meas_std(logs)
        step("measurement noise", meas_std, "the logs' format declares its sensors' noise (schema meas_std)"
             if meas_std is not None else "estimated from the data by the identifier (no --meas-std, none declared)")
    else:
        step("measurement noise", dict(meas_std), "asked")
    proc = _froude_process_std(defaults, L)
    if proc is not None:
        ekf_opts["process_std"] = {**proc, **dict(ekf_opts.get("process_std") or {})}
        step("process noise", {k2: float(f"{v:.4g}") for k2, v in ekf_opts["process_std"].items()},
             f"{name}'s recipe default at Lpp {defaults.process_std[0]:g} m, "
             f"Froude-scaled to {L:g} m" + ("; current states from the environment model" if env else ""))
    if log is not None:
        log(f"recipe: running the EKF: {n_passes} pass(es) over {len(used)} log(s), "
            f"{sum(len(lg) for lg in used)} samples, "
            f"{len(est) if est is not None else len([q for q in m0.param_names if q not in fix])} coefficients ...")
    ekf = EKFIdentifier(m0, estimate=est, fixed=fix or None, n_passes=n_passes, tune_noise=tune_noise,
                        progress=progress, meas_std=meas_std, **ekf_opts).fit(used)
    step("EKF", ekf.message_, f"{len(ekf.estimated_)} parameters estimated, {n_passes} passes")
    if not ekf.success_ and "gate" not in ekf_opts and getattr(ekf, "gate", None) is not None:
        # the start transient of a model far from the data gives large innovations; rejecting them (gating)
        # leaves the filter open-loop (the MARIN KVLCC2 mmg fit diverges at t = 38 s with the default gate)
        first = ekf.message_
        if log is not None:
            log(f"recipe: the EKF failed with the innovation gate ({first}): running it again without ...")
        ekf = EKFIdentifier(m0, estimate=est, fixed=fix or None, n_passes=n_passes, tune_noise=tune_noise,
                            progress=progress, meas_std=meas_std, **{**ekf_opts, "gate": None}).fit(used)
        step("EKF", ekf.message_, f"refitted without innovation gating: with the default gate the filter failed ({first})")
    fit = RecipeFit(ekf=ekf, steps=steps, logs=used, free_in_refine=free_in_refine, lpp=L, source_logs=logs,
                    sampling=sampling_check)
    mode = refine
    if mode == "auto" and (env or not defaults.auto_refine):
        mode = None
        step("refinement", "none", "models with wind/current parts are not refined" if env else
             f"{name}: none by default (its recipe default: its study's refinements kept nothing)")
    elif mode == "auto":
        kinds = _kinds(logs, L)
        mode = AUTO_REFINE if {"turning", "zigzag"} <= kinds else None
        step("refinement", mode or "none", f"turning circles and zigzags among the logs: {AUTO_REFINE} at metric "
             f"weight {METRIC_WEIGHT if metric_weight is None else metric_weight:g} (chosen by "
             "leave-one-run-out within the KVLCC2 training runs, docs/validation.md)" if mode else
             (f"the logs hold {' and '.join(sorted(kinds))} only: no refinement" if kinds else
              "the logs hold no standard manoeuvre (turning circle or zigzag from a steady approach): no refinement"))
    elif mode in (None, "none"):
        mode = None
        step("refinement", "none", "asked")
    else:
        step("refinement", mode, "asked")
    if mode is None:
        return fit
    return refine_fit(fit, logs, mode, max_nfev=max_nfev, metric_weight=metric_weight,
                      hold_unresolved=hold_unresolved, sign_bounds=sign_bounds,
                      physical_damping=physical_damping, log=log, progress=progress)


def recipe_table(fit: RecipeFit) -> pd.DataFrame:
    """The recipe's steps as a table (step, value, reason)."""
    return pd.DataFrame(fit.steps)
