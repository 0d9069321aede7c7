"""Sampling rules of the fit recipe: the EKF's sampling step from the start model's time constants, the
linear range of a model linear in v and r, and resampling of logs (every k-th sample, one common grid).
Steps 2 and 2b of :mod:`shipid.identify.recipe`."""
from __future__ import annotations

import math
import warnings

import numpy as np

from ..logs import TrialLog
from .plausibility import time_constant_at

__all__ = ["choose_sampling", "fastest_time_constant", "common_grid", "linear_sway_yaw", "linear_window", "LINEAR_DRIFT_DEG", "SAMPLES_PER_TAU"]

#: Samples per fastest time constant of the model at the EKF step (RK4 with h = tau/25 is accurate to ~1e-7
#: per step); a model may set its own (``recipe_defaults.samples_per_tau``).  Finer is not better for every
#: model: at 50 (every MARIN KVLCC2 sample) the kcs-response refinement stops on its 60-evaluation limit on the
#: KVLCC2 training runs.
SAMPLES_PER_TAU = 25
#: Drift angle [deg] up to which :func:`linear_window` uses a log for a model linear in v and r: the usual
#: range of linear hull manoeuvring derivatives (drift of a few degrees up to about 10; beyond it cross-flow
#: drag grows with v|v|).  Taken as that usual value, not tuned: 6 and 10 deg were both tried on the KVLCC2
#: training runs (tc+-35, zz+-10) and give the same (physical) yaw signs; the hold-out runs were not used.
LINEAR_DRIFT_DEG = 10.0
#: Samples slower than this fraction of a log's 90th-percentile speed are not tested against
#: :data:`LINEAR_DRIFT_DEG` (the drift angle is undefined near rest).  A round value, not tuned: the
#: MARIN runs never come below it (their linear windows are unchanged); it keeps logs that start from
#: rest from being cut at their first sample.
DRIFT_SPEED_FRACTION = 0.25
#: Fewest samples a log keeps in the linear range to be fitted at all (fewer: the log is left out, and said).
MIN_WINDOW_SAMPLES = 20


def every_kth(k: int) -> str:
    """``"every sample"``, ``"every 2nd sample"``, ``"every 3rd sample"``, ``"every 4th sample"``, ..."""
    if k == 1:
        return "every sample"
    suffix = "th" if 10 <= k % 100 <= 20 else {1: "st", 2: "nd", 3: "rd"}.get(k % 10, "th")
    return f"every {k}{suffix} sample"


def _approach_speed(logs) -> float:
    speeds = []
    for lg in logs:
        u = np.asarray(lg["u"], dtype=float)[:20]
        v = np.asarray(lg["v"], dtype=float)[:20] if "v" in lg.channels else 0.0
        U = np.hypot(u, v)
        if np.isfinite(U).any():
            speeds.append(float(np.nanmean(U)))
    if not speeds:
        raise ValueError("no log has a measured approach speed (u)")
    return float(np.median(speeds))


def _speed_scale(logs) -> tuple[float, str]:
    """The speed U of the own-damping margin's time scale L/U (step 6b): the approach speed
    (:func:`_approach_speed`), or the median speed over all samples when the logs start from rest (approach
    speed below a tenth of it); ``(nan, why)`` when neither is positive."""
    sp = np.concatenate([np.hypot(np.asarray(lg["u"], dtype=float),
                                  np.asarray(lg["v"], dtype=float) if "v" in lg.channels else 0.0) for lg in logs])
    sp = sp[np.isfinite(sp)]
    med = float(np.median(sp)) if sp.size else float("nan")
    try:
        U0 = _approach_speed(logs)
    except ValueError:
        U0 = float("nan")
    if np.isfinite(U0) and U0 > 0 and not (med > 10.0 * U0):
        return U0, "the approach speed"
    if np.isfinite(med) and med > 0:
        return med, "the median speed (the logs start from rest)"
    return float("nan"), "no log moves"


