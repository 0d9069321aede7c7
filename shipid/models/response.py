"""KCS 3-DOF response model of Hajizadeh et al.

States ``x, y, psi, u, v, r`` (earth-fixed position [m], heading [rad],
body-axis surge/sway [m/s], yaw rate [rad/s]); inputs ``delta`` [rad] (positive
turns the ship to starboard, i.e. produces positive r with the synthetic set)
and ``n`` [rps]; 16 parameters::

    du/dt = a1 u + a2 v^2 + a3 r^2 + a4 delta^2 + a5 v r + a6 v delta
            + a7 r delta + a8 u n + a9 n|n|
    dv/dt = b1 v + b2 r + b3 delta + b4 u r
    dr/dt = c1 v + c2 r + c3 delta

plus kinematics ``x' = u cos psi - v sin psi``, ``y' = u sin psi + v cos psi``,
``psi' = r``.  The equations are linear in the parameters, so ``jac_p`` is the
regressor matrix; both Jacobians are analytic.

Reference: Hajizadeh, Seif & Mehdigholi (Sharif University of Technology, in Persian): ship manoeuvring
coefficients by system identification from free-running model tests (KCS, augmented-state EKF).
"""
from __future__ import annotations

import numpy as np

from .._jit import rebind
from . import _response_equations as _req
from .base import OWN_DAMPING_SIGNS, STERN_RUDDER_SIGNS, RUDDER_UNIT_FIX, Model, batch_shape
from .prime import FroudeScaled

__all__ = ["KCSResponseModel", "RESPONSE_REGRESSORS", "PRIME_EXPONENTS"]

#: The equations (one copy, :mod:`._response_equations`) on numpy arrays.
_EQ = rebind(_req.FUNCTIONS, _req.NUMPY)
_POS = {"x": _req.KCS_JX_POS, "p": _req.KCS_JP_POS, "u": _req.KCS_JU_POS}


def _rows(p):
    """The parameters as a sequence of components (``p.T`` for a batch)."""
    return p.T if p.ndim <= 2 else np.moveaxis(p, -1, 0)


#: Regressor of each coefficient, for tables and identifiability messages.
RESPONSE_REGRESSORS = {
    "a1": "u", "a2": "v^2", "a3": "r^2", "a4": "delta^2", "a5": "v*r", "a6": "v*delta",
    "a7": "r*delta", "a8": "u*n", "a9": "n|n|",
    "b1": "v", "b2": "r", "b3": "delta", "b4": "u*r",
    "c1": "v", "c2": "r", "c3": "delta",
}
#: SI dimension of each coefficient as exponents (metre, second) of ``m^a s^b``, rps counting as 1/s
#: (from the units below: e.g. ``a9 n^2`` is an acceleration, so a9 is in m; ``c1 v`` is in 1/s^2, so
#: c1 is in 1/(m s)).  Prime value ``c' = c / (L^a (L/g)^(b/2))`` (:mod:`shipid.models.prime`).
PRIME_EXPONENTS = {
    "a1": (0, -1), "a2": (-1, 0), "a3": (1, 0), "a4": (1, -2), "a5": (0, 0), "a6": (0, -1), "a7": (1, -1),
    "a8": (0, 0), "a9": (1, 0),
    "b1": (0, -1), "b2": (1, -1), "b3": (1, -2), "b4": (0, 0),
    "c1": (-1, -1), "c2": (0, -1), "c3": (0, -2),
}


