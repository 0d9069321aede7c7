"""The MMG equations (Yasukawa & Yoshimura 2015) -- the one copy.

Written on Python floats with the :mod:`math` functions that are this
module's globals, which makes the module itself the one-sample backend.
:func:`shipid._jit.rebind` runs the same code objects on other globals:
numpy's functions (batched arrays), complex-step-safe ones (Jacobians), and,
with numba (installed with shipid where it has wheels), compiled.  See
:mod:`shipid.models.mmg` for the model, the symbols and the equation numbers;
``c`` is the sequence of constants of :meth:`MMGModel._derived
<shipid.models.mmg.MMGModel._derived>`.
"""
from __future__ import annotations

import cmath
import math
from math import asin as arcsin, atan as arctan, cos, exp, sin, sqrt

import numpy as np

from .kinematics import planar_rates_cs

#: Non-dimensional (prime-system) parameters, in the order :func:`derived` unpacks them
#: (``shipid.models.mmg.MMG_PARAM_NAMES``).
PARAM_NAMES = (
    "R0", "Xvv", "Xvr", "Xrr", "Xvvvv",
    "Yv", "Yr", "Yvvv", "Yvvr", "Yvrr", "Yrrr",
    "Nv", "Nr", "Nvvv", "Nvvr", "Nvrr", "Nrrr",
    "mx", "my", "Jz",
    "tP", "wP0", "k0", "k1", "k2", "xP", "C1", "C2p", "C2m",
    "tR", "aH", "xH", "gammaR_m", "gammaR_p", "lR", "eps", "kappa", "f_alpha",
    "delta0",
)

#: Number of constants of ``MMGModel._derived`` used by the force equations (the rest: eq. (4)).
N_FORCE_CONSTS = 43

#: Names of the values returned by :func:`forces`, in order.
FORCE_KEYS = ("X_H", "Y_H", "N_H", "X_P", "X_R", "Y_R", "N_R", "F_N", "T", "w_P", "u_R", "v_R", "alpha_R", "beta", "U")


def sign(z):
    return 1.0 if z > 0 else (-1.0 if z < 0 else 0.0)


def sign_nn(z):
    """+1 for z >= 0, -1 for z < 0 (the branch of a coefficient chosen by z < 0)."""
    return math.copysign(1.0, z)


def sqrt_pos(z):
    """sqrt(max(z, 0))."""
    return math.sqrt(z) if z > 0 else 0.0


def inv_pos(z):
    """1/z for z > 0, else 0 (the prime-system velocities v' = v/U, r' = r L/U are set to 0 at U = 0,
    where the hull polynomial has no defined value; the model is not valid there)."""
    return 1.0 / z if z > 0 else 0.0


def derived(p, P):
    """Constants ``c`` of the equations for one parameter set: everything that depends only on the
    parameters and the particulars, folded once so that :func:`forces` and :func:`rates` do the least
    arithmetic per call.

    ``p``: the 39 parameters in :data:`PARAM_NAMES` order (floats, arrays, complex);
    ``P``: the particulars ``(lpp, draught, rho, D_p, H_R, A_R, x_R, displacement, x_G, kzz)``.
    The first :data:`N_FORCE_CONSTS` constants are those of :func:`forces`, the last 7 those of eq. (4).
    To add a parameter: append its name to :data:`PARAM_NAMES`, unpack it here, append what the
    equations need to the force constants (raising :data:`N_FORCE_CONSTS`) and unpack it in
    :func:`forces`.
    """
    L, d, rho, Dp, H_R, A_R, x_R, disp, x_G, kzz = P[0], P[1], P[2], P[3], P[4], P[5], P[6], P[7], P[8], P[9]
    (R0, Xvv, Xvr, Xrr, Xvvvv, Yv, Yr, Yvvv, Yvvr, Yvrr, Yrrr, Nv, Nr, Nvvv, Nvvr, Nvrr, Nrrr,
     mx, my, Jz, tP, wP0, k0, k1, k2, xP, C1, C2p, C2m,
     tR, aH, xH, gRm, gRp, lR, eps, kappa, f_alpha, delta0) = p[:39]
    cq = 0.5 * rho * L * d                       # 1/2 rho L d (hull force scale / U^2)
    w1 = 1.0 - wP0                               # 1 - w_P0
    eta = Dp / H_R
    m = rho * disp
    q2 = 0.5 * rho * L * L * d
    Mx = m + mx * q2                             # m + m_x
    My = m + my * q2                             # m + m_y
    B = x_G * m                                  # x_G m
    C = m * (kzz * L) ** 2 + x_G * x_G * m + Jz * q2 * L * L  # I_zG + x_G^2 m + J_z
    det = My * C - B * B
    return (
        L, cq, cq * L,
        R0, Xvv, Xvr, Xrr, Xvvvv, Yv, Yr, Yvvv, Yvvr, Yvrr, Yrrr, Nv, Nr, Nvvv, Nvvr, Nvrr, Nrrr,
        # propeller wake, eq. (16); C2 = C2p for beta_P > 0, C2m for beta_P < 0, written as
        # (C2p + C2m)/2 + sign(beta_P) (C2p - C2m)/2 (the value at beta_P = 0 is multiplied by 0)
        xP, -C1, w1, w1 * (0.5 * (C2p + C2m) - 1.0), w1 * 0.5 * (C2p - C2m),
        k0 * Dp * Dp, k1 * Dp, k2, rho * Dp * Dp, (1.0 - tP) * rho * Dp * Dp,  # thrust, eqs. (11)-(15)
        8.0 / math.pi, kappa, eta, 1.0 - eta, eps,                  # rudder inflow, eqs. (23)-(25)
        # gamma_R = gammaR_m for beta_R < 0 else gammaR_p, as mean + sign(beta_R) half-difference
        # (v_R = U gamma_R beta_R vanishes at beta_R = 0 either way)
        lR, 0.5 * (gRp + gRm), 0.5 * (gRp - gRm), 0.5 * rho * A_R * f_alpha,  # eqs. (20)-(22), (26)-(27)
        -(1.0 - tR), -(1.0 + aH), -(x_R + aH * xH) * L,            # eqs. (17)-(19)
        delta0,                                                     # rudder neutral angle
        1.0 / Mx, Mx, My, B, C / det, B / det, My / det,           # eq. (4) solved for u', v', r'
    )


