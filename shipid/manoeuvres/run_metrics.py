"""Standard-manoeuvre metrics of any run (TrialLog, DataFrame or SimulationResult): the manoeuvre kind is
detected from the rudder, and the turning or zigzag metrics are computed with the same code as simulations use."""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
import pandas as pd

from ..simulate import SimulationResult
from ._series import detect_execute
from .runner import ship_info
from .turning import turning_metrics
from .zigzag import zigzag_metrics


class NotStandardManoeuvre(ValueError):
    """The run is a manoeuvre, but not a standard one (ITTC 7.5-04-02-01: a turning circle or zigzag from a steady
    approach at a constant engine setting): a start from rest, the propeller astern.  Judge it by open-loop
    prediction (``--horizon``) or, when it holds its rudder through a turn, by :func:`steady_turn`."""


def detect_manoeuvre(delta, threshold_deg: float = 2.0, n=None) -> str:
    """``"zigzag"`` when the rudder goes both ways from its initial value by more than ``threshold_deg``
    after the execute and holds each side beyond half its largest deflection for at least
    :data:`ZIGZAG_SIDE_SHARE` of the time, else ``"turning"``.  With the propeller rate ``n``, a run whose propeller runs astern
    after the execute is not a standard manoeuvre (berthing, operator-driven random runs; ITTC 7.5-04-02-01's
    turning circles and zigzags keep the approach's engine setting): ValueError, which says so."""
    delta = np.asarray(delta, dtype=float)
    d = np.degrees(delta - float(delta[0]))
    up, down = d.max() > threshold_deg, d.min() < -threshold_deg
    if not (up or down):
        raise ValueError("no manoeuvre: the rudder never moves more than "
                         f"{threshold_deg} deg from its initial value")
    k = int(np.flatnonzero(np.abs(d) > threshold_deg)[0])  # the first sample past the threshold
    if n is not None:
        na = np.asarray(n, dtype=float)[k:]
        na = na[np.isfinite(na)]
        if na.size:
            if na.min() < 0.0:
                raise NotStandardManoeuvre(
                    f"not a standard manoeuvre: the propeller runs astern after the execute (n from {na.min():.3g} "
                    f"to {na.max():.3g}); turning and zigzag metrics need a constant rate ahead (berthing or random "
                    "runs: judge them by open-loop prediction, --horizon)")
    if up and down:
        # a zigzag holds the rudder on both sides in turn; a turning circle holds one side, with at most brief
        # corrections of the other (the Esso Osaka turning runs: up to 8 % of the time beyond half the largest
        # deflection on the other side; their zigzags and the MARIN/KCS ones: 27 % or more on each side)
        da = d[k:]
        half = 0.5 * float(np.abs(da).max())
        if min(np.mean(da > half), np.mean(da < -half)) >= ZIGZAG_SIDE_SHARE:
            return "zigzag"
    return "turning"


#: Smallest share of the time after the execute that a zigzag's rudder spends beyond half its largest deflection
#: on each side (a round value between the turning runs' largest, 0.08, and the zigzags' smallest, 0.27, over the
#: 12 Esso Osaka turning and 7 zigzag runs, the 6 MARIN KVLCC2 runs and the bundled KCS logs).
ZIGZAG_SIDE_SHARE = 0.15


#: Smallest ratio of the speed at the rudder execute to the median speed after it in a standard manoeuvre (a steady
#: approach, ITTC 7.5-04-02-01).  A round value between the runs that start from rest with the rudder already moving
#: (the Esso Osaka turning and zigzag runs: 0.01-0.36) and the standard ones (MARIN KVLCC2, the bundled KCS logs:
#: 1.00-2.6; a turn slows down after the execute, so its ratio exceeds 1).
APPROACH_SPEED_RATIO_MIN = 0.5


def _check_steady_approach(sub: pd.DataFrame) -> None:
    """ValueError when the rudder execute (:func:`detect_execute`) comes before the ship is under way: its speed
    there below :data:`APPROACH_SPEED_RATIO_MIN` of its median speed after it (a start from rest, where the execute,
    the approach speed and every distance measured from them mean nothing)."""
    if "u" not in sub.columns:
        return
    u = sub["u"].to_numpy(float)
    U = np.hypot(u, sub["v"].to_numpy(float)) if "v" in sub.columns else np.abs(u)
    i, te = detect_execute(sub["time"].to_numpy(float), sub["delta"].to_numpy(float))
    after = U[i:][np.isfinite(U[i:])]
    if not after.size or not np.isfinite(U[i]):
        return
    med = float(np.median(after))
    if med > 0 and U[i] < APPROACH_SPEED_RATIO_MIN * med:
        raise NotStandardManoeuvre(
            f"not a standard manoeuvre: the rudder moves at t = {te:.3g} s at {U[i]:.2g} m/s, under half the median "
            f"speed after it ({med:.2g} m/s): a start from rest, not a steady approach; cut the log to its approach "
            "(TrialLog.window) or judge it by --horizon")


