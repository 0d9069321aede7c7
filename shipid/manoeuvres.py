"""Standard manoeuvres (turning circle, zigzag) for any model, and their metrics.

Simulation
----------
:func:`turning_circle`, :func:`zigzag` and :func:`turning_sweep` run the
standard manoeuvres of ITTC 7.5-04-02-01 / IMO MSC.137(76) for **any**
protocol model with states ``x, y, psi, u, v, r`` and inputs ``delta, n``,
as one vectorised batch through :func:`shipid.simulate.simulate`:
steady approach (the propeller rps that holds the approach speed with the
rudder amidships is solved through the model's own ``rhs``), rudder moved at
the ship's steering rate to the ordered angle (turning circle: held until the
heading has changed by at least 540 deg; zigzag: reversed each time the
heading deviation reaches the switch angle -- a batch-aware feedback law).

Sign convention: positive ``delta`` is the model's own positive rudder; the
side of a turn is taken from the heading change (positive psi change =
starboard for the shipped models).  Logs may use the opposite rudder sign
(the MARIN files do: +35 deg there turns to port); the metrics never use the
rudder sign, only the execute time and the heading.

Metrics
-------
:func:`turning_metrics`, :func:`zigzag_metrics` and :func:`metrics` work on
plain arrays, on a DataFrame/TrialLog (columns ``time, x, y, psi, u, [v],
delta``) and on a simulation, with the same code:

* execute: the first sample with ``|delta - delta[0]| > 0.5 deg`` (as in the
  MARIN README), unless the execute time is known (simulations pass it);
* advance / transfer: position change along / across the heading at the
  execute when the heading has changed by 90 deg (linear interpolation
  between samples); tactical diameter: across-distance at 180 deg;
* steady turning diameter: least-squares circle through the track after the
  heading change has passed 360 deg (270 deg when the run is shorter), speed
  loss ``1 - U_steady/U_approach`` over the same part;
* zigzag: first / second overshoot angle and their times from the first
  execute, time to second execute, and the initial turning ability (track
  length from the first to the second execute, IMO's 10 deg heading change);
* IMO MSC.137(76) criteria with the L/V-dependent overshoot limits.

The results state the reference point of the positions they used: the
model's origin (midship for ``mmg``) for simulations, the logged point for
logs unless ``reference_offset`` moves it to midship.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any, Sequence

import numpy as np
import pandas as pd

from .models.base import Model
from .simulate import METHODS, InputLaw, SimulationResult, simulate

__all__ = [
    "TurningMetrics", "ZigzagMetrics", "ManoeuvreResult", "turning_metrics", "zigzag_metrics", "metrics",
    "detect_manoeuvre", "detect_execute", "imo_limits", "turning_circle", "zigzag", "turning_sweep",
    "steady_rps", "ship_info", "RampSchedule", "TurningRudder", "ZigzagRudder", "SampledHold",
]

EXECUTE_THRESHOLD_DEG = 0.5
_REQUIRED_STATES = ("x", "y", "psi", "u", "v", "r")
_REQUIRED_INPUTS = ("delta", "n")
#: Ship facts of models that do not carry them (SPEC.md section 1: the KCS model of seed 002).
_KNOWN_SHIPS = {"kcs-response": {"lpp": 4.36, "rudder_rate": math.radians(16.8), "design_speed": 1.7}}


# --------------------------------------------------------------------------- results
@dataclass
class TurningMetrics:
    """Turning-circle metrics (ITTC 7.5-04-02-01 / IMO MSC.137(76)).

    Lengths in metres and in ship lengths (``*_L``); angles in degrees;
    times [s] from the execute; speeds [m/s].  NaN where the run did not
    reach the heading change a metric needs (see ``message``).
    """

    lpp: float
    side: str                     # "starboard" (heading increasing) or "port"
    rudder_deg: float             # ordered rudder angle (signed, as logged / simulated)
    approach_speed: float
    advance: float = math.nan
    transfer: float = math.nan
    tactical_diameter: float = math.nan
    steady_diameter: float = math.nan
    steady_speed: float = math.nan
    speed_loss: float = math.nan  # 1 - U_steady / U_approach
    time_90: float = math.nan
    time_180: float = math.nan
    max_heading_change_deg: float = math.nan
    track_reach_10deg: float = math.nan  # track length to a 10 deg heading change (IMO initial turning, 10 deg rudder)
    execute_time: float = math.nan
    reference: str = "logged point"
    success: bool = True
    message: str = ""

    def __post_init__(self):
        self.manoeuvre = "turning"

    @property
    def advance_L(self) -> float:
        return self.advance / self.lpp

    @property
    def transfer_L(self) -> float:
        return self.transfer / self.lpp

    @property
    def tactical_diameter_L(self) -> float:
        return self.tactical_diameter / self.lpp

    @property
    def steady_diameter_L(self) -> float:
        return self.steady_diameter / self.lpp

    def imo(self) -> dict:
        """IMO MSC.137(76) turning criteria: advance < 4.5 L, tactical diameter < 5 L (and initial turning
        track reach <= 2.5 L when the rudder is 10 deg).  ``None`` where not applicable/unavailable."""
        out = {
            "advance_limit_L": 4.5, "advance_pass": _le(self.advance_L, 4.5),
            "tactical_diameter_limit_L": 5.0, "tactical_diameter_pass": _le(self.tactical_diameter_L, 5.0),
        }
        if abs(abs(self.rudder_deg) - 10.0) < 1.0:
            out["initial_turning_limit_L"] = 2.5
            out["initial_turning_pass"] = _le(self.track_reach_10deg / self.lpp, 2.5)
        return out

    def to_dict(self) -> dict:
        """Plain JSON-able dict (keys ``manoeuvre``, ``advance_L``, ``transfer_L``, ``tactical_diameter_L``,
        ``steady_diameter_L``, ``speed_loss`` ... and the IMO checks under ``imo``)."""
        d = asdict(self)
        d = {"manoeuvre": "turning", "advance_L": self.advance_L, "transfer_L": self.transfer_L,
             "tactical_diameter_L": self.tactical_diameter_L, "steady_diameter_L": self.steady_diameter_L,
             "speed_loss": self.speed_loss, "initial_turning_L": self.track_reach_10deg / self.lpp, **d}
        d["imo"] = self.imo()
        return _jsonable(d)


@dataclass
class ZigzagMetrics:
    """Zigzag metrics (ITTC 7.5-04-02-01 / IMO MSC.137(76)); angles [deg], times [s] from the first execute."""

    lpp: float
    rudder_deg: float            # rudder amplitude (positive)
    switch_deg: float            # heading deviation at which the rudder is reversed (positive)
    first_side: str              # side of the first heading change: "starboard" or "port"
    approach_speed: float
    overshoot1_deg: float = math.nan
    overshoot2_deg: float = math.nan
    overshoot1_time: float = math.nan
    overshoot2_time: float = math.nan
    time_second_execute: float = math.nan
    time_third_execute: float = math.nan
    initial_turning: float = math.nan  # track length first -> second execute [m]
    execute_time: float = math.nan
    reference: str = "logged point"
    success: bool = True
    message: str = ""

    def __post_init__(self):
        self.manoeuvre = "zigzag"

    @property
    def initial_turning_L(self) -> float:
        return self.initial_turning / self.lpp

    @property
    def l_over_v(self) -> float:
        """L/V [s] with the approach speed."""
        return self.lpp / self.approach_speed

    def imo(self) -> dict:
        """IMO MSC.137(76) checks that apply to this zigzag (10/10: first and second overshoot with the
        L/V-dependent limits and initial turning <= 2.5 L; 20/20: first overshoot <= 25 deg)."""
        lim = imo_limits(self.lpp, self.approach_speed)
        out: dict[str, Any] = {"L_over_V_s": self.l_over_v}
        if abs(self.rudder_deg - 10) < 1 and abs(self.switch_deg - 10) < 1:
            out.update(overshoot1_limit_deg=lim["zz10_overshoot1_deg"], overshoot1_pass=_le(self.overshoot1_deg, lim["zz10_overshoot1_deg"]),
                       overshoot2_limit_deg=lim["zz10_overshoot2_deg"], overshoot2_pass=_le(self.overshoot2_deg, lim["zz10_overshoot2_deg"]),
                       initial_turning_limit_L=2.5, initial_turning_pass=_le(self.initial_turning_L, 2.5))
        elif abs(self.rudder_deg - 20) < 1 and abs(self.switch_deg - 20) < 1:
            out.update(overshoot1_limit_deg=lim["zz20_overshoot1_deg"], overshoot1_pass=_le(self.overshoot1_deg, lim["zz20_overshoot1_deg"]))
        return out

    def to_dict(self) -> dict:
        """Plain JSON-able dict (keys ``manoeuvre``, ``overshoot1_deg``, ``overshoot2_deg``, ... ``imo``)."""
        d = {"manoeuvre": "zigzag", **asdict(self), "initial_turning_L": self.initial_turning_L}
        d["imo"] = self.imo()
        return _jsonable(d)


def _le(value, limit):
    return None if not np.isfinite(value) else bool(value <= limit)


def _jsonable(d):
    out = {}
    for k, v in d.items():
        if isinstance(v, dict):
            out[k] = _jsonable(v)
        elif isinstance(v, (np.floating, float)):
            out[k] = None if not np.isfinite(v) else float(v)
        elif isinstance(v, np.bool_):
            out[k] = bool(v)
        elif isinstance(v, np.integer):
            out[k] = int(v)
        else:
            out[k] = v
    return out


def imo_limits(lpp: float, speed: float) -> dict:
    """IMO MSC.137(76) limits for a ship of length ``lpp`` [m] at test speed ``speed`` [m/s].

    10/10 first overshoot: 10 deg if L/V < 10 s, 20 deg if L/V >= 30 s, 5 + L/V/2 between;
    10/10 second overshoot: 25 / 40 / 17.5 + 0.75 L/V; 20/20 first overshoot 25 deg;
    advance 4.5 L, tactical diameter 5 L, initial turning 2.5 L.
    """
    if not (lpp > 0 and speed > 0):
        raise ValueError(f"imo_limits: lpp and speed must be positive, got lpp={lpp}, speed={speed}")
    lv = lpp / speed
    if lv < 10:
        o1, o2 = 10.0, 25.0
    elif lv >= 30:
        o1, o2 = 20.0, 40.0
    else:
        o1, o2 = 5.0 + 0.5 * lv, 17.5 + 0.75 * lv
    return {"L_over_V_s": lv, "zz10_overshoot1_deg": o1, "zz10_overshoot2_deg": o2, "zz20_overshoot1_deg": 25.0,
            "advance_L": 4.5, "tactical_diameter_L": 5.0, "initial_turning_L": 2.5}


# --------------------------------------------------------------------------- metric helpers
def detect_execute(t, delta, threshold_deg: float = EXECUTE_THRESHOLD_DEG) -> tuple[int, float]:
    """Index and time of the rudder execute: first sample with ``|delta - delta[0]| > threshold``.

    ``delta`` in radians.  Raises ValueError when the rudder never moves.
    """
    delta = np.asarray(delta, dtype=float)
    moved = np.abs(delta - delta[0]) > math.radians(threshold_deg)
    if not moved.any():
        raise ValueError(f"no rudder execute found: |delta - delta[0]| never exceeds {threshold_deg} deg")
    i = int(np.argmax(moved))
    return i, float(np.asarray(t)[i])


def _crossing_rows(t, h, level, start, valid):
    """Per row of ``h (B, n)``: the first sample at or after ``start (B,)`` (and inside ``valid (B, n)``)
    where ``h`` reaches ``level`` upwards, with the crossing linearly interpolated.

    Returns ``(found, k, f, time)``, arrays (B,): the index after the crossing, the fraction of the
    interval before it (1.0 when the level is reached at ``start`` itself) and the time.
    """
    col = np.arange(h.shape[1])
    mask = (h >= level) & (col >= start[:, None]) & valid
    found = mask.any(axis=1)
    k = np.argmax(mask, axis=1)
    rows = np.arange(h.shape[0])
    km = np.maximum(k - 1, 0)
    at_start = k == start
    with np.errstate(invalid="ignore", divide="ignore"):
        f = np.where(at_start, 1.0, (level - h[rows, km]) / (h[rows, k] - h[rows, km]))
        time = np.where(at_start, t[k], t[km] + f * (t[k] - t[km]))  # rows not found: unused
    return found, k, f, time


def _crossing(t, h, level, start):
    """:func:`_crossing_rows` for one series: ``(index_after, fraction, time)`` or None."""
    found, k, f, time = _crossing_rows(t, h[None], level, np.array([start]), np.ones((1, h.size), bool))
    return (int(k[0]), float(f[0]), float(time[0])) if found[0] else None


def _interp_rows(a, k, f):
    """``a`` at fraction ``f`` of the interval before index ``k``, per row (``a[k]`` when f >= 1 or k == 0)."""
    rows = np.arange(a.shape[0])
    km = np.maximum(k - 1, 0)
    with np.errstate(invalid="ignore"):  # f is not finite in rows without a crossing (unused)
        return np.where((f < 1.0) & (k > 0), a[rows, km] + f * (a[rows, k] - a[rows, km]), a[rows, k])


def _at_time_rows(t, a, te):
    """``np.interp(te[b], t, a[b])`` for each row ``b`` of ``a (B, n)`` (``te`` inside ``[t0, t_end]``)."""
    j = np.clip(np.searchsorted(t, te, side="right") - 1, 0, t.size - 2)
    w = (te - t[j]) / (t[j + 1] - t[j])
    rows = np.arange(a.shape[0])
    return np.where(w == 0.0, a[rows, j], a[rows, j] + w * (a[rows, j + 1] - a[rows, j]))


def _masked_sum(a, mask):
    """Row sums of ``a`` over ``mask`` (NaNs inside the mask propagate, outside are ignored)."""
    return np.where(mask, a, 0.0).sum(axis=1)


def _circle_fit_rows(x, y, mask):
    """Least-squares (Kasa) circle through the points of each row selected by ``mask``; (xc, yc, radius).

    Minimises sum (x^2 + y^2 + D x + E y + F)^2 in coordinates centred on the points' mean, where
    the normal equations separate: a 2x2 system for (D, E) and F = -mean(x^2 + y^2).
    """
    nw = mask.sum(axis=1)
    mx, my = _masked_sum(x, mask) / nw, _masked_sum(y, mask) / nw
    xc = np.where(mask, x - mx[:, None], 0.0)
    yc = np.where(mask, y - my[:, None], 0.0)
    z = xc * xc + yc * yc
    sxx, syy, sxy = (xc * xc).sum(1), (yc * yc).sum(1), (xc * yc).sum(1)
    sxz, syz = (xc * z).sum(1), (yc * z).sum(1)
    det = sxx * syy - sxy * sxy
    a = 0.5 * (sxz * syy - syz * sxy) / det
    b = 0.5 * (syz * sxx - sxz * sxy) / det
    F = -z.sum(1) / nw
    return mx + a, my + b, np.sqrt(np.maximum(a * a + b * b - F, 0.0))


def _unwrap(psi):
    """``np.unwrap(psi)`` (float array), skipping the work when no step exceeds pi (simulated headings;
    with NaNs it always unwraps, as before)."""
    psi = np.asarray(psi, dtype=float)
    return psi if psi.size < 2 or np.abs(np.diff(psi)).max() <= math.pi else np.unwrap(psi)


def _side(sign):
    return "starboard" if sign > 0 else "port"


def turning_metrics(t, x, y, psi, u, delta, *, lpp: float, v=None, execute_time: float | None = None,
                    reference: str = "logged point") -> TurningMetrics:
    """Turning-circle metrics from time series.

    Parameters
    ----------
    t : array (n,)  time [s]
    x, y : array (n,)  earth-fixed position [m] of the reference point
    psi : array (n,)  heading [rad], unwrapped (it is unwrapped again here)
    u : array (n,)  surge speed [m/s]; ``v`` (sway) optional, U = hypot(u, v)
    delta : array (n,)  rudder angle [rad] (any sign convention)
    lpp : float  ship length [m] for the non-dimensional values
    execute_time : float, optional  known execute time (else detected from ``delta``)
    reference : str  what the positions refer to (copied into the result)
    """
    t, x, y, u, delta = (np.asarray(a, dtype=float) for a in (t, x, y, u, delta))
    U = np.abs(u) if v is None else np.hypot(u, np.asarray(v, dtype=float))
    if not lpp or lpp <= 0:
        raise ValueError(f"turning_metrics: lpp must be a positive length in metres, got {lpp}")
    ie, te = _execute(t, delta, execute_time)
    return _turning_rows(t, x[None], y[None], np.asarray(psi, dtype=float)[None], U[None], delta[None], lpp,
                         np.array([ie]), np.array([te]), reference, np.array([t.size]))[0]


def _turning_rows(t, x, y, psi, U, delta, lpp, ie, te, reference, n_valid) -> list[TurningMetrics]:
    """:func:`turning_metrics` of B runs on one time grid at once (the one copy of the definitions).

    ``x, y, psi, U, delta`` (B, n); ``ie, te`` (B,) execute index and time (``t[ie - 1] < te <= t[ie]``);
    row ``b`` uses its first ``n_valid[b]`` samples (a simulation that failed later).
    """
    B, n = x.shape
    col = np.arange(n)
    valid = col < n_valid[:, None]
    # headings: unwrap only when a valid step exceeds pi (never, for simulations)
    dpsi_step = np.abs(np.diff(psi, axis=1))
    if n > 1 and not np.all(np.where(valid[:, 1:], dpsi_step, 0.0) <= math.pi):
        psi = np.unwrap(psi, axis=1)
    psi_e, xe, ye = (_at_time_rows(t, a, te) for a in (psi, x, y))
    dpsi = psi - psi_e[:, None]
    after = (t >= te[:, None]) & valid
    rows = np.arange(B)
    s = np.where(dpsi[rows, np.argmax(np.where(after, np.abs(dpsi), -np.inf), axis=1)] >= 0, 1.0, -1.0)
    h = s[:, None] * dpsi
    rud = delta[rows, np.argmax(np.where(valid, np.abs(delta - delta[:, :1]), -np.inf), axis=1)]
    # approach speed: mean of the (at most) 20 samples up to and including the execute sample
    back = ie[:, None] - np.arange(20)[None, :]
    U_app = _masked_sum(U[rows[:, None], np.maximum(back, 0)], back >= 0) / np.minimum(ie + 1, 20)
    hmax_all = np.where(after, h, -np.inf).max(axis=1)
    cos_e, sin_e = np.cos(psi_e)[:, None], np.sin(psi_e)[:, None]
    dx, dy = x - xe[:, None], y - ye[:, None]
    along = dx * cos_e + dy * sin_e
    across = s[:, None] * (-dx * sin_e + dy * cos_e)
    # track length: cumulative segment lengths, with a NaN segment anywhere in a range making it NaN
    seg = np.hypot(np.diff(x, axis=1), np.diff(y, axis=1))
    bad = ~np.isfinite(seg)
    cum = np.concatenate([np.zeros((B, 1)), np.cumsum(np.where(bad, 0.0, seg), axis=1)], axis=1)
    cbad = np.concatenate([np.zeros((B, 1), int), np.cumsum(bad, axis=1)], axis=1)
    f10, k10, fr10, _ = _crossing_rows(t, h, math.radians(10), ie, valid)
    km = np.maximum(k10 - 1, 0)
    reach = np.where(k10 > ie, cum[rows, km] - cum[rows, ie] + fr10 * seg[rows, np.minimum(km, n - 2)], 0.0)
    reach = np.where((k10 > ie) & (cbad[rows, k10] - cbad[rows, ie] > 0), np.nan, reach)
    f90, k90, fr90, t90 = _crossing_rows(t, h, math.pi / 2, ie, valid)
    f180, k180, fr180, t180 = _crossing_rows(t, h, math.pi, ie, valid)
    adv, trf, tdia = _interp_rows(along, k90, fr90), _interp_rows(across, k90, fr90), _interp_rows(across, k180, fr180)
    # the steady part ends where the rudder leaves its held angle (pull-out at the end of MARIN's tc runs)
    held = delta[rows, k90]
    moved = (np.abs(delta - held[:, None]) > math.radians(1.0)) & (col >= k90[:, None]) & valid & f90[:, None]
    has_moved = moved.any(axis=1)
    held_end = np.where(has_moved, np.argmax(moved, axis=1), n_valid)
    in_hold = after & (col < held_end[:, None])
    hmax = np.where(in_hold, h, -np.inf).max(axis=1)
    start = np.where(hmax >= math.radians(450), math.radians(360), math.radians(270))
    steady = in_hold & (h >= start[:, None])
    n_steady = steady.sum(axis=1)
    fit = (n_steady >= 10) & (hmax - start >= math.radians(90))
    with np.errstate(invalid="ignore", divide="ignore"):  # rows without a steady part give NaN, unused
        _, _, R = _circle_fit_rows(x, y, steady & fit[:, None])
        U_steady = _masked_sum(U, steady) / n_steady
    out = []
    for b in range(B):
        res = TurningMetrics(lpp=float(lpp), side=_side(s[b]), rudder_deg=math.degrees(rud[b]),
                             approach_speed=float(U_app[b]), execute_time=float(te[b]), reference=reference,
                             max_heading_change_deg=math.degrees(hmax_all[b]))
        msgs = []
        if f10[b]:
            res.track_reach_10deg = float(reach[b])
        if f90[b]:
            res.advance, res.transfer, res.time_90 = float(adv[b]), float(trf[b]), float(t90[b]) - res.execute_time
        else:
            msgs.append("heading change never reached 90 deg")
        if f180[b]:
            res.tactical_diameter, res.time_180 = float(tdia[b]), float(t180[b]) - res.execute_time
        else:
            msgs.append("heading change never reached 180 deg")
        if has_moved[b]:
            msgs.append(f"rudder left its held angle at t = {t[held_end[b]]:.1f} s; metrics use the track before it")
        if fit[b]:
            res.steady_diameter = 2 * float(R[b])
            res.steady_speed = float(U_steady[b])
            res.speed_loss = 1.0 - res.steady_speed / res.approach_speed
            if start[b] < math.radians(360):
                msgs.append("steady part taken from 270 deg heading change (run shorter than 450 deg)")
        else:
            msgs.append("run too short for the steady turning diameter (needs >= 360 deg heading change)")
        res.success = bool(f90[b] and f180[b])
        res.message = "; ".join(msgs) if msgs else "ok"
        out.append(res)
    return out


def zigzag_metrics(t, psi, delta, *, lpp: float, u=None, v=None, x=None, y=None, execute_time: float | None = None,
                   switch_deg: float | None = None, rudder_deg: float | None = None,
                   reference: str = "logged point") -> ZigzagMetrics:
    """Zigzag metrics from time series.

    Parameters
    ----------
    t, psi, delta : arrays (n,)  time [s], heading [rad], rudder [rad] (any sign convention)
    lpp : float  ship length [m]
    u, v : arrays, optional  speeds [m/s] (approach speed for the IMO L/V limits)
    x, y : arrays, optional  positions [m] (initial turning track length)
    execute_time : float, optional  known first-execute time (else detected)
    switch_deg, rudder_deg : float, optional  nominal switch heading and rudder amplitude [deg];
        default: the rudder amplitude rounded to a whole degree, and switch = rudder (an x/x zigzag).
    """
    t, delta = np.asarray(t, dtype=float), np.asarray(delta, dtype=float)
    psi = _unwrap(psi)
    ie, te = _execute(t, delta, execute_time)
    psi_e = _at_time(t, psi, te)
    dpsi = psi - psi_e
    da = delta[t >= te]
    # amplitude about zero from the peak-to-peak swing (the approach rudder delta[0] is not the zero of the
    # zigzag: MARIN zz_10 starts at -0.8 deg and swings -9.95 .. +10.7)
    amp = float((da.max() - da.min()) / 2) if (da.max() > 0 > da.min()) else float(np.max(np.abs(da)))
    rud = float(round(math.degrees(amp))) if rudder_deg is None else float(rudder_deg)
    sw = rud if switch_deg is None else float(switch_deg)
    if sw <= 0:
        raise ValueError(f"zigzag_metrics: switch angle must be positive, got {sw}")
    after = np.nonzero(t >= te)[0]
    # side of the first heading change: first time |dpsi| reaches half the switch angle
    big = after[np.abs(dpsi[after]) >= math.radians(sw) / 2]
    if big.size == 0:
        raise ValueError(f"zigzag_metrics: the heading never changed by {sw / 2:g} deg after the execute; not a zigzag")
    s = 1.0 if dpsi[big[0]] > 0 else -1.0
    h = s * dpsi
    U_app = math.nan
    if u is not None:
        uu = np.asarray(u, dtype=float)
        U = np.abs(uu) if v is None else np.hypot(uu, np.asarray(v, dtype=float))
        U_app = float(np.mean(U[: ie + 1][-max(1, min(ie + 1, 20)):]))
    res = ZigzagMetrics(lpp=float(lpp), rudder_deg=rud, switch_deg=sw, first_side=_side(s), approach_speed=U_app,
                        execute_time=te, reference=reference)
    lev = math.radians(sw)
    msgs = []
    c2 = _crossing(t, h, lev, ie)
    if not c2:
        res.success, res.message = False, f"heading deviation never reached the switch angle {sw:g} deg"
        return res
    k2, f2, t2 = c2
    res.time_second_execute = t2 - te
    if x is not None and y is not None:
        xx, yy = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
        seg = np.hypot(np.diff(xx[ie:k2 + 1]), np.diff(yy[ie:k2 + 1]))
        res.initial_turning = float(seg[:-1].sum() + f2 * seg[-1]) if seg.size else 0.0
    c3 = _crossing(t, -h, lev, k2)
    end1 = c3[0] if c3 else h.size
    seg1 = slice(k2, end1)
    j = k2 + int(np.argmax(h[seg1]))
    if c3:
        res.overshoot1_deg = float(np.degrees(h[j]) - sw)
        res.overshoot1_time = float(t[j] - te)
        res.time_third_execute = c3[2] - te
        c4 = _crossing(t, h, lev, c3[0])
        end2 = c4[0] if c4 else h.size
        j2 = c3[0] + int(np.argmax(-h[c3[0]:end2]))
        # the extreme counts when the heading turned back after it (fourth execute, or > 0.5 deg recovery)
        if c4 or (j2 < h.size - 1 and h[end2 - 1] - h[j2] > math.radians(0.5)):
            res.overshoot2_deg = float(np.degrees(-h[j2]) - sw)
            res.overshoot2_time = float(t[j2] - te)
            if not c4:
                msgs.append("run ends before the fourth execute; second overshoot from the turned-back heading")
        else:
            msgs.append("run ends before the heading turned back after the third execute: no second overshoot")
    else:
        if j < h.size - 1 and h[-1] < h[j] - math.radians(0.5):
            res.overshoot1_deg = float(np.degrees(h[j]) - sw)
            res.overshoot1_time = float(t[j] - te)
        msgs.append("run ends before the third execute: second overshoot not available")
    res.success = bool(np.isfinite(res.overshoot1_deg))
    res.message = "; ".join(msgs) if msgs else "ok"
    return res


def _execute(t, delta, execute_time):
    if execute_time is None:
        return detect_execute(t, delta)
    te = float(execute_time)
    if not (t[0] <= te <= t[-1]):
        raise ValueError(f"execute_time {te} s is outside the time range [{t[0]}, {t[-1]}] s")
    return int(np.searchsorted(t, te, side="left")), te


def _at_time(t, a, te):
    return float(np.interp(te, t, a))


def detect_manoeuvre(delta, threshold_deg: float = 2.0) -> str:
    """``"zigzag"`` when the rudder goes both ways from its initial value by more than ``threshold_deg``
    after the execute, else ``"turning"``."""
    d = np.degrees(np.asarray(delta, dtype=float) - float(np.asarray(delta)[0]))
    up, down = d.max() > threshold_deg, d.min() < -threshold_deg
    if not (up or down):
        raise ValueError("no manoeuvre: the rudder never moves more than "
                         f"{threshold_deg} deg from its initial value")
    return "zigzag" if (up and down) else "turning"


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
            execute_time: float | None = None, switch_deg: float | None = None, name: str | None = None):
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
    execute_time, switch_deg : optional overrides (see :func:`turning_metrics`, :func:`zigzag_metrics`).

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
    kind = detect_manoeuvre(sub["delta"].to_numpy(float)) if kind == "auto" else kind
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
                              switch_deg=switch_deg, reference=reference)
    raise ValueError(f"kind={kind!r}: use 'auto', 'turning' or 'zigzag'")



# --------------------------------------------------------------------------- input laws
class RampSchedule:
    """A set-point schedule followed at a limited rate (propeller rps, ...): piecewise linear in time.

    Parameters
    ----------
    start : float  value at t = 0
    steps : sequence of (t_s, value)  set points ordered from time t_s on
    rate : float  largest rate of change [unit/s]
    """

    def __init__(self, start: float, steps: Sequence = (), rate: float = math.inf):
        if not rate > 0:
            raise ValueError(f"RampSchedule: rate must be positive, got {rate}")
        knots_t, knots_v = [0.0], [float(start)]
        steps = sorted((float(a), float(b)) for a, b in steps)
        for i, (ts, target) in enumerate(steps):
            t_next = steps[i + 1][0] if i + 1 < len(steps) else math.inf
            v = float(np.interp(ts, knots_t, knots_v)) if ts <= knots_t[-1] else knots_v[-1]
            while knots_t and knots_t[-1] > ts:  # a new set point interrupts a running ramp
                knots_t.pop(), knots_v.pop()
            if not knots_t or knots_t[-1] < ts:
                knots_t.append(ts), knots_v.append(v)
            t_reach = ts + abs(target - v) / rate if math.isfinite(rate) else ts
            if t_reach > ts:
                t_end = min(t_reach, t_next)
                knots_t.append(t_end), knots_v.append(v + math.copysign(rate * (t_end - ts), target - v))
            elif target != v:  # infinite rate: a jump (as two knots 1e-9 s apart)
                knots_t.append(ts + 1e-9), knots_v.append(target)
        self.t = np.array(knots_t)
        self.v = np.array(knots_v)

    @property
    def stops(self) -> tuple:
        """Kinks of the schedule [s]."""
        return tuple(float(a) for a in self.t[1:])

    def __call__(self, t):
        """Value(s) at time(s) ``t``."""
        return np.interp(t, self.t, self.v, right=self.v[-1])


class _RudderLaw(InputLaw):
    """Shared parts of the manoeuvre laws: rudder ramp at the steering rate, propeller from rps or a schedule."""

    def __init__(self, nu, idl, inn, n, rate, te, batch):
        self.nu, self.idl, self.inn = nu, idl, inn
        self.rate, self.te, self.batch = float(rate), float(te), batch
        self.n = n
        self._stops = [self.te] + (list(n.stops) if isinstance(n, RampSchedule) else [])

    @property
    def stops(self) -> tuple:
        return tuple(sorted(set(self._stops)))

    def _n(self, t):
        if isinstance(self.n, RampSchedule):
            return self.n(t)
        return self.n if np.ndim(t) == 0 else np.asarray(self.n)[..., None]

    def _pack(self, delta, n, shape):
        u = np.empty(shape + (self.nu,))
        u[..., self.idl] = delta
        u[..., self.inn] = n
        return u

    def _pack_now(self, delta, t):
        """Inputs at one time: a copy of a cached template with the rps filled (constant rps)."""
        if isinstance(self.n, RampSchedule):
            return self._pack(delta, self.n(t), self.batch)
        tpl = self.__dict__.get("_tpl")
        if tpl is None:
            tpl = self._tpl = self._pack(0.0, self.n, self.batch)
        u = tpl.copy()
        u[..., self.idl] = delta
        return u


class TurningRudder(_RudderLaw):
    """Turning-circle rudder: from 0 at the execute time ``te`` to ``delta`` at the steering ``rate`` [rad/s], then held.

    Parameters
    ----------
    delta : array (B,)  ordered rudder angles [rad] (signed)
    n : array (B,) or RampSchedule  propeller rps
    rate, te : float  steering rate [rad/s], execute time [s]
    nu, idl, inn : int  number of inputs, index of the rudder and of the rps input
    """

    def __init__(self, delta, n, rate, te, *, nu=2, idl=0, inn=1):
        delta = np.asarray(delta, dtype=float)
        super().__init__(nu, idl, inn, n, rate, te, delta.shape)
        self.delta = delta
        self._sign, self._mag = np.sign(delta), np.abs(delta)
        self._stops += sorted(set((self.te + self._mag[delta != 0] / self.rate).tolist()))

    def _delta(self, t):
        if np.ndim(t) == 0:
            return self._sign * np.minimum(self.rate * max(t - self.te, 0.0), self._mag)
        return self._sign[..., None] * np.minimum(self.rate * np.maximum(t - self.te, 0.0), self._mag[..., None])

    def inputs(self, t, x):
        return self._pack_now(self._delta(t), t)

    def input_history(self, t, x):
        return self._pack(self._delta(np.asarray(t)), self._n(np.asarray(t)), self.batch + (np.size(t),))


class ZigzagRudder(_RudderLaw):
    """Zigzag rudder law: the one implementation of the ITTC/IMO zigzag (used by :func:`zigzag` and by
    :func:`shipid.synthetic.make_trial`).

    At ``te`` the rudder is ordered to ``first * amp``; it moves at the steering ``rate``; each member
    reverses its order when its heading deviation from ``psi0`` reaches ``switch`` on the side it is
    turning to.  The reversal is a located event (:class:`~shipid.simulate.InputLaw`): it happens at the
    crossing itself, not at the start of the next step, so overshoot angles converge with the step.

    Parameters
    ----------
    amp, switch : float  rudder amplitude and switch heading deviation [rad] (positive)
    first : array (B,)  +1 (starboard / positive rudder first) or -1
    psi0 : array (B,) or None  reference heading [rad]; None: each member's heading at the first
        execute ``te`` (the ITTC definition; it differs from the start heading when an asymmetric ship,
        e.g. with a rudder neutral angle, drifts off course during the approach)
    n : array (B,) or RampSchedule  propeller rps
    rate, te : float  steering rate [rad/s], time of the first execute [s]
    ipsi, nu, idl, inn : int  index of psi in the state; inputs as in :class:`TurningRudder`

    Attributes
    ----------
    count : ndarray (B,) int  rudder executes so far (1 after the first)
    t_switch : list of (time, mask)  the reversals
    """

    has_events = True

    def __init__(self, amp, switch, first, psi0, n, rate, te, *, ipsi=2, nu=2, idl=0, inn=1):
        first = np.asarray(first, dtype=float)
        super().__init__(nu, idl, inn, n, rate, te, first.shape)
        self.amp, self.lev, self.ipsi = float(amp), float(switch), ipsi
        self.psi0 = None if psi0 is None else np.broadcast_to(np.asarray(psi0, dtype=float), first.shape).copy()
        # history of (t_s, delta at t_s, order from t_s on); the rudder moves from delta_s towards the order
        self._hist_t = [self.te]
        self._hist = [(np.zeros(first.shape), first * self.amp)]
        self.count = np.ones(first.shape, dtype=int)
        self.t_switch: list = []

    def _delta(self, t):
        """Rudder at scalar time ``t``."""
        if t < self.te:
            return np.zeros(self.batch)
        k = int(np.searchsorted(self._hist_t, t, side="right")) - 1
        d0, cmd = self._hist[k]
        lim = self.rate * (t - self._hist_t[k])
        return d0 + np.clip(cmd - d0, -lim, lim)

    def inputs(self, t, x):
        return self._pack_now(self._delta(t), t)

    def event(self, t, x):
        if np.all(np.asarray(t) < self.te):
            return np.full(self.batch, -1.0)
        if self.psi0 is None:  # first evaluation at the execute (te is a step boundary / stop)
            self.psi0 = np.array(x[..., self.ipsi], dtype=float)
        g = np.sign(self._hist[-1][1]) * (x[..., self.ipsi] - self.psi0) - self.lev
        return np.where(np.asarray(t) < self.te, -1.0, g)

    def on_event(self, t, x, mask):
        d = self._delta(t)
        cmd = self._hist[-1][1]
        self._hist_t.append(float(t))
        self._hist.append((d, np.where(mask, -cmd, cmd)))
        self.count = self.count + mask
        self.t_switch.append((float(t), mask.copy()))

    def input_history(self, t, x):
        t = np.asarray(t, dtype=float)
        delta = np.zeros(self.batch + (t.size,))
        for k, ts in enumerate(self._hist_t):
            t_next = self._hist_t[k + 1] if k + 1 < len(self._hist_t) else np.inf
            sel = (t >= ts) & (t < t_next)
            if np.any(sel):
                d0, cmd = self._hist[k]
                lim = self.rate * (t[sel] - ts)
                delta[..., sel] = d0[..., None] + np.clip((cmd - d0)[..., None], -lim, lim)
        return self._pack(delta, self._n(t), self.batch + (t.size,))

class SampledHold:
    """An input law applied by a sampled (digital) controller with zero-order hold, as a plain
    ``controller(t, x)`` for :func:`shipid.simulate.simulate`.

    At each sample time ``t`` (the start of an interval of length ``dt``) the law's events are checked on
    the sampled state (a zigzag reverses when the sampled heading deviation has reached the switch
    angle), and the value the law reaches at ``t + dt`` (the rudder after ``dt`` of steering at the
    rate) is held over the interval.  The held value is the logged one, so a log made this way satisfies
    exactly the zero-order-hold input assumption of the identifier (the EKF).  Used by
    :func:`shipid.synthetic.make_trial`; :func:`zigzag` / :func:`turning_circle` use the continuous law.
    """

    def __init__(self, law: InputLaw, dt: float):
        if not dt > 0:
            raise ValueError(f"SampledHold: dt must be positive, got {dt}")
        self.law, self.dt = law, float(dt)
        self._t_last = -math.inf

    def __call__(self, t, x):
        law = self.law
        if law.has_events and t > self._t_last:  # simulate() asks again at the final time: no new decision
            hit = law.event(t, x) >= 0
            if np.any(hit):
                law.on_event(t, x, hit)
        self._t_last = max(self._t_last, t)
        return law.inputs(t + self.dt, x)


# --------------------------------------------------------------------------- simulation
def ship_info(model: Model) -> dict:
    """Ship facts a manoeuvre needs: ``lpp`` [m], ``rudder_rate`` [rad/s], ``design_speed`` [m/s].

    Taken from model attributes of those names, then from the default parameter set's
    ``operating_point`` (``lpp_m``, ``u0_m_s``, ``rudder_rate_deg_s``), then from the known
    ships of SPEC.md; missing ones are absent from the dict.
    """
    info: dict[str, float] = {}
    for k in ("lpp", "rudder_rate", "design_speed"):
        val = getattr(model, k, None)
        if val is not None:
            info[k] = float(val)
    try:
        op = type(model).parameter_set(type(model).default_parameter_set).extra.get("operating_point", {}) \
            if getattr(type(model), "default_parameter_set", None) else {}
    except (ValueError, OSError):
        op = {}
    for key, name, conv in (("lpp_m", "lpp", 1.0), ("u0_m_s", "design_speed", 1.0), ("rudder_rate_deg_s", "rudder_rate", math.pi / 180)):
        if name not in info and key in op:
            info[name] = float(op[key]) * conv
    for k, val in _KNOWN_SHIPS.get(model.name, {}).items():
        info.setdefault(k, val)
    return info


def _check_model(model: Model):
    miss = [s for s in _REQUIRED_STATES if s not in model.state_names] + \
           [s for s in _REQUIRED_INPUTS if s not in model.input_names]
    if miss:
        raise ValueError(f"model '{model.name}' lacks {miss}; standard manoeuvres need states {_REQUIRED_STATES} "
                         f"and inputs {_REQUIRED_INPUTS}")


def _approach_state(model, speeds):
    B = speeds.shape[0]
    x0 = np.zeros((B, model.nx))
    x0[:, model.state_index("u")] = speeds
    return x0


def steady_rps(model: Model, speed, *, params=None, n_max: float = 1e3, xtol: float = 1e-10) -> np.ndarray:
    """Propeller rps holding ``speed`` [m/s] in a straight run (du/dt = 0, delta = 0, v = r = 0).

    Vectorised bisection over a batch of speeds through ``model.rhs``; works for any protocol model
    with states ``u`` and input ``n``.  ``params`` may be one parameter vector (np,) or one per speed
    (B, np).  Raises ValueError when no rps in (0, n_max] gives du/dt = 0.
    """
    _check_model(model)
    speeds = np.atleast_1d(np.asarray(speed, dtype=float))
    if np.any(speeds <= 0):
        raise ValueError(f"approach speed must be positive, got {speeds[speeds <= 0][0]}")
    p = model.params if params is None else np.asarray(params, dtype=float)
    iu, idl, inn = model.state_index("u"), model.input_index("delta"), model.input_index("n")
    x0 = _approach_state(model, speeds)

    def acc(n):
        uin = np.zeros((speeds.size, model.nu))
        uin[:, inn] = n
        return model.rhs(0.0, x0, uin, p)[:, iu]

    grid = np.concatenate([[0.0], np.geomspace(1e-3, n_max, 120)])
    G = grid.size
    ug = np.zeros((speeds.size, G, model.nu))
    ug[..., inn] = grid
    pg = p[:, None, :] if p.ndim == 2 else p  # per-speed parameters broadcast over the grid
    vals = model.rhs(0.0, np.repeat(x0[:, None, :], G, axis=1), ug, pg)[..., iu]  # (B, G), one batched call
    lo = np.full(speeds.size, np.nan)
    hi = np.full(speeds.size, np.nan)
    for b in range(speeds.size):
        k = np.nonzero((vals[b, :-1] < 0) & (vals[b, 1:] >= 0))[0]
        if k.size == 0:
            raise ValueError(f"model '{model.name}': no propeller rps in (0, {n_max}] holds {speeds[b]:.4g} m/s "
                             "(du/dt never changes sign); pass n= explicitly")
        lo[b], hi[b] = grid[k[0]], grid[k[0] + 1]
    del idl
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        a = acc(mid)
        lo = np.where(a < 0, mid, lo)
        hi = np.where(a < 0, hi, mid)
        if np.all(hi - lo < xtol * np.maximum(1.0, hi)):
            break
    return 0.5 * (lo + hi)


@dataclass
class ManoeuvreResult:
    """A batch of simulated standard manoeuvres.

    Attributes
    ----------
    kind : "turning" or "zigzag"
    simulation : SimulationResult
        The batched run (``x`` shape (B, n_t, nx)).
    settings : DataFrame
        One row per member: rudder_deg, speed, n, side/first side, switch_deg (zigzag).
    metrics : list of TurningMetrics / ZigzagMetrics
    success : bool
    message : str
    """

    kind: str
    simulation: SimulationResult
    settings: pd.DataFrame
    metrics: list
    success: bool = True
    message: str = "ok"

    def to_pandas(self) -> pd.DataFrame:
        """Settings and metrics, one row per member (the flat keys of ``to_dict``)."""
        rows = []
        for i, m in enumerate(self.metrics):
            d = {k: v for k, v in m.to_dict().items() if not isinstance(v, dict)}
            rows.append({**self.settings.iloc[i].to_dict(), **d})
        return pd.DataFrame(rows)

    def member(self, i: int) -> pd.DataFrame:
        """Time series of member ``i`` (states and inputs)."""
        return self.simulation.to_pandas(member=i)


def _resolve(model, speed, n, rudder_rate, lpp, params):
    _check_model(model)
    info = ship_info(model)
    L = lpp if lpp is not None else info.get("lpp")
    if L is None:
        raise ValueError(f"model '{model.name}': ship length unknown; pass lpp=")
    rate = rudder_rate if rudder_rate is not None else info.get("rudder_rate")
    if rate is None:
        raise ValueError(f"model '{model.name}': rudder rate unknown; pass rudder_rate= [rad/s]")
    if speed is None and n is None:
        speed = info.get("design_speed")
        if speed is None:
            raise ValueError(f"model '{model.name}': approach speed unknown; pass speed= [m/s]")
    return float(L), float(rate), speed


def _run_batched(model, x0, t_step, controller_factory, done, params, t_max, chunk, method="rk4", rtol=1e-6):
    """Integrate in chunks until ``done(X_all, t_all)`` or ``t_max``; returns a SimulationResult.

    ``t_step`` is a step [s] or a callable ``(T, X) -> step`` choosing the step of the next chunk from
    the run so far (the time grid of ``simulate`` may be non-uniform).
    """
    ctrl = controller_factory()
    ts, Xs, Us, stats = [], [], [], []
    t0 = 0.0
    x = x0
    T = X = None  # the run so far (concatenated once per chunk)
    ok, msg = True, "integration finished"
    while True:
        h = t_step(T, X) if callable(t_step) else t_step
        n_steps = max(1, int(round(chunk / h)))
        t = t0 + h * np.arange(n_steps + 1)
        res = simulate(model, x, t, controller=ctrl, params=params, method=method, rtol=rtol,
                       first_step=stats[-1].get("h_last") if stats else None)
        stats.append(res.meta)
        ts.append(t if not ts else t[1:])
        Xs.append(res.x if not Xs else res.x[:, 1:])
        Us.append(res.u if not Us else res.u[:, 1:])
        if not res.success:
            ok, msg = False, res.message
            break
        x = res.x[:, -1]
        t0 = t[-1]
        T, X = np.concatenate(ts), np.concatenate(Xs, axis=1)
        finished = done(T, X)
        if finished or t0 >= t_max - 1e-9:
            if not finished:
                ok, msg = False, f"t_max = {t_max:g} s reached before every member finished the manoeuvre"
            break
    T, X, Uo = np.concatenate(ts), np.concatenate(Xs, axis=1), np.concatenate(Us, axis=1)
    # the last input sample of a chunk is re-evaluated by the next chunk: keep the later value
    p = model.params if params is None else np.asarray(params, dtype=float)
    meta = {"method": method}
    for k in ("n_steps", "n_rejected", "n_fev"):
        if any(k in m for m in stats):
            meta[k] = int(sum(m.get(k, 0) for m in stats))
    return SimulationResult(t=T, x=X, u=Uo, model=model, params=np.array(p), success=ok, message=msg, meta=meta)


def _time_step(L, speeds, dt):
    if dt is not None:
        return float(dt)
    return 0.05 * L / float(np.max(speeds))  # 20 RK4 steps per ship length travelled


def turning_circle(model: Model, rudder_deg: float | Sequence[float] = 35.0, *, speed=None, n=None,
                   side: str = "both", rudder_rate: float | None = None, heading_change_deg: float = 540.0,
                   execute_time: float | None = None, dt: float | None = None, t_max: float | None = None,
                   lpp: float | None = None, params=None, steady_step_factor: float = 4.0,
                   method: str = "rk4", rtol: float = 1e-6) -> ManoeuvreResult:
    """Simulate turning circles as one batch.

    Parameters
    ----------
    model : Model  with states x, y, psi, u, v, r and inputs delta, n
    rudder_deg : float or sequence  ordered rudder angle(s) [deg], magnitudes (``side`` sets the sign)
        or signed values with ``side="given"``.
    speed : float or sequence, optional  approach speed(s) [m/s]; default the model's design speed
    n : float or sequence, optional  propeller rps; default: the steady rps at ``speed``
    side : {"both", "starboard", "port", "given"}  starboard = positive rudder.
    rudder_rate : float, optional  [rad/s]; default the model's (``ship_info``)
    heading_change_deg : float  run until every member has turned this much (default 540)
    execute_time : float, optional  time of the rudder order [s]; default 2 L/U of steady approach
    dt : float, optional  RK4 step [s]; default L/(20 U)
    steady_step_factor : float  step multiplier once every member has turned 270 deg (steady turning;
        capped at 0.25 L/U); 1 keeps the step fixed
    t_max : float, optional  safety limit [s]; default 60 L/U
    lpp : float, optional  ship length for the metrics (default the model's)
    params : array, optional  model parameters (default ``model.params``)
    method : {"rk4", "dopri5"}  integrator (:func:`shipid.simulate.simulate`): fixed-step RK4 with step
        ``dt``, or adaptive Dormand-Prince 5(4) at tolerance ``rtol`` (then ``dt`` is only the output
        spacing the metrics interpolate on; far fewer model evaluations at equal accuracy)
    rtol : float  ``dopri5`` relative tolerance (absolute: 1e-3 rtol)

    Returns
    -------
    ManoeuvreResult
        Members ordered as (rudder, speed, side) with side fastest.
    """
    _check_method(method)
    L, rate, speed = _resolve(model, speed, n, rudder_rate, lpp, params)
    rud = np.atleast_1d(np.asarray(rudder_deg, dtype=float))
    sides = {"both": [1.0, -1.0], "starboard": [1.0], "port": [-1.0], "given": [1.0]}.get(side)
    if sides is None:
        raise ValueError(f"side={side!r}: use 'both', 'starboard', 'port' or 'given'")
    if side != "given" and np.any(rud <= 0):
        raise ValueError(f"rudder_deg must be positive magnitudes with side={side!r} (got {rud.tolist()}); use side='given' for signed angles")
    spd = np.atleast_1d(np.asarray(speed, dtype=float)) if speed is not None else None
    nn = np.atleast_1d(np.asarray(n, dtype=float)) if n is not None else None
    if spd is None:
        spd = np.full(nn.shape, np.nan)
    if nn is None:
        nn = steady_rps(model, spd, params=params)
    if spd.shape != nn.shape:
        raise ValueError(f"speed and n must have the same length, got {spd.size} and {nn.size}")
    if np.any(np.isnan(spd)):  # n given without speed: run to the steady speed of that n
        spd = _speed_for_rps(model, nn, params)
    R, S, Sd = np.meshgrid(rud, np.arange(spd.size), sides, indexing="ij")
    R, S, Sd = R.ravel(), S.ravel(), Sd.ravel()
    delta_t = np.radians(R) * Sd
    speeds, ns = spd[S], nn[S]
    return _simulate_turns(model, delta_t, speeds, ns, rate, L, heading_change_deg, execute_time, dt, t_max, params,
                           coarsen=steady_step_factor, method=method, rtol=rtol)


def _check_method(method):
    if method not in METHODS:
        raise ValueError(f"method={method!r}: use one of {METHODS}")


def _speed_for_rps(model, n, params):
    lo, hi = np.full(n.shape, 1e-3), np.full(n.shape, 1e3)
    iu, inn = model.state_index("u"), model.input_index("n")
    p = model.params if params is None else params
    for _ in range(100):
        mid = np.sqrt(lo * hi)
        x0 = _approach_state(model, mid)
        uin = np.zeros((n.size, model.nu))
        uin[:, inn] = n
        a = model.rhs(0.0, x0, uin, p)[:, iu]
        lo, hi = np.where(a > 0, mid, lo), np.where(a > 0, hi, mid)
    return np.sqrt(lo * hi)


def _simulate_turns(model, delta_target, speeds, ns, rate, L, heading_change_deg, execute_time, dt, t_max, params,
                    coarsen=4.0, method="rk4", rtol=1e-6):
    B = delta_target.size
    te = 2.0 * L / float(np.min(speeds)) if execute_time is None else float(execute_time)
    h = _time_step(L, speeds, dt)
    te = h * round(te / h)
    t_max = 60.0 * L / float(np.min(speeds)) + te if t_max is None else float(t_max)
    idl, inn, ipsi = model.input_index("delta"), model.input_index("n"), model.state_index("psi")
    target = math.radians(heading_change_deg)

    def factory():
        return TurningRudder(delta_target, ns, rate, te, nu=model.nu, idl=idl, inn=inn)

    def done(T, X):
        ke = int(np.searchsorted(T, te))
        if ke >= T.size:
            return False
        dpsi = np.abs(X[:, ke:, ipsi] - X[:, ke:ke + 1, ipsi])
        return bool(np.all(dpsi.max(axis=1) >= target))

    coarse = min(coarsen, 0.25 * L / float(np.max(speeds)) / h) if coarsen > 1 else 1.0

    def step(T, X):
        # once every member has turned 270 deg the turn is steady: larger steps (the metrics at 90 and
        # 180 deg and the rudder transient are always integrated with the fine step)
        if T is None or T[-1] < te:
            return h
        ke = int(np.searchsorted(T, te))
        steady = np.all(np.abs(X[:, -1, ipsi] - X[:, ke, ipsi]) >= math.radians(270))
        return h * coarse if steady else h

    chunk = max(10 * L / float(np.min(speeds)), te + h)
    sim = _run_batched(model, _approach_state(model, speeds), step, factory, done, params, t_max, chunk, method, rtol)
    settings = pd.DataFrame({"rudder_deg": np.degrees(delta_target), "speed": speeds, "n": ns})
    ref = "midship" if model.name == "mmg" else f"model origin of '{model.name}'"
    X = sim.x
    finite = np.all(np.isfinite(X), axis=2)
    n_valid = np.where(finite.all(axis=1), X.shape[1], np.argmax(~finite, axis=1))
    ie = int(np.searchsorted(sim.t, te, side="left"))
    iu, iv = model.state_index("u"), model.state_index("v")
    mets = _turning_rows(sim.t, X[..., 0], X[..., 1], X[..., ipsi], np.hypot(X[..., iu], X[..., iv]), sim.u[..., idl],
                         L, np.full(B, ie), np.full(B, te), ref, n_valid)
    for b, m in enumerate(mets):
        m.rudder_deg = float(np.degrees(delta_target[b]))
        m.approach_speed = float(speeds[b])
        if n_valid[b] <= ie:
            m.success, m.message = False, "simulation became non-finite before the rudder execute"
        elif n_valid[b] < X.shape[1]:
            m.success, m.message = False, "simulation became non-finite; " + m.message
    success = sim.success and all(m.success for m in mets)
    return ManoeuvreResult("turning", sim, settings, mets, success, sim.message)


def zigzag(model: Model, rudder_deg: float = 10.0, switch_deg: float | None = None, *, speed=None, n=None,
           first: str = "both", rudder_rate: float | None = None, n_executes: int = 4,
           execute_time: float | None = None, dt: float | None = None, t_max: float | None = None,
           lpp: float | None = None, params=None, method: str = "rk4", rtol: float = 1e-6) -> ManoeuvreResult:
    """Simulate zigzag manoeuvres (delta/psi, e.g. 10/10, 20/20) as one batch.

    Parameters
    ----------
    rudder_deg, switch_deg : float  rudder amplitude and switch heading deviation [deg] (switch defaults to rudder)
    speed, n : optional  approach speed(s) [m/s] / rps (see :func:`turning_circle`)
    first : {"both", "starboard", "port"}  side of the first rudder execute
    n_executes : int  run until this many rudder executes have happened (>= 4 gives the second overshoot)

    method, rtol : integrator and ``dopri5`` tolerance (see :func:`turning_circle`); ``dt`` is the RK4 step
        or, for ``dopri5``, the output spacing

    The rudder logic is :class:`ZigzagRudder`: each member reverses its rudder order when its own
    heading deviation reaches the switch angle on the side it is turning to (located within the step);
    the rudder moves at the ship's rudder rate.
    """
    _check_method(method)
    L, rate, speed = _resolve(model, speed, n, rudder_rate, lpp, params)
    sw = float(rudder_deg if switch_deg is None else switch_deg)
    if rudder_deg <= 0 or sw <= 0:
        raise ValueError(f"zigzag: rudder_deg and switch_deg must be positive, got {rudder_deg}/{sw}")
    firsts = {"both": [1.0, -1.0], "starboard": [1.0], "port": [-1.0]}.get(first)
    if firsts is None:
        raise ValueError(f"first={first!r}: use 'both', 'starboard' or 'port'")
    spd = np.atleast_1d(np.asarray(speed, dtype=float)) if speed is not None else None
    nn = np.atleast_1d(np.asarray(n, dtype=float)) if n is not None else None
    if nn is None:
        nn = steady_rps(model, spd, params=params)
    if spd is None:
        spd = _speed_for_rps(model, nn, params)
    S, F = np.meshgrid(np.arange(spd.size), firsts, indexing="ij")
    S, F = S.ravel(), F.ravel()
    speeds, ns = spd[S], nn[S]
    B = F.size
    te = 2.0 * L / float(np.min(speeds)) if execute_time is None else float(execute_time)
    h = _time_step(L, speeds, dt)
    te = h * round(te / h)
    t_max = 80.0 * L / float(np.min(speeds)) + te if t_max is None else float(t_max)
    idl, inn, ipsi = model.input_index("delta"), model.input_index("n"), model.state_index("psi")
    amp, lev = math.radians(rudder_deg), math.radians(sw)
    x0 = _approach_state(model, speeds)
    law: list = []

    def factory():
        # reference heading: each member's heading at the execute (ITTC), not at the start of the approach
        law[:] = [ZigzagRudder(amp, lev, F, None, ns, rate, te, ipsi=ipsi, nu=model.nu, idl=idl, inn=inn)]
        return law[0]

    def done(T, X):
        return bool(np.all(law[0].count >= n_executes + 1)) and T[-1] > te

    chunk = max(10 * L / float(np.min(speeds)), te + h)
    sim = _run_batched(model, x0, h, factory, done, params, t_max, chunk, method, rtol)
    settings = pd.DataFrame({"rudder_deg": rudder_deg, "switch_deg": sw, "first": [_side(f) for f in F],
                             "speed": speeds, "n": ns})
    ref = "midship" if model.name == "mmg" else f"model origin of '{model.name}'"
    mets = []
    for b in range(B):
        X = sim.x[b]
        good = np.all(np.isfinite(X), axis=1)
        last = X.shape[0] if good.all() else int(np.argmax(~good))
        m = zigzag_metrics(sim.t[:last], X[:last, ipsi], sim.u[b, :last, idl], lpp=L, u=X[:last, model.state_index("u")],
                           v=X[:last, model.state_index("v")], x=X[:last, 0], y=X[:last, 1], execute_time=te,
                           switch_deg=sw, rudder_deg=rudder_deg, reference=ref)
        m.approach_speed = float(speeds[b])
        mets.append(m)
    success = sim.success and all(m.success for m in mets)
    return ManoeuvreResult("zigzag", sim, settings, mets, success, sim.message)


def turning_sweep(model: Model, rudder_deg: Sequence[float] = (10.0, 15.0, 25.0), speeds: Sequence[float] = (1.7, 2.0, 2.2),
                  *, side: str = "starboard", rudder_rate: float | None = None, heading_change_deg: float = 540.0,
                  dt: float | None = None, lpp: float | None = None, params=None, method: str = "rk4",
                  rtol: float = 1e-6) -> pd.DataFrame:
    """Turning diameters over rudder angle x approach speed, simulated as ONE batch (seed 002 studies).

    The rps of each approach speed is the steady rps of the model at that speed (:func:`steady_rps`).

    Returns
    -------
    DataFrame
        One row per (rudder, speed[, side]): rudder_deg, speed, n, advance_L, transfer_L,
        tactical_diameter_L, steady_diameter_L, tactical_diameter [m], steady_diameter [m], speed_loss, success.
    """
    res = turning_circle(model, list(rudder_deg), speed=list(speeds), side=side, rudder_rate=rudder_rate,
                         heading_change_deg=heading_change_deg, dt=dt, lpp=lpp, params=params, method=method, rtol=rtol)
    df = res.to_pandas()
    cols = ["rudder_deg", "speed", "n", "side", "advance_L", "transfer_L", "tactical_diameter_L", "steady_diameter_L",
            "tactical_diameter", "steady_diameter", "speed_loss", "success"]
    return df[cols]