def forces(uu, v, r, delta, n, c):
    """The values named by :data:`FORCE_KEYS` (forces [N], moments [N m], speeds, angles), eqs. (7)-(28)."""
    (L, cq, cqL,
     R0, Xvv, Xvr, Xrr, Xvvvv, Yv, Yr, Yvvv, Yvvr, Yvrr, Yrrr, Nv, Nr, Nvvv, Nvvr, Nvrr, Nrrr,
     xP, mC1, w1, wcA, wcD, kT0, kT1, k2, cT, cXP, c8pi, kappa, eta, one_m_eta, eps,
     lR, gRA, gRD, cF, cXR, cYR, cNR, delta0) = c[:N_FORCE_CONSTS]
    # hull, eqs. (7)-(10): v' = v/U, r' = r L/U, beta = asin(-v')
    U2 = uu * uu + v * v
    U = sqrt(U2)
    iU = inv_pos(U)  # 0 at rest (u = v = 0): no NaN; the MMG hull model itself is not valid there
    vp = v * iU
    rp = (r * L) * iU
    beta = -arcsin(vp)
    vp2, rp2 = vp * vp, rp * rp
    XH = (cq * U2) * (vp2 * (Xvv + Xvvvv * vp2) + Xvr * (vp * rp) + Xrr * rp2 - R0)
    YH = (cq * U2) * (vp * (Yv + Yvvv * vp2 + Yvrr * rp2) + rp * (Yr + Yvvr * vp2 + Yrrr * rp2))
    NH = (cqL * U2) * (vp * (Nv + Nvvv * vp2 + Nvrr * rp2) + rp * (Nr + Nvvr * vp2 + Nrrr * rp2))
    # propeller, eqs. (11)-(16): 1 - w_P = (1 - w_P0)(1 + (1 - exp(-C1 |beta_P|))(C2 - 1))
    betaP = beta - xP * rp
    sP = sign(betaP)
    one_m_wP = w1 + (wcA + wcD * sP) * (1.0 - exp(mC1 * (betaP * sP)))
    uP = uu * one_m_wP
    uP2 = uP * uP
    # K_T n|n| D_P^2 with J_P = u_P/(|n| D_P): the thrust reverses with n (astern), free of the 1/n in J_P
    sn = sign_nn(n)
    KTn2D2 = (kT0 * (n * sn) + kT1 * uP) * n + k2 * uP2 * sn
    # rudder, eqs. (17)-(28)
    a = uP + kappa * (sqrt_pos(uP2 + c8pi * KTn2D2) - uP)
    uR = eps * sqrt(eta * (a * a) + one_m_eta * uP2)
    betaR = beta - lR * rp
    vR = (U * (gRA + gRD * sign_nn(betaR))) * betaR
    alphaR = delta - delta0 - arctan(vR * inv_pos(uR))  # delta0: rudder neutral angle (not in the standard)
    FN = cF * (uR * uR + vR * vR) * sin(alphaR)
    FNcd = FN * cos(delta)
    return (XH, YH, NH, cXP * KTn2D2, cXR * FN * sin(delta), cYR * FNcd, cNR * FNcd, FN, cT * KTn2D2,
            1.0 - one_m_wP, uR, vR, alphaR, beta, U)


