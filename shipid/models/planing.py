"""4-DOF planing boat of Ghorbani et al.: surge, sway, roll, yaw.

States ``x, y, psi, phi, u, v, p, r`` (earth-fixed position [m], heading
[rad], roll [rad], body-axis surge/sway [m/s], roll/yaw rate [rad/s]);
inputs ``T`` (total thrust of the two vectored outboards [N]) and ``phi_p``
(their steering angle [rad], positive pushes the stern to starboard).

Equations (Ghorbani et al., eqs. (1)-(5))::

    (m - X_udot) u'                 = -k_R R_T(u) + T cos(phi_p) + m v r
    M [v', p', r']^T                = [Y, K, N]^T
    Y = T sin(phi_p) + Y_uv u v + Y_ur u r + Y_p p + Y_phi phi + Y_vv v |v|_s - m u r
    K = T z_p sin(phi_p) + K_uv u v + K_ur u r + K_p p + K_phi phi
    N = -T x_p sin(phi_p) + N_uv u v + N_ur u r + N_p p + N_phi phi
    phi' = p,  psi' = r cos(phi)
    x' = u cos(psi) - v sin(psi) cos(phi),  y' = u sin(psi) + v cos(psi) cos(phi)

with the constant mass matrix ``M = [[m - Y_vdot, -Y_pdot, -Y_rdot],
[-K_vdot, Ixx - K_pdot, -K_rdot], [-N_vdot, -N_pdot, Izz - N_rdot]]`` and
``|v|_s = sqrt(v^2 + 0.01)`` (a smooth ``|v|``).  The paper writes the
velocity derivatives as constants (``Y_v v``); here they are proportional to
the forward speed (``Y_v = Y_uv u``), which is what slender-body theory gives
and keeps the model sensible from rest to full speed.

``R_T(u)`` is Savitsky's planing resistance (:mod:`shipid.savitsky`) of the
hull of Table 1 tabulated once per hull, or a user table; ``k_R`` scales it.

Sources and assumptions (every value is in ``parameters/planing_table1.json``):

* Table 1 of Ghorbani et al.: ``m``, ``Ixx``, ``Izz``, beam, length, LCG, deadrise, rho.
* VCG = 0.50 m above keel and thrust line through the CG (``f = 0``,
  ``eps = 0``) for the trim equilibrium: shipid assumptions (not in the
  paper; the paper took ``R_T`` from Maxsurf's Savitsky module, whose planing
  prediction uses the same simplified case).
* Sway/yaw derivatives: slender-body theory with flow separation at the
  transom (Faltinsen 2005, *Hydrodynamics of High-Speed Marine Vehicles*,
  ch. 10, and Newman 1977, *Marine Hydrodynamics*, sec. 7.?; derived in
  :func:`slender_body_derivatives`) using the 2-D sway added mass of a
  vertical plate of the local keel draught, ``a22 = rho pi d^2 / 2``, and the
  running trim and wetted length from Savitsky at the reference speed 9 m/s.
* Roll: ``K_phi = -m g GM`` with an assumed running GM of 0.5 m, ``K_p`` from
  an assumed 10 % of critical roll damping, ``K_pdot = -0.2 Ixx`` (20 % added
  roll inertia); sway-roll couplings from the lateral force acting at
  ``z_H`` below the CG (one third of the transom draught above the keel).
  Lewandowski (2004) gives empirical heel-induced side force and yaw moment
  for planing hulls; we do not have his coefficients here, so
  ``Y_phi = N_phi = Y_p = N_p = 0`` (stated in the parameter file).
* Propellers: ``x_p = LCG + 0.30 m`` aft of the CG (outboard bracket),
  0.25 m below the keel.  The paper writes ``K = T z_p sin(phi_p)``; with z
  positive down the moment of a side force below the CG is
  ``-z T sin(phi_p)``, so we store ``z_p = -(depth of propeller below CG)``
  to keep the paper's formula and the physics.

Reference: Ghorbani, Salarieh & Assadian (Sharif University of Technology, in Persian): time-optimal
trajectory design for a high-speed planing craft.
"""
from __future__ import annotations

import functools

import numpy as np

from ..savitsky import PlaningHull, ResistanceCurve, resistance_curve, savitsky_equilibrium
from .base import Model

__all__ = ["PlaningBoatModel", "TABLE1_HULL", "slender_body_derivatives"]

#: Hull of Ghorbani et al., Table 1, with shipid's VCG/thrust-line assumptions.
TABLE1_HULL = PlaningHull(mass=3600.0, beam=2.018, lcg=2.518, vcg=0.50, deadrise=20.0, length=7.95,
                          epsilon=0.0, f=0.0, rho=1025.0)

