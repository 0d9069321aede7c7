"""The environment wrapper's equations (wind force, current) -- the one copy.

Scalar source in the style of :mod:`shipid.models._mmg_equations`: :func:`shipid._jit.rebind` runs it
on numpy arrays (real and complex) for :class:`~shipid.environment.EnvironmentModel` and
:class:`~shipid.environment.WindForce`, and compiled by numba inside the EKF kernel and the batched
right-hand side.  The base ship model's equations are not called through the model: ``derived`` and
``rates`` below are the *globals* of the set, bound by :func:`equation_sets` to the base equations
module's own functions (``_mmg_equations`` or ``_lowspeed_equations``), so base, wind and current compile
into one function.  See :mod:`shipid.environment.model` for the physics.

Constants ``c`` (:func:`env_derived`): ``HEADER`` entries -- flags wind, current, ground velocities,
``1/2 rho_air A_T``, ``1/2 rho_air A_L``, ``1/2 rho_air A_L L``, the ten Fourier components -- then the
base model's constants, whose last 7 are the eq. (4) mass constants ``1/Mx, Mx, My, B, C/det, B/det,
My/det`` (both base modules keep that layout).  Fixed constants ``P``: the base particulars (10), then
the number of base parameters, the three flags and the three wind scales.
"""
from __future__ import annotations

import cmath
import hashlib
import math
from math import cos, sin

import numpy as np

from .._jit import rebind


#: Number of environment constants before the base model's in :func:`env_derived`.
HEADER = 16
#: Number of base particulars in ``P`` (``ShipEquationsModel._particulars_tuple``).
N_PART = 10

#: Bound by :func:`equation_sets` to the base model's equations (this module's own values are unused).
derived = rates = None


def coefficients_cs(c, s, comp):
    """``(C_X, C_Y, C_N)`` from ``c = cos gamma``, ``s = sin gamma`` by the multiple-angle identities
    (complex-step safe); ``comp`` the ten components in :data:`shipid.environment.wind.WIND_PARAM_NAMES` order."""
    X0, X1, X3, X5, Y1, Y3, Y5, N1, N2, N3 = comp
    c2, s2 = c * c - s * s, 2.0 * s * c
    c3, s3 = c2 * c - s2 * s, s2 * c + c2 * s
    c5, s5 = c3 * c2 - s3 * s2, s3 * c2 + c3 * s2
    CX = X0 + X1 * c + X3 * c3 + X5 * c5
    CY = -(Y1 * s + Y3 * s3 + Y5 * s5)
    CN = -(N1 * s + N2 * s2 + N3 * s3)
    return CX, CY, CN


def inv_sqrt_pos(z):
    """1/sqrt(z) for z > 0, else 0."""
    return 1.0 / math.sqrt(z) if z > 0 else 0.0


def wind_force(ac, as_, qAT, qAL, qALL, X0, X1, X3, X5, Y1, Y3, Y5, N1, N2, N3):
    """``(X_A, Y_A, N_A)`` [N, N, N m] from the apparent wind vector written as ``(V cos g, V sin g)``
    (no angle, smooth at V = 0), the scales ``1/2 rho_air A_T``, ``1/2 rho_air A_L``, ``1/2 rho_air A_L L``
    and the ten Fourier components (:func:`coefficients_cs`)."""
    V2 = ac * ac + as_ * as_
    iV = inv_sqrt_pos(V2)
    CX, CY, CN = coefficients_cs(ac * iV, as_ * iV, (X0, X1, X3, X5, Y1, Y3, Y5, N1, N2, N3))
    return qAT * V2 * CX, qAL * V2 * CY, qALL * V2 * CN


def env_derived(p, P):
    """Constants of one parameter set: the environment header, then the base model's constants."""
    nb = int(P[N_PART].real)
    if P[N_PART + 1].real > 0.5:
        X0, X1, X3, X5, Y1, Y3, Y5 = p[nb], p[nb + 1], p[nb + 2], p[nb + 3], p[nb + 4], p[nb + 5], p[nb + 6]
        N1, N2, N3 = p[nb + 7], p[nb + 8], p[nb + 9]
    else:
        X0 = X1 = X3 = X5 = Y1 = Y3 = Y5 = N1 = N2 = N3 = 0.0 * P[0]
    head = (P[N_PART + 1], P[N_PART + 2], P[N_PART + 3], P[N_PART + 4], P[N_PART + 5], P[N_PART + 6],
            X0, X1, X3, X5, Y1, Y3, Y5, N1, N2, N3)
    return head + derived(p, P)


