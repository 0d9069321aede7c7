"""Analytic bang-bang answer of Ghorbani et al.'s scenario 1 (straight-line minimum time).

With the craft on its line of sight the 4-DOF model reduces to (Ghorbani et al., eq. (23))::

    (m - X_udot) u' = T - R_T(u),   x' = u,   0 <= T <= T_max

Minimum time from rest to ``x = X`` with the terminal speed ``u_f`` is one
switch from full thrust to zero (Pontryagin, eq. (28); no singular arc since
the system is controllable).  The switch lies where the full-thrust
trajectory from ``(0, 0)`` meets the zero-thrust (coasting) curve through
``(X, u_f)`` in the u-x phase plane.  The coasting curve is a quadrature (integrated once in u, rtol 1e-11)::

    x_c(u) = X - int_{u_f}^{u} M w / R(w) dw,   t_c(u) = int_{u_f}^{u} M / R(w) dw

Note ``t_c`` diverges as ``u_f -> 0`` whenever ``R ~ u^2`` at low speed: with
no brake a displacement hull never stops exactly, so a "stop" needs a small
terminal speed ``u_f`` (we use 0.5 m/s, see docs/control.md).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

__all__ = ["BangBang", "bang_bang_straight"]


@dataclass
class BangBang:
    """Switching-curve solution.

    Attributes
    ----------
    switch_x, switch_u, switch_t : float
        Switch position [m], speed [m/s] and time [s].
    coast_time : float [s]
    final_time : float [s]
    accel : (t, x, u) arrays of the full-thrust branch up to the switch
    coast : (u, x) arrays of the coasting curve from the switch to the end
    """

    switch_x: float
    switch_u: float
    switch_t: float
    coast_time: float
    final_time: float
    accel: tuple
    coast: tuple


def bang_bang_straight(resistance, mass: float, thrust: float, distance: float, final_speed: float) -> BangBang:
    """Minimum-time single-switch answer for ``(mass) u' = T - R(u)``.

    Parameters
    ----------
    resistance : callable
        ``R(u)`` [N], vectorised.
    mass : float
        Effective mass ``m - X_udot`` [kg].
    thrust : float
        ``T_max`` [N].
    distance : float
        Target position ``X`` [m].
    final_speed : float
        Terminal speed ``u_f > 0`` [m/s].
    """
    if not final_speed > 0:
        raise ValueError(f"bang_bang_straight: final_speed must be > 0 (an unbraked hull never stops exactly), got {final_speed!r}")
    M = float(mass)

    def acc(t, y):
        return [y[1], (thrust - float(resistance(y[1]))) / M]

    sol = solve_ivp(acc, (0.0, 2000.0), [0.0, 0.0], dense_output=True, rtol=1e-10, atol=1e-10, max_step=0.5,
                    events=lambda t, y: y[0] - distance)
    t_hit = sol.t_events[0][0]
    u_top = float(sol.sol(t_hit)[1])
    # the coasting curve by quadrature in u, once, with dense output:
    # d x_c / du = -M u / R(u),  d t_c / du = M / R(u),  x_c(u_f) = X,  t_c(u_f) = 0
    coast = solve_ivp(lambda u, y: [-M * u / float(resistance(u)), M / float(resistance(u))], (final_speed, u_top),
                      [distance, 0.0], dense_output=True, rtol=1e-11, atol=1e-9)

    def coast_x(u):
        return float(coast.sol(u)[0])

    def gap(t):
        x, u = sol.sol(t)
        return x - coast_x(u) if u > final_speed else x - distance

    t_lo = 1e-6
    while sol.sol(t_lo)[1] <= final_speed:
        t_lo *= 2
    ts = brentq(gap, t_lo, t_hit, xtol=1e-12)
    xs, us = sol.sol(ts)
    tc = float(coast.sol(us)[1])
    tt = np.linspace(0, ts, 200)
    xa, ua = sol.sol(tt)
    uc = np.linspace(us, final_speed, 200)
    xc = coast.sol(uc)[0]
    return BangBang(switch_x=float(xs), switch_u=float(us), switch_t=float(ts), coast_time=float(tc),
                    final_time=float(ts + tc), accel=(tt, xa, ua), coast=(uc, xc))
