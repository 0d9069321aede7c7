"""``response-nl``: the response model of Hajizadeh et al. plus speed-dependent non-linear damping.

The seed's linear sway/yaw equations cannot represent turning circles and
zigzags at once (the yaw damping does not grow with drift and yaw rate, and
does not scale with speed, so a model fitted to zigzags turns far too
tightly or too widely).  This model keeps the 16 seed terms unchanged (same
names, same meaning as ``kcs-response``) and adds, in sway and yaw,

* speed-proportional linear damping ``|u| v`` (sway, yaw) and ``|u| r`` (yaw):
  hull forces are ``1/2 rho L d U^2 f(v', r')`` with ``v' = v/U``,
  ``r' = r L/U``, so the linear terms are ``U v`` and ``U r``; the seed has
  only ``b4 u r`` in sway.  The speed is ``|u|`` (U ~ |u|), not ``u``: with
  ``u`` the damping turns into anti-damping going astern, which made
  open-loop predictions of the low-speed Esso Osaka runs blow up (317 of
  2515 starts, 99 % of them after u < 0; docs/environment.md); for u >= 0
  nothing changes; for the same reason the surge term ``a8 u n`` of the seed
  is ``a8 u |n|`` here (a propeller turning astern must not feed the surge
  speed); for n >= 0 it is the seed's term;
* second-order modulus damping ``v|v|`` and ``r|r|`` (cross-flow drag; from
  ``U^2 v'|v'| = v|v|`` these need no speed factor);
* third-order cross terms ``v^2 r / |u|`` and ``v r^2 / |u|`` (from
  ``U^2 v'^2 r' = L v^2 r / U``, with U ~ |u| for the small drift of a ship in
  service; ``|u|`` is floored at ``u_floor`` = 0.05 m/s to keep the terms finite);
* a propeller-induced side force and yaw moment ``b0 n^2``, ``c0 n^2``: a
  single-screw ship is not port/starboard symmetric (the rotating propeller
  and its slipstream load the hull and the rudder asymmetrically, so the
  rudder angle for a straight course is not zero and the turns to the two
  sides differ; e.g. the measured KVLCC2 tactical diameters of 3.07 L and
  3.33 L).  The force scales with the thrust, i.e. with ``n^2`` at a given
  advance ratio.  It is the response-model image of a rudder neutral angle
  ``delta_0`` (``c3 (delta - delta_0) = c3 delta - c3 delta_0``) scaled with
  the propeller loading; :class:`~shipid.models.mmg.MMGModel` carries the
  same effect as its parameter ``delta0``.  Zero in the default set (which
  was fitted before these two terms existed).

Equations (states ``x, y, psi, u, v, r``; inputs ``delta`` [rad], ``n`` [rps])::

    du/dt = a1 u + a2 v^2 + a3 r^2 + a4 delta^2 + a5 v r + a6 v delta + a7 r delta + a8 u |n| + a9 n|n|
    dv/dt = b1 v + b2 r + b3 delta + b4 u r
            + b5 |u| v + b6 v|v| + b7 r|r| + b8 v^2 r/|u| + b9 v r^2/|u| + b0 n^2
    dr/dt = c1 v + c2 r + c3 delta
            + c4 |u| v + c5 |u| r + c6 v|v| + c7 r|r| + c8 v^2 r/|u| + c9 v r^2/|u| + c0 n^2

plus the kinematics of ``kcs-response``.  Linear in the 29 parameters, so
``jac_p`` is the regressor matrix and an equation-error fit is a linear least
squares problem (:func:`shipid.identify.from_model.fit_to_model`); all Jacobians are analytic.

The default parameter set ``"mmg-kcs-fit"`` was obtained with
:func:`shipid.identify.from_model.fit_to_model` from the ``mmg`` model's KCS set (recipe and achieved
accuracy in the parameter file and docs/validation.md).
"""
from __future__ import annotations

import numpy as np

from .._jit import rebind
from . import _response_equations as _req
from .base import RUDDER_UNIT_FIX, STERN_RUDDER_SIGNS, Model, RecipeDefaults, batch_shape
from .prime import FroudeScaled
from .response import PRIME_EXPONENTS as _SEED_EXPONENTS
from .response import _rows

__all__ = ["ResponseNLModel", "RESPONSE_NL_REGRESSORS", "PRIME_EXPONENTS", "ASYM_NAMES"]