def _frame(data) -> tuple[pd.DataFrame, Any]:
    """Normalise a TrialLog / DataFrame / SimulationResult to a frame with column ``time``."""
    ship = getattr(data, "ship", None)
    if hasattr(data, "data") and isinstance(getattr(data, "data"), pd.DataFrame):
        df = data.data
    elif isinstance(data, pd.DataFrame):
        df = data
        if "time" not in df.columns:
            if "t" in df.columns:
                df = df.rename(columns={"t": "time"})
            elif df.index.name in ("time", "t"):
                df = df.reset_index().rename(columns={df.index.name: "time"})
    else:
        raise ValueError(f"metrics(): expected a TrialLog, a pandas DataFrame or a SimulationResult, got {type(data).__name__}")
    return df, ship


def metrics(data, *, lpp: float | None = None, kind: str = "auto", reference_offset: float | None = None,
            execute_time: float | None = None, switch_deg: float | None = None, name: str | None = None,
            rudder_deg: float | None = None, check_deg: float | None = None):
    """Standard-manoeuvre metrics of a log or a simulated run.

    Parameters
    ----------
    data : TrialLog, DataFrame or SimulationResult (single member)
        Needs ``time`` (column or index), ``psi`` [rad], ``delta`` [rad]; turning circles also
        ``x, y`` [m] and ``u`` [m/s] (``v`` optional).
    lpp : float, optional
        Ship length [m]; defaults to the log's ship particulars (``data.ship.lpp``) or the model's ``lpp``.
    kind : {"auto", "turning", "zigzag"}
    reference_offset : float, optional
        Distance [m] of the logged point forward of midship; positions are moved to midship
        (``reference="midship"``).  Without it the logged point is used as it is.
    execute_time : optional override (see :func:`turning_metrics`, :func:`zigzag_metrics`).
    rudder_deg, check_deg : float, optional
        Zigzag: nominal rudder and check (switch) angles [deg] (``switch_deg`` is the older name of
        ``check_deg``); by default both are read from the log (the check angle from the heading
        deviation at the rudder reversals, :func:`~shipid.manoeuvres.zigzag.infer_check_angle`).

    Returns
    -------
    TurningMetrics or ZigzagMetrics
    """
    reference = "logged point"
    if isinstance(data, SimulationResult):
        if data.batched:
            raise ValueError("metrics(): batched simulation; pass result.to_pandas(member=i) or use the manoeuvre result's metrics")
        lpp = lpp if lpp is not None else getattr(data.model, "lpp", None) or ship_info(data.model).get("lpp")
        data = data.to_pandas()
        reference = "model origin (midship for mmg)"
    df, ship = _frame(data)
    label = name or getattr(data, "name", None) or "data"
    if lpp is None:
        lpp = getattr(ship, "lpp", None)
    if lpp is None or not lpp > 0:
        raise ValueError(f"{label}: ship length unknown; pass lpp= (or --lpp on the command line)")
    for col in ("time", "psi", "delta"):
        if col not in df.columns:
            raise ValueError(f"{label}: column '{col}' missing; metrics need time, psi [rad] and delta [rad]"
                             f" (have {list(df.columns)})")
    sub = df.dropna(subset=["time", "psi", "delta"])
    if len(sub) < 3:
        raise ValueError(f"{label}: fewer than 3 rows with time, psi and delta all present")
    psi = sub["psi"].to_numpy(float)
    if np.nanmax(np.abs(np.diff(psi))) > 1.0 and np.nanmax(np.abs(psi)) > 2 * math.pi + 1:
        raise ValueError(f"{label}: column 'psi' jumps by more than 1 rad between samples and exceeds 2 pi; "
                         "it looks like degrees -- convert to radians")
    if kind == "auto":
        try:
            kind = detect_manoeuvre(sub["delta"].to_numpy(float),
                                    n=sub["n"].to_numpy(float) if "n" in sub.columns else None)
            _check_steady_approach(sub)
        except ValueError as exc:
            raise type(exc)(f"{label}: {exc}") from None  # (NotStandardManoeuvre stays one)
    if kind == "turning":  # positions and speed must be present on the samples used
        sub = sub.dropna(subset=[c for c in ("x", "y", "u") if c in sub.columns])
    t = sub["time"].to_numpy(float)
    psi = sub["psi"].to_numpy(float)
    delta = sub["delta"].to_numpy(float)
    x = sub["x"].to_numpy(float) if "x" in sub else None
    y = sub["y"].to_numpy(float) if "y" in sub else None
    if x is not None and reference_offset is not None:
        x = x - reference_offset * np.cos(psi)
        y = y - reference_offset * np.sin(psi)
        reference = "midship"
    u = sub["u"].to_numpy(float) if "u" in sub else None
    v = sub["v"].to_numpy(float) if "v" in sub else None
    if kind == "turning":
        missing = [c for c, a in (("x", x), ("y", y), ("u", u)) if a is None]
        if missing:
            raise ValueError(f"{label}: turning-circle metrics need column(s) {missing}")
        return turning_metrics(t, x, y, psi, u, delta, lpp=lpp, v=v, execute_time=execute_time, reference=reference)
    if kind == "zigzag":
        return zigzag_metrics(t, psi, delta, lpp=lpp, u=u, v=v, x=x, y=y, execute_time=execute_time,
                              switch_deg=switch_deg, check_deg=check_deg, rudder_deg=rudder_deg, reference=reference)
    raise ValueError(f"kind={kind!r}: use 'auto', 'turning' or 'zigzag'")


