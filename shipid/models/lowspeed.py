"""Low-speed, four-quadrant MMG-type manoeuvring model (``lowspeed``), valid at rest and astern.

The standard MMG model (:mod:`shipid.models.mmg`) expands the hull forces in ``v/U`` and ``r L/U``
and its propeller in ``J = u_P/(n D)``: it assumes forward speed, small drift and a propeller turning
ahead.  Harbour and berthing manoeuvres -- starts from rest, drift angles to 90 degrees and beyond,
astern propeller -- need another form.  This model follows the structure of the "unified" low-speed
hull model of Yoshimura (Y. Yoshimura, M. Nakao, A. Ishibashi (2009), *Unified mathematical model for
ocean and harbour manoeuvring*, MARSIM 2009) with Kose's cross-flow integral (K. Kose, H. Hashizume,
H. Yumuro (1984), *Manoeuvring characteristics of ships at low speed*, J. Kansai Soc. Naval Arch.
190), the form used for this very data set (the 3 m Esso Osaka) by Wakita et al. (2022, J. Mar. Sci.
Technol. 27:772-785) and Miyauchi et al. (2022, J. Mar. Sci. Technol. 27:1065-1083).  What follows
is this package's own write-up of that structure; where it differs (resistance interpolation,
smooth propeller quadrants, rudder in reversed flow) it says so.

States, inputs and axes are those of ``mmg``: midship position ``x, y`` [m], heading ``psi`` [rad],
body velocities at midship ``u, v`` [m/s] (``v`` to starboard), yaw rate ``r`` [rad/s]; inputs rudder
``delta`` [rad] and propeller ``n`` [rps] (negative = astern).  ``U = sqrt(u^2 + v^2)``, ``L`` = Lpp,
``q = 1/2 rho L d``.

Hull (no division by U)::

    X_H = q [ (X0F (U + u)/2 + X0A (U - u)/2) u + Xvv v^2 + Xvr v r L ]
    Y_H = q [ Yv v |u| + Yr r L u - CD int_{-1/2}^{1/2} (v + CrY r L s) |v + CrY r L s| ds ]
    N_H = q L [ Nv v u + Nr r L |u| - CD int_{-1/2}^{1/2} (v + CrN r L s) |v + CrN r L s| s ds ]

The resistance term blends the ahead (``X0F``, drift 0) and astern (``X0A``, drift 180 deg) values
with ``(1 + cos beta)/2`` (Yoshimura uses a linear interpolation in ``|beta|``; the cosine form is
smooth at rest).  The cross-flow integral is evaluated by Gauss-Legendre quadrature (24 nodes).

Propeller, four quadrants (``T`` thrust, ``u_P = u (1 - w_P0)`` for ``u > 0``, ``u`` otherwise)::

    n >= 0:  X_P = (1 - tP) rho D^2 (k0 n^2 D^2 + k1 n D u_P + k2 u_P^2)      (MMG K_T(J) polynomial)
    n <  0:  X_P = rho D^2 (CTa0 n^2 D^2 + CTa1 n D u)                      (astern K_T, linear in J)
             Y_P = q n^2 D^2 YPa,   N_P = q L n^2 D^2 NPa                  (astern side force)

Rudder: ``F_N = 1/2 rho A_R f_alpha U_R (u_R sin delta - v_R cos delta)`` -- the MMG normal force
``U_R^2 sin(delta - atan2(v_R, u_R))`` written without the angle, so that it stays defined and
reverses correctly when the flow meets the rudder from behind (``u_R < 0``, going astern).
``v_R = -gammaR (v + lR L r)``; ``u_R = eps ssqrt(eta a|a| + (1 - eta) u_P|u_P|)`` with
``a = u_P + kappa (sqrt(u_P^2 + 8 T+/(pi rho D^2)) - |u_P|)`` and ``T+`` the ahead thrust only
(``ssqrt(z) = sign(z) sqrt|z|``; for ``u_P >= 0`` and ``n >= 0`` this is the MMG eq. (23)-(25)); an
astern propeller sends its race forward, away from the rudder.  ``X_R = -(1 - tR) F_N sin delta``,
``Y_R = -(1 + aH) F_N cos delta``, ``N_R = -(x_R + aH xH) L F_N cos delta``.

Motion: eq. (4) of Yasukawa & Yoshimura (2015), as in ``mmg``.  All coefficients are
non-dimensional with ``1/2 rho L d`` (forces, per velocity squared) and ``1/2 rho L^2 d`` (moments);
added masses as in ``mmg``; the model is Froude-scalable (``lpp=``, :meth:`LowSpeedModel.scaled`).

Jacobians: complex step on the (complex-safe) numpy equations, exact to rounding.
"""
from __future__ import annotations

from typing import Mapping

import numpy as np

from .base import ComplexStepJacobians, Model
from .kinematics import planar_rates
from .mmg import MMGParticulars, eq4_mass_matrix

__all__ = ["LowSpeedModel", "LOWSPEED_PARAM_NAMES"]