class KCSResponseModel(FroudeScaled, Model):
    """The Hajizadeh et al. KCS response model (16 coefficients a1..a9, b1..b4, c1..c3).

    Parameter sets shipped: ``"synthetic-truth"`` (default; the documented set
    the bundled synthetic logs were generated with, see ``data/README.md``) and
    ``"table3"`` (the paper's Table 3 as printed -- units unstated, does not
    close a turning circle; never use it as a validation truth).

    The coefficients are dimensional (SI) and belong to a ship of length ``lpp``;
    :meth:`to_prime` / :meth:`from_prime` convert them to and from the Froude
    non-dimensional system and :meth:`scaled` gives the geometrically similar ship
    of another length (:data:`PRIME_EXPONENTS`, :mod:`shipid.models.prime`).

    Parameters
    ----------
    params : mapping, array, str or None
        As for every model; default set ``"synthetic-truth"`` (the 4.36 m KCS model).
    lpp : float, optional
        Length [m] of the ship the model describes.  A named parameter set (or the
        default) is Froude-scaled from its own length to ``lpp``; coefficients given
        as a mapping or array are taken as they are (they belong to that ship).
    design_speed, rudder_rate : float, optional
        Approach speed [m/s] and steering rate [rad/s] of that ship (replace the set's).

    Attributes
    ----------
    lpp, design_speed, rudder_rate : float or None
        Ship length [m], approach speed [m/s], steering rate [rad/s] (those of a
        named set, Froude-scaled; None when unknown).
    """

    name = "kcs-response"
    #: sway damping b1 (dv/dt per v) and yaw damping c2 (dr/dt per r)
    dissipative = ("b1", "c2")
    #: the linear model's own damping b1, c2 < 0; a stern rudder b3 < 0, c3 > 0; thrust a9 > 0
    physics_signs = {"b1": OWN_DAMPING_SIGNS["sway"], "c2": OWN_DAMPING_SIGNS["yaw"],
                     "b3": STERN_RUDDER_SIGNS["sway"], "c3": STERN_RUDDER_SIGNS["yaw"],
                     "a9": (+1, "the propeller pushes the ship ahead for n > 0", ("n",), "check the sign of n (--sign n=-1)")}
    #: c3 L^2/U^2 of the published sets' linearisations at their design speeds: MMG KVLCC2 (Yasukawa &
    #: Yoshimura 2015) 1.19, MMG KCS (mmg_kcs.json) 1.97, lowspeed Esso Osaka 1.38, response-nl mmg-kcs-fit
    #: 1.14, and the synthetic-truth set 0.92 (tests/test_verdict.py recomputes them)
    physics_ranges = {"c3": (0.92, 1.97, ("delta",), RUDDER_UNIT_FIX)}
    state_names = ("x", "y", "psi", "u", "v", "r")
    input_names = ("delta", "n")
    param_names = ("a1", "a2", "a3", "a4", "a5", "a6", "a7", "a8", "a9",
                   "b1", "b2", "b3", "b4", "c1", "c2", "c3")
    units = {
        "x": "m", "y": "m", "psi": "rad", "u": "m/s", "v": "m/s", "r": "rad/s",
        "delta": "rad", "n": "rps",
        "a1": "1/s", "a2": "1/m", "a3": "m", "a4": "m/s^2", "a5": "1", "a6": "1/s",
        "a7": "m/s", "a8": "1", "a9": "m", "b1": "1/s", "b2": "m/s", "b3": "m/s^2", "b4": "1",
        "c1": "1/(m s)", "c2": "1/s", "c3": "1/s^2",
    }
    default_parameter_set = "synthetic-truth"
    prime_exponents = PRIME_EXPONENTS

    def __init__(self, params=None, *, lpp: float | None = None, design_speed: float | None = None,
                 rudder_rate: float | None = None):
        super().__init__(params)
        self._init_ship(params, lpp, design_speed, rudder_rate)

    def _rhs(self, t, x, u, p):
        out = _EQ["kcs_rates"](x[..., 2], x[..., 3], x[..., 4], x[..., 5], u[..., 0], u[..., 1], _rows(p))
        return _req.stack_numpy(batch_shape(x, u, p), out)

    def identifiability_notes(self, arrays, estimated) -> list[str]:
        """Warn when n is constant over all logs: u, u*n and n^2 are then collinear."""
        n = np.concatenate([a.U[:, 1] for a in arrays])
        if not {"a1", "a8", "a9"} <= set(estimated) or n.size == 0:  # one of them held: the others separate
            return []
        n_mean = float(np.mean(n))
        if np.ptp(n) <= 0.01 * max(abs(n_mean), 1e-9):
            return [
                f"a1, a8, a9 cannot be separated: the propeller rate is constant (n = {n_mean:.4g} rps) in every log, "
                "so the regressors u, u*n and n^2 are collinear; only a1 + a8*n and a9*n^2 are determined "
                "(fix a8 or add logs with rpm changes)"
            ]
        return []

    def _jacobian(self, x, u, p, which: str, ncol: int):
        """Jacobian ``which`` ("x", "p", "u") from the entries of ``_response_equations.kcs_jac_*``."""
        vals = _EQ["kcs_jac_" + which](x[..., 2], x[..., 3], x[..., 4], x[..., 5], u[..., 0], u[..., 1], _rows(p))
        return _req.fill_numpy(batch_shape(x, u, p) + (6, ncol), _POS[which], vals)

    def _jac_x(self, t, x, u, p):
        return self._jacobian(x, u, p, "x", 6)

    def _jac_p(self, t, x, u, p):
        return self._jacobian(x, u, p, "p", 16)

    def _jac_u(self, t, x, u, p):
        return self._jacobian(x, u, p, "u", 2)

    # the compiled EKF kernel (shipid._kernel) uses the same equations
    _equations = _req.KERNEL_KCS
    _python_replay = True  # 66 against 190 us per sample (6000-sample replay, 2 RK4 steps per sample)

