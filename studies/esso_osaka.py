"""Esso Osaka 3 m model, outdoor free-running runs with wind (FRT-DS-ESSO): fit and cross-validate.

A thin user of the public API: logs read with the ``esso-frt`` schema, models built with
:func:`shipid.models.get_model` and :func:`shipid.environment.with_environment`, fitted with
:class:`shipid.identify.EKFIdentifier`, judged by :func:`shipid.validation.horizon.horizon_prediction`
(open-loop prediction from the measured state every 5 s).  The runs are split by run into ``folds``
(:func:`assign_folds`; ``"loro"``: leave-one-run-out): every model that is fitted is fitted on the other
folds only, so every error reported is on runs the fit has not seen.

Choices (made once, before looking at any held-out error, and the same for every model):

* data: every run except ``turn_cut_14-Sep-2020_15_58_08`` (a trimmed copy of
  ``turn_14-Sep-2020_15_58_08``: keeping both would put the same samples in a training and a test fold);
  for the fits every ``fit_every``-th sample (default 20: 0.5 Hz) with two RK4 substeps per interval;
* noise: measurement std 0.01 m (x, y), 0.003 rad (psi), 0.01 m/s (u, v), 0.003 rad/s (r) -- the GNSS/IMU
  scatter seen in the second differences of the logs; process std 0.005 m/sqrt(s) (x, y),
  0.002 rad/sqrt(s) (psi), 0.003 m/s/sqrt(s) (u, v), 0.002 rad/s/sqrt(s) (r): the model error of a
  manoeuvring model in gusting wind, about a third of the measured accelerations' scatter.  The identifier's
  automatic defaults were not used (on these runs they diverge);
* estimated coefficients :data:`ESTIMATE` (hull, thrust ahead and astern, astern side force, rudder lift and
  its hull interaction aH, tR, and the cross-flow factor CrY -- the last three kept by cross-validation) and,
  with wind, :data:`ESTIMATE_WIND`; prior = ``esso-osaka-prior`` with :data:`PRIOR_PARAMS` (the
  side-dependent flow straightening, kept by cross-validation) and 100 % prior std;
* current: constant per run (reset at each run), estimated with prior std 0.05 m/s; in prediction the
  held-out run starts with the training runs' mean current (a wind-driven start current,
  ``current_start="wind"``, was scored and not kept);
* EKF inputs: the identifier's defaults, first-order hold and a 5-sigma innovation gate -- chosen by 8-fold
  cross-validation against held inputs without gating (docs/environment.md); a constant current per run was
  preferred to a random walk by the same cross-validation;
* fits on all run types and by run type (``by_type``); which to use for a run type is a cross-validated
  choice (:data:`CHOSEN_SCOPE`, docs/environment.md);
* the rule: each candidate was written down before it ran and kept only when it lowered the cross-validated
  mean of the per-type 30 s median position errors (8-fold, then leave-one-run-out); the numbers are in
  docs/environment.md.  Scored and not kept: a rudder rate limit (``rudder_rate``), 1 Hz fits, the aft wind
  geometry (``wind``), per-type fits on the other types' posterior (``by_type_prior="others"``), the
  cross-flow factor ``CrN`` (with ``CrY``), a wake falling with drift, the side force and yaw moment of the
  propeller turning ahead (``YPf``, ``NPf``), a rudder neutral angle (``delta0``), the wind-driven start
  current, rudder stall at 24.1 deg (``kstall``), a side-dependent rudder normal force (``dfalpha``) and the
  wake's side-dependent fall with drift (``C2p``, ``C2m``) (8-fold means 0.3017, 0.2873, 0.2964 against
  0.2823), a windowed output-error refinement of the EKF fits on 30 s open-loop prediction windows of the
  training runs (:func:`refine_on_windows`; 8-fold means 0.3398, 0.3271, 0.3181 against 0.2823: it traded
  position error for heading error), and the same on position only with ``aH``, ``tR`` held, with a linear and
  a robust loss (0.2837, 0.2831 against 0.2823: better on the training zigzags, not on the held-out ones).
  The defaults are the chosen settings.
"""
from __future__ import annotations

import glob
import os
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from shipid.environment import WindForce
from shipid.models import model_class
from shipid.logs.schema import PRESETS

__all__ = ["run_study", "refine_on_windows", "in_sample_errors", "REFINE_DEFAULTS", "REFINE_CANDIDATES", "anemometer_check", "path_relative_error", "current_vs_wind", "start_current_floor", "drift_factor", "with_drift_current", "air_velocity", "EssoStudy", "load_runs", "recipe_loro", "error_diagnosis", "residual_accelerations", "split_position_error", "PRIOR_PARAMS", "DATA_DIR", "ESTIMATE", "ESTIMATE_WIND", "RUN_TYPES"]

#: Where the shared data set lives relative to the repository root.
DATA_DIR = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "esso_osaka_frt"
RUN_TYPES = ("turning", "zigzag", "random", "berthing")
#: A trimmed copy of another run (same samples): left out.
DUPLICATES = ("turn_cut_14-Sep-2020_15_58_08",)
#: Estimated hull, propeller and rudder coefficients (one copy: the ``lowspeed`` model's recipe default, which
#: ``shipid fit`` uses).  ``aH``, ``tR`` kept by the rule (leave-one-run-out chosen-scope mean of the 30 s medians
#: 0.2780 against 0.2793 m); with them ``f_alpha``, ``aH`` and ``tR`` are not separately identifiable (they
#: scatter over the folds; docs/environment.md) -- read them as a group, not one by one.  ``CrY`` (the yaw-rate
#: weighting of the cross-flow sway force) kept by the rule (8-fold mean 0.28228 against 0.28981,
#: leave-one-run-out chosen-scope mean 0.26546 against 0.27080; docs/environment.md).
_LOWSPEED = model_class("lowspeed").recipe_defaults  # what `shipid fit` uses for lowspeed (one copy, in the model)
ESTIMATE = tuple(_LOWSPEED.estimate)
ESTIMATE_WIND = tuple(WindForce.recipe_estimate)
#: Values replacing the ``esso-osaka-prior`` set's in every ``lowspeed`` fit of the study: the MMG standard
#: method's side-dependent flow straightening at the KVLCC2's published split (gamma_R 0.640 / 0.395 for
#: beta_R > 0 / < 0, Yasukawa & Yoshimura 2015: +-0.1225 about the prior's 0.5), kept by the rule (8-fold mean
#: of the 30 s medians 0.2898 vs 0.2922, leave-one-run-out chosen-scope mean 0.2708 vs 0.2780;
#: docs/environment.md).  ``run_study(prior_params={})`` fits without it.
PRIOR_PARAMS = dict(_LOWSPEED.start)  # (one copy: the recipe's lowspeed start default)
#: Measurement noise of the fits: the ``esso-frt`` format's sensor noise (one copy, in the log adapter).
MEAS_STD = dict(PRESETS["esso-frt"].meas_std)
#: Process noise of the fits at 3 m (one copy: the recipe's lowspeed default, Froude-scaled there to other lengths).
PROCESS_STD = dict(_LOWSPEED.process_std[1])


#: Froude-scaled IMO minimum steering-gear rate (2.32 deg/s at full scale, A.751(18)) for the 3 m model
#: of the 325 m Esso Osaka: 2.32 * sqrt(325 / 3) = 24.1 deg/s (a candidate scored and not kept,
#: docs/environment.md: the logged rudder angle of the zigzags jumps by 40 deg within one 0.1 s sample).
FROUDE_RUDDER_RATE_DEG_S = 2.32 * float(np.sqrt(325.0 / 3.0))


