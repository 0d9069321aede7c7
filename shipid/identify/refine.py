"""Refinement of the fit recipe (step 6 of :mod:`shipid.identify.recipe`): an output-error fit started from
the EKF stage, optionally with the training runs' own standard-manoeuvre errors (:func:`metric_residuals`),
and the physical-damping constraint."""
from __future__ import annotations

import warnings

import numpy as np

from ..manoeuvres import metrics as manoeuvre_metrics, ship_info, standard_manoeuvre
from .batch import OutputErrorRefiner
from .diagnostics import damping_check, DAMPING_MARGIN, damping_penalty
from .sampling import _head, _lpp_of, _speed_scale, common_grid

__all__ = ["refine_fit", "metric_residuals", "METRIC_TOL", "METRIC_WEIGHT", "REFINE_MODES", "AUTO_REFINE"]

#: Metric residual scales of the ``"metrics"`` refinement: tactical diameter [%], first / second overshoot [deg]
#: (a model off by this much pays as much as a replay error the size of the signal).
METRIC_TOL = {"tactical_diameter_L": 5.0, "overshoot1_deg": 2.0, "overshoot2_deg": 3.0}
REFINE_MODES = ("output-error", "metrics")
#: Default multiplier of the metric residuals in ``refine="metrics"`` (:func:`refine_fit`): 0.1, chosen by
#: leave-one-run-out from 0.1, 0.3, 0.5, 1 (see :data:`AUTO_REFINE`).  At 1 the six training metrics dominate
#: eight free parameters and the fit matches the metrics, not the dynamics (worst left-out run 5.3 tolerances);
#: at 0.1 they steer the replay fit (output error) towards the standard-manoeuvre quantities, which the
#: replay alone (weight 0) predicts worse on the left-out runs.
METRIC_WEIGHT = 0.1
#: What ``refine="auto"`` does when the logs hold turning circles and zigzags: the metric-augmented refinement
#: at weight :data:`METRIC_WEIGHT`.  Chosen by leave-one-run-out within the four KVLCC2 training runs (fit on
#: three, predict the fourth's tactical diameter or overshoots; score = the worst goal-normalised error over
#: the folds; rule written before any variant ran; the held-out zz+-20 never read; docs/validation.md):
#: metrics at weight 0.1 1.96, 0.3 2.19, 0.5 2.25, 1 5.34; output-error 2.47, output-error with heading 2.48.
AUTO_REFINE = "metrics"


def metric_residuals(model, logs, *, lpp: float | None = None, tolerances=None, names=None):
    """Closed-loop standard-manoeuvre errors of ``model`` on ``logs`` as a function of its parameters.

    Returns ``(f, used)``: ``f(params) -> array (B, m)`` for parameter vectors of shape (B, np) (or (np,),
    then (m,)) -- for each turning log the tactical-diameter error [%] and for each zigzag the first and
    second overshoot errors [deg] of the model's closed-loop manoeuvre matching the log (same rudder and
    check angle, side, approach speed; the log's rudder rate, else the model's;
    :func:`shipid.manoeuvres.standard_manoeuvre`), each divided by its tolerance (:data:`METRIC_TOL`);
    and the names of the logs used (logs without standard-manoeuvre metrics are left out).  The B
    parameter sets of one manoeuvre run as one batch; a manoeuvre a set cannot complete gives 1e3.
    """
    L = _lpp_of(logs, lpp)
    tol = {**METRIC_TOL, **(tolerances or {})}
    jobs, used = [], []
    for i, lg in enumerate(logs):
        name = names[i] if names else lg.name
        try:
            mm = manoeuvre_metrics(lg, lpp=L, name=name)
        except ValueError:
            continue
        d = mm.to_dict()
        keys = ("tactical_diameter_L",) if d["manoeuvre"] == "turning" else ("overshoot1_deg", "overshoot2_deg")
        if not all(d.get(k) is not None for k in keys):
            continue
        rate = getattr(lg.ship, "rudder_rate", None) or ship_info(model).get("rudder_rate")
        jobs.append((mm, d, rate, keys))
        used.append(name)

    def f(params):
        P = np.asarray(params, dtype=float)
        P2 = np.atleast_2d(P)
        B = P2.shape[0]
        cols = []
        for mm, m, rate, keys in jobs:
            turning = m["manoeuvre"] == "turning"
            block = np.full((B, len(keys)), 1e3)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                try:  # the turns only need the tactical diameter: 200 deg
                    run = standard_manoeuvre(model, mm, rudder_rate=rate, lpp=L, params=P2, heading_change_deg=200.0)
                except ValueError:
                    run = None
            for b in range(B if run is not None else 0):
                d = run.metrics[b].to_dict()
                for j, c in enumerate(keys):
                    if d.get(c) is not None and np.isfinite(d[c]):
                        err = 100 * (d[c] - m[c]) / m[c] if turning else d[c] - m[c]
                        block[b, j] = err / tol[c]
            cols.append(block)
        out = np.concatenate(cols, axis=1) if cols else np.zeros((B, 0))
        return out if P.ndim == 2 else out[0]

    return f, used