#: A steady turn (:func:`steady_turn`): the rudder is "held" while it stays within :data:`HOLD_RUDDER_DEG` of the
#: hold's first angle, which must be at least :data:`TURN_RUDDER_DEG`, and the propeller within
#: :data:`HOLD_RPS_SHARE` of its rate there (or 0.2 rps, whichever is larger).
HOLD_RUDDER_DEG = 1.0
HOLD_RPS_SHARE = 0.05
TURN_RUDDER_DEG = 5.0
#: Heading change [deg] over the hold from which a run's steady turn is reported by ``shipid validate``/``metrics``
#: (a turn short of the 360 deg a steady diameter needs is reported as such; the brief holds of the Esso Osaka
#: random, berthing and zigzag runs turn 0-70 deg, the turning runs' holds 292-868 deg).
STEADY_REPORT_DEG = 180.0


@dataclass
class SteadyTurn:
    """The steady turn of a run's longest rudder hold (:func:`steady_turn`).  ``hold_start``, ``hold_end`` [s]: the
    rudder and the propeller at one setting in between; ``rudder_deg``, ``n`` that setting; ``heading_change_deg`` turned
    during the hold; ``steady_diameter_L`` the diameter of the circle fitted to the track once the hold has turned
    360 deg (270 when it turns less than 450), as :func:`~shipid.manoeuvres.turning.turning_metrics` defines the
    steady diameter; ``steady_speed`` [m/s] the mean speed there; ``time_360_s`` = pi D / U, the time a full circle
    takes at that speed."""

    name: str
    lpp: float
    hold_start: float
    hold_end: float
    rudder_deg: float
    n: float | None
    side: str
    heading_change_deg: float
    steady_diameter_L: float = math.nan
    steady_speed: float = math.nan
    time_360_s: float = math.nan
    success: bool = False
    message: str = ""

    def to_dict(self) -> dict:
        return {k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in asdict(self).items()}