def rate_limit(t, x, rate):
    """``x(t)`` followed by a rate-limited actuator: at most ``rate`` [units of x per s] per step, starting
    from ``x[0]`` (a steering gear's constant slew rate between the logged angle samples)."""
    t = np.asarray(t, dtype=float)
    x = np.asarray(x, dtype=float)
    out = np.empty_like(x)
    out[0] = x[0]
    dt = np.diff(t)
    for i in range(1, len(x)):
        step = rate * dt[i - 1]
        out[i] = out[i - 1] + min(max(x[i] - out[i - 1], -step), step)
    return out


def load_runs(data_dir=DATA_DIR, types=RUN_TYPES, max_runs: int | None = None,
              rudder_rate: float | None = None) -> list:
    """The runs as TrialLogs (``esso-frt`` schema), with ``run_type`` in ``log.meta``; rows with missing
    samples (the empty trailing rows of one zigzag file) are dropped.  ``rudder_rate`` [deg/s]: pass the
    logged rudder angle through a rate limiter of that slew rate (:func:`rate_limit`; None: as logged)."""
    from shipid.logs import read_log

    data_dir = Path(data_dir)
    if not data_dir.is_dir():
        raise FileNotFoundError(f"{data_dir}: Esso Osaka data set (FRT-DS-ESSO) not found")
    out = []
    for kind in types:
        files = sorted(glob.glob(str(data_dir / kind / "*.csv")))
        files = [f for f in files if Path(f).stem not in DUPLICATES][:max_runs]
        for f in files:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", UserWarning)
                lg = read_log(f, schema="esso-frt", interpolate_inputs=True)
            lg.data = lg.data.dropna().reset_index(drop=True)
            if rudder_rate is not None:
                lg.data["delta"] = rate_limit(lg.data["time"], lg.data["delta"], np.radians(rudder_rate))
            lg.run_type = kind
            out.append(lg)
    return out


def _frame(lg, every: int) -> pd.DataFrame:
    d = lg.data.iloc[::every].reset_index(drop=True)
    d.attrs["name"] = lg.name
    return d


@dataclass
class EssoStudy:
    """Result of :func:`run_study`.

    Attributes
    ----------
    horizon : DataFrame
        Median / p90 position error [m], median heading error [deg], starts and blow-ups per model, run
        type and horizon (on held-out runs for fitted models).
    coefficients : DataFrame
        Fitted coefficients (value, std) per fold of the environment-aware fit.
    currents : DataFrame
        Estimated current per training run (cx, cy and std) of the environment-aware fits.
    turning : DataFrame
        Measured vs predicted (replayed) turning metrics of the turning runs.
    fits : dict
        Per fold and model: ``success``, ``message``, ``seconds``.
    models : dict
        Per fold, the fitted models.
    """

    horizon: pd.DataFrame
    coefficients: pd.DataFrame
    currents: pd.DataFrame
    turning: pd.DataFrame
    fits: dict = field(default_factory=dict)
    models: dict = field(default_factory=dict)
    settings: dict = field(default_factory=dict)

    def table(self, seconds: float = 30.0) -> pd.DataFrame:
        """Median position error at ``seconds`` [m]: models x run types."""
        h = self.horizon[self.horizon.seconds == seconds]
        return h.pivot(index="model", columns="run_type", values="position_error_median_m")

    def goals(self, env: str = "lowspeed + wind + current fitted",
              plain: str = "lowspeed fitted (no environment)") -> pd.DataFrame:
        """The issue's goals per run type and horizon: the environment-aware model's median error and its
        ratios to dead reckoning (goal <= 0.5), to the KVLCC2 set Froude-scaled (<= 0.7) and to the same
        model fitted without environment terms (<= 0.75, 30 s), and its blow-ups."""
        rows = []
        h = self.horizon.set_index(["model", "run_type", "seconds"])
        for (kind, sec), g in self.horizon.groupby(["run_type", "seconds"]):
            e = h.loc[(env, kind, sec)]
            val = e.position_error_median_m
            ref = lambda m: h.loc[(m, kind, sec)].position_error_median_m if (m, kind, sec) in h.index else np.nan  # noqa: E731
            rows.append({"run_type": kind, "seconds": sec, "median_m": val,
                         "vs_dead_reckoning": val / ref("dead reckoning"),
                         "vs_kvlcc2_scaled": val / ref("mmg kvlcc2 (Froude-scaled, no fit)"),
                         "vs_no_environment": val / ref(plain), "n_blowups": int(e.n_blowups)})
        return pd.DataFrame(rows)

    def markdown(self, seconds=(10.0, 30.0, 60.0)) -> str:
        """Tables of median (p90) position errors [m] per model and run type, one per horizon."""
        out = []
        types = [t for t in RUN_TYPES if t in set(self.horizon.run_type)]
        for sec in seconds:
            h = self.horizon[self.horizon.seconds == sec].set_index(["model", "run_type"])
            out.append(f"after {sec:g} s: median (p90) [m]\n\n| model | " + " | ".join(types) + " |\n|---|"
                       + "---|" * len(types))
            for m in dict.fromkeys(self.horizon.model):
                cells = [f"{h.loc[(m, t)].position_error_median_m:.3f} ({h.loc[(m, t)].position_error_p90_m:.2f})"
                         if (m, t) in h.index else "" for t in types]
                out.append(f"| {m} | " + " | ".join(cells) + " |")
            out.append("")
        return "\n".join(out)


#: A windowed output-error refinement of every environment-aware EKF fit (scored and not kept; docs/environment.md), i.e. fit for what is judged.  After the EKF, the estimated coefficients
#: (``ESTIMATE`` + ``ESTIMATE_WIND``) are adjusted by :class:`shipid.identify.batch.OutputErrorRefiner` to
#: minimise the open-loop prediction error of windows of the *training* runs
#: (:func:`shipid.identify.batch.prediction_windows`): a window starts at the measured state every ``every`` s,
#: runs ``horizon`` s with the measured inputs and wind, ``sample_every``-th 10 Hz sample (2 Hz), one RK4
#: step per sample, inputs held between samples (as the judged predictions hold them), cost on ``x, y, psi``
#: weighted by ``meas_std`` (0.3 m: the goal; 0.05 rad: the heading error that moves a 30 s zigzag
#: prediction by about 0.3 m), at most ``max_nfev`` evaluations.  ``current``: each window starts with its run's
#: current as estimated by the EKF (``"own"``) or with the training runs' mean current, as the held-out
#: predictions do (``"mean"``); ``balance``: every window weighs the same (``False``) or each run type's
#: windows weigh the same in total (``True``: the judged score is the mean over the four types).
REFINE_DEFAULTS = {"horizon": 30.0, "every": 10.0, "sample_every": 5, "channels": ("x", "y", "psi"),
                   "meas_std": {"x": 0.3, "y": 0.3, "psi": 0.05}, "max_nfev": 20, "input_hold": "zoh",
                   "current": "own", "balance": False, "hold": (), "loss": "linear", "f_scale": 1.0}
#: Candidates: R1 the refinement above, R2 with the training mean current as every window's start current, R3
#: with each run type weighing the same.  None kept (8-fold means 0.3398 / 0.3271 / 0.3181 against 0.2823; the
#: heading weight let the fit trade position error for heading error, on the training runs too).
REFINE_CANDIDATES = {"R1": {}, "R2": {"current": "mean"}, "R3": {"balance": True}}
#: Further candidates: R3's settings with the cost on position only (x, y at 0.3 m) and the ridge coefficients ``aH``, ``tR`` held at the EKF fit's values
#: (P1), and the same with the robust loss ``soft_l1``, ``f_scale`` 1, i.e. quadratic up to one 0.3 m
#: normalised residual and linear beyond (P2: the judged number is a median).
REFINE_CANDIDATES["P1"] = {"balance": True, "channels": ("x", "y"), "meas_std": {"x": 0.3, "y": 0.3},
                           "hold": ("aH", "tR")}