def _log_step(logs) -> float:
    """The coarsest of the logs' median sample steps [s]."""
    return max(float(np.median(np.diff(lg.time))) for lg in logs if lg.time.size > 1)


def fastest_time_constant(model, logs) -> tuple[float, float, str]:
    """``(tau [s], U [m/s], where U comes from)``: the fastest time constant of ``model``'s surge, sway and yaw
    (its Jacobian's largest decay rate) in straight running at the logs' approach speed U (or the median speed
    of logs that start from rest), with the propeller rate that holds that speed.  ValueError when unknown."""
    U, speed_why = _speed_scale(logs)  # the approach speed, or the median speed of logs that start from rest
    if not U > 0:
        raise ValueError(speed_why)
    return time_constant_at(model, U), U, speed_why


def choose_sampling(model, logs, samples_per_tau: int | None = None) -> tuple[int, str]:
    """Every how many samples of the logs the EKF uses, and why (see the module docstring, step 2);
    ``samples_per_tau`` default: the model's ``recipe_defaults.samples_per_tau``, else :data:`SAMPLES_PER_TAU`."""
    if samples_per_tau is None:
        samples_per_tau = model.recipe_defaults.samples_per_tau or SAMPLES_PER_TAU
    dt_log = _log_step(logs)
    try:
        tau, U, speed_why = fastest_time_constant(model, logs)
    except (ValueError, np.linalg.LinAlgError) as exc:
        return 1, f"every sample (log step {dt_log:.3g} s): the model's time constants are unknown ({exc})"
    k = max(1, int(math.floor(tau / samples_per_tau / dt_log + 1e-9)))
    return k, (f"{every_kth(k)} ({k * dt_log:.3g} s): fastest time constant of the start model at "
               f"{speed_why} of the logs, {U:.3g} m/s, is {tau:.3g} s, >= {samples_per_tau} steps per time "
               f"constant, log step {dt_log:.3g} s")


def linear_sway_yaw(model) -> bool:
    """True when every regressor of the model's sway and yaw equations is at most linear in ``v, r``:
    ``jac_p`` of the ``v`` and ``r`` rows changes by exactly twice as much from ``v = r = 0`` to
    ``(2 v, 2 r)`` as to ``(v, r)`` (any speed, rudder, propeller rate).  A model with cross-flow terms
    (``v|v|``, ``r|r|``, ``v^2 r / u``: ``response-nl``, ``mmg``) is not linear."""
    if not all(s in model.state_names for s in ("u", "v", "r")):
        return False
    rows = [model.state_index("v"), model.state_index("r")]
    x = np.zeros(model.nx)
    x[model.state_index("u")] = 5.0
    u_in = np.full(model.nu, 0.1)
    if "n" in model.input_names:
        u_in[model.input_index("n")] = 1.0
    J = []
    for f in (0.0, 1.0, 2.0):
        x[rows] = f * np.array([0.3, 0.01])
        J.append(np.asarray(model.jac_p(0.0, x, u_in), dtype=float)[rows])
    return bool(np.allclose(J[2] - J[0], 2.0 * (J[1] - J[0]), rtol=1e-9, atol=1e-12))