def rates(psi, uu, v, r, delta, n, c):
    """``(x', y', psi', u', v', r')``: eq. (4) solved for the accelerations, and the kinematics."""
    F = forces(uu, v, r, delta, n, c)
    iMx, Mx, My, B, a_fy, a_fn, b_fn = c[N_FORCE_CONSTS:]
    du = (F[0] + F[4] + F[3] + (My * v + B * r) * r) * iMx
    ur = uu * r
    fy = F[1] + F[5] - Mx * ur
    fn = F[2] + F[6] - B * ur
    xd, yd, psid = planar_rates_cs(uu, v, r, cos(psi), sin(psi))
    return xd, yd, psid, du, a_fy * fy - a_fn * fn, b_fn * fn - a_fn * fy


def rhs_one(x, u, c):
    """Rates of one sample: ``x (6,)``, ``u (2,)`` -> ``(6,)`` (used compiled)."""
    out = np.empty(6)
    out[0], out[1], out[2], out[3], out[4], out[5] = rates(x[2], x[3], x[4], x[5], u[0], u[1], c)
    return out


def rhs_rows(x, u, c):
    """Rates of N samples: ``x (N, 6)``, ``u (N, 2)``, constants ``c (1, nc)`` shared or ``(N, nc)``
    per sample -> ``(N, 6)`` (a loop; used compiled)."""
    out = np.empty((x.shape[0], 6))
    per_sample = c.shape[0] > 1
    for i in range(x.shape[0]):
        ci = c[i] if per_sample else c[0]
        out[i, 0], out[i, 1], out[i, 2], out[i, 3], out[i, 4], out[i, 5] = rates(
            x[i, 2], x[i, 3], x[i, 4], x[i, 5], u[i, 0], u[i, 1], ci)
    return out


def cs_columns(xc, uc, pc, Pc, c, h, which, cols, out):
    """Complex-step derivatives of the rates of one sample, columns ``cols`` into ``out (6, k)``.

    ``xc (6,)``, ``uc (2,)``, ``pc (39,)``, ``Pc`` complex copies of the state, inputs, parameters and
    particulars (perturbed in place and restored); ``c`` the constants of ``pc``; ``which``: 0 -> d/dx,
    1 -> d/du, 2 -> d/dp (the constants are re-derived for each perturbed parameter).
    """
    ih = 1j * h
    for jj in range(cols.shape[0]):
        j = cols[jj]
        if which == 0:
            xc[j] += ih
            f = rates(xc[2], xc[3], xc[4], xc[5], uc[0], uc[1], c)
            xc[j] -= ih
        elif which == 1:
            uc[j] += ih
            f = rates(xc[2], xc[3], xc[4], xc[5], uc[0], uc[1], c)
            uc[j] -= ih
        else:
            pc[j] += ih
            f = rates(xc[2], xc[3], xc[4], xc[5], uc[0], uc[1], derived(pc, Pc))
            pc[j] -= ih
        for m in range(6):
            out[m, j] = f[m].imag / h


#: The state columns the rates depend on (x and y do not enter them).
X_COLS = np.arange(2, 6)


def jacobians(x, u, p, P, h, which, pcols):
    """Complex-step Jacobians of the rates of N samples (used compiled, with complex-safe globals).

    ``x (N, 6)``, ``u (N, 2)`` real; ``p (Np, 39)`` real with Np = 1 (shared) or N; ``P`` the
    particulars (see :func:`derived`); ``h`` the step; ``which``: 0 -> d/dx (N, 6, 6), 1 -> d/du
    (N, 6, 2), 2 -> d/dp (N, 6, 39), of which only the parameter columns ``pcols`` (int array) are
    computed (the others are 0).  Exact to rounding (no subtraction).
    """
    N = x.shape[0]
    xc, uc, pc = x.astype(np.complex128), u.astype(np.complex128), p.astype(np.complex128)
    Pc = P.astype(np.complex128)
    cols = X_COLS if which == 0 else (np.arange(2) if which == 1 else pcols)
    out = np.zeros((N, 6, 6 if which == 0 else (2 if which == 1 else p.shape[1])))
    c = derived(pc[0], Pc)
    if which == 2 and p.shape[0] == 1:
        # shared parameters: the perturbed constants are derived once per column, not once per sample
        for jj in range(cols.shape[0]):
            j = cols[jj]
            pc[0, j] += 1j * h
            cj = derived(pc[0], Pc)
            pc[0, j] -= 1j * h
            for i in range(N):
                f = rates(xc[i, 2], xc[i, 3], xc[i, 4], xc[i, 5], uc[i, 0], uc[i, 1], cj)
                for m in range(6):
                    out[i, m, j] = f[m].imag / h
        return out
    for i in range(N):
        ip = i if p.shape[0] > 1 else 0
        if p.shape[0] > 1 and which != 2:
            c = derived(pc[ip], Pc)
        cs_columns(xc[i], uc[i], pc[ip], Pc, c, h, which, cols, out[i])
    return out