REFINE_CANDIDATES["P2"] = {**REFINE_CANDIDATES["P1"], "loss": "soft_l1", "f_scale": 1.0}
#: None kept (8-fold means 0.2837 / 0.2831 against 0.2823; the refinements converged and lowered the in-sample
#: zigzag error by 8-11 %, the held-out one rose by 2 %): ``refine`` stays off by default.


def refine_on_windows(model, runs, currents, *, estimate, horizon=30.0, every=10.0, sample_every=5,
                      channels=("x", "y", "psi"), meas_std=None, max_nfev=20, input_hold="zoh", current="own",
                      balance=False, hold=(), loss="linear", f_scale=1.0):
    """Refine a fitted environment-aware model on open-loop prediction windows of ``runs`` (
    :data:`REFINE_DEFAULTS` explains the settings).  ``currents``: per run ``{"cx": .., "cy": ..}`` estimated by
    the fit.  ``hold``: coefficients of ``estimate`` held at the fitted model's values; ``loss``,
    ``f_scale``: the refiner's loss.  Returns the fitted :class:`shipid.identify.batch.OutputErrorRefiner`."""
    from shipid.identify.batch import OutputErrorRefiner, prediction_windows

    if current == "mean":
        mean = {k: float(np.mean([c[k] for c in currents])) for k in ("cx", "cy")}
        currents = [mean] * len(currents)
    elif current != "own":
        raise ValueError(f"current must be 'own' or 'mean', got {current!r}")
    wins, x0 = prediction_windows(model, runs, horizon, every, sample_every=sample_every, initial=list(currents))
    weights = None
    if balance:
        kinds = [getattr(runs[w.attrs["log"]], "run_type", "") for w in wins]
        count = {k: kinds.count(k) for k in set(kinds)}
        weights = [len(wins) / (len(count) * count[k]) for k in kinds]
    unknown = [h for h in hold if h not in estimate]
    if unknown:
        raise ValueError(f"hold: {unknown} are not among the estimated coefficients {tuple(estimate)}")
    ref = OutputErrorRefiner(model, estimate=[e for e in estimate if e not in hold], channels=list(channels),
                             meas_std=dict(meas_std or REFINE_DEFAULTS["meas_std"]), max_nfev=max_nfev,
                             input_hold=input_hold, log_weights=weights, loss=loss, f_scale=f_scale)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return ref.fit(wins, x0=x0)


def in_sample_errors(models: dict, runs, currents, horizon: float = 30.0, start_every: float = 10.0,
                     eval_every: int = 2) -> pd.DataFrame:
    """Open-loop prediction errors of fitted ``models`` (name -> model) on runs they were fitted on (in-sample),
    judged like the held-out runs (:func:`shipid.validation.horizon.horizon_prediction` on the
    ``eval_every``-th 10 Hz sample) but each run started with its own ``currents`` entry (``{"cx", "cy"}``, as
    estimated by the fit; None for models without a current).  The diagnosis of the refinement: does it lower
    the judged error on its own training runs?  Columns ``model``, ``run``, ``run_type``, ``position_error``
    [m], ``heading_error`` [deg] at ``horizon``, one row per start."""
    from shipid.validation.horizon import horizon_prediction

    rows = []
    for lg, c in zip(runs, currents):
        d = _frame(lg, eval_every)
        for name, m in models.items():
            init = c if "cx" in m.state_names else None
            r = horizon_prediction(m, d, horizons=(horizon,), start_every=start_every, initial=init)
            for e, h in zip(r.position_error[:, 0], r.heading_error[:, 0]):
                if not np.isnan(e):
                    rows.append({"model": name, "run": lg.name, "run_type": lg.run_type, "position_error": float(e),
                                 "heading_error": float(h)})
    return pd.DataFrame(rows)


#: Trailing window [s] of the measured true wind behind a held-out start's wind-driven current
#: (``current_start="wind"``; fixed with the round-7 candidate list, docs/environment.md).
DRIFT_WINDOW_S = 60.0


def air_velocity(frame) -> np.ndarray:
    """``(N, 2)`` earth-fixed velocity of the air [m/s] (where the true wind blows *to*) of a frame with
    ``wind_speed_true`` and ``wind_dir_true`` (direction it comes from, measured like the heading)."""
    ws = frame["wind_speed_true"].to_numpy(dtype=float)
    wd = frame["wind_dir_true"].to_numpy(dtype=float)
    return np.column_stack([-ws * np.cos(wd), -ws * np.sin(wd)])


def drift_factor(currents, winds) -> float:
    """Least-squares ``k`` of ``c = k w`` over runs: per-run currents ``(n, 2)`` [m/s] on the runs' mean air
    velocities ``(n, 2)`` (a current driven down the wind, proportional to it, no intercept)."""
    c, w = np.asarray(currents, dtype=float), np.asarray(winds, dtype=float)
    den = float(np.sum(w * w))
    return float(np.sum(c * w) / den) if den > 0 else 0.0


def with_drift_current(frame: pd.DataFrame, k: float, window: float = DRIFT_WINDOW_S) -> pd.DataFrame:
    """``frame`` with columns ``cx, cy`` = ``k`` x the mean air velocity over the trailing ``window`` s up
    to each sample (causal; shorter at the run's start): the start current of a prediction from each
    sample when the current is taken to be wind-driven (:func:`drift_factor`)."""
    t = frame["time"].to_numpy(dtype=float)
    w = air_velocity(frame)
    cs = np.vstack([np.zeros((1, 2)), np.cumsum(w, axis=0)])
    i = np.arange(t.size)
    j0 = np.searchsorted(t, t - window, side="left")
    mean = (cs[i + 1] - cs[j0]) / (i + 1 - j0)[:, None]
    out = frame.copy()
    out["cx"], out["cy"] = k * mean[:, 0], k * mean[:, 1]
    return out


def _fit(model, frames, estimate, substeps, input_hold="foh", gate=5.0, prior_std=1.0):
    from shipid.identify import EKFIdentifier

    extra = model.identifier_settings() if hasattr(model, "identifier_settings") else {}
    pstd = dict(PROCESS_STD, **extra.pop("process_std", {}))
    ident = EKFIdentifier(model, estimate=list(estimate), init="model", meas_std=MEAS_STD, process_std=pstd,
                          n_passes=2, substeps=substeps, input_hold=input_hold, gate=gate, prior_std=prior_std,
                          **extra)
    t0 = time.time()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        ident.fit(frames)
    return ident, time.time() - t0


def _turning_rows(lg, models, every) -> list[dict]:
    """Steady turning of a measured turning run against each model's replay of its inputs (from the
    run's first state, open loop over the whole run): steady diameter / L, steady speed, time to
    turn 360 deg in the steady part (from the mean yaw rate of the last half of the turn)."""
    from shipid.manoeuvres.run_metrics import metrics
    from shipid.simulate import replay

    d = _frame(lg, every)
    out = []

    def row(name, frame):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            m = metrics(frame, lpp=3.0, kind="turning").to_dict()
        psi = np.unwrap(frame["psi"].to_numpy(dtype=float))
        t = frame["time"].to_numpy(dtype=float)
        half = t >= t[0] + 0.5 * (t[-1] - t[0])
        rate = abs(np.polyfit(t[half], psi[half], 1)[0]) if half.sum() > 2 else np.nan
        out.append({"run": lg.name, "model": name, "steady_diameter_L": m.get("steady_diameter_L"),
                    "steady_speed": m.get("steady_speed"), "time_360_s": 2 * np.pi / rate if rate > 0 else np.nan,
                    "success": m.get("success")})

    row("measured", d)
    for name, model in models.items():
        if model.nu == 0:
            continue
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            sim = replay(model, d, substeps=1)
        if not sim.success:
            out.append({"run": lg.name, "model": name, "success": False})
            continue
        f = sim.to_pandas().reset_index()
        row(name, f.assign(delta=d["delta"].to_numpy()))
    return out


