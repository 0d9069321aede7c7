"""Current from a turning test: the IMO drift method (MSC/Circ.1053, Explanatory notes to the standards
for ship manoeuvrability, 2002, sec. 3.4.2 and appendix 2).

In a steady turning circle the ship returns to the same heading every 360 degrees; without current it
would return to the same place.  The displacement between two such instants divided by their time
difference is the current (drift) velocity over ground.  :func:`current_from_turn` takes every pair of
samples 360 degrees of heading apart within the steady part of the turn and averages their drift.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

__all__ = ["current_from_turn", "CurrentEstimate"]


@dataclass
class CurrentEstimate:
    """Result of :func:`current_from_turn`.

    Attributes
    ----------
    cx, cy : float
        Current (drift) velocity, earth-fixed [m/s].
    cx_std, cy_std : float
        Standard errors [m/s]: spread of the pair estimates over sqrt of the number of independent turns.
    n_pairs : int
        Sample pairs 360 deg apart used.
    n_turns : float
        Heading change in the steady part divided by 360 deg.
    success : bool
    message : str
    """

    cx: float
    cy: float
    cx_std: float
    cy_std: float
    n_pairs: int
    n_turns: float
    success: bool
    message: str

    @property
    def speed(self) -> float:
        return float(np.hypot(self.cx, self.cy))

    def to_pandas(self) -> pd.Series:
        return pd.Series({k: getattr(self, k) for k in ("cx", "cy", "cx_std", "cy_std", "n_pairs", "n_turns",
                                                         "success", "message")}, name="current_from_turn")


def current_from_turn(log, *, skip_deg: float = 180.0, t_start: float | None = None) -> CurrentEstimate:
    """Uniform current from a long turning circle by the IMO drift method.

    Parameters
    ----------
    log : TrialLog or DataFrame
        With ``time`` [s], ``x``, ``y`` [m] and ``psi`` [rad] (wrapped or not).
    skip_deg : float
        Heading change [deg] after the start of the turn (or after ``t_start``) before the turn counts
        as steady (IMO: the transient of the first part of the turn is excluded).
    t_start : float, optional
        Time [s] of the rudder execute; default: the first sample with a yaw rate above 10 % of the
        median yaw rate of the run's second half.

    Returns
    -------
    CurrentEstimate
        ``success`` False (NaN estimate) when the steady part holds less than 360 deg of heading change.
    """
    df = log if isinstance(log, pd.DataFrame) else getattr(log, "data", None)
    if df is None or not {"time", "x", "y", "psi"} <= set(df.columns):
        raise ValueError("current_from_turn: log needs columns time, x, y, psi")
    d = df[["time", "x", "y", "psi"]].dropna()
    t, x, y = (d[k].to_numpy(dtype=float) for k in ("time", "x", "y"))
    psi = np.unwrap(d["psi"].to_numpy(dtype=float))
    if t.size < 10:
        raise ValueError(f"current_from_turn: only {t.size} complete samples")
    rate = np.gradient(psi, t)
    sgn = np.sign(np.median(rate[t.size // 2:])) or 1.0
    if t_start is None:
        ref = np.median(np.abs(rate[t.size // 2:]))
        on = np.flatnonzero(sgn * rate > 0.1 * ref)
        t_start = t[on[0]] if on.size else t[0]
    h = sgn * psi
    h = np.maximum.accumulate(h)  # heading change made monotone (noise at the start of the turn)
    k0 = int(np.searchsorted(t, t_start))
    steady = np.flatnonzero((np.arange(t.size) >= k0) & (h >= h[k0] + np.radians(skip_deg)))
    nan = CurrentEstimate(np.nan, np.nan, np.nan, np.nan, 0, 0.0, False, "")
    if steady.size < 2:
        nan.message = f"no steady turning: heading change after {skip_deg} deg of transient is too small"
        return nan
    hs, k1 = h[steady], steady[0]
    n_turns = float((hs[-1] - hs[0]) / (2 * np.pi))
    first = steady[hs <= hs[-1] - 2 * np.pi]
    if first.size == 0:
        nan.n_turns, nan.message = n_turns, (f"the steady part of the turn covers {360 * n_turns:.0f} deg; the drift "
                                             "method needs at least 360 deg")
        return nan
    target = h[first] + 2 * np.pi
    ts = t[k1:]
    t2 = np.interp(target, h[k1:], ts)
    x2, y2 = np.interp(t2, ts, x[k1:]), np.interp(t2, ts, y[k1:])
    dt = t2 - t[first]
    cx, cy = (x2 - x[first]) / dt, (y2 - y[first]) / dt
    n_ind = max(1.0, n_turns - 1.0 + 1.0)
    return CurrentEstimate(
        cx=float(np.mean(cx)), cy=float(np.mean(cy)), cx_std=float(np.std(cx) / np.sqrt(n_ind) + 1e-12),
        cy_std=float(np.std(cy) / np.sqrt(n_ind) + 1e-12), n_pairs=int(first.size), n_turns=n_turns, success=True,
        message=f"{first.size} sample pairs 360 deg apart over {360 * n_turns:.0f} deg of steady turning")