def linear_window(log, max_drift_deg: float = LINEAR_DRIFT_DEG):
    """The log up to (not including) the first sample whose drift angle ``atan2(|v|, u)`` exceeds
    ``max_drift_deg``; the whole log when it never does.  Keeps name, ship and provenance; a note says
    what was left out.

    Near rest the drift angle is undefined (a log that starts from rest, as the Esso Osaka runs do, has
    |v| ~ u ~ noise there), so samples slower than :data:`DRIFT_SPEED_FRACTION` of the log's 90th-percentile
    speed are not tested: they neither cut the log nor count as drift."""
    if "v" not in log.channels:
        return log
    u, v = np.asarray(log["u"], dtype=float), np.asarray(log["v"], dtype=float)
    beta = np.degrees(np.arctan2(np.abs(v), u))
    speed = np.hypot(u, v)
    fast = speed >= DRIFT_SPEED_FRACTION * np.nanpercentile(speed, 90) if np.isfinite(speed).any() else speed > 0
    out = np.flatnonzero(np.isfinite(beta) & fast & (beta > max_drift_deg))
    if not out.size:
        return log
    end = int(out[0])
    return TrialLog(log.data.iloc[:end].reset_index(drop=True), name=log.name, ship=log.ship, path=log.path,
                    sha256=log.sha256, rows=log.rows[:end], units_in=log.units_in,
                    notes=list(log.notes) + [f"samples from t = {log.time[end]:.4g} s on left out: drift angle "
                                             f"{beta[end]:.3g} deg above {max_drift_deg:g} deg (fit recipe, linear range)"],
                    fmt=log.fmt, meas_std=getattr(log, "meas_std", None))


def _every(log, k: int):
    """The log with every ``k``-th sample, keeping its name, ship and provenance (path, sha256)."""
    if k == 1:
        return log
    return TrialLog(log.data.iloc[::k].reset_index(drop=True), name=log.name, ship=log.ship, path=log.path,
                    sha256=log.sha256, rows=log.rows[::k], units_in=log.units_in,
                    notes=list(log.notes) + [f"{every_kth(k)} (fit recipe)"], fmt=log.fmt,
                    meas_std=getattr(log, "meas_std", None))


def _head(log, n: int):
    """The first ``n`` samples of a log, keeping its name, ship and provenance."""
    return TrialLog(log.data.iloc[:n].reset_index(drop=True), name=log.name, ship=log.ship, path=log.path,
                    sha256=log.sha256, rows=log.rows[:n], units_in=log.units_in, notes=list(log.notes), fmt=log.fmt,
                    meas_std=getattr(log, "meas_std", None))


def common_grid(logs, dt: float) -> list:
    """The logs resampled (linear interpolation) onto one time grid ``t = k dt`` from each log's start [s],
    all as long as the longest: past the end of a shorter log its measured channels are NaN (missing, not
    fitted) and its inputs ``delta, n`` hold their last value.  Logs on one grid are simulated as one batch
    by the output-error refinement."""
    if not dt > 0:
        raise ValueError(f"dt must be a positive time step [s], got {dt}")
    span = max(lg.time[-1] - lg.time[0] for lg in logs)
    t = dt * np.arange(int(span // dt) + 1)
    out = []
    for lg in logs:
        tr = lg.time - lg.time[0]
        inside = t <= tr[-1] + 1e-9
        ch = {}
        for c in lg.channels:
            if c == "time":
                continue
            v = np.interp(t, tr, lg[c])
            ch[c] = v if c in ("delta", "n") else np.where(inside, v, np.nan)
        with warnings.catch_warnings():  # the padding is missing data by design
            warnings.simplefilter("ignore", UserWarning)
            new = TrialLog.from_arrays(t, name=lg.name, ship=lg.ship, consistency_checks=False, **ch)
        new.path, new.sha256 = lg.path, lg.sha256
        out.append(new)
    return out




def _lpp_of(logs, lpp=None) -> float:
    if lpp is not None:
        return float(lpp)
    lpps = {float(lg.ship.lpp) for lg in logs if getattr(lg, "ship", None) is not None}
    if len(lpps) != 1:
        raise ValueError("the logs' ship length is " + ("unknown" if not lpps else f"ambiguous {sorted(lpps)} m")
                         + "; pass lpp= (--lpp) or ship particulars")
    return lpps.pop()


#: Smallest Froude number U / sqrt(g L) that the fastest sample of the logs must reach for a fit (0.01: 0.054 m/s
#: for a 3 m model, 0.56 m/s for a 320 m ship; the fastest samples of the Esso Osaka runs, the slowest logs here,
#: reach 0.024-0.10).