#: Calm-water models fitted besides ``lowspeed`` (name -> (model factory, estimated coefficients)):
#: the KVLCC2 MMG set Froude-scaled to 3 m as the prior of an ``mmg`` fit.
CALM_WATER = {"mmg": ("mmg kvlcc2 prior, fitted", ("R0", "Yv", "Yr", "Nv", "Nr", "Yvvv", "Nrrr", "tP", "f_alpha"))}


def assign_folds(runs, folds) -> dict:
    """Run name -> fold.  ``folds="loro"`` (or the number of runs): leave-one-run-out; an integer k: the
    runs dealt round-robin into k folds in file order, run type after run type (so every type is spread
    over the folds)."""
    k = len(runs) if folds in ("loro", None) else int(folds)
    if not 2 <= k <= len(runs):
        raise ValueError(f"folds must be 'loro' or an integer from 2 to the number of runs ({len(runs)}), got {folds!r}")
    return {lg.name: j % k for j, lg in enumerate(runs)}


def run_study(data_dir=DATA_DIR, *, folds="loro", fit_every: int = 20, eval_every: int = 2,
              horizons=(10.0, 30.0, 60.0), start_every: float = 5.0, types=RUN_TYPES, max_runs: int | None = None,
              by_type: bool = True, calm_water=("mmg",), input_hold: str = "foh", gate: float | None = 5.0,
              current: str = "constant", estimate=ESTIMATE, estimate_wind=ESTIMATE_WIND, substeps: int = 2,
              fixed: bool = True, turning: bool = True, all_types: bool = True, progress: bool = True,
              rudder_rate: float | None = None, wind="esso-osaka-3m", by_type_prior: str = "prior",
              prior_params: dict | None = PRIOR_PARAMS, current_start: str = "mean",
              refine: dict | None = None) -> EssoStudy:
    """Fit and cross-validate on the Esso Osaka runs (see the module docstring for every choice).

    Parameters
    ----------
    folds : "loro" or int
        Cross-validation by run (:func:`assign_folds`): each fold is predicted by models fitted on the
        other folds only.
    fit_every, eval_every : int
        Decimation of the 10 Hz logs for fitting and for the horizon predictions.
    by_type : bool
        Also fit per run type (training runs of the held-out run's type only), besides the fit on all types.
    calm_water : sequence of str
        Calm-water models of :data:`CALM_WATER` fitted on all types too.
    input_hold, gate : EKF input hold and innovation gate (the identifier's defaults: ``"foh"``, 5).
    current : {"constant", "random-walk"}
        Current of the environment-aware fits (per run; reset at each run).
    fixed : bool
        Score the models that are not fitted (dead reckoning, KVLCC2 scaled, the prior).
    all_types : bool
        Fit on all run types (with ``False`` only the per-type fits, e.g. to run them on other folds).
    max_runs : int, optional
        At most this many runs per type (the fast mode of the tests and the notebook).
    rudder_rate : float, optional
        Rate-limit the logged rudder angle to this slew rate [deg/s] in fits and predictions
        (:func:`load_runs`; None: as logged).
    by_type_prior : {"prior", "others"}
        Start and prior of the per-type fits: the ``esso-osaka-prior`` set with 100 % std (default), or the
        fit on the training runs of the *other* run types with its estimated stds (sequential Bayes: the
        other types' posterior is this type's prior; no run enters twice).
    prior_params : dict, optional
        Values that replace those of the ``esso-osaka-prior`` set in the start and prior of every
        ``lowspeed`` fit (default :data:`PRIOR_PARAMS`, chosen by cross-validation; ``{}``: the prior set).
    wind : WindForce or "esso-osaka-3m"
        Above-water geometry of the wind force (the prior of the estimated components and the value of the
        others).
    current_start : {"mean", "wind"}
        Start current of a held-out run's predictions: the training runs' mean current (default), or
        wind-driven, ``k`` x the mean air velocity of the trailing :data:`DRIFT_WINDOW_S` before each start,
        ``k`` fitted to the training runs' estimated currents on their mean air velocities
        (:func:`drift_factor`, :func:`with_drift_current`; docs/environment.md).
    refine : dict, optional
        Refine every environment-aware fit on open-loop prediction windows of its training runs
        (:func:`refine_on_windows` with :data:`REFINE_DEFAULTS` updated by this dict); None: the EKF fit.
    """
    from shipid.environment import with_environment
    from shipid.models import get_model
    from shipid.validation.horizon import dead_reckoning, horizon_prediction

    if current_start not in ("mean", "wind"):
        raise ValueError(f"current_start must be 'mean' or 'wind', got {current_start!r}")
    runs = load_runs(data_dir, types, max_runs, rudder_rate=rudder_rate)
    fold_of = assign_folds(runs, folds)
    n_folds = max(fold_of.values()) + 1
    prior = get_model("lowspeed")
    if prior_params:
        prior = prior.with_params(prior_params)
    env0 = with_environment(prior, wind=wind, current=current)
    kvlcc2 = get_model("mmg", "kvlcc2", lpp=prior.lpp)
    fixed_models = {"dead reckoning": dead_reckoning(), "mmg kvlcc2 (Froude-scaled, no fit)": kvlcc2,
                    "lowspeed prior (no fit)": prior,
                    "lowspeed prior + Fujiwara wind (no fit)": with_environment(prior, wind=wind)}
    if not fixed:
        fixed_models = {"dead reckoning": fixed_models["dead reckoning"]}
    rows, coefs, currents, fits, models, turning_rows = [], [], [], {}, {}, []
    errs: dict = {}
    hold = dict(input_hold=input_hold, gate=gate)

    def record(model_name, lg, model, initial=None):
        frame = _frame(lg, eval_every)
        if initial is not None and "k" in initial:   # wind-driven start current, per start
            frame, initial = with_drift_current(frame, initial["k"]), None
        r = horizon_prediction(model, frame, horizons=horizons, start_every=start_every,
                               initial=initial, name=lg.name)
        errs.setdefault((model_name, lg.run_type), []).append(r)

    def strip_wind(frames):
        return [f.drop(columns=[c for c in f.columns if c.startswith("wind")]) for f in frames]

    def stds(ident):
        s = ident.summary()
        return {n: float(s.loc[n, "std"]) for n in s.index if np.isfinite(s.loc[n, "std"]) and s.loc[n, "std"] > 0}

    def fit_pair(train, k, tag, start=None, return_identifiers=False):
        """The plain and the environment-aware lowspeed fits on ``train``; their models and mean current.
        ``start``: ``(plain identifier, environment-aware identifier)`` of an earlier fit whose estimates
        and stds are the prior (sequential Bayes: ``by_type_prior="others"``)."""
        frames = [_frame(lg, fit_every) for lg in train]
        m_p, m_e, ps_p, ps_e = prior, env0, 1.0, 1.0
        if start is not None:
            m_p, m_e, ps_p, ps_e = start[0].to_model(), start[1].to_model(), stds(start[0]), stds(start[1])
        plain, sec0 = _fit(m_p, strip_wind(frames), estimate, substeps, prior_std=ps_p, **hold)
        env, sec1 = _fit(m_e, frames, tuple(estimate) + tuple(estimate_wind), substeps, prior_std=ps_e, **hold)
        fits.setdefault(k, {})[f"lowspeed{tag}"] = {"success": plain.success_, "message": plain.message_,
                                                    "seconds": sec0}
        fits[k][f"lowspeed + wind + current{tag}"] = {"success": env.success_, "message": env.message_,
                                                      "seconds": sec1}
        s = env.summary()
        for name in s.index:
            coefs.append({"fold": k, "fit": tag.strip(" ()") or "all types", "parameter": name,
                          "value": s.loc[name, "value"], "std": s.loc[name, "std"]})
        cc, ww = [], []
        for st, f in zip(env.states_, frames):
            row = {"fold": k, "fit": tag.strip(" ()") or "all types", "run": f.attrs["name"],
                   "cx": st.cx.iloc[0], "cx_std": st.cx_std.iloc[0], "cy": st.cy.iloc[0], "cy_std": st.cy_std.iloc[0]}
            currents.append(row)
            cc.append((row["cx"], row["cy"]))
            ww.append(air_velocity(f).mean(axis=0))
        c_mean = np.mean(cc, axis=0) if cc else (0.0, 0.0)
        if return_identifiers:
            return plain, env
        m_env = env.to_model()
        if refine is not None:
            t0 = time.time()
            ref = refine_on_windows(m_env, train, [{"cx": c[0], "cy": c[1]} for c in cc],
                                    estimate=tuple(estimate) + tuple(estimate_wind), **{**REFINE_DEFAULTS, **refine})
            m_env = ref.to_model()
            fits[k][f"lowspeed + wind + current{tag} refined"] = {
                "success": ref.success_, "message": ref.message_, "seconds": time.time() - t0, "nfev": ref.nfev_,
                "cost_start": ref.cost_start_, "cost": ref.cost_}
            for name in ref.estimated_:
                coefs.append({"fold": k, "fit": (tag.strip(" ()") or "all types") + " refined", "parameter": name,
                              "value": float(ref.coef_[name]), "std": float(ref.coef_std_[name])})
        if current_start == "wind":
            kd = drift_factor(cc, ww)
            coefs.append({"fold": k, "fit": tag.strip(" ()") or "all types", "parameter": "drift_k",
                          "value": kd, "std": np.nan})
            return plain.to_model(), m_env, {"k": kd}
        return plain.to_model(), m_env, {"cx": float(c_mean[0]), "cy": float(c_mean[1])}

    it = range(n_folds)
    if progress:
        from tqdm.auto import tqdm

        it = tqdm(it, desc="folds")
    for k in it:
        train = [lg for lg in runs if fold_of[lg.name] != k]
        test = [lg for lg in runs if fold_of[lg.name] == k]
        if not test:
            continue
        if not train:
            raise ValueError("run_study: a fold has no training runs; use folds >= 2 and at least two runs")
        for lg in test:
            for nm, m in fixed_models.items():
                record(nm, lg, m)
        models[k] = {}
        c_mean = None
        if all_types:
            m_plain, m_env, c_mean = fit_pair(train, k, "")
            models[k] = {"lowspeed fitted (no environment)": m_plain, "lowspeed + wind + current fitted": m_env}
        frames = [_frame(lg, fit_every) for lg in train]
        for cw in (calm_water if all_types else ()):
            label, est = CALM_WATER[cw]
            ident, sec = _fit(kvlcc2, strip_wind(frames), est, substeps, **hold)
            fits[k][label] = {"success": ident.success_, "message": ident.message_, "seconds": sec}
            models[k][label] = ident.to_model()
        for lg in test:
            for nm, m in models[k].items():
                record(nm, lg, m, initial=c_mean if "current" in nm else None)
        if by_type:
            for kind in sorted({lg.run_type for lg in test}):
                same = [lg for lg in train if lg.run_type == kind]
                if not same:
                    continue
                start = None
                if by_type_prior == "others":
                    others = [lg for lg in train if lg.run_type != kind]
                    start = fit_pair(others, k, f" (not {kind})", return_identifiers=True) if others else None
                tp, te, tc = fit_pair(same, k, f" ({kind})", start=start)
                models[k][f"lowspeed fitted by type ({kind})"] = tp
                models[k][f"lowspeed + wind + current fitted by type ({kind})"] = te
                for lg in [t for t in test if t.run_type == kind]:
                    record("lowspeed fitted by type (no environment)", lg, tp)
                    record("lowspeed + wind + current fitted by type", lg, te, initial=tc)
        if turning:
            for lg in test:
                if lg.run_type == "turning":
                    mk = {nm: m for nm, m in models[k].items() if "by type" not in nm or "turning" in nm}
                    turning_rows.extend(_turning_rows(lg, {**fixed_models, **mk}, eval_every))
    for (model_name, kind), results in errs.items():
        for j, H in enumerate(results[0].horizons):
            pe = np.concatenate([r.position_error[:, j] for r in results])
            he = np.concatenate([r.heading_error[:, j] for r in results])
            ok = ~np.isnan(pe)
            rows.append({"model": model_name, "run_type": kind, "seconds": float(H), "n_runs": len(results),
                         "n_starts": int(ok.sum()), "n_blowups": int(np.isinf(pe[ok]).sum()),
                         "position_error_median_m": float(np.median(pe[ok])) if ok.any() else np.nan,
                         "position_error_p90_m": float(np.percentile(pe[ok], 90)) if ok.any() else np.nan,
                         "heading_error_median_deg": float(np.median(he[ok])) if ok.any() else np.nan})
    return EssoStudy(horizon=pd.DataFrame(rows), coefficients=pd.DataFrame(coefs), currents=pd.DataFrame(currents),
                     turning=pd.DataFrame(turning_rows), fits=fits, models=models,
                     settings={"folds": folds, "n_folds": n_folds, "fit_every": fit_every, "eval_every": eval_every,
                               "start_every": start_every, "runs": [lg.name for lg in runs], "fold_of": fold_of,
                               "input_hold": input_hold, "gate": gate, "current": current,
                               "estimate": list(estimate), "estimate_wind": list(estimate_wind),
                               "rudder_rate": rudder_rate, "by_type_prior": by_type_prior,
                               "prior_params": dict(prior_params or {}), "current_start": current_start,
                               "refine": None if refine is None else {**REFINE_DEFAULTS, **refine},
                               "wind": getattr(wind, "to_dict", lambda: wind)()})


