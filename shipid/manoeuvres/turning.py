"""Turning circles: the metrics (advance, transfer, tactical and steady diameter, speed loss) of one or a
batch of runs, and their simulation for any protocol model."""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Sequence

import numpy as np
import pandas as pd

from ..models.base import Model
from ._series import _at_time_rows, _circle_fit_rows, _crossing_rows, _execute, _interp_rows, _jsonable, _masked_sum, _side
from .imo import _le
from .laws import TurningRudder
from .runner import ManoeuvreResult, _approach_state, _check_method, _resolve, _run_batched, _speed_for_rps, _time_step, steady_rps


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

    ``x, y, psi, U, delta`` (B, n); ``ie, te`` (B,) execute index and time (``t[ie - 1] <= te <= t[ie]``);
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


def turning_sweep(model: Model, rudder_deg: Sequence[float] = (10.0, 15.0, 25.0), speeds: Sequence[float] = (1.7, 2.0, 2.2),
                  *, side: str = "starboard", rudder_rate: float | None = None, heading_change_deg: float = 540.0,
                  dt: float | None = None, lpp: float | None = None, params=None, method: str = "rk4",
                  rtol: float = 1e-6) -> pd.DataFrame:
    """Turning diameters over rudder angle x approach speed, simulated as ONE batch (Hajizadeh et al. studies).

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
