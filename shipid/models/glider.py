"""Underwater glider in the vertical plane (Divsalar et al.).

Fossen's 6-DOF form ``M v' + C(v) v + D(v) v + g(eta) = tau`` reduced to
surge, heave and pitch (``v = p = r = 0``, ``phi = psi = 0``), ``tau = 0``
(no thrust), with optional added mass.

Frames and states
-----------------
Earth frame: ``x`` horizontal [m], ``z`` vertical **positive down** (depth)
[m], origin on the free surface at the launch point.  Body frame: origin at
the centre of buoyancy (CB), ``x_b`` forward along the hull axis, ``z_b``
down.  States ``x, z, theta, u, w, q``: position, pitch angle [rad]
(positive nose up), body-axis surge and heave velocity [m/s], pitch rate
[rad/s].  Input ``delta`` [rad]: fin incidence relative to the hull,
positive = leading edge up, i.e. positive fin lift (towards ``-z_b``) at zero
angle of attack.

Kinematics::

    x'     =  u cos(theta) + w sin(theta)
    z'     = -u sin(theta) + w cos(theta)
    theta' =  q

Kinetics (Fossen 2011, eqs. 3.43 and 6.x, planar part; ``X_udot``,
``Z_wdot``, ``M_qdot`` are Fossen's added-mass derivatives, <= 0)::

    (m - X_udot) u' + m z_g q'            = X - m w q + m x_g q^2 + Z_wdot w q
    (m - Z_wdot) w' - m x_g q'            = Z + m u q + m z_g q^2 - X_udot u q
    m z_g u' - m x_g w' + (Iy - M_qdot) q' = M - m z_g w q - m x_g u q
                                              - (Z_wdot - X_udot) u w

The last added-mass term is the Munk moment.  ``Iy`` is about the CB.

External forces (``V^2 = u^2 + w^2``, ``alpha = atan2(w, u)``):

* Restoring, paper eq. (34) with ``phi = 0`` (CB at the origin)::

      X_G = -(W - B) sin(theta),  Z_G = (W - B) cos(theta),
      M_G = -z_g W sin(theta) - x_g W cos(theta),   W = m g, B = rho Vol g

* Hull drag along the velocity, ``C_D = a alpha^2 + b |alpha| + c``
  (paper eq. 30, figure 5: a = 5.25, b = -0.315, c = 0.732), reference area
  ``A_f = pi d^2 / 4`` (frontal area)::

      X_D = -1/2 rho A_f C_D V u,   Z_D = -1/2 rho A_f C_D V w

  i.e. ``-1/2 rho A_f C_D V^2 (cos alpha, sin alpha)`` exactly, not the
  paper's small-angle expansion of eq. (32).  The paper's quadratic uses
  signed ``alpha``; for an axisymmetric hull drag must be even in alpha, so
  the fitted curve (figure 5 is for alpha >= 0) is applied to ``|alpha|``.

* Hull lift (figure 6, ``C_L_alpha = 4.79 /rad``), perpendicular to the
  velocity, reference area ``A_f``::

      L = 1/2 rho A_f CL_alpha alpha V^2,
      X_L = L sin(alpha),  Z_L = -L cos(alpha)

  The paper's eq. (33) keeps only ``Z_L``; the surge component of a force
  perpendicular to the velocity is kept here.

* Hull pitch moment (figure 7, ``C_M_alpha = 0.0974 /rad``), reference area
  ``A_f`` and reference length ``length`` (hull length)::

      M_H = 1/2 rho A_f length CM_alpha alpha V^2

  positive (nose up) for positive alpha: the destabilising Munk-type moment
  of a bare hull.

* Fins (the pair as one NACA0009 wing of span ``fin_span`` and chord
  ``fin_chord``, planform area ``A_fin = fin_span fin_chord``, aspect ratio
  ``Lambda = fin_span / fin_chord``; the paper's eq. (19), "length/area", is
  not dimensionless and is read as this standard aspect ratio), at
  ``x = x_fin`` on the hull axis.  Local velocity ``(u, w - q x_fin)``, flow
  angle ``delta_h = atan2(w - q x_fin, u)``, effective angle
  ``delta_e = delta + delta_h``; paper eqs. (17)-(21) **with the local speed
  squared** ``V_f^2`` that the paper's eqs. (20)-(21) omit::

      C_l = 6.13 Lambda / (2.25 + Lambda),   C_d = C_l^2 / (pi Lambda)
      L_f = 1/2 rho A_fin C_l sin(delta_e) cos(delta_e) V_f^2
      D_f = 1/2 rho A_fin C_d sin(delta_e)^2 V_f^2
      X_F = L_f sin(delta_h) - D_f cos(delta_h)
      Z_F = -L_f cos(delta_h) - D_f sin(delta_h),   M_F = -x_fin Z_F

The geometry the paper does not print (fin span, fin position) is stated in
the parameter JSON with its caveat.

Reference: Divsalar, Shafaghat, Farhadi & Alemian (Babol Noshirvani University of Technology, in Persian):
parameters affecting the trajectory of a spherical-nose marine glider.
"""
from __future__ import annotations

