"""Input laws of the standard manoeuvres: rate-limited set-point schedules, the turning-circle and the
zigzag rudder (a located-event feedback law), and a sampled zero-order-hold wrapper for synthetic logs."""
from __future__ import annotations

import bisect
import math
from typing import Sequence

import numpy as np

from ..simulate import InputLaw


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
        # read at every integration step: sorted once per change of the list
        cached = self.__dict__.get("_stops_sorted")
        if cached is None or cached[0] != len(self._stops):
            cached = self._stops_sorted = (len(self._stops), tuple(sorted(set(self._stops))))
        return cached[1]

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
        k = bisect.bisect_right(self._hist_t, t) - 1  # (the history is in time order)
        d0, cmd = self._hist[k]
        lim = self.rate * (t - self._hist_t[k])
        return d0 + np.minimum(np.maximum(cmd - d0, -lim), lim)  # np.clip's values, without its overhead

    def inputs(self, t, x):
        return self._pack_now(self._delta(t), t)

    def event(self, t, x):
        scalar = np.ndim(t) == 0
        if (t < self.te) if scalar else np.all(np.asarray(t) < self.te):
            return np.full(self.batch, -1.0)
        if self.psi0 is None:  # first evaluation at the execute (te is a step boundary / stop)
            self.psi0 = np.array(x[..., self.ipsi], dtype=float)
        g = np.sign(self._hist[-1][1]) * (x[..., self.ipsi] - self.psi0) - self.lev
        return g if scalar else np.where(np.asarray(t) < self.te, -1.0, g)  # (scalar t >= te here)

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