def split_position_error(dt: float, meas: dict, pred: dict) -> dict:
    """Which predicted quantity makes an open-loop position error: the measured track re-integrated
    (trapezoid, sample spacing ``dt``) with one predicted quantity swapped in.

    ``meas``, ``pred``: arrays ``psi, u, v`` over the prediction window (body velocities over ground).
    Returns the end-point distances [m] of the re-integrated track from the measured one's integral:
    ``heading`` (predicted heading, measured u, v), ``velocity`` (measured heading, predicted u, v),
    ``u`` and ``v`` (only that velocity predicted).  Each is the error that quantity alone would make."""
    def end(psi, u, v):
        c, s = np.cos(psi), np.sin(psi)
        xd, yd = u * c - v * s, u * s + v * c
        return np.array([np.sum(xd[1:] + xd[:-1]), np.sum(yd[1:] + yd[:-1])]) * (0.5 * dt)

    ref = end(meas["psi"], meas["u"], meas["v"])
    cases = {"heading": (pred["psi"], meas["u"], meas["v"]), "velocity": (meas["psi"], pred["u"], pred["v"]),
             "u": (meas["psi"], pred["u"], meas["v"]), "v": (meas["psi"], meas["u"], pred["v"])}
    return {k: float(np.hypot(*(end(*a) - ref))) for k, a in cases.items()}