SEED_NAMES = ("a1", "a2", "a3", "a4", "a5", "a6", "a7", "a8", "a9", "b1", "b2", "b3", "b4", "c1", "c2", "c3")
EXTRA_NAMES = ("b5", "b6", "b7", "b8", "b9", "c4", "c5", "c6", "c7", "c8", "c9")
#: Propeller-induced port/starboard asymmetry (regressor n^2), appended after the symmetric terms.
ASYM_NAMES = ("b0", "c0")

#: Regressor of each coefficient (for tables and identifiability messages).
RESPONSE_NL_REGRESSORS = {
    "a1": "u", "a2": "v^2", "a3": "r^2", "a4": "delta^2", "a5": "v*r", "a6": "v*delta", "a7": "r*delta",
    "a8": "u*|n|", "a9": "n|n|",
    "b1": "v", "b2": "r", "b3": "delta", "b4": "u*r", "b5": "|u|*v", "b6": "v|v|", "b7": "r|r|",
    "b8": "v^2 r/|u|", "b9": "v r^2/|u|",
    "c1": "v", "c2": "r", "c3": "delta", "c4": "|u|*v", "c5": "|u|*r", "c6": "v|v|", "c7": "r|r|",
    "c8": "v^2 r/|u|", "c9": "v r^2/|u|", "b0": "n^2", "c0": "n^2",
}
#: SI dimension of each coefficient as exponents (metre, second); rps counts as 1/s.  The prime
#: (Froude non-dimensional) value is ``c' = c / (L^a (L/g)^(b/2))`` for ``c`` in m^a s^b, so under
#: Froude scaling to ``lam`` times the length a coefficient scales by ``lam^(a + b/2)``.
PRIME_EXPONENTS = {
    **_SEED_EXPONENTS,
    "b5": (-1, 0), "b6": (-1, 0), "b7": (1, 0), "b8": (0, 0), "b9": (1, 0), "b0": (1, 0),
    "c4": (-2, 0), "c5": (-1, 0), "c6": (-2, 0), "c7": (0, 0), "c8": (-1, 0), "c9": (0, 0), "c0": (0, 0),
}
# parameter index -> (equation row 3/4/5, regressor position in that row)
_U_IDX = [0, 1, 2, 3, 4, 5, 6, 7, 8]
_V_IDX = [9, 10, 11, 12, 16, 17, 18, 19, 20, 27]      # b1 b2 b3 b4 b5 b6 b7 b8 b9 b0
_R_IDX = [13, 14, 15, 21, 22, 23, 24, 25, 26, 28]     # c1 c2 c3 c4 c5 c6 c7 c8 c9 c0

#: The equations (one copy, :mod:`._response_equations`) on numpy arrays.
_EQ = rebind(_req.FUNCTIONS, _req.NUMPY)
_POS = {"x": _req.NL_JX_POS, "p": _req.NL_JP_POS, "u": _req.NL_JU_POS}