LOWSPEED_PARAM_NAMES = (
    "X0F", "X0A", "Xvv", "Xvr", "Yv", "Yr", "Nv", "Nr", "CD", "CrY", "CrN",
    "mx", "my", "Jz",
    "tP", "wP0", "k0", "k1", "k2", "CTa0", "CTa1", "YPa", "NPa",
    "tR", "aH", "xH", "gammaR", "lR", "eps", "kappa", "f_alpha",
)

_S, _W = np.polynomial.legendre.leggauss(24)
_S, _W = 0.5 * _S, 0.5 * _W  # nodes and weights on [-1/2, 1/2]


def _re(z):
    return np.real(z)


def _abs(z):
    """|z| from the sign of the real part (complex-step safe)."""
    return z * np.where(_re(z) < 0, -1.0, 1.0)


def _pos(z):
    """max(z, 0), complex-step safe."""
    return z * (_re(z) > 0)


def _ssqrt(z):
    """sign(z) sqrt(|z|), complex-step safe (0 at 0)."""
    s = np.where(_re(z) < 0, -1.0, 1.0)
    a = z * s
    return s * np.sqrt(np.where(_re(a) > 0, a, 1.0)) * (_re(a) > 0)


class LowSpeedModel(ComplexStepJacobians, Model):
    """Low-speed four-quadrant manoeuvring model (see the module docstring for the equations).

    Parameters
    ----------
    params : mapping, array, str or None
        Non-dimensional coefficients (:data:`LOWSPEED_PARAM_NAMES`) or a shipped set name
        (default ``"esso-osaka-prior"``, whose particulars are then used too).
    particulars : MMGParticulars, mapping or str, optional
        The ship (same fields as ``mmg``); defaults to the named/default set's.
    lpp : float, optional
        Rescale the particulars to this length [m] (Froude, geometric similarity).
    """

    name = "lowspeed"
    state_names = ("x", "y", "psi", "u", "v", "r")
    input_names = ("delta", "n")
    param_names = LOWSPEED_PARAM_NAMES
    units = {"x": "m", "y": "m", "psi": "rad", "u": "m/s", "v": "m/s", "r": "rad/s", "delta": "rad", "n": "rps",
             **{k: "-" for k in LOWSPEED_PARAM_NAMES}, "f_alpha": "1/rad"}
    default_parameter_set = "esso-osaka-prior"

    def __init__(self, params=None, *, particulars=None, lpp: float | None = None):
        super().__init__(params)
        if particulars is None:
            particulars = params if isinstance(params, str) else self.default_parameter_set
        if isinstance(particulars, str):
            extra = self.parameter_set(particulars).extra
            particulars = MMGParticulars.from_mapping(extra["particulars"])
        elif isinstance(particulars, Mapping):
            particulars = MMGParticulars.from_mapping(particulars)
        elif not isinstance(particulars, MMGParticulars):
            raise ValueError(f"particulars must be MMGParticulars, a mapping or a parameter-set name, got "
                             f"{type(particulars).__name__}")
        self.particulars = particulars.scaled(lpp) if lpp is not None else particulars

    lpp = property(lambda self: self.particulars.lpp, doc="Length between perpendiculars [m].")
    rudder_rate = property(lambda self: self.particulars.rudder_rate, doc="Steering-gear rate [rad/s].")
    design_speed = property(lambda self: self.particulars.design_speed, doc="Default approach speed [m/s].")

    def options(self) -> dict:
        return {"particulars": self.particulars.to_dict()}

    def scaled(self, lpp_new: float) -> "LowSpeedModel":
        """The same non-dimensional model for the geometrically similar ship of length ``lpp_new``."""
        new = self.with_params(self.params)
        new.particulars = self.particulars.scaled(lpp_new)
        return new

    # ------------------------------------------------------------- equations
    def _coef(self, p):
        c = p.T if p.ndim <= 2 else np.moveaxis(p, -1, 0)
        return dict(zip(self.param_names, c))

    def mass_matrix(self, params=None) -> np.ndarray:
        """Rigid-body plus added mass matrix of eq. (4) at midship, shape ``(..., 3, 3)`` [kg, kg m, kg m^2]
        (rows surge, sway, yaw); used to add external forces (wind) to the model."""
        c = self._coef(self.params if params is None else np.asarray(params))  # complex kept (complex step)
        return eq4_mass_matrix(self.particulars, c["mx"], c["my"], c["Jz"])

    def forces(self, x, u, params=None) -> dict:
        """Hull, propeller and rudder forces [N] and moments [N m] at midship (dict of arrays)."""
        return self._forces(np.asarray(x, dtype=float), np.asarray(u, dtype=float), self._p(params))

    def _forces(self, x, u, p) -> dict:
        P, c = self.particulars, self._coef(p)
        L, d, rho, D = P.lpp, P.draught, P.rho, P.D_p
        q = 0.5 * rho * L * d
        uu, v, r = x[..., 3], x[..., 4], x[..., 5]
        delta, n = u[..., 0], u[..., 1]
        U = np.sqrt(uu * uu + v * v)
        au = _abs(uu)
        rL = r * L
        # hull: resistance blended ahead/astern, linear terms, Kose cross-flow integral
        s = _S.reshape((-1,) + (1,) * np.ndim(rL * c["CrY"]))
        wy = v + c["CrY"] * rL * s
        wn = v + c["CrN"] * rL * s
        Yc = np.tensordot(_W, wy * _abs(wy), axes=(0, 0))
        Nc = np.tensordot(_W * _S, wn * _abs(wn), axes=(0, 0))
        XH = q * ((c["X0F"] * (U + uu) * 0.5 + c["X0A"] * (U - uu) * 0.5) * uu + c["Xvv"] * v * v + c["Xvr"] * v * rL)
        YH = q * (c["Yv"] * v * au + c["Yr"] * rL * uu - c["CD"] * Yc)
        NH = q * L * (c["Nv"] * v * uu + c["Nr"] * rL * au - c["CD"] * Nc)
        # propeller, four quadrants
        ahead = _re(n) >= 0
        uP = uu * np.where(_re(uu) > 0, 1.0 - c["wP0"], 1.0)
        T_ahead = rho * D * D * (c["k0"] * n * n * D * D + c["k1"] * n * D * uP + c["k2"] * uP * uP)
        T_astern = rho * D * D * (c["CTa0"] * n * n * D * D + c["CTa1"] * n * D * uu)
        T = np.where(ahead, T_ahead, T_astern)
        XP = T * np.where(ahead, 1.0 - c["tP"], 1.0)
        n2a = n * n * (~ahead)
        YP = q * n2a * D * D * c["YPa"]
        NP = q * L * n2a * D * D * c["NPa"]
        # rudder
        eta = D / P.H_R
        Tp = _pos(T) * ahead
        a = uP + c["kappa"] * (np.sqrt(uP * uP + 8.0 * Tp / (np.pi * rho * D * D)) - _abs(uP))
        uR = c["eps"] * _ssqrt(eta * a * _abs(a) + (1.0 - eta) * uP * _abs(uP))
        vR = -c["gammaR"] * (v + c["lR"] * rL)
        UR = np.sqrt(uR * uR + vR * vR)
        FN = 0.5 * rho * P.A_R * c["f_alpha"] * UR * (uR * np.sin(delta) - vR * np.cos(delta))
        XR = -(1.0 - c["tR"]) * FN * np.sin(delta)
        YR = -(1.0 + c["aH"]) * FN * np.cos(delta)
        NR = -(P.x_R + c["aH"] * c["xH"]) * L * FN * np.cos(delta)
        return {"X_H": XH, "Y_H": YH, "N_H": NH, "X_P": XP, "Y_P": YP, "N_P": NP, "X_R": XR, "Y_R": YR, "N_R": NR,
                "T": T, "F_N": FN, "u_R": uR, "v_R": vR, "U": U}

    def _rhs(self, t, x, u, p):
        F = self._forces(x, u, p)
        X = F["X_H"] + F["X_P"] + F["X_R"]
        Y = F["Y_H"] + F["Y_P"] + F["Y_R"]
        N = F["N_H"] + F["N_P"] + F["N_R"]
        return _motion(self.particulars, self._coef(p), x, X, Y, N)

    # ------------------------------------------------------------- Jacobians

    @classmethod
    def sample_point(cls, rng, batch=()):
        """A random (x, u) over all four quadrants for protocol tests."""
        x = np.zeros(batch + (6,))
        x[..., 0:2] = rng.normal(size=batch + (2,))
        x[..., 2] = rng.normal(size=batch)
        x[..., 3] = 0.2 * rng.normal(size=batch)
        x[..., 4] = 0.1 * rng.normal(size=batch)
        x[..., 5] = 0.05 * rng.normal(size=batch)
        u = np.stack([0.4 * rng.normal(size=batch), 8.0 * rng.normal(size=batch)], axis=-1)
        return x, u


def _motion(P: MMGParticulars, c, x, X, Y, N):
    """Eq. (4) of Yasukawa & Yoshimura (2015) solved for the accelerations, and the kinematics."""
    M = eq4_mass_matrix(P, c["mx"], c["my"], c["Jz"])
    Mx, My, B, C = M[..., 0, 0], M[..., 1, 1], M[..., 1, 2], M[..., 2, 2]
    psi, uu, v, r = x[..., 2], x[..., 3], x[..., 4], x[..., 5]
    du = (X + (My * v + B * r) * r) / Mx
    fy = Y - Mx * uu * r
    fn = N - B * uu * r
    det = My * C - B * B
    dv = (C * fy - B * fn) / det
    dr = (My * fn - B * fy) / det
    out = [*planar_rates(psi, uu, v, r), du, dv, dr]
    shape = np.broadcast_shapes(*[np.shape(o) for o in out])
    return np.stack([np.broadcast_to(o, shape) for o in out], axis=-1)