def _fold_current(study: "EssoStudy", k) -> pd.Series:
    """The mean current (``cx``, ``cy``) of fold ``k``'s all-types fit: the start of its predictions."""
    c = study.currents
    return c[(c.fold == k) & (c.fit == "all types")][["cx", "cy"]].mean()


def _run_currents(study: "EssoStudy") -> pd.DataFrame:
    """Per run (index): the current (``cx``, ``cy``) estimated for it by the all-types fits that trained on it,
    mean over those folds."""
    return study.currents[study.currents.fit == "all types"].groupby("run")[["cx", "cy"]].mean()


def _held_out_prediction(study: "EssoStudy", lg, model: str, horizon: float, start_every: float):
    """Run ``lg`` (its evaluation frame) and its open-loop ``horizon`` s predictions by the fold model of
    ``study`` that did not see it, started with that fold's mean current: ``(frame, HorizonResult, model)``."""
    from shipid.validation.horizon import horizon_prediction

    k = study.settings["fold_of"][lg.name]
    m = study.models[k][model]
    cur = _fold_current(study, k)
    d = _frame(lg, study.settings["eval_every"])
    init = {"cx": float(cur.cx), "cy": float(cur.cy)} if "cx" in m.state_names else None
    return d, horizon_prediction(m, d, horizons=(horizon,), start_every=start_every, initial=init), m


def error_diagnosis(study: "EssoStudy", run_type: str = "zigzag", horizon: float = 30.0,
                    model: str = "lowspeed + wind + current fitted", data_dir=DATA_DIR,
                    start_every: float = 5.0, runs=None) -> pd.DataFrame:
    """Per start of the held-out runs of ``run_type``: what the ``horizon`` s position error is made of.

    Each run is predicted by the fold model of ``study`` that did not see it (all-types fit, started with
    that fit's mean current), as in :func:`run_study`.  Columns: ``error`` (position, m), the
    :func:`split_position_error` parts ``e_heading``, ``e_velocity``, ``e_u``, ``e_v``; the errors at the
    horizon (predicted − measured) ``d_psi_deg``, ``d_u``, ``d_v``, ``d_r``; the measured ``r_end``, ``v_end``
    (whose signs tell a port from a starboard turn); and ``t_v``, ``t_r``, ``t_u``, ``t_psi``: the first time
    [s] the error of v exceeds 0.02 m/s, of r 0.01 rad/s, of u 0.03 m/s, of heading 5 deg (NaN: never).
    ``runs``: the logs (``name``, ``run_type``, ``data``; default the ``run_type`` runs of ``data_dir``)."""
    rows = []
    for lg in load_runs(data_dir, (run_type,)) if runs is None else runs:
        d, r, m = _held_out_prediction(study, lg, model, horizon, start_every)
        X, tt = r.tracks["x"], r.tracks["t"]
        dt = tt[1] - tt[0]
        kh = int(round(horizon / dt))
        t = d["time"].to_numpy()
        for i, t0 in enumerate(r.start_times):
            k0 = int(np.searchsorted(t, t0))
            if k0 + kh >= t.size:
                continue
            sl = slice(k0, k0 + kh + 1)
            meas = {s: d[s].to_numpy()[sl] for s in ("x", "y", "psi", "u", "v", "r")}
            pred = {s: X[i, : kh + 1, m.state_index(s)] for s in meas}
            err = {s: pred[s] - meas[s] for s in ("u", "v", "r")}
            err["psi"] = np.degrees(np.angle(np.exp(1j * (pred["psi"] - meas["psi"]))))

            def first(e, thr):
                j = int(np.argmax(np.abs(e) > thr))
                return float(tt[j]) if abs(e[j]) > thr else np.nan

            parts = split_position_error(dt, meas, pred)
            rows.append({"run": lg.name, "start_time": float(t0),
                         "error": float(np.hypot(pred["x"][-1] - meas["x"][-1], pred["y"][-1] - meas["y"][-1])),
                         **{f"e_{k_}": v for k_, v in parts.items()},
                         "d_psi_deg": float(err["psi"][-1]), "d_u": float(err["u"][-1]), "d_v": float(err["v"][-1]),
                         "d_r": float(err["r"][-1]), "r_end": float(meas["r"][-1]), "v_end": float(meas["v"][-1]),
                         "t_v": first(err["v"], 0.02), "t_r": first(err["r"], 0.01), "t_u": first(err["u"], 0.03),
                         "t_psi": first(err["psi"], 5.0)})
    return pd.DataFrame(rows)


def current_vs_wind(study: "EssoStudy", data_dir=DATA_DIR, runs=None) -> pd.DataFrame:
    """Per run: the current estimated for it by the all-types fits that trained on it (mean over those folds)
    and its components along (``c_down`` = c.w/|w|) and across (``c_cross`` = (wx cy - wy cx)/|w|) the run's mean
    air velocity ``wx, wy`` (where the true wind blows to; :func:`air_velocity`), with ``ratio`` = ``c_down`` /
    |w| (the diagnosis of a current driven down the wind)."""
    c = _run_currents(study)
    rows = []
    for lg in load_runs(data_dir) if runs is None else runs:
        if lg.name not in c.index:
            continue
        w = air_velocity(lg.data).mean(axis=0)
        cx, cy = c.loc[lg.name]
        W = float(np.hypot(*w))
        down, cross = (cx * w[0] + cy * w[1]) / W, (-cx * w[1] + cy * w[0]) / W
        rows.append({"run": lg.name, "run_type": lg.run_type, "wx": w[0], "wy": w[1], "cx": cx, "cy": cy,
                     "c_down": down, "c_cross": cross, "ratio": down / W})
    return pd.DataFrame(rows)


def start_current_floor(study: "EssoStudy", model: str = "lowspeed + wind + current fitted", data_dir=DATA_DIR,
                        horizons=(10.0, 30.0, 60.0)) -> pd.DataFrame:
    """Median position error [m] per run type and horizon of the fold models (as :func:`run_study`) with the
    held-out run started from: the fold's mean current (``"fold mean"``, the study's protocol), zero
    current, the run's **own** current as estimated by the folds that trained on it (``"own (oracle)"``: it
    uses the run's data, a floor, not a predictor), and the fold mean with the measured start ``u, v, r``
    replaced by a 2 s quadratic Savitzky-Golay fit (``"smoothed start"``: what the start state's noise costs)."""
    from scipy.signal import savgol_filter

    from shipid.validation.horizon import horizon_prediction

    own = _run_currents(study)
    fold_of, every = study.settings["fold_of"], study.settings["eval_every"]
    errs: dict = {}
    for lg in load_runs(data_dir):
        if lg.name not in fold_of:
            continue
        k = fold_of[lg.name]
        m = study.models[k][model]
        fm = {n: float(v) for n, v in _fold_current(study, k).items()}
        sm = lg.data.copy()
        for s in ("u", "v", "r"):
            sm[s] = savgol_filter(sm[s].to_numpy(dtype=float), 21, 2)
        cases = {"fold mean": (lg.data, fm), "zero": (lg.data, {"cx": 0.0, "cy": 0.0}),
                 "own (oracle)": (lg.data, {n: float(v) for n, v in own.loc[lg.name].items()}),
                 "smoothed start": (sm, fm)}
        for case, (d, init) in cases.items():
            r = horizon_prediction(m, d.iloc[::every].reset_index(drop=True), horizons=horizons,
                                   start_every=study.settings["start_every"], initial=init)
            errs.setdefault((case, lg.run_type), []).append(r.position_error)
    rows = [{"start": case, "run_type": kind, "seconds": float(H),
             "position_error_median_m": float(np.nanmedian(np.concatenate(v)[:, j]))}
            for (case, kind), v in errs.items() for j, H in enumerate(horizons)]
    return pd.DataFrame(rows)


