"""The ``lowspeed`` equations -- the one copy.

Written on Python floats with the :mod:`math` functions and the branch helpers that are this module's
globals, which makes the module itself the one-sample backend.  :func:`shipid._jit.rebind` runs the
same code objects on other globals: numpy's functions (batched arrays, real or complex -- the branch
helpers of :data:`NUMPY` take their branches from the real part, so complex-step Jacobians run on
them too) and, with numba (installed with shipid where it has wheels), compiled real and complex sets.  See
:mod:`shipid.models.lowspeed` for the model, the symbols and the references; ``c`` is the sequence of
constants of :func:`derived`.

The branches (ahead/astern propeller, wake only for ``u > 0``, ahead thrust only in the race) are
written as products with 0/1 step functions, so the same expression serves floats and arrays.
"""
from __future__ import annotations

import cmath
import hashlib
import math
from math import atan as arctan, cos, exp, sin, sqrt

import numpy as np

from . import _mmg_equations as _mmg
from .kinematics import planar_rates_cs

#: Parameters, in the order :func:`derived` unpacks them (``shipid.models.lowspeed.LOWSPEED_PARAM_NAMES``).
PARAM_NAMES = (
    "X0F", "X0A", "Xvv", "Xvr", "Yv", "Yr", "Nv", "Nr", "CD", "CrY", "CrN",
    "mx", "my", "Jz",
    "tP", "wP0", "k0", "k1", "k2", "CTa0", "CTa1", "YPa", "NPa",
    "tR", "aH", "xH", "gammaR", "lR", "eps", "kappa", "f_alpha",
    "dgammaR", "xP", "C1", "C2p", "C2m",
    "YPf", "NPf", "delta0",
    "dfalpha", "kstall",
)

#: Names of the values returned by :func:`forces`, in order.
FORCE_KEYS = ("X_H", "Y_H", "N_H", "X_P", "Y_P", "N_P", "X_R", "Y_R", "N_R", "T", "F_N", "u_R", "v_R", "U")

#: Number of constants of :func:`derived` read by :func:`forces` (the last 7 are eq. (4)'s, as in ``mmg``).
N_FORCE_CONSTS = 45

# Gauss-Legendre nodes and weights of the cross-flow integrals on [-1/2, 1/2] (24 nodes)
_s, _w = np.polynomial.legendre.leggauss(24)
S_NODES = np.ascontiguousarray(0.5 * _s)
W_NODES = np.ascontiguousarray(0.5 * _w)
SW_NODES = np.ascontiguousarray(S_NODES * W_NODES)
N_NODES = 24


def absf(z):
    """|z| (for complex z: z times the sign of its real part)."""
    return z if z >= 0 else -z


def step_nn(z):
    """1 for z >= 0, else 0."""
    return 1.0 if z >= 0 else 0.0


def step_pos(z):
    """1 for z > 0, else 0."""
    return 1.0 if z > 0 else 0.0


def ssqrt(z):
    """sign(z) sqrt(|z|) (0 at 0)."""
    if z > 0:
        return sqrt(z)
    if z < 0:
        return -sqrt(-z)
    return 0.0 * z


def derived(p, P):
    """Constants ``c`` of the equations for one parameter set (everything that depends only on the
    parameters and the particulars).

    ``p``: the 41 parameters in :data:`PARAM_NAMES` order (floats, arrays, complex);
    ``P``: the particulars ``(lpp, draught, rho, D_p, H_R, A_R, x_R, displacement, x_G, kzz)`` (as
    ``mmg``).  The first :data:`N_FORCE_CONSTS` are those of :func:`forces`, the last 7 those of eq. (4)
    (``1/Mx, Mx, My, B, C/det, B/det, My/det``, the layout of :func:`shipid.models._mmg_equations.derived`,
    which :mod:`shipid.environment` relies on to add external forces).
    """
    L, d, rho, Dp, H_R, A_R, x_R, disp, x_G, kzz = P[0], P[1], P[2], P[3], P[4], P[5], P[6], P[7], P[8], P[9]
    (X0F, X0A, Xvv, Xvr, Yv, Yr, Nv, Nr, CD, CrY, CrN, mx, my, Jz, tP, wP0, k0, k1, k2, CTa0, CTa1, YPa, NPa,
     tR, aH, xH, gammaR, lR, eps, kappa, f_alpha, dgammaR, xP, C1, C2p, C2m, YPf, NPf, delta0,
     dfalpha, kstall) = p[:41]
    q = 0.5 * rho * L * d
    m = rho * disp
    q2 = 0.5 * rho * L * L * d
    Mx = m + mx * q2
    My = m + my * q2
    B = x_G * m
    C = m * (kzz * L) ** 2 + x_G * x_G * m + Jz * q2 * L * L
    det = My * C - B * B
    eta = Dp / H_R
    return (
        L, q, q * L, 0.5 * X0F, 0.5 * X0A, Xvv, Xvr, Yv, Yr, Nv, Nr, CD, CrY * L, CrN * L,   # hull
        wP0, rho * Dp * Dp, k0 * Dp * Dp, k1 * Dp, k2, CTa0 * Dp * Dp, CTa1 * Dp,        # propeller
        q * Dp * Dp * YPa, q * L * Dp * Dp * NPa, tP,
        8.0 / (math.pi * rho * Dp * Dp), kappa, eta, 1.0 - eta, eps, gammaR, lR * L,     # rudder inflow
        0.5 * rho * A_R * f_alpha, -(1.0 - tR), -(1.0 + aH), -(x_R + aH * xH) * L,       # rudder forces
        dgammaR, xP * L, -C1, 0.5 * (C2p + C2m) - 1.0, 0.5 * (C2p - C2m),               # MMG eqs. (16), (26)
        q * Dp * Dp * YPf, q * L * Dp * Dp * NPf, delta0,                                # ahead side force, neutral angle
        dfalpha, kstall ** 8,                                                            # side-dependent lift, stall
        1.0 / Mx, Mx, My, B, C / det, B / det, My / det,                                 # eq. (4)
    )