class ResponseNLModel(FroudeScaled, Model):
    """The KCS response model with speed-dependent non-linear sway/yaw damping (29 coefficients).

    The coefficients are dimensional (SI, as ``kcs-response``) and belong to a
    ship of length ``lpp``; :meth:`to_prime`/:meth:`from_prime` convert them
    to and from the Froude-non-dimensional (prime) system, and
    :meth:`scaled` gives the geometrically similar ship of another length
    (times x sqrt(lam), positions x lam for ``lam = L_new/L``; see
    :mod:`shipid.scaling`).

    Parameters
    ----------
    params : mapping, array, str or None
        As for every model; default set ``"mmg-kcs-fit"``.  With the thirteen
        new coefficients zero the model equals ``kcs-response``.
    lpp : float, optional
        Length [m] of the ship the model describes.  A named parameter set
        (or the default) is Froude-scaled from its own length (its
        ``operating_point``) to ``lpp``; coefficients given as a mapping or
        array are taken as they are (they already belong to that ship).
    design_speed, rudder_rate : float, optional
        Approach speed [m/s] and steering rate [rad/s] of that ship (replace the set's).

    Attributes
    ----------
    lpp, design_speed, rudder_rate : float or None
        Ship length [m], approach speed [m/s], steering rate [rad/s] (those of
        a named set, Froude-scaled; None when unknown).
    u_floor : float
        Lower bound [m/s] of ``u`` in the ``1/u`` factors (default 0.05).
    """

    name = "response-nl"
    #: the sway damping of v (b1 v + b5 |u| v + b6 v|v|: at rest, growing with speed, cross-flow) and the yaw
    #: damping of r (c2 r + c5 |u| r + c7 r|r|); each <= 0 keeps dv/dt per v and dr/dt per r (without the
    #: cross terms) negative at every speed from rest
    dissipative = ("b1", "b5", "b6", "c2", "c5", "c7")
    #: a stern rudder b3 < 0, c3 > 0; thrust a9 > 0 (the own damping is a sum of terms: damping_check)
    physics_signs = {"b3": STERN_RUDDER_SIGNS["sway"], "c3": STERN_RUDDER_SIGNS["yaw"],
                     "a9": (+1, "the propeller pushes the ship ahead for n > 0", ("n",), "check the sign of n (--sign n=-1)")}
    #: as kcs-response's c3 (the seed terms have the same meaning)
    physics_ranges = {"c3": (0.92, 1.97, ("delta",), RUDDER_UNIT_FIX)}
    #: The fit recipe holds the asymmetry terms b0, c0 at their start (the EKF does not identify them from turns
    #: and zigzags at one rpm: docs/validation.md), and its staged start fits ``kcs-response`` (the 16 terms
    #: this model extends) at the logs' scale first, the non-linear terms starting at 0.
    recipe_defaults = RecipeDefaults(fixed=("b0", "c0"), seed_model="kcs-response")
    state_names = ("x", "y", "psi", "u", "v", "r")
    input_names = ("delta", "n")
    param_names = SEED_NAMES + EXTRA_NAMES + ASYM_NAMES
    units = {"x": "m", "y": "m", "psi": "rad", "u": "m/s", "v": "m/s", "r": "rad/s", "delta": "rad", "n": "rps",
             "a1": "1/s", "a2": "1/m", "a3": "m", "a4": "m/s^2", "a5": "1", "a6": "1/s", "a7": "m/s", "a8": "1",
             "a9": "m", "b1": "1/s", "b2": "m/s", "b3": "m/s^2", "b4": "1", "c1": "1/(m s)", "c2": "1/s",
             "c3": "1/s^2", "b5": "1/m", "b6": "1/m", "b7": "m", "b8": "1", "b9": "m", "c4": "1/m^2",
             "c5": "1/m", "c6": "1/m^2", "c7": "1", "c8": "1/m", "c9": "1", "b0": "m", "c0": "1"}
    default_parameter_set = "mmg-kcs-fit"
    prime_exponents = PRIME_EXPONENTS
    u_floor = 0.05

    def __init__(self, params=None, *, lpp: float | None = None, design_speed: float | None = None,
                 rudder_rate: float | None = None):
        super().__init__(params)
        self._init_ship(params, lpp, design_speed, rudder_rate)

    # ----------------------------------------------------------- regressors
    def regressors(self, x, u):
        """Regressor arrays of the u, v and r equations, shapes (..., 9), (..., 10), (..., 10)
        (order of ``_U/_V/_R_IDX``)."""
        x, u = np.asarray(x, dtype=float), np.asarray(u, dtype=float)
        g = np.stack(np.broadcast_arrays(*_EQ["nl_regressors"](x[..., 3], x[..., 4], x[..., 5], u[..., 0], u[..., 1],
                                                                self.u_floor)), axis=-1)
        return g[..., :9], g[..., 9:19], g[..., 19:]

    def _rhs(self, t, x, u, p):
        out = _EQ["nl_rates"](x[..., 2], x[..., 3], x[..., 4], x[..., 5], u[..., 0], u[..., 1], _rows(p),
                              self.u_floor)
        return _req.stack_numpy(batch_shape(x, u, p), out)

    # ------------------------------------------------------------- Jacobians
    def _jacobian(self, x, u, p, which: str, ncol: int):
        """Jacobian ``which`` ("x", "p", "u") from the entries of ``_response_equations.nl_jac_*``."""
        vals = _EQ["nl_jac_" + which](x[..., 2], x[..., 3], x[..., 4], x[..., 5], u[..., 0], u[..., 1], _rows(p),
                                      self.u_floor)
        return _req.fill_numpy(batch_shape(x, u, p) + (6, ncol), _POS[which], vals)

    def _jac_x(self, t, x, u, p):
        return self._jacobian(x, u, p, "x", 6)

    def _jac_p(self, t, x, u, p):
        return self._jacobian(x, u, p, "p", self.np)

    def _jac_u(self, t, x, u, p):
        return self._jacobian(x, u, p, "u", 2)

    # the compiled EKF kernel (shipid._kernel) uses the same equations
    _equations = _req.KERNEL_NL
    _python_replay = True  # 60 against 200 us per sample (as kcs-response)

    def _kernel_constants(self) -> np.ndarray:
        return np.array([self.u_floor])

    _pi = {k: i for i, k in enumerate(SEED_NAMES + EXTRA_NAMES + ASYM_NAMES)}