def sign_cs(z):
    """:func:`sign` of the real part (complex step: branches from the real part)."""
    x = z.real
    return 1.0 if x > 0 else (-1.0 if x < 0 else 0.0)


def sign_nn_cs(z):
    return math.copysign(1.0, z.real)


def sqrt_pos_cs(z):
    return cmath.sqrt(z) if z.real > 0 else 0j


def inv_pos_cs(z):
    return 1.0 / z if z.real > 0 else 0j


#: The functions of this module in dependency order (what :func:`shipid._jit.rebind` rebinds).
FUNCTIONS = {"sign": sign, "sign_nn": sign_nn, "sqrt_pos": sqrt_pos, "inv_pos": inv_pos, "planar_rates_cs": planar_rates_cs,
             "derived": derived, "forces": forces, "rates": rates, "rhs_one": rhs_one, "rhs_rows": rhs_rows}

#: The complex-step set compiled for the Jacobians: the same equations with complex-safe elementary
#: functions (``sign`` and friends branch on the real part), and the driver :func:`jacobians`.
FUNCTIONS_CS = {"sign": sign_cs, "sign_nn": sign_nn_cs, "sqrt_pos": sqrt_pos_cs, "inv_pos": inv_pos_cs,
                "planar_rates_cs": planar_rates_cs, "derived": derived, "forces": forces, "rates": rates,
                "cs_columns": cs_columns, "jacobians": jacobians}
#: Globals of the compiled complex-step set (``cmath``).
CMATH = {"sqrt": cmath.sqrt, "exp": cmath.exp, "arcsin": cmath.asin, "arctan": cmath.atan, "sin": cmath.sin,
         "cos": cmath.cos}

_NUMPY_BASE = {"sqrt": np.sqrt, "exp": np.exp, "arcsin": np.arcsin, "arctan": np.arctan, "sin": np.sin,
               "cos": np.cos}

#: Globals of the batched numpy backend (real arrays).
NUMPY = {**_NUMPY_BASE, "sign": np.sign, "sign_nn": lambda z: np.copysign(1.0, z),
         "sqrt_pos": lambda z: np.sqrt(np.maximum(z, 0.0)),
         "inv_pos": lambda z: np.divide(1.0, z, out=np.zeros(np.shape(z)), where=np.asarray(z) > 0)}

#: Globals of the complex-step backend: signs and branches from the real part.
COMPLEX_STEP = {**_NUMPY_BASE, "sign": lambda z: np.sign(np.real(z)),
                "sign_nn": lambda z: np.copysign(1.0, np.real(z)),
                "sqrt_pos": lambda z: np.sqrt(z * (np.real(z) > 0)),
                "inv_pos": lambda z: np.where(np.real(z) > 0, 1.0 / np.where(np.real(z) > 0, z, 1.0), 0.0)}


# ------------------------------------------------------------------ the EKF kernel's protocol
# (see shipid.models._response_equations and shipid._kernel): constants once per step,
# the rates of one sample, and the complex-step Jacobians of one sample (``cs_columns`` and
# ``derived_cs`` are the complex-step set's compiled functions, given as globals by the model).
#: Complex step of the compiled Jacobians (as ``MMGModel._H_CS``).
H_CS = 1e-30


def k_consts(p, P):
    return np.array(derived(p, P))


def k_rhs(t, x, u, c, out):
    out[0], out[1], out[2], out[3], out[4], out[5] = rates(x[2], x[3], x[4], x[5], u[0], u[1], c)


def k_jac(t, x, u, p, P, c, cols, Jx, Jp):
    xc, uc, pc, Pc = x.astype(np.complex128), u.astype(np.complex128), p.astype(np.complex128), P.astype(np.complex128)
    cc = derived_cs(pc, Pc)
    cs_columns(xc, uc, pc, Pc, cc, H_CS, 0, X_COLS, Jx)
    cs_columns(xc, uc, pc, Pc, cc, H_CS, 2, cols, Jp)


#: The kernel-protocol set (dependency order); needs the globals ``cs_columns`` and ``derived_cs``.
KERNEL = {**FUNCTIONS, "k_consts": k_consts, "k_rhs": k_rhs, "k_jac": k_jac}