def anemometer_check(data_dir=DATA_DIR, runs=None) -> pd.DataFrame:
    """A physics check of the logged wind against the ship's own motion (docs/environment.md).

    The logged true wind is the apparent wind converted with the logged ``psi, u, v``.  If the anemometer
    had a constant direction offset ``phi0`` or gain ``s`` (``s e^{i phi0}`` times the apparent air velocity,
    complex, body axes), the logged true air velocity ``W_log`` (earth, complex, where the wind blows to)
    would be ``s e^{i phi0} W + (1 - s e^{i phi0}) V``, ``V`` the ship's velocity over ground: a term that
    follows the ship.  Per run, the complex least-squares coefficient ``m`` of ``W_log`` on ``V`` (both less
    their means) estimates ``1 - s e^{i phi0}`` (0 for a correct sensor; a 10 deg offset gives ``|m|`` 0.17)
    if the real wind does not follow the ship.  Columns: ``run``, ``run_type``, ``m_re``, ``m_im``,
    ``wind_std``, ``speed_std`` [m/s] (the scatter of ``W_log`` and of ``V``)."""
    rows = []
    for lg in load_runs(data_dir) if runs is None else runs:
        d = lg.data
        w = air_velocity(d) @ np.array([1.0, 1j])
        V = (d.u.to_numpy(dtype=float) + 1j * d.v.to_numpy(dtype=float)) * np.exp(1j * d.psi.to_numpy(dtype=float))
        w, V = w - w.mean(), V - V.mean()
        m = np.vdot(V, w) / np.vdot(V, V)
        rows.append({"run": lg.name, "run_type": lg.run_type, "m_re": float(m.real), "m_im": float(m.imag),
                     "wind_std": float(np.sqrt(np.mean(np.abs(w) ** 2))), "speed_std": float(np.sqrt(np.mean(np.abs(V) ** 2)))})
    return pd.DataFrame(rows)


def path_relative_error(study: "EssoStudy", model: str = "lowspeed + wind + current fitted", horizon: float = 30.0,
                        data_dir=DATA_DIR, runs=None, start_every: float = 5.0) -> pd.DataFrame:
    """Per start of every held-out run: the ``horizon`` s position error of the fold model that did not see
    the run (all-types fit, started with that fit's mean current, as :func:`run_study`) beside the path the
    ship measured in that time (sum of the distances between the samples) and the median propeller rate.
    Columns ``run``, ``run_type``, ``error``, ``path`` [m], ``n`` [rps]; ``error / path`` is the error per
    metre sailed, which compares run types of different speeds (docs/environment.md)."""
    rows = []
    for lg in load_runs(data_dir) if runs is None else runs:
        d, r, _ = _held_out_prediction(study, lg, model, horizon, start_every)
        t = d["time"].to_numpy(dtype=float)
        x, y, n = d.x.to_numpy(dtype=float), d.y.to_numpy(dtype=float), d.n.to_numpy(dtype=float)
        s = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(x), np.diff(y)))])
        for i, t0 in enumerate(r.start_times):
            e = r.position_error[i, 0]
            k0, k1 = int(np.searchsorted(t, t0)), int(np.searchsorted(t, t0 + horizon))
            if np.isnan(e) or k1 >= t.size:
                continue
            rows.append({"run": lg.name, "run_type": lg.run_type, "error": float(e), "path": float(s[k1] - s[k0]),
                         "n": float(np.median(n[k0:k1 + 1]))})
    return pd.DataFrame(rows)