_SMOOTH_V2 = 0.01  # (m/s)^2, smoothing of |v| in the cross-flow drag


@functools.lru_cache(maxsize=16)
def _cached_curve(hull: PlaningHull) -> ResistanceCurve:
    return resistance_curve(hull)


def slender_body_derivatives(hull: PlaningHull, speed: float = 9.0, gm: float = 0.5, roll_damping_ratio: float = 0.1,
                             ixx: float = 1435.0, prop_below_keel: float = 0.25, prop_aft_of_transom: float = 0.30,
                             cross_flow_cd: float = 1.0) -> dict:
    """Manoeuvring derivatives of a planing hull from slender-body theory.

    Strip theory with the lateral force per unit length
    ``f(x) = -(d/dt - U d/dx)[a22(x) (v + x r)]`` (Newman 1977; Faltinsen
    2005, ch. 10), integrated from the transom ``x_T = -LCG`` (where the flow
    separates and ``a22`` stays finite) to the forward end of the wetted keel
    ``x_F`` (``a22 = 0``), gives with ``A_k = int x^k a22 dx``::

        Y_vdot = -A0, Y_rdot = N_vdot = -A1, N_rdot = -A2
        Y_v = -U a22(x_T),          Y_r = -U x_T a22(x_T)
        N_v = -U (x_T a22(x_T) + A0), N_r = -U (x_T^2 a22(x_T) + A1)

    ``a22 = rho pi d(x)^2 / 2`` (vertical plate of the local keel draught
    ``d``, infinite-frequency free-surface condition), ``d`` growing linearly
    from 0 at ``x_F`` to ``L_K sin(tau)`` at the transom, where the wetted
    keel length ``L_K = lam b + b tan(beta) / (2 pi tan(tau))`` and trim
    ``tau`` come from Savitsky's equilibrium at ``speed``.

    Returns
    -------
    dict
        Parameter name -> value, velocity derivatives per unit forward speed
        (``Y_uv = Y_v / U``), plus ``"_geometry"`` with the intermediate values.
    """
    pt = savitsky_equilibrium(hull, speed)
    if not pt.success:
        raise ValueError(f"slender_body_derivatives: no Savitsky equilibrium at {speed} m/s: {pt.message}")
    rho, b = hull.rho, hull.beam
    tau, beta = np.radians(pt.trim), np.radians(hull.deadrise)
    LK = pt.lam * b + b * np.tan(beta) / (2 * np.pi * np.tan(tau))
    dT = LK * np.sin(tau)
    xT = -hull.lcg
    xs = np.linspace(xT, xT + LK, 401)
    d = dT * (xT + LK - xs) / LK
    a22 = rho * np.pi * d**2 / 2
    A0, A1, A2 = (np.trapezoid(xs**k * a22, xs) for k in range(3))
    a22T = a22[0]
    zH = hull.vcg - dT / 3.0  # lateral force centre below the CG [m]
    m = hull.mass
    kphi = -m * 9.80665 * gm
    kpdot = -0.2 * ixx
    kp = -2 * roll_damping_ratio * np.sqrt(-kphi * (ixx - kpdot))
    out = {
        "Y_vdot": -A0, "Y_rdot": -A1, "N_vdot": -A1, "N_rdot": -A2,
        "Y_uv": -a22T, "Y_ur": -xT * a22T, "N_uv": -(xT * a22T + A0), "N_ur": -(xT**2 * a22T + A1),
        "K_vdot": zH * A0, "K_rdot": zH * A1, "Y_pdot": zH * A0, "N_pdot": zH * A1,
        "K_uv": zH * a22T, "K_ur": zH * xT * a22T,
        "K_p": kp, "K_phi": kphi, "K_pdot": kpdot,
        "Y_vv": -0.5 * rho * cross_flow_cd * LK * dT / 2,
        "x_p": hull.lcg + prop_aft_of_transom,
        "z_p": -(hull.vcg + prop_below_keel),
        "_geometry": {"trim_deg": pt.trim, "lam": pt.lam, "wetted_keel_length_m": LK, "transom_draught_m": dT,
                      "a22_transom_kg_m": a22T, "z_H_m": zH, "reference_speed_m_s": speed},
    }
    return out