def env_rates(psi, uu, v, r, cx, cy, delta, n, ws, wd, c):
    """``(x', y', psi', u', v', r')`` of the base model with wind and current (the current states have
    zero rates).  ``uu, v``: the state velocities (over ground or through the water, by flag);
    ``cx, cy`` the earth-fixed current [m/s]; ``ws, wd`` the true wind speed [m/s] and direction from [rad]."""
    cb = c[HEADER:]
    cp, sp = cos(psi), sin(psi)
    uc = cp * cx + sp * cy
    vc = -sp * cx + cp * cy
    if c[2].real > 0.5:  # states over ground: the hydrodynamics see the velocity through the water
        ug, vg, ur, vr = uu, v, uu - uc, v - vc
    else:
        ug, vg, ur, vr = uu + uc, v + vc, uu, v
    f = rates(psi, ur, vr, r, delta, n, cb)
    du, dv, dr = f[3], f[4], f[5]
    if c[0].real > 0.5:  # wind: the air velocity relative to the ship, in body axes; M^-1 (X_A, Y_A, N_A)
        wx, wy = -ws * cos(wd), -ws * sin(wd)
        ax = cp * wx + sp * wy - ug
        ay = -sp * wx + cp * wy - vg
        XA, YA, NA = wind_force(-ax, -ay, c[3], c[4], c[5], c[6], c[7], c[8], c[9], c[10], c[11], c[12], c[13],
                                c[14], c[15])
        iMx, Mx, My, B, a_fy, a_fn, b_fn = cb[-7:]
        du = du + XA * iMx
        dv = dv + a_fy * YA - a_fn * NA
        dr = dr + b_fn * NA - a_fn * YA
    if c[1].real > 0.5 and c[2].real > 0.5:  # d/dt of the rotated current in body axes
        du = du + r * vc
        dv = dv - r * uc
    return cp * ug - sp * vg, sp * ug + cp * vg, r, du, dv, dr


def env_rates_x(x, u, c):
    """:func:`env_rates` of one sample from its state ``x (6 or 8,)`` and inputs ``u (2 or 4,)``."""
    zero = 0.0 * x[0]
    cx = x[6] if c[1].real > 0.5 else zero
    cy = x[7] if c[1].real > 0.5 else zero
    ws = u[2] if c[0].real > 0.5 else 0.0 * u[0]
    wd = u[3] if c[0].real > 0.5 else 0.0 * u[0]
    return env_rates(x[2], x[3], x[4], x[5], cx, cy, u[0], u[1], ws, wd, c)


def env_rhs_rows(x, u, c):
    """Rates of N samples: ``x (N, nx)``, ``u (N, nu)``, ``c (1, nc)`` shared or ``(N, nc)`` -> ``(N, nx)``
    (a loop; used compiled)."""
    out = np.zeros((x.shape[0], x.shape[1]))
    per_sample = c.shape[0] > 1
    for i in range(x.shape[0]):
        ci = c[i] if per_sample else c[0]
        out[i, 0], out[i, 1], out[i, 2], out[i, 3], out[i, 4], out[i, 5] = env_rates_x(x[i], u[i], ci)
    return out


def env_cs_columns(xc, uc, pc, Pc, c, h, which, cols, out):
    """Complex-step derivatives of the rates of one sample, columns ``cols`` into ``out (nx, k)``
    (``which``: 0 d/dx, 2 d/dp with the constants re-derived per perturbed parameter)."""
    ih = 1j * h
    for jj in range(cols.shape[0]):
        j = cols[jj]
        if which == 0:
            xc[j] += ih
            f = env_rates_x(xc, uc, c)
            xc[j] -= ih
        else:
            pc[j] += ih
            f = env_rates_x(xc, uc, env_derived(pc, Pc))
            pc[j] -= ih
        for m in range(6):
            out[m, j] = f[m].imag / h