def forces(uu, v, r, delta, n, c):
    """The values named by :data:`FORCE_KEYS` (forces [N], moments [N m] at midship, speeds [m/s])."""
    (L, q, qL, hX0F, hX0A, Xvv, Xvr, Yv, Yr, Nv, Nr, CD, CrYL, CrNL,
     wP0, rhoD2, k0D2, k1D, k2, CTa0D2, CTa1D, cYP, cNP, tP,
     c8, kappa, eta, one_m_eta, eps, gammaR, lRL, cF, cXR, cYR, cNR,
     dgammaR, xPL, mC1, c2A, c2D, cYPf, cNPf, delta0, dfalpha, kS8) = c[:N_FORCE_CONSTS]
    U = sqrt(uu * uu + v * v)
    au = absf(uu)
    # hull: resistance blended ahead/astern, linear terms, Kose's cross-flow integrals (Gauss-Legendre)
    Yc = 0.0 * v
    Nc = 0.0 * v
    for i in range(N_NODES):
        wy = v + CrYL * r * S_NODES[i]
        wn = v + CrNL * r * S_NODES[i]
        Yc = Yc + W_NODES[i] * (wy * absf(wy))
        Nc = Nc + SW_NODES[i] * (wn * absf(wn))
    rL = r * L
    XH = q * ((hX0F * (U + uu) + hX0A * (U - uu)) * uu + Xvv * v * v + Xvr * v * rL)
    YH = q * (Yv * v * au + Yr * rL * uu - CD * Yc)
    NH = qL * (Nv * v * uu + Nr * rL * au - CD * Nc)
    # propeller, four quadrants: ahead K_T polynomial (n >= 0), astern linear K_T and side force (n < 0)
    ah = step_nn(n)
    # wake ahead (u > 0) falling with drift and yaw, MMG eq. (16): 1 - w_P = (1 - w_P0)(1 + (1 - exp(-C1
    # |beta_P|))(C2 - 1)), C2 = C2p for beta_P > 0, C2m for beta_P < 0, beta_P = atan(-(v + x_P L r)/u)
    # (= beta - x'_P r' to first order); no wake for u <= 0 (the division is then by 1 and multiplied by 0)
    sp = step_pos(uu)
    vPl = v + xPL * r
    bPa = arctan(absf(vPl) / (uu * sp + (1.0 - sp)))
    fP = 1.0 + (c2A + c2D * (1.0 - 2.0 * step_pos(vPl))) * (1.0 - exp(mC1 * bPa))
    uP = uu * (1.0 - sp * (1.0 - (1.0 - wP0) * fP))
    T = rhoD2 * (ah * (k0D2 * n * n + k1D * n * uP + k2 * uP * uP) + (1.0 - ah) * (CTa0D2 * n * n + CTa1D * n * uu))
    XP = T * (1.0 - tP * ah)
    # side force and yaw moment of the propeller, both proportional to n^2: astern (YPa, NPa) and, for a
    # single screw turning ahead, the lateral force the MMG standard method neglects (YPf, NPf; default 0)
    n2 = n * n
    YP = n2 * (cYP * (1.0 - ah) + cYPf * ah)
    NP = n2 * (cNP * (1.0 - ah) + cNPf * ah)
    # rudder: inflow from the ahead thrust only, normal force without the inflow angle
    Tp = T * (step_pos(T) * ah)
    a = uP + kappa * (sqrt(uP * uP + c8 * Tp) - absf(uP))
    uR = eps * ssqrt(eta * (a * absf(a)) + one_m_eta * (uP * absf(uP)))
    # flow straightening gammaR + dgammaR for beta_R > 0 (w < 0), gammaR - dgammaR for beta_R < 0 (MMG eq. (26))
    w = v + lRL * r
    vR = dgammaR * absf(w) - gammaR * w
    UR = sqrt(uR * uR + vR * vR)
    # rudder neutral angle delta0: the rudder acts as if at delta - delta0 (default 0)
    sd, cd = sin(delta - delta0), cos(delta - delta0)
    sa = uR * sd - vR * cd          # U_R sin(alpha_R)
    # stall (default off, kstall = 0): sin(alpha_R) levels off at 1/kstall = sin(alpha_stall), smoothly,
    # sin a / (1 + (kstall sin a)^8)^(1/8); the 1e-12 m^2/s^2 keeps it defined at rest (U_R = 0)
    gS = (1.0 + kS8 * (sa * sa / (UR * UR + 1e-12)) ** 4) ** -0.125
    FN0 = cF * UR * sa * gS
    # side-dependent normal force (default off): f_alpha (1 + dfalpha) for F_N > 0 (rudder to starboard
    # in flow from ahead), f_alpha (1 - dfalpha) for F_N < 0
    FN = FN0 + dfalpha * absf(FN0)
    return (XH, YH, NH, XP, YP, NP, cXR * FN * sd, cYR * FN * cd, cNR * FN * cd, T, FN, uR, vR, U)