def _kinds(logs, L) -> set:
    kinds = set()
    for lg in logs:
        try:
            kinds.add(manoeuvre_metrics(lg, lpp=L).manoeuvre)
        except ValueError:
            pass
    return kinds


def refine_fit(fit: RecipeFit, logs, mode: str = "output-error", *, max_nfev: int = 60,
               metric_weight: float | None = None, channels=None, hold_unresolved: bool = True,
               grid_dt=None, sign_bounds: bool = False, physical_damping: bool = True, log=None,
               progress: bool = False) -> RecipeFit:
    """Step 6 of the recipe on a fitted EKF stage: a new :class:`RecipeFit` with the refinement.

    Parameters
    ----------
    fit : RecipeFit  an EKF stage made by :func:`fit_logs` (``refine=None``); it is not modified
    logs : sequence of TrialLog  the same training logs as passed to :func:`fit_logs` (full rate: the
        ``"metrics"`` mode measures their standard-manoeuvre metrics)
    mode : {"output-error", "metrics"}
    max_nfev : int  evaluation limit of ``least_squares``
    metric_weight : float, optional  multiplier of the metric residuals (``"metrics"`` only; default
        :data:`METRIC_WEIGHT`): the objective is replay cost + ``metric_weight**2`` * sum((error/tol)**2)
    channels : sequence of str, optional  replayed channels (default: u, v, r where all logs have them)
    grid_dt : None, "log" or float  the refinement's common grid step: None (default) twice the EKF step;
        ``"log"`` the logs' own step (full rate, ``logs`` cut to the spans the EKF used); a step [s]
    hold_unresolved : bool  hold at their EKF-stage values the coefficients the solver cannot resolve
        (:func:`shipid.identify.batch.identifiable_subset`; default True); False: refine every one
    sign_bounds : bool  keep the model's dissipative coefficients (``model.dissipative``, the pure sway and yaw
        damping terms) <= 0 (default False; :class:`shipid.identify.batch.OutputErrorRefiner`).  Not the
        default: on the MARIN ``response-nl`` fit the held set follows the BLAS thread count and the cross
        terms can still make the own damping positive (docs/validation.md)
    physical_damping : bool  when the refined model's own sway or yaw damping is positive along the logged
        states (:func:`~shipid.identify.diagnostics.damping_check` fails), solve again from the same start with
        the constraint ``d(dv/dt)/dv, d(dr/dt)/dr <= -DAMPING_MARGIN * U/L`` at those states as an exterior
        penalty (:func:`~shipid.identify.diagnostics.damping_penalty`; default True).  A fit that keeps its own
        damping negative is not touched.  Unlike ``sign_bounds`` it constrains the damping itself, whatever
        terms make it up (docs/validation.md)
    log : callable, optional  called with one line per step, and one as each solve starts (they take a while)
    progress : bool  a bar over the refinement's replays (tqdm, on stderr)
    """
    if mode not in REFINE_MODES:
        raise ValueError(f"mode={mode!r}: use one of {REFINE_MODES}")
    w = METRIC_WEIGHT if metric_weight is None else float(metric_weight)
    if not (np.isfinite(w) and w >= 0):
        raise ValueError(f"metric_weight={metric_weight!r}: give a finite weight >= 0")
    steps = [dict(s) for s in fit.steps]

    def step(name, value, reason):
        steps.append({"step": name, "value": value, "reason": reason})
        if log is not None:
            log(f"recipe: {name}: {value} -- {reason}")

    out = type(fit)(ekf=fit.ekf, steps=steps, logs=fit.logs, free_in_refine=list(fit.free_in_refine), lpp=fit.lpp,
                    source_logs=list(fit.source_logs), sampling=dict(fit.sampling))
    ekf, used, L = fit.ekf, fit.logs, fit.lpp
    if not ekf.success_:
        step("refinement", "skipped", f"the EKF stage failed ({ekf.message_}): no refinement from a diverged filter")
        return out
    src = used
    if grid_dt is None:
        dt_ref = 2.0 * float(np.median(np.diff(used[0].time)))
    elif grid_dt == "log":
        # full rate: the training logs themselves over the spans the EKF used (same start, same end)
        by_name = {lg.name: lg for lg in logs}
        src = []
        for u_lg in used:
            full = by_name.get(u_lg.name, u_lg)
            keep = np.flatnonzero(full.time <= u_lg.time[-1] + 1e-9)
            src.append(full if keep.size == len(full) else _head(full, keep.size))
        dt_ref = float(min(np.median(np.diff(lg.time)) for lg in src))
    else:
        dt_ref = float(grid_dt)
        if not (np.isfinite(dt_ref) and dt_ref > 0):
            raise ValueError(f"grid_dt={grid_dt!r}: give None, 'log' or a positive step in seconds")
    grid = common_grid(src, dt_ref)
    chans = list(channels) if channels is not None else [c for c in ("u", "v", "r")
                                                          if all(c in lg.channels for lg in grid)]
    sstd = {c: float(np.nanstd(np.concatenate([lg[c] for lg in grid]))) for c in chans}
    nsamp = np.array([np.isfinite(lg["u"]).sum() for lg in grid], dtype=float)
    start_model = ekf.to_model()
    extra = None
    if mode == "metrics":
        out.metric_weight = w
        f, with_metrics = metric_residuals(start_model, logs, lpp=L)
        if with_metrics and w > 0:
            extra = f if w == 1.0 else (lambda P, _f=f: w * np.asarray(_f(P)))
        step("metric residuals", with_metrics, "the training logs' own standard-manoeuvre metrics over "
             + ", ".join(f"{k} {v:g}" for k, v in METRIC_TOL.items()) + f", weight {w:g}")
    est_ref = list(ekf.estimated_) + [p for p in fit.free_in_refine if p not in ekf.estimated_]

    def refine(extra_res):
        return OutputErrorRefiner(start_model, estimate=est_ref, channels=chans, meas_std=sstd,
                                  log_weights=list(1.0 / np.maximum(nsamp, 1.0)), extra_residuals=extra_res,
                                  max_nfev=max_nfev, hold_unresolved=hold_unresolved,
                                  sign_bounds=sign_bounds, progress=progress).fit(grid, start=ekf)

    if log is not None:
        log(f"recipe: refining {len(est_ref)} coefficients by replaying {len(grid)} log(s) "
            f"(at most {max_nfev} evaluations; each Jacobian takes {len(est_ref) + 1} replays in one batch) ...")
    ref = refine(extra)
    damp = None
    if physical_damping and {"v", "r"} <= set(start_model.state_names):
        damp = damping_check(start_model.with_params(ref.coef_.to_numpy()), used)
    U0, what_U = _speed_scale(logs) if damp is not None and damp["physical"] is False else (float("nan"), "")
    if damp is not None and damp["physical"] is False and not np.isfinite(U0):
        step("physical damping", False, f"the refined model's own damping is not negative along the logs, but "
             f"{what_U}: no speed scale for the constraint's margin; the fit is kept unconstrained (its "
             "diagnostics say so)")
    elif damp is not None and damp["physical"] is False:
        pen = damping_penalty(start_model, used, time_scale=L / U0)
        both = pen if extra is None else (lambda P, _e=extra, _p=pen: np.concatenate(
            [np.asarray(_e(P), dtype=float).reshape(np.shape(P)[0], -1), _p(P)], axis=1))

        def where(d):
            frac = ", ".join(f"{100 * d[s]['fraction_positive']:.1f} % ({s})" for s in ("v", "r"))
            rest = ", ".join(f"{d['rest'][s]:+.3g} 1/s ({s})" for s in ("v", "r") if d["rest"][s] is not None)
            return f"own damping positive at {frac} of the logged states, at rest {rest}"

        first = f"unconstrained: {where(damp)}, cost {ref.cost_:.4g}"
        if log is not None:
            log(f"recipe: own damping positive ({where(damp)}): refining again with it constrained ...")
        ref = refine(both)
        damp2 = damping_check(start_model.with_params(ref.coef_.to_numpy()), used)
        pen_cost = 0.5 * float(np.sum(pen(ref.coef_.to_numpy()) ** 2))
        step("physical damping", bool(damp2["physical"]),
             f"{first}; solved again from the same start with d(dv/dt)/dv and d(dr/dt)/dr <= -{DAMPING_MARGIN:g} U/L "
             f"(U = {U0:.4g} m/s, {what_U}; L = {L:.4g} m) at the logged states and at rest as a penalty: "
             f"{where(damp2)}, "
             f"cost {ref.cost_:.4g} of which the penalty {pen_cost:.3g}")
    elif damp is not None:
        step("physical damping", True, "the refined model's own sway and yaw damping is negative along the logged "
             "states and not positive at rest: no constraint needed")
    out.refiner = ref
    if ref.subset_ is not None:
        sub = ref.subset_
        step("identifiable subset", list(ref.held_),
             (f"held at their EKF-stage values: {', '.join(ref.held_)}" if ref.held_ else "every coefficient refined")
             + f" -- directions of the start's scaled Jacobian with singular value below sqrt(2 ftol cost) = "
             f"{sub['threshold']:.3g} (a change of the coefficients by their own size moves the cost by less than "
             f"the solver's tolerance ftol = {sub['ftol']:g}); scaled J^T J condition {sub['condition']:.3g}"
             + (f" -> {sub['condition_kept']:.3g}" if ref.held_ else ""))
    elif not hold_unresolved:
        step("identifiable subset", None, "off (asked): every coefficient refined")
    if sign_bounds:
        bnd = ref.sign_bounded_
        step("physical signs", list(ref.at_bound_),
             (f"{', '.join(bnd)} kept <= 0 (dissipative: pure sway/yaw damping)" if bnd else
              "the model declares no dissipative coefficient among the refined ones")
             + (f"; held on the bound 0 (the unconstrained fit puts them on the wrong side): "
                f"{', '.join(ref.at_bound_)}" if ref.at_bound_ else ""))
    step("output-error", ref.message_, f"{len(est_ref)} parameters on a {dt_ref:.3g} s common grid, channels "
         f"{chans} over their spread, each log weighted 1/samples; {ref.nfev_} evaluations, cost "
         f"{ref.cost_start_:.4g} -> {ref.cost_:.4g}")
    return out