import numpy as np

from .base import Model

__all__ = ["GliderModel"]

_PARAMS = (
    "a", "b", "c", "CL_alpha", "CM_alpha",
    "m", "volume", "Iy", "x_g", "z_g",
    "diameter", "length", "fin_span", "fin_chord", "x_fin",
    "X_udot", "Z_wdot", "M_qdot", "rho", "g",
)


class GliderModel(Model):
    """Spherical-nose underwater glider of Divsalar et al., surge/heave/pitch.

    States ``x, z, theta, u, w, q`` (z positive down = depth); input
    ``delta`` (fin incidence [rad]); 20 parameters (see :attr:`units`).  The
    hydrodynamic coefficients ``a, b, c, CL_alpha, CM_alpha`` are parameters
    so the EKF can identify them; the CG offset ``x_g`` is a parameter so a
    batch study can give each member its own value.

    Parameter sets: ``"paper"`` (default; Divsalar et al. table 1 and figures 5-7,
    no added mass) and ``"paper-added-mass"`` (same plus prolate-spheroid
    added mass).  Jacobians are central differences evaluated in one
    vectorised call (the equations involve a 3x3 mass-matrix solve and
    ``atan2``; analytic derivatives would be a second copy of them).
    """

    name = "glider"
    state_names = ("x", "z", "theta", "u", "w", "q")
    input_names = ("delta",)
    param_names = _PARAMS
    units = {
        "x": "m", "z": "m (down)", "theta": "rad", "u": "m/s", "w": "m/s", "q": "rad/s",
        "delta": "rad",
        "a": "1/rad^2", "b": "1/rad", "c": "1", "CL_alpha": "1/rad", "CM_alpha": "1/rad",
        "m": "kg", "volume": "m^3", "Iy": "kg m^2", "x_g": "m", "z_g": "m",
        "diameter": "m", "length": "m", "fin_span": "m", "fin_chord": "m", "x_fin": "m",
        "X_udot": "kg", "Z_wdot": "kg", "M_qdot": "kg m^2", "rho": "kg/m^3", "g": "m/s^2",
    }
    default_parameter_set = "paper"

    @classmethod
    def sample_point(cls, rng: np.random.Generator, batch: tuple = ()) -> tuple[np.ndarray, np.ndarray]:
        """A valid state/input sample for protocol tests: gliding at ~1.5 m/s.

        Returns ``x`` of shape ``batch + (6,)`` and ``u`` of shape ``batch + (1,)``.
        """
        x = rng.normal(size=batch + (6,)) * np.array([1.0, 1.0, 0.4, 0.1, 0.2, 0.3])
        x[..., 3] += 1.5
        u = rng.normal(size=batch + (1,)) * 0.15
        return x, u

    # ------------------------------------------------------------ pieces
    @staticmethod
    def _split(p):
        # contiguous copies: column views of a (B, np) array are strided and slow
        cols = np.ascontiguousarray(np.moveaxis(p, -1, 0))
        return dict(zip(_PARAMS, cols))

    def forces(self, t, x, u, params=None) -> dict[str, np.ndarray]:
        """Force/moment breakdown in body axes at one or many points.

        Returns a dict of arrays of shape ``(...,)``: ``X_G, Z_G, M_G``
        (restoring), ``X_D, Z_D`` (hull drag), ``X_L, Z_L`` (hull lift),
        ``M_H`` (hull moment), ``X_F, Z_F, M_F`` (fins), and ``alpha``,
        ``delta_e`` [rad].  Units N and N m.
        """
        x, u = np.asarray(x, dtype=float), np.asarray(u, dtype=float)
        out = self._forces(x, u, self._p(params))[0]
        out.pop("_state")
        sde, cde = out.pop("_sde_cde")
        out["delta_e"] = np.arctan2(sde, cde)
        return out

    def _constants(self, p):
        """Parameter-derived constants, cached for the last parameter array seen."""
        key = (p.shape, p.tobytes())
        cache = self.__dict__.get("_kcache")
        if cache is not None and cache[0] == key:
            return cache[1]
        P = self._split(p)
        m, xg, zg, rho, g = P["m"], P["x_g"], P["z_g"], P["rho"], P["g"]
        W = m * g
        K = {"a": P["a"], "b": P["b"], "c": P["c"], "x_fin": P["x_fin"], "m": m, "x_g": xg, "z_g": zg}
        K["WB"] = W - rho * P["volume"] * g
        K["zgW"], K["xgW"] = zg * W, xg * W
        half = 0.5 * rho * (np.pi / 4.0) * P["diameter"] ** 2        # 1/2 rho A_f
        K["half"] = half
        K["CLh"] = half * P["CL_alpha"]
        K["CMh"] = half * P["length"] * P["CM_alpha"]
        span, chord = P["fin_span"], P["fin_chord"]
        lam = span / chord                                           # aspect ratio
        cl = 6.13 * lam / (2.25 + lam)                               # paper eq. (17)
        qf = 0.5 * rho * span * chord
        K["qcl"] = qf * cl
        K["qcd"] = qf * cl * cl / (np.pi * lam)                      # paper eq. (18)
        Xu, Zw, Mq = P["X_udot"], P["Z_wdot"], P["M_qdot"]
        K["m_Zw"], K["m_Xu"], K["Zw_Xu"] = m - Zw, m - Xu, Zw - Xu
        # mass matrix [[m11, 0, m13], [0, m22, m23], [m13, m23, m33]]: inverse by its adjugate
        m11, m22, m33 = m - Xu, m - Zw, P["Iy"] - Mq
        m13, m23 = m * zg, -m * xg
        i11 = m22 * m33 - m23 * m23
        i13 = -m22 * m13
        det = m11 * i11 + m13 * i13
        K["i11"], K["i12"], K["i13"] = i11 / det, m13 * m23 / det, i13 / det
        K["i22"], K["i23"], K["i33"] = (m11 * m33 - m13 * m13) / det, -m11 * m23 / det, m11 * m22 / det
        self.__dict__["_kcache"] = (key, K)
        return K

    def _forces(self, x, u_in, p):
        K = self._constants(p)
        _, _, th, uu, w, q = np.ascontiguousarray(np.moveaxis(x, -1, 0))
        delta = u_in[..., 0]
        out = {}
        sth, cth = np.sin(th), np.cos(th)
        out["X_G"] = -K["WB"] * sth
        out["Z_G"] = K["WB"] * cth
        out["M_G"] = -K["zgW"] * sth - K["xgW"] * cth
        # hull: drag along -velocity, lift perpendicular, moment; cos(alpha) = u/V, sin(alpha) = w/V
        V2 = uu * uu + w * w
        V = np.sqrt(V2)
        alpha = np.arctan2(w, uu)
        cd = (K["a"] * alpha + K["b"] * np.sign(alpha)) * alpha + K["c"]
        hv = K["half"] * V * cd
        out["X_D"] = -hv * uu
        out["Z_D"] = -hv * w
        lift = K["CLh"] * V * alpha                # L / V
        out["X_L"] = lift * w                      # L sin(alpha)
        out["Z_L"] = -lift * uu                    # -L cos(alpha)
        out["M_H"] = K["CMh"] * alpha * V2
        # fins at x_fin: local flow angle delta_h, effective angle delta_e = delta + delta_h
        wf = w - q * K["x_fin"]
        vf2 = uu * uu + wf * wf
        vf = np.sqrt(vf2)
        pos = vf > 0
        vs = np.where(pos, vf, 1.0)
        cdh = np.where(pos, uu / vs, 1.0)           # cos(delta_h)
        sdh = np.where(pos, wf / vs, 0.0)           # sin(delta_h)
        sd, cdl = np.sin(delta), np.cos(delta)
        sde = sd * cdh + cdl * sdh                  # sin(delta_e)
        cde = cdl * cdh - sd * sdh                  # cos(delta_e)
        sv = sde * vf2
        lf = K["qcl"] * cde * sv
        df = K["qcd"] * sde * sv
        out["X_F"] = lf * sdh - df * cdh
        out["Z_F"] = -lf * cdh - df * sdh
        out["M_F"] = -K["x_fin"] * out["Z_F"]
        out["alpha"] = alpha
        out["_sde_cde"] = (sde, cde)
        out["_state"] = (th, uu, w, q, sth, cth)
        return out, K

    def _rhs(self, t, x, u, p):
        F, K = self._forces(x, u, p)
        th, uu, w, q, sth, cth = F["_state"]
        m, xg, zg = K["m"], K["x_g"], K["z_g"]
        mq = m * q
        X = F["X_G"] + F["X_D"] + F["X_L"] + F["X_F"] + (xg * mq - w * K["m_Zw"]) * q
        Z = F["Z_G"] + F["Z_D"] + F["Z_L"] + F["Z_F"] + (uu * K["m_Xu"] + zg * mq) * q
        M = F["M_G"] + F["M_H"] + F["M_F"] - (zg * w + xg * uu) * mq - K["Zw_Xu"] * uu * w
        shape = np.broadcast_shapes(np.shape(X), np.shape(Z), np.shape(M), np.shape(th))
        out = np.empty(shape + (6,))
        out[..., 0] = uu * cth + w * sth
        out[..., 1] = w * cth - uu * sth
        out[..., 2] = q
        out[..., 3] = K["i11"] * X + K["i12"] * Z + K["i13"] * M
        out[..., 4] = K["i12"] * X + K["i22"] * Z + K["i23"] * M
        out[..., 5] = K["i13"] * X + K["i23"] * Z + K["i33"] * M
        return out

    # ------------------------------------------------ vectorised Jacobians
    def _fd_vec(self, t, x, u, p, which: str) -> np.ndarray:
        """Central differences with all columns in one batched ``_rhs`` call.

        Same step as :meth:`Model._fd` (``1e-6 (1 + |v_j|)``).
        """
        args = [x, u, p]
        k = {"x": 0, "u": 1, "p": 2}[which]
        base = args[k]
        n = base.shape[-1]
        shape = np.broadcast_shapes(x.shape[:-1], u.shape[:-1], p.shape[:-1])
        if n == 0:
            return np.zeros(shape + (self.nx, 0))
        h = 1e-6 * (1.0 + np.abs(base))                       # (..., n)
        eye = np.eye(n)
        steps = h[..., None, :] * eye                          # (..., n, n): row j perturbs column j
        pert = np.concatenate([base[..., None, :] + steps, base[..., None, :] - steps], axis=-2)  # (..., 2n, n)
        a = [arr[..., None, :] for arr in args]                # add the perturbation axis
        a[k] = pert
        f = self._rhs(t, *a)                                   # (..., 2n, nx)
        d = (f[..., :n, :] - f[..., n:, :]) / (2 * h)[..., :, None]   # (..., n, nx)
        return np.broadcast_to(np.swapaxes(d, -1, -2), shape + (self.nx, n)).copy()

    def _jac_x(self, t, x, u, p):
        return self._fd_vec(t, x, u, p, "x")

    def _jac_p(self, t, x, u, p):
        return self._fd_vec(t, x, u, p, "p")

    def _jac_u(self, t, x, u, p):
        return self._fd_vec(t, x, u, p, "u")