def rates(psi, uu, v, r, delta, n, c):
    """``(x', y', psi', u', v', r')``: eq. (4) of Yasukawa & Yoshimura (2015) solved for the
    accelerations, and the kinematics."""
    F = forces(uu, v, r, delta, n, c)
    iMx, Mx, My, B, a_fy, a_fn, b_fn = c[N_FORCE_CONSTS:]
    du = (F[0] + F[3] + F[6] + (My * v + B * r) * r) * iMx
    ur = uu * r
    fy = F[1] + F[4] + F[7] - Mx * ur
    fn = F[2] + F[5] + F[8] - B * ur
    xd, yd, psid = planar_rates_cs(uu, v, r, cos(psi), sin(psi))
    return xd, yd, psid, du, a_fy * fy - a_fn * fn, b_fn * fn - a_fn * fy


# ------------------------------------------------------------------ complex-safe scalar helpers
def absf_cs(z):
    return z if z.real >= 0 else -z


def step_nn_cs(z):
    return 1.0 if z.real >= 0 else 0.0


def step_pos_cs(z):
    return 1.0 if z.real > 0 else 0.0


def ssqrt_cs(z):
    if z.real > 0:
        return cmath.sqrt(z)
    if z.real < 0:
        return -cmath.sqrt(-z)
    return 0.0 * z


#: The functions of this module in dependency order (what :func:`shipid._jit.rebind` rebinds).
#: The sample drivers (``rhs_one``, ``rhs_rows``, ``jacobians``, ``cs_columns``) and the kernel protocol
#: (``k_consts``, ``k_rhs``, ``k_jac``) are ``mmg``'s, rebound on these equations: they only call
#: ``derived`` and ``rates``.
FUNCTIONS = {"absf": absf, "step_nn": step_nn, "step_pos": step_pos, "ssqrt": ssqrt,
             "planar_rates_cs": planar_rates_cs, "derived": derived, "forces": forces, "rates": rates,
             "rhs_one": _mmg.rhs_one, "rhs_rows": _mmg.rhs_rows}

#: The complex-step set (compiled for the kernel's Jacobians).
FUNCTIONS_CS = {"absf": absf_cs, "step_nn": step_nn_cs, "step_pos": step_pos_cs, "ssqrt": ssqrt_cs,
                "planar_rates_cs": planar_rates_cs, "derived": derived, "forces": forces, "rates": rates,
                "cs_columns": _mmg.cs_columns, "jacobians": _mmg.jacobians}
#: Globals of the compiled complex-step set.
CMATH = {"sqrt": cmath.sqrt, "sin": cmath.sin, "cos": cmath.cos, "exp": cmath.exp, "arctan": cmath.atan}


def _np_ssqrt(z):
    s = np.where(np.real(z) < 0, -1.0, 1.0)
    a = z * s
    return s * np.sqrt(np.where(np.real(a) > 0, a, 1.0)) * (np.real(a) > 0)


#: Globals of the batched numpy backend (real or complex arrays: branches from the real part).
NUMPY = {"sqrt": np.sqrt, "sin": np.sin, "cos": np.cos, "exp": np.exp, "arctan": np.arctan,
         "absf": lambda z: z * np.where(np.real(z) < 0, -1.0, 1.0),
         "step_nn": lambda z: (np.real(z) >= 0) * 1.0, "step_pos": lambda z: (np.real(z) > 0) * 1.0,
         "ssqrt": _np_ssqrt}
COMPLEX_STEP = NUMPY

#: The kernel-protocol set (dependency order); needs the globals ``cs_columns`` and ``derived_cs``.
KERNEL = {**FUNCTIONS, "k_consts": _mmg.k_consts, "k_rhs": _mmg.k_rhs, "k_jac": _mmg.k_jac}

#: numba cache tag of the compiled sets (the drivers live in ``_mmg_equations``, whose cache numba keys
#: by that file: the tag carries this file's hash so that an edited equation is recompiled).
with open(__file__, "rb") as _fh:
    JIT_TAG = "__lowspeed_" + hashlib.sha1(_fh.read()).hexdigest()[:10]