# ------------------------------------------------------------------ the EKF kernel's protocol
H_CS = 1e-30


def env_k_consts(p, P):
    return np.array(env_derived(p, P))


def env_k_rhs(t, x, u, c, out):
    out[0], out[1], out[2], out[3], out[4], out[5] = env_rates_x(x, u, c)
    for i in range(6, out.shape[0]):
        out[i] = 0.0


def env_k_jac(t, x, u, p, P, c, cols, Jx, Jp):
    xc, uc, pc, Pc = x.astype(np.complex128), u.astype(np.complex128), p.astype(np.complex128), P.astype(np.complex128)
    cc = env_derived_cs(pc, Pc)
    env_cs_columns(xc, uc, pc, Pc, cc, H_CS, 0, np.arange(2, x.shape[0]), Jx)
    env_cs_columns(xc, uc, pc, Pc, cc, H_CS, 2, cols, Jp)


FUNCTIONS = {"coefficients_cs": coefficients_cs, "inv_sqrt_pos": inv_sqrt_pos, "wind_force": wind_force,
             "env_derived": env_derived, "env_rates": env_rates, "env_rates_x": env_rates_x,
             "env_rhs_rows": env_rhs_rows}


def _inv_sqrt_pos_cs(z):
    return 1.0 / cmath.sqrt(z) if z.real > 0 else 0j


FUNCTIONS_CS = {"coefficients_cs": coefficients_cs, "inv_sqrt_pos": _inv_sqrt_pos_cs, "wind_force": wind_force,
                "env_derived": env_derived, "env_rates": env_rates, "env_rates_x": env_rates_x,
                "env_cs_columns": env_cs_columns}


def _np_inv_sqrt_pos(z):
    pos = np.real(z) > 0
    return np.where(pos, 1.0 / np.sqrt(np.where(pos, z, 1.0)), 0.0)


NUMPY = {"cos": np.cos, "sin": np.sin, "inv_sqrt_pos": _np_inv_sqrt_pos}
CMATH = {"cos": cmath.cos, "sin": cmath.sin}

with open(__file__, "rb") as _fh:
    _HASH = hashlib.sha1(_fh.read()).hexdigest()[:10]

_SETS: dict = {}


def equation_sets(base_eqm) -> dict:
    """The wrapper's function sets on the base equations module ``base_eqm`` (cached per module):
    ``"numpy"``, ``"complex"`` (numpy arrays, real / complex step), ``"kernel"`` (the kernel protocol,
    for :mod:`shipid._kernel`), ``"real"``, ``"cs"`` (function dicts for :func:`shipid._jit.compiled`,
    with their namespaces ``"cmath"``) and ``"tag"`` (numba cache tag)."""
    out = _SETS.get(base_eqm.__name__)
    if out is None:
        base = {k: f for k, f in base_eqm.FUNCTIONS.items()}
        base_cs = {k: f for k, f in base_eqm.FUNCTIONS_CS.items()}
        cplx = getattr(base_eqm, "COMPLEX_STEP", base_eqm.NUMPY)
        tag = "__env" + getattr(base_eqm, "JIT_TAG", "__" + base_eqm.__name__.rsplit(".", 1)[-1]) + "_" + _HASH
        out = _SETS[base_eqm.__name__] = {
            "numpy": rebind({**base, **FUNCTIONS}, {**base_eqm.NUMPY, **NUMPY}),
            "complex": rebind({**base, **FUNCTIONS}, {**cplx, **NUMPY}),
            "real": {**base, **FUNCTIONS},
            "cs": {**base_cs, **FUNCTIONS_CS},
            "cmath": {**base_eqm.CMATH, **CMATH},
            "kernel": {**base, **FUNCTIONS, "k_consts": env_k_consts, "k_rhs": env_k_rhs, "k_jac": env_k_jac},
            "tag": tag,
        }
    return out


def wind_force_numpy():
    """:func:`wind_force` on numpy arrays (real or complex), for :meth:`WindForce.force_cs`."""
    if "wind" not in _SETS:
        _SETS["wind"] = rebind({"coefficients_cs": coefficients_cs, "inv_sqrt_pos": inv_sqrt_pos,
                                "wind_force": wind_force}, NUMPY)["wind_force"]
    return _SETS["wind"]