class PlaningBoatModel(Model):
    """Planing boat (4 DOF) with Savitsky resistance, time-optimal manoeuvring study.

    Parameters
    ----------
    params : mapping, array, str or None
        See :class:`shipid.models.base.Model`; default set ``"table1"``.
    hull : PlaningHull, optional
        Hull for the Savitsky resistance curve (default :data:`TABLE1_HULL`).
    resistance_table : (speeds, forces), optional
        A measured/tabulated ``R_T`` [N] at speeds [m/s] used instead of Savitsky.
    """

    name = "planing-boat"
    state_names = ("x", "y", "psi", "phi", "u", "v", "p", "r")
    input_names = ("T", "phi_p")
    param_names = ("m", "Ixx", "Izz", "X_udot", "Y_vdot", "Y_pdot", "Y_rdot", "K_vdot", "K_pdot", "K_rdot",
                   "N_vdot", "N_pdot", "N_rdot", "Y_uv", "Y_ur", "Y_p", "Y_phi", "Y_vv",
                   "K_uv", "K_ur", "K_p", "K_phi", "N_uv", "N_ur", "N_p", "N_phi", "x_p", "z_p", "k_R")
    units = {"x": "m", "y": "m", "psi": "rad", "phi": "rad", "u": "m/s", "v": "m/s", "p": "rad/s", "r": "rad/s",
             "T": "N", "phi_p": "rad", "m": "kg", "Ixx": "kg m^2", "Izz": "kg m^2", "X_udot": "kg",
             "Y_vdot": "kg", "Y_pdot": "kg m", "Y_rdot": "kg m", "K_vdot": "kg m", "K_pdot": "kg m^2",
             "K_rdot": "kg m^2", "N_vdot": "kg m", "N_pdot": "kg m^2", "N_rdot": "kg m^2",
             "Y_uv": "kg/m", "Y_ur": "kg", "Y_p": "kg m/s", "Y_phi": "N/rad", "Y_vv": "kg/m",
             "K_uv": "kg", "K_ur": "kg m", "K_p": "kg m^2/s", "K_phi": "N m/rad",
             "N_uv": "kg", "N_ur": "kg m", "N_p": "kg m^2/s", "N_phi": "N m/rad", "x_p": "m", "z_p": "m", "k_R": "1"}
    default_parameter_set = "table1"

    def __init__(self, params=None, hull: PlaningHull | None = None,
                 resistance_table: tuple | None = None):
        super().__init__(params)
        self.hull = TABLE1_HULL if hull is None else hull
        if resistance_table is not None:
            s, r = resistance_table
            self.resistance = ResistanceCurve(np.asarray(s, float), np.asarray(r, float), source="user table")
        else:
            self.resistance = _cached_curve(self.hull)

    @classmethod
    def sample_point(cls, rng, batch=()):
        """A valid sample point for protocol tests: moderate speed, thrust and angles."""
        x = rng.normal(size=batch + (8,)) * np.array([5, 5, 0.5, 0.1, 1, 0.3, 0.1, 0.1])
        x[..., 4] += 8.0
        u = np.stack([3000 + 500 * rng.normal(size=batch), 0.2 * rng.normal(size=batch)], axis=-1)
        return x, u

    # ------------------------------------------------------------------ helpers
    def _minv(self, p):
        """Inverse of the sway-roll-yaw mass matrix (cached for 1-D parameter vectors)."""
        if p.ndim == 1:
            key = p.tobytes()
            cache = self.__dict__.setdefault("_minv_cache", {})
            if key not in cache:
                if len(cache) > 64:
                    cache.clear()
                cache[key] = np.linalg.inv(self._mass_matrix(p))
            return cache[key]
        return np.linalg.inv(self._mass_matrix(p))

    @staticmethod
    def _mass_matrix(p):
        P = lambda i: p[..., i]  # noqa: E731
        m, Ixx, Izz = P(0), P(1), P(2)
        rows = [
            [m - P(4), -P(5), -P(6)],
            [-P(7), Ixx - P(8), -P(9)],
            [-P(10), -P(11), Izz - P(12)],
        ]
        shape = p.shape[:-1]
        M = np.empty(shape + (3, 3))
        for i in range(3):
            for j in range(3):
                M[..., i, j] = rows[i][j]
        return M

    def _forces(self, x, u, p):
        phi, uu, v, pp, r = x[..., 3], x[..., 4], x[..., 5], x[..., 6], x[..., 7]
        T, ang = u[..., 0], u[..., 1]
        P = p.T.__getitem__ if p.ndim <= 1 else (lambda i: p[..., i])  # noqa: E731
        s = np.sin(ang)
        av = np.sqrt(v**2 + _SMOOTH_V2)
        Y = T * s + P(13) * uu * v + P(14) * uu * r + P(15) * pp + P(16) * phi + P(17) * v * av - P(0) * uu * r
        K = T * P(27) * s + P(18) * uu * v + P(19) * uu * r + P(20) * pp + P(21) * phi
        N = -T * P(26) * s + P(22) * uu * v + P(23) * uu * r + P(24) * pp + P(25) * phi
        X = -P(28) * self.resistance(uu) + T * np.cos(ang) + P(0) * v * r
        return X, Y, K, N

    # ----------------------------------------------------------------- dynamics
    def _rhs(self, t, x, u, p):
        psi, phi, uu, v, pp, r = (x[..., i] for i in range(2, 8))
        X, Y, K, N = self._forces(x, u, p)
        Mi = self._minv(p)
        F = np.stack(np.broadcast_arrays(Y, K, N), axis=-1)
        acc = (Mi @ F[..., None])[..., 0]
        du = X / (p[..., 0] - p[..., 3])
        cps, sps, cph = np.cos(psi), np.sin(psi), np.cos(phi)
        out = [uu * cps - v * sps * cph, uu * sps + v * cps * cph, r * cph, pp + 0 * uu, du,
               acc[..., 0], acc[..., 1], acc[..., 2]]
        if x.ndim == 1 and u.ndim == 1 and p.ndim == 1:
            return np.array(out, dtype=float)
        return np.stack(np.broadcast_arrays(*out), axis=-1)

    def _jac_x(self, t, x, u, p):
        psi, phi, uu, v, pp, r = (x[..., i] for i in range(2, 8))
        shape = np.broadcast_shapes(x.shape[:-1], u.shape[:-1], p.shape[:-1])
        J = np.zeros(shape + (8, 8))
        P = lambda i: p[..., i]  # noqa: E731
        cps, sps, cph, sph = np.cos(psi), np.sin(psi), np.cos(phi), np.sin(phi)
        # kinematics
        J[..., 0, 2] = -uu * sps - v * cps * cph
        J[..., 0, 3] = v * sps * sph
        J[..., 0, 4] = cps
        J[..., 0, 5] = -sps * cph
        J[..., 1, 2] = uu * cps - v * sps * cph
        J[..., 1, 3] = -v * cps * sph
        J[..., 1, 4] = sps
        J[..., 1, 5] = cps * cph
        J[..., 2, 3] = -r * sph
        J[..., 2, 7] = cph
        J[..., 3, 6] = 1.0
        # surge
        mx = P(0) - P(3)
        J[..., 4, 4] = -P(28) * self.resistance.derivative(uu) / mx
        J[..., 4, 5] = P(0) * r / mx
        J[..., 4, 7] = P(0) * v / mx
        # sway/roll/yaw forces: dF/d(phi, u, v, p, r) -> columns 3..7
        av = np.sqrt(v**2 + _SMOOTH_V2)
        dF = np.zeros(shape + (3, 5))
        dF[..., 0, 0] = P(16)
        dF[..., 0, 1] = P(13) * v + P(14) * r - P(0) * r
        dF[..., 0, 2] = P(13) * uu + P(17) * (av + v**2 / av)
        dF[..., 0, 3] = P(15)
        dF[..., 0, 4] = P(14) * uu - P(0) * uu
        dF[..., 1, 0] = P(21)
        dF[..., 1, 1] = P(18) * v + P(19) * r
        dF[..., 1, 2] = P(18) * uu
        dF[..., 1, 3] = P(20)
        dF[..., 1, 4] = P(19) * uu
        dF[..., 2, 0] = P(25)
        dF[..., 2, 1] = P(22) * v + P(23) * r
        dF[..., 2, 2] = P(22) * uu
        dF[..., 2, 3] = P(24)
        dF[..., 2, 4] = P(23) * uu
        J[..., 5:8, 3:8] = self._minv(p) @ dF
        return J

    def _jac_u(self, t, x, u, p):
        T, ang = u[..., 0], u[..., 1]
        shape = np.broadcast_shapes(x.shape[:-1], u.shape[:-1], p.shape[:-1])
        J = np.zeros(shape + (8, 2))
        P = lambda i: p[..., i]  # noqa: E731
        s, c = np.sin(ang), np.cos(ang)
        mx = P(0) - P(3)
        J[..., 4, 0] = c / mx
        J[..., 4, 1] = -T * s / mx
        dF = np.zeros(shape + (3, 2))
        dF[..., 0, 0] = s
        dF[..., 0, 1] = T * c
        dF[..., 1, 0] = P(27) * s
        dF[..., 1, 1] = P(27) * T * c
        dF[..., 2, 0] = -P(26) * s
        dF[..., 2, 1] = -P(26) * T * c
        J[..., 5:8, :] = self._minv(p) @ dF
        return J
