"""Speed and power of a vessel on a route leg: the PSO paper's USV curves or any shipid model.

A *speed-power model* answers, for a leg sailed at the propulsor's fixed
setting, what the speed over ground along the leg and the shaft/electric
power are, given the current and the wind resolved along the leg::

    us, P, w = model.leg(current_along, wind_against)

``current_along`` [m/s] is the current component along the leg direction
(``Uc cos psi_rc`` of Li et al.: positive = following current);
``wind_against`` [m/s] is ``Ua cos psi_ra`` with ``psi_ra`` the angle between
the heading and the direction the wind comes *from* (positive = head wind);
``us`` is the speed over ground along the leg [m/s], ``P`` the power [W] and
``w`` the speed through the water [m/s].  All arrays broadcast.

:class:`PaperUSVModel` -- Li et al., eqs. (8)-(12) at the
fixed 2000 rpm::

    Fc = 3.9 w |w|,  w = us - Uc cos psi_rc        (current drag, N)
    Fw = 0.02 v |v|, v = us + Ua cos psi_ra        (wind drag, N)
    Ft = 0.0076 w^2 - 2.654 w + 17.024             (thrust, N)
    Pt = -39.5 w + 850                             (power, W)
    Ft = Fc + Fw                                   (leg equilibrium)

solved in closed form (a quadratic in ``w`` on each side of ``v = 0``).

:class:`ModelSpeedPower` -- the plug-in: the through-water speed is the
steady surge speed of a shipid model (any model with a state ``u`` and an
input ``n``) at a given propeller rate, found by solving the surge equation
``rhs_u = 0`` with the other states and inputs held (default 0, i.e. straight
ahead, rudder amidships); the power is ``P = c_P n^3`` (propeller law, ``c_P``
given or calibrated from one measured power) or a user function.  An
identified calm-water model knows nothing about wind, so ``wind_against`` is
ignored (stated in ``docs/routing.md``).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Mapping

import numpy as np
from scipy.optimize import brentq

from ..models.base import Model

__all__ = ["PaperUSVModel", "ModelSpeedPower", "steady_surge_speed"]


@dataclass(frozen=True)
class PaperUSVModel:
    """The "Wave Rider" USV of Li et al. at its fixed 2000 rpm (eqs. 8-12).

    Coefficients default to the paper's; change them for another craft.
    ``Fc = kc w|w|``, ``Fw = kw v|v|``, ``Ft = t2 w^2 + t1 w + t0``,
    ``Pt = p1 w + p0``.
    """

    kc: float = 3.9
    kw: float = 0.02
    t2: float = 0.0076
    t1: float = -2.654
    t0: float = 17.024
    p1: float = -39.5
    p0: float = 850.0

    def water_speed(self, current_along, wind_against) -> np.ndarray:
        """Through-water speed ``w`` [m/s] solving ``Ft(w) = Fc(w) + Fw(w + s)``, ``s = c + a``."""
        c = np.asarray(current_along, dtype=float)
        a = np.asarray(wind_against, dtype=float)
        s = c + a
        # v = w + s >= 0:  (kc + kw - t2) w^2 + (2 kw s - t1) w + kw s^2 - t0 = 0
        w_pos = _pos_root(self.kc + self.kw - self.t2, 2 * self.kw * s - self.t1, self.kw * s**2 - self.t0)
        # v < 0 (tail wind faster than the boat): (kc - kw - t2) w^2 + (-2 kw s - t1) w - kw s^2 - t0 = 0
        w_neg = _pos_root(self.kc - self.kw - self.t2, -2 * self.kw * s - self.t1, -self.kw * s**2 - self.t0)
        return np.where(w_pos + s >= 0, w_pos, w_neg)

    def leg(self, current_along, wind_against):
        """``(us, P, w)``: speed over ground along the leg [m/s], power [W], through-water speed [m/s]."""
        w = self.water_speed(current_along, wind_against)
        us = w + np.asarray(current_along, dtype=float)
        P = self.p1 * w + self.p0
        return us, P, w


def _pos_root(A, B, C):
    """Largest real root of ``A w^2 + B w + C`` (NaN where none)."""
    disc = B * B - 4 * A * C
    with np.errstate(invalid="ignore"):
        return (-B + np.sqrt(disc)) / (2 * A)


def steady_surge_speed(model: Model, n: float, *, state: Mapping[str, float] | None = None,
                       inputs: Mapping[str, float] | None = None, surge: str = "u", rate: str = "n",
                       bracket: tuple[float, float] = (1e-6, 50.0)) -> float:
    """Steady surge speed [m/s] of ``model`` at propeller rate ``n`` [rps]: the root of ``rhs_u = 0``.

    Parameters
    ----------
    model : Model
        Any protocol model with a state named ``surge`` and an input named ``rate``.
    n : float
        Propeller rate [rps] (the model's unit of its input ``rate``).
    state, inputs : mapping, optional
        Values of the other states and inputs (default 0: straight ahead,
        rudder amidships).
    bracket : (float, float)
        Surge speeds [m/s] bracketing the root.

    Raises
    ------
    ValueError
        When the model lacks ``surge``/``rate`` or ``rhs_u`` does not change sign in ``bracket``.
    """
    iu = model.state_index(surge)
    inn = model.input_index(rate)
    x = np.zeros(model.nx)
    for k, v in (state or {}).items():
        x[model.state_index(k)] = float(v)
    uu = np.zeros(model.nu)
    for k, v in (inputs or {}).items():
        uu[model.input_index(k)] = float(v)
    uu[inn] = float(n)

    def f(speed):
        xx = x.copy()
        xx[iu] = speed
        return float(model.rhs(0.0, xx, uu)[iu])

    fa, fb = f(bracket[0]), f(bracket[1])
    if not (np.isfinite(fa) and np.isfinite(fb)) or fa * fb > 0:
        raise ValueError(
            f"model '{model.name}': d{surge}/dt does not change sign between {surge} = {bracket[0]} and {bracket[1]} m/s "
            f"at {rate} = {n} (values {fa:.3g}, {fb:.3g}); no steady speed there -- check the parameters or pass bracket="
        )
    return float(brentq(f, *bracket, xtol=1e-12, rtol=1e-12))


class ModelSpeedPower:
    """Leg speed and power from a shipid model at a fixed propeller rate (plug-in for the planners).

    Parameters
    ----------
    model : Model
        Protocol model with a surge state and a propeller-rate input
        (e.g. ``get_model("kcs-response")`` or a model built from a
        ``shipid fit`` result).
    n : float
        Propeller rate [rps].
    power : float or callable
        ``c_P`` [W s^3] of ``P = c_P n^3``, or ``power(n, u) -> W``.
    state, inputs, surge, rate, bracket
        Passed to :func:`steady_surge_speed`.
    """

    def __init__(self, model: Model, n: float, power: float | Callable[[float, float], float], *,
                 state: Mapping[str, float] | None = None, inputs: Mapping[str, float] | None = None,
                 surge: str = "u", rate: str = "n", bracket: tuple[float, float] = (1e-6, 50.0)):
        self.model = model
        self.n = float(n)
        self.speed = steady_surge_speed(model, self.n, state=state, inputs=inputs, surge=surge, rate=rate,
                                        bracket=bracket)
        if callable(power):
            self.power = float(power(self.n, self.speed))
        else:
            self.c_p = float(power)
            self.power = self.c_p * self.n**3
        if not (np.isfinite(self.power) and self.power >= 0):
            raise ValueError(f"ModelSpeedPower: power must be a finite non-negative number of watts, got {self.power}")

    @classmethod
    def calibrated(cls, model: Model, n: float, *, n_ref: float, power_ref: float, **kw) -> "ModelSpeedPower":
        """Propeller law ``P = c_P n^3`` with ``c_P = power_ref / n_ref^3`` (one measured point)."""
        if n_ref <= 0 or power_ref < 0:
            raise ValueError(f"calibration point must have n_ref > 0 and power_ref >= 0, got {n_ref}, {power_ref}")
        return cls(model, n, power_ref / n_ref**3, **kw)

    def leg(self, current_along, wind_against):
        """``(us, P, w)`` as :meth:`PaperUSVModel.leg`; the wind is ignored (calm-water model)."""
        c = np.asarray(current_along, dtype=float)
        shape = np.broadcast_shapes(c.shape, np.shape(wind_against))
        w = np.full(shape, self.speed)
        return w + c, np.full(shape, self.power), w

    def __repr__(self):
        return f"ModelSpeedPower({self.model.name!r}, n={self.n:g} rps: {self.speed:.4g} m/s, {self.power:.4g} W)"