def residual_accelerations(study: "EssoStudy", candidates=("YPf", "NPf", "delta0", "CrY", "CrN"),
                           model: str = "lowspeed + wind + current fitted", data_dir=DATA_DIR,
                           every: int = 2, window: int = 21, runs=None) -> pd.DataFrame:
    """Equation error of the fold models on the runs they did not see: per sample (every ``every``-th of the
    10 Hz log), the measured sway and yaw accelerations (Savitzky-Golay derivative over ``window`` samples,
    quadratic) minus the fold model's at the measured state, inputs and wind (current: the fold's mean, as
    in :func:`run_study`), as ``ev`` [m/s^2] and ``er`` [rad/s^2], with the model's sensitivities
    ``Jv_<name>``, ``Jr_<name>`` of those accelerations to the ``lowspeed`` parameters ``candidates`` (the
    fold's fitted values, rebuilt on the current equations so that parameters added since are at their
    defaults).  Regressing ``ev, er`` on a candidate's columns says how much of the residual it could take.
    ``runs``: the logs (``name``, ``run_type``, ``data``; default :func:`load_runs` of ``data_dir``)."""
    from scipy.signal import savgol_filter

    from shipid.environment import with_environment
    from shipid.models import get_model

    base = get_model("lowspeed").with_params(study.settings.get("prior_params") or {})
    env = with_environment(base, wind=study.settings.get("wind") or "esso-osaka-3m", current="constant")
    fold_of = study.settings["fold_of"]
    rows = []
    for lg in load_runs(data_dir) if runs is None else runs:
        k = fold_of[lg.name]
        fitted = study.models[k][model]
        ps = dict(zip(fitted.param_names, fitted.params))
        m = env.with_params({n: ps[n] for n in env.param_names if n in ps})
        cur = _fold_current(study, k)
        d = lg.data
        t = d["time"].to_numpy(dtype=float)
        dt = float(np.median(np.diff(t)))
        X = np.column_stack([d.x, d.y, np.unwrap(d.psi.to_numpy(dtype=float)), d.u, d.v, d.r,
                             np.full(len(d), cur.cx), np.full(len(d), cur.cy)])
        U = d[list(m.input_names)].to_numpy(dtype=float)
        vd = savgol_filter(d.v.to_numpy(dtype=float), window, 2, deriv=1, delta=dt)
        rd = savgol_filter(d.r.to_numpy(dtype=float), window, 2, deriv=1, delta=dt)
        jc = [m.param_index(c) for c in candidates]
        idx = np.arange(window // 2, len(d) - window // 2, every)
        f = m.rhs(0.0, X[idx], U[idx])      # all samples as one batch (the models are time-invariant)
        J = m.jac_p(0.0, X[idx], U[idx])
        block = {"run": lg.name, "run_type": lg.run_type, "time": t[idx], "u": X[idx, 3], "v": X[idx, 4],
                 "r": X[idx, 5], "delta": U[idx, 0], "n": U[idx, 1], "ev": vd[idx] - f[:, 4], "er": rd[idx] - f[:, 5]}
        for c, j in zip(candidates, jc):
            block["Jv_" + c], block["Jr_" + c] = J[:, 4, j], J[:, 5, j]
        rows.append(pd.DataFrame(block))
    return pd.concat(rows, ignore_index=True) if rows else pd.DataFrame()


#: The study's chosen scope of the fit for a left-out run of each type (docs/environment.md): the training runs of
#: its own type, except zigzags, fitted on all types (only six zigzag training runs).
CHOSEN_SCOPE = {"turning": "type", "zigzag": "all", "random": "type", "berthing": "type"}


def recipe_loro(data_dir=DATA_DIR, *, types=RUN_TYPES, horizons=(10.0, 30.0, 60.0), start_every: float = 5.0,
                scope=None, fit_options=None, sampling: str = "default") -> pd.DataFrame:
    """Leave-one-run-out through the product's path, as a user runs it: ``shipid fit --schema esso-frt --model
    lowspeed --wind --current`` (:func:`shipid.identify.fit_logs` with its defaults, on the files as read by the
    CLI) on the training runs of the chosen scope (:data:`CHOSEN_SCOPE`, or ``scope`` per type), then `shipid
    validate --horizon`'s prediction of the left-out run at full rate, from its measured states and the fit's
    mean current.  One row per left-out run and horizon: the position errors of its finished starts
    (``errors``, blow-ups as inf), their number and the blow-ups, the training runs' number, the fit's success.
    ``fit_options``: further keyword arguments of :func:`~shipid.identify.fit_logs`; ``sampling="rule"``: the
    recipe's time-constant rule (:func:`~shipid.identify.recipe.choose_sampling`) instead of the model's default
    step."""
    from shipid.environment import with_environment
    from shipid.identify.recipe import choose_sampling, current_start, fit_logs
    from shipid.logs import read_log
    from shipid.models import get_model
    from shipid.validation.horizon import horizon_prediction

    if sampling not in ("default", "rule"):
        raise ValueError(f"sampling={sampling!r}: use 'default' or 'rule'")
    scope = {**CHOSEN_SCOPE, **dict(scope or {})}
    runs = []
    for kind in types:
        for f in sorted(glob.glob(str(Path(data_dir) / kind / "*.csv"))):
            if Path(f).stem in DUPLICATES:
                continue
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", UserWarning)
                lg = read_log(f, schema="esso-frt")
            runs.append((kind, lg))
    rows = []
    for kind, held in runs:
        train = [lg for k2, lg in runs if lg is not held and (scope[kind] == "all" or k2 == kind)]
        model = with_environment(get_model("lowspeed"), wind="esso-osaka-3m", current="constant")
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            opts = dict(fit_options or {})
            if sampling == "rule":
                opts["dt"] = choose_sampling(model, train)[0]
            fit = fit_logs(train, model, ekf_options=model.identifier_settings(), start_defaults=True, **opts)
            cs = current_start(fit.ekf)  # what the result JSON carries for validate (no full result needed)
            h = horizon_prediction(fit.to_model(), held, horizons=horizons, start_every=start_every,
                                   initial={"cx": cs["cx"], "cy": cs["cy"]}, name=held.name)
        for j, H in enumerate(h.horizons):
            pe = h.position_error[:, j]
            ok = ~np.isnan(pe)
            rows.append({"run": held.name, "run_type": kind, "seconds": float(H), "n_train": len(train),
                         "success": bool(fit.success), "n_starts": int(ok.sum()),
                         "n_blowups": int(np.isinf(pe[ok]).sum()), "errors": pe[ok]})
    return pd.DataFrame(rows)


def _main(argv=None):  # pragma: no cover - the full study (slow): python -m studies.esso_osaka
    import argparse
    import pickle

    ap = argparse.ArgumentParser(description="Esso Osaka cross-validated study")
    ap.add_argument("--folds", default="loro")
    ap.add_argument("--input-hold", default="foh")
    ap.add_argument("--gate", default="5")
    ap.add_argument("--current", default="constant")
    ap.add_argument("--fit-every", type=int, default=20)
    ap.add_argument("--estimate", default=",".join(ESTIMATE))
    ap.add_argument("--estimate-extra", default="", help="comma-separated coefficients estimated besides --estimate")
    ap.add_argument("--no-by-type", action="store_true")
    ap.add_argument("--no-calm-water", action="store_true")
    ap.add_argument("--no-turning", action="store_true")
    ap.add_argument("--no-all-types", action="store_true", help="only the per-type fits")
    ap.add_argument("--no-fixed", action="store_true", help="score dead reckoning only of the unfitted models")
    ap.add_argument("--rudder-rate", type=float, default=None,
                    help="rate-limit the logged rudder angle [deg/s]; 'froude' below")
    ap.add_argument("--froude-rudder-rate", action="store_true",
                    help=f"--rudder-rate {FROUDE_RUDDER_RATE_DEG_S:.1f} (IMO 2.32 deg/s Froude-scaled to 3 m)")
    ap.add_argument("--wind-cbr", type=float, default=None,
                    help="superstructure centroid C_BR [m] of the wind geometry (default: the esso_osaka_3m preset)")
    ap.add_argument("--by-type-prior", default="prior", choices=("prior", "others"))
    ap.add_argument("--set", default="", help="comma-separated name=value replacing values of the lowspeed prior "
                    f"(start and prior of every fit), on top of {PRIOR_PARAMS} (dgammaR=0: the setting before)")
    ap.add_argument("--current-start", default="mean", choices=("mean", "wind"),
                    help="start current of held-out predictions: training mean, or wind-driven")
    ap.add_argument("--refine", default=None, choices=tuple(REFINE_CANDIDATES),
                    help="refine the environment-aware fits on open-loop prediction windows (candidates scored and not kept)")
    ap.add_argument("--save", help="pickle the EssoStudy here")
    a = ap.parse_args(argv)
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    from dataclasses import replace

    from shipid.environment import WindForce

    wind = "esso-osaka-3m" if a.wind_cbr is None else replace(WindForce.esso_osaka_3m(), C_BR=a.wind_cbr)
    rate = FROUDE_RUDDER_RATE_DEG_S if a.froude_rudder_rate else a.rudder_rate
    t0 = time.time()
    res = run_study(folds=a.folds if a.folds == "loro" else int(a.folds), input_hold=a.input_hold,
                    gate=None if a.gate.lower() == "none" else float(a.gate), current=a.current,
                    fit_every=a.fit_every, estimate=tuple(a.estimate.split(",")) + tuple(x for x in a.estimate_extra.split(",") if x), by_type=not a.no_by_type,
                    calm_water=() if a.no_calm_water else ("mmg",), turning=not a.no_turning,
                    all_types=not a.no_all_types, fixed=not a.no_fixed, progress=False, rudder_rate=rate, wind=wind,
                    by_type_prior=a.by_type_prior, current_start=a.current_start,
                    refine=None if a.refine is None else REFINE_CANDIDATES[a.refine],
                    prior_params={**PRIOR_PARAMS, **{k: float(v) for k, v in (x.split("=") for x in a.set.split(",") if x)}})
    print(f"settings: {res.settings | {'runs': len(res.settings['runs']), 'fold_of': '...'}}; {time.time() - t0:.0f} s")
    with pd.option_context("display.width", 200, "display.max_rows", 500, "display.float_format", "{:.3f}".format):
        for H in (10.0, 30.0, 60.0):
            print(f"median position error after {H:g} s [m]")
            print(res.table(H).to_string())
        print(res.horizon.to_string())
        if len(res.coefficients):
            c = res.coefficients[res.coefficients.fit == "all types"]
            print(c.groupby("parameter")[["value", "std"]].agg(["median", "min", "max"]).to_string())
        if len(res.currents):
            print(res.currents[["cx", "cy"]].describe().to_string())
        if len(res.turning):
            print(res.turning.groupby("model")[["steady_diameter_L", "steady_speed", "time_360_s"]].median().to_string())
        print({k: {m: (v["success"], round(v["seconds"], 1)) for m, v in f.items()} for k, f in res.fits.items()})
        if not a.no_all_types:
            print(res.goals().to_string())
        print(res.markdown())
    if a.save:
        with open(a.save, "wb") as fh:
            pickle.dump(res, fh)


if __name__ == "__main__":  # pragma: no cover
    _main()