def steady_turn(data, *, lpp: float | None = None, name: str | None = None) -> SteadyTurn:
    """The steady turn of a run that is not a standard turning circle (a start from rest, an operator steering
    before the hold; the Esso Osaka turning runs): the longest stretch over which the rudder stays at one angle of
    at least :data:`TURN_RUDDER_DEG` (within :data:`HOLD_RUDDER_DEG`), ended where the propeller leaves its rate at
    the stretch's start (:data:`HOLD_RPS_SHARE`), is taken as the turn, its start as the execute, and the steady
    diameter and speed are computed as for a turning circle (the approach quantities -- advance, tactical diameter,
    speed loss -- mean nothing without a steady approach and are not given).  ``success`` False (with the reason)
    when the hold turns less than 360 deg.

    Raises ValueError when the run holds no rudder angle of :data:`TURN_RUDDER_DEG` or more, or lacks the channels
    (time, x, y, psi, u, delta)."""
    if isinstance(data, SimulationResult):
        lpp = lpp if lpp is not None else getattr(data.model, "lpp", None) or ship_info(data.model).get("lpp")
        data = data.to_pandas()
    df, ship = _frame(data)
    label = name or getattr(data, "name", None) or "data"
    lpp = lpp if lpp is not None else getattr(ship, "lpp", None)
    if lpp is None or not lpp > 0:
        raise ValueError(f"{label}: ship length unknown; pass lpp= (or --lpp on the command line)")
    need = ["time", "x", "y", "psi", "u", "delta"]
    missing = [c for c in need if c not in df.columns]
    if missing:
        raise ValueError(f"{label}: a steady turn needs column(s) {missing}")
    sub = df.dropna(subset=need)
    if len(sub) < 10:
        raise ValueError(f"{label}: fewer than 10 rows with {', '.join(need)} all present")
    t, x, y, psi, u, delta = (sub[c].to_numpy(float) for c in need)
    v = sub["v"].to_numpy(float) if "v" in sub.columns else None
    i0, i1 = _longest_hold(t, delta)
    if i0 is None:
        raise ValueError(f"{label}: no rudder hold of at least {TURN_RUDDER_DEG:g} deg (within {HOLD_RUDDER_DEG:g} deg) "
                         "in the run: no turn to measure")
    n_hold = None
    if "n" in sub.columns:
        n = sub["n"].to_numpy(float)
        if np.isfinite(n[i0:i1]).all():
            n_hold = float(n[i0])
            off = np.flatnonzero(np.abs(n[i0:i1] - n_hold) > max(HOLD_RPS_SHARE * abs(n_hold), 0.2))
            i1 = i0 + int(off[0]) if off.size else i1  # the propeller leaves its setting: the hold ends there
    if i1 - i0 < 10:
        raise ValueError(f"{label}: the rudder and propeller setting holds for {i1 - i0} samples only")
    t, x, y, psi, u, delta = (a[:i1] for a in (t, x, y, psi, u, delta))
    v = v[:i1] if v is not None else None
    tm = turning_metrics(t, x, y, psi, u, delta, lpp=lpp, v=v, execute_time=float(t[i0]))
    res = SteadyTurn(name=str(label), lpp=float(lpp), hold_start=float(t[i0]), hold_end=float(t[-1]),
                     rudder_deg=math.degrees(float(np.median(delta[i0:]))), n=n_hold, side=tm.side,
                     heading_change_deg=tm.max_heading_change_deg)
    if math.isfinite(tm.steady_diameter):
        res.steady_diameter_L = tm.steady_diameter_L
        res.steady_speed = tm.steady_speed
        res.time_360_s = math.pi * tm.steady_diameter / tm.steady_speed if tm.steady_speed > 0 else math.nan
        res.success = True
        res.message = "ok" if tm.max_heading_change_deg >= 450 else "steady part from 270 deg of the hold (< 450 deg)"
    else:
        res.message = (f"the hold turns {tm.max_heading_change_deg:.0f} deg from t = {t[i0]:.1f} s to {t[-1]:.1f} s; "
                       "a steady turn needs 360 deg")
    return res


def reported_steady_turn(data, *, lpp: float | None = None, name: str | None = None) -> SteadyTurn | None:
    """:func:`steady_turn` when the run's hold turns at least :data:`STEADY_REPORT_DEG` (what ``shipid validate``
    and ``shipid metrics`` report for a run that is not a standard manoeuvre), else None (no hold, a brief one,
    or channels missing)."""
    try:
        st = steady_turn(data, lpp=lpp, name=name)
    except ValueError:
        return None
    return st if st.heading_change_deg >= STEADY_REPORT_DEG else None


def _longest_hold(t, delta) -> tuple:
    """``(i0, i1)``: the samples ``i0 .. i1-1`` of the longest stretch (in time) over which the rudder stays within
    :data:`HOLD_RUDDER_DEG` of its angle at ``i0``, that angle at least :data:`TURN_RUDDER_DEG`; ``(None, None)``
    when there is none."""
    tol, turn = math.radians(HOLD_RUDDER_DEG), math.radians(TURN_RUDDER_DEG)
    d, tt = np.asarray(delta, dtype=float).tolist(), np.asarray(t, dtype=float).tolist()  # one pass on floats: O(n)
    best, longest, i0, n = (None, None), -1.0, 0, len(d)
    for i in range(1, n + 1):
        if i < n and abs(d[i] - d[i0]) <= tol:
            continue
        if abs(d[i0]) >= turn and tt[i - 1] - tt[i0] > longest:
            best, longest = (i0, i), tt[i - 1] - tt[i0]
        i0 = i
    return best
