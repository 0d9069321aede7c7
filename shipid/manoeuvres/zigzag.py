"""Zigzag manoeuvres: the metrics (overshoots, execute times, initial turning) and their simulation."""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
import pandas as pd

from ..models.base import Model
from ._series import _at_time, _crossing, _execute, _jsonable, _side, _unwrap
from .imo import _le, imo_limits
from .laws import ZigzagRudder
from .runner import ManoeuvreResult, _approach_state, _check_method, _resolve, _run_batched, _speed_for_rps, _time_step, steady_rps


@dataclass
class ZigzagMetrics:
    """Zigzag metrics (ITTC 7.5-04-02-01 / IMO MSC.137(76)); angles [deg], times [s] from the first execute."""

    lpp: float
    rudder_deg: float            # rudder amplitude (positive)
    switch_deg: float            # check angle: heading deviation at which the rudder is reversed (positive)
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
    check_source: str = "given"  # where the check angle came from: "given", "log" (rudder reversals), "rudder"
    success: bool = True
    message: str = ""

    def __post_init__(self):
        self.manoeuvre = "zigzag"

    @property
    def check_deg(self) -> float:
        """The check (switch) angle [deg]: heading deviation at which the rudder is reversed."""
        return self.switch_deg

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


def zigzag_metrics(t, psi, delta, *, lpp: float, u=None, v=None, x=None, y=None, execute_time: float | None = None,
                   switch_deg: float | None = None, rudder_deg: float | None = None, check_deg: float | None = None,
                   reference: str = "logged point") -> ZigzagMetrics:
    """Zigzag metrics from time series.

    Parameters
    ----------
    t, psi, delta : arrays (n,)  time [s], heading [rad], rudder [rad] (any sign convention)
    lpp : float  ship length [m]
    u, v : arrays, optional  speeds [m/s] (approach speed for the IMO L/V limits)
    x, y : arrays, optional  positions [m] (initial turning track length)
    execute_time : float, optional  known first-execute time (else detected)
    rudder_deg : float, optional  nominal rudder amplitude [deg]; default the rudder's swing about its
        mean, rounded to a whole degree.
    check_deg : float, optional  nominal check (switch) angle [deg], the heading deviation at which the
        rudder is reversed (``switch_deg`` is the same, older name).  Default: inferred from the log --
        the heading deviation from the first execute at the rudder reversals (:func:`infer_check_angle`:
        median of the first three; the rudder angle when within 1.5 deg of it, else rounded to a whole
        degree), so a 10/5 zigzag reads as 10/5; the rudder angle when the log has no reversal.
    """
    if check_deg is not None and switch_deg is not None and float(check_deg) != float(switch_deg):
        raise ValueError(f"zigzag_metrics: check_deg={check_deg} and switch_deg={switch_deg} differ; give one")
    check = check_deg if check_deg is not None else switch_deg
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
    source = "given"
    if check is None:
        inferred = infer_check_angle(t, dpsi, delta, ie, rud)
        sw, source = (inferred, "log") if inferred is not None else (rud, "rudder")
    else:
        sw = float(check)
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
                        execute_time=te, reference=reference, check_source=source)
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


def rudder_reversals(delta, start: int, tol_deg: float = 0.5) -> list[int]:
    """Indices of the rudder reversals after sample ``start``: at each extreme of the rudder, the last
    sample within ``tol_deg / 2`` of it before the rudder has moved back by more than ``tol_deg`` (the
    rudder order changed sides there).

    ``delta`` [rad] (n,); the first motion away from ``delta[start]`` by more than ``tol_deg`` sets the
    initial direction.  A rudder held with sensor noise below ``tol_deg`` gives no reversal.
    """
    d = np.asarray(delta, dtype=float)
    tol = math.radians(tol_deg)
    direction, ext, k_ext, out = 0, d[start], start, []
    for k in range(start + 1, d.size):
        x = d[k]
        if not np.isfinite(x):
            continue
        if direction == 0:
            if abs(x - d[start]) > tol:
                direction, ext, k_ext = (1 if x > d[start] else -1), x, k
            continue
        if direction * (x - ext) >= -0.5 * tol:  # still at the extreme (held with sensor noise) or beyond it
            if direction * (x - ext) > 0:
                ext = x
            k_ext = k
        elif direction * (ext - x) > tol:
            out.append(k_ext)
            direction, ext, k_ext = -direction, x, k
    return out


#: Largest difference [deg] between the heading deviation at the logged rudder reversals and the rudder
#: angle for which a zigzag reads as an x/x zigzag: the logged reversal lags the heading's crossing of the
#: check angle by the steering reaction (MARIN KVLCC2 20/20: 19.2 .. 21.5 deg at the reversals).
CHECK_SNAP_DEG = 1.5


def infer_check_angle(t, dpsi, delta, start: int, rudder_deg: float | None = None, n_use: int = 3) -> float | None:
    """The zigzag's check angle [deg] from a log: the heading deviation ``|dpsi|`` [rad] from the first
    execute at the first ``n_use`` rudder reversals (:func:`rudder_reversals`), their median.  Within
    :data:`CHECK_SNAP_DEG` of the rudder angle ``rudder_deg`` it is the rudder angle (an x/x zigzag);
    else rounded to a whole degree (nominal check angles are whole degrees).  None when the log has
    no reversal."""
    rev = rudder_reversals(delta, start)[:n_use]
    if not rev:
        return None
    val = float(np.median(np.degrees(np.abs(np.asarray(dpsi, dtype=float)[rev]))))
    if rudder_deg is not None and abs(val - rudder_deg) <= CHECK_SNAP_DEG:
        return float(rudder_deg)
    return float(max(round(val), 1.0))


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
