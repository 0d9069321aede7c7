"""The equations of ``kcs-response`` and ``response-nl`` -- the one copy.

Written on Python floats with :mod:`math` functions as this module's globals
(like :mod:`shipid.models._mmg_equations`); :func:`shipid._jit.rebind` runs
the same code objects on numpy arrays (the models' batched paths) and, with
numba installed, compiled (the EKF kernel :mod:`shipid._kernel`).
See :mod:`shipid.models.response` (Hajizadeh et al., eq. (3)) and
:mod:`shipid.models.response_nl` for the equations and their symbols.

Jacobians are returned as tuples of their structurally non-zero entries in
the order of the ``*_POS`` tables ``((row, column), ...)``; :func:`fill`
writes them into a matrix (numpy path: :func:`fill_numpy`, broadcast over
leading axes).  Both models are linear in their parameters, so the parameter
Jacobian is the regressor matrix.

``p`` below is any sequence of the parameters in ``param_names`` order
(floats, an array, or the rows of ``p.T`` for batched arrays).
"""
from __future__ import annotations

from math import cos, sin

import numpy as np

from .kinematics import PLANAR_JAC_POS, planar_jac_cs, planar_rates_cs


def inv_floor(uu, floor):
    """``1 / max(u, floor)`` (the ``1/u`` of the response-nl cross terms)."""
    return 1.0 / max(uu, floor)


def dinv_floor(uu, floor):
    """Derivative of :func:`inv_floor` with respect to ``u`` (0 below the floor)."""
    return -1.0 / (uu * uu) if uu > floor else 0.0


def absf(z):
    return abs(z)


def sgn_nn(z):
    """+1 for z >= 0, -1 for z < 0 (the derivative of |z|, taken as +1 at 0)."""
    return 1.0 if z >= 0 else -1.0


# ------------------------------------------------------------------ kcs-response (16 parameters)
def kcs_rates(psi, uu, v, r, d, n, p):
    """``(x', y', psi', u', v', r')`` of the response model of Hajizadeh et al. (eq. (3))."""
    a1, a2, a3, a4, a5, a6, a7, a8, a9, b1, b2, b3, b4, c1, c2, c3 = p[:16]
    xd, yd, psid = planar_rates_cs(uu, v, r, cos(psi), sin(psi))
    du = (a1 + a8 * n) * uu + a2 * v * v + a3 * r * r + a4 * d * d + (a5 * r + a6 * d) * v + a7 * r * d + a9 * n * absf(n)
    dv = b1 * v + (b2 + b4 * uu) * r + b3 * d
    dr = c1 * v + c2 * r + c3 * d
    return xd, yd, psid, du, dv, dr


#: Positions of the entries returned by :func:`kcs_jac_x` after the planar ones.
KCS_JX_POS = PLANAR_JAC_POS + ((3, 3), (3, 4), (3, 5), (4, 3), (4, 4), (4, 5), (5, 4), (5, 5))


def kcs_jac_x(psi, uu, v, r, d, n, p):
    """Non-zero entries of d rates / d x at :data:`KCS_JX_POS`."""
    a1, a2, a3, a4, a5, a6, a7, a8, a9, b1, b2, b3, b4, c1, c2, c3 = p[:16]
    j0, j1, j2, j3, j4, j5, j6 = planar_jac_cs(uu, v, cos(psi), sin(psi))
    return (j0, j1, j2, j3, j4, j5, j6,
            a1 + a8 * n, 2.0 * a2 * v + a5 * r + a6 * d, 2.0 * a3 * r + a5 * v + a7 * d,
            b4 * r, b1, b2 + b4 * uu, c1, c2)


#: Positions of the entries of :func:`kcs_jac_p` (the regressors).
KCS_JP_POS = tuple((3, j) for j in range(9)) + ((4, 9), (4, 10), (4, 11), (4, 12), (5, 13), (5, 14), (5, 15))


def kcs_jac_p(psi, uu, v, r, d, n, p):
    """Non-zero entries of d rates / d p at :data:`KCS_JP_POS` (the regressors of eq. (3))."""
    return (uu, v * v, r * r, d * d, v * r, v * d, r * d, uu * n, n * absf(n), v, r, d, uu * r, v, r, d)


KCS_JU_POS = ((3, 0), (3, 1), (4, 0), (5, 0))


def kcs_jac_u(psi, uu, v, r, d, n, p):
    """Non-zero entries of d rates / d u at :data:`KCS_JU_POS`."""
    a1, a2, a3, a4, a5, a6, a7, a8, a9, b1, b2, b3, b4, c1, c2, c3 = p[:16]
    return (2.0 * a4 * d + a6 * v + a7 * r, a8 * uu + 2.0 * a9 * absf(n), b3, c3)


# ------------------------------------------------------------------ response-nl (29 parameters)
# order: a1..a9 b1..b4 c1..c3 (the seed's), b5..b9 c4..c9, b0 c0; ``uf`` is the floor of u in 1/u.
def nl_regressors(uu, v, r, d, n, uf):
    """Regressors of the u, v and r equations: 9 + 10 + 10 values (order of ``response_nl._U/_V/_R_IDX``)."""
    # the added damping scales with the speed |u| (hull forces ~ U v, U r and L v^2 r/U): with u itself
    # it would turn into anti-damping going astern, where the predictions blew up (docs/environment.md)
    au = absf(uu)
    q = inv_floor(au, uf)
    vav, rar, vvr, vrr, nn = v * absf(v), r * absf(r), v * v * r * q, v * r * r * q, n * n
    return (uu, v * v, r * r, d * d, v * r, v * d, r * d, uu * absf(n), n * absf(n),
            v, r, d, uu * r, au * v, vav, rar, vvr, vrr, nn,
            v, r, d, au * v, au * r, vav, rar, vvr, vrr, nn)


def nl_rates(psi, uu, v, r, d, n, p, uf):
    """``(x', y', psi', u', v', r')`` of response-nl (module docstring of :mod:`shipid.models.response_nl`)."""
    (a1, a2, a3, a4, a5, a6, a7, a8, a9, b1, b2, b3, b4, c1, c2, c3,
     b5, b6, b7, b8, b9, c4, c5, c6, c7, c8, c9, b0, c0) = p[:29]
    g = nl_regressors(uu, v, r, d, n, uf)
    du = (a1 * g[0] + a2 * g[1] + a3 * g[2] + a4 * g[3] + a5 * g[4] + a6 * g[5] + a7 * g[6] + a8 * g[7]
          + a9 * g[8])
    dv = (b1 * g[9] + b2 * g[10] + b3 * g[11] + b4 * g[12] + b5 * g[13] + b6 * g[14] + b7 * g[15] + b8 * g[16]
          + b9 * g[17] + b0 * g[18])
    dr = (c1 * g[19] + c2 * g[20] + c3 * g[21] + c4 * g[22] + c5 * g[23] + c6 * g[24] + c7 * g[25] + c8 * g[26]
          + c9 * g[27] + c0 * g[28])
    xd, yd, psid = planar_rates_cs(uu, v, r, cos(psi), sin(psi))
    return xd, yd, psid, du, dv, dr


#: Parameter index of each regressor of :func:`nl_regressors` (its rows 3, 4, 5 in turn).
NL_JP_POS = (tuple((3, j) for j in range(9)) + tuple((4, j) for j in (9, 10, 11, 12, 16, 17, 18, 19, 20, 27))
             + tuple((5, j) for j in (13, 14, 15, 21, 22, 23, 24, 25, 26, 28)))


def nl_jac_p(psi, uu, v, r, d, n, p, uf):
    """Non-zero entries of d rates / d p at :data:`NL_JP_POS` (the regressors)."""
    return nl_regressors(uu, v, r, d, n, uf)


NL_JX_POS = PLANAR_JAC_POS + ((3, 3), (3, 4), (3, 5), (4, 3), (4, 4), (4, 5), (5, 3), (5, 4), (5, 5))


def nl_jac_x(psi, uu, v, r, d, n, p, uf):
    """Non-zero entries of d rates / d x at :data:`NL_JX_POS`."""
    (a1, a2, a3, a4, a5, a6, a7, a8, a9, b1, b2, b3, b4, c1, c2, c3,
     b5, b6, b7, b8, b9, c4, c5, c6, c7, c8, c9, b0, c0) = p[:29]
    au, su = absf(uu), sgn_nn(uu)
    q = inv_floor(au, uf)
    dq = dinv_floor(au, uf) * su
    j0, j1, j2, j3, j4, j5, j6 = planar_jac_cs(uu, v, cos(psi), sin(psi))
    vvr, vrr = v * v * r, v * r * r
    av, ar = 2.0 * absf(v), 2.0 * absf(r)
    return (j0, j1, j2, j3, j4, j5, j6,
            a1 + a8 * absf(n), 2.0 * a2 * v + a5 * r + a6 * d, 2.0 * a3 * r + a5 * v + a7 * d,
            # sway: coefficients of v, r, u r, u v, v|v|, r|r|, v^2 r/u, v r^2/u = b1 b2 b4 b5 b6 b7 b8 b9
            b4 * r + b5 * v * su + (b8 * vvr + b9 * vrr) * dq,
            b1 + b5 * au + b6 * av + (2.0 * b8 * v * r + b9 * r * r) * q,
            b2 + b4 * uu + b7 * ar + (b8 * v * v + 2.0 * b9 * v * r) * q,
            # yaw: c1 c2 c5 c4 c6 c7 c8 c9
            (c5 * r + c4 * v) * su + (c8 * vvr + c9 * vrr) * dq,
            c1 + c4 * au + c6 * av + (2.0 * c8 * v * r + c9 * r * r) * q,
            c2 + c5 * au + c7 * ar + (c8 * v * v + 2.0 * c9 * v * r) * q)


NL_JU_POS = ((3, 0), (3, 1), (4, 0), (5, 0), (4, 1), (5, 1))


def nl_jac_u(psi, uu, v, r, d, n, p, uf):
    """Non-zero entries of d rates / d u at :data:`NL_JU_POS`."""
    (a1, a2, a3, a4, a5, a6, a7, a8, a9, b1, b2, b3, b4, c1, c2, c3,
     b5, b6, b7, b8, b9, c4, c5, c6, c7, c8, c9, b0, c0) = p[:29]
    return (2.0 * a4 * d + a6 * v + a7 * r, a8 * uu * sgn_nn(n) + 2.0 * a9 * absf(n), b3, c3, 2.0 * b0 * n,
            2.0 * c0 * n)


# ------------------------------------------------------------------ matrices from entries
def fill(J, pos, vals):
    """``J[pos[k]] = vals[k]`` for one sample (``pos`` an (m, 2) int array; used compiled)."""
    for k in range(pos.shape[0]):
        J[pos[k, 0], pos[k, 1]] = vals[k]


def stack_numpy(shape, vals) -> np.ndarray:
    """``vals`` (arrays broadcast to ``shape``) stacked along a new last axis (cheaper than ``np.stack``
    of broadcast arrays: one allocation, one assignment per component)."""
    out = np.empty(tuple(shape) + (len(vals),))
    for i, val in enumerate(vals):
        out[..., i] = val
    return out


def fill_numpy(shape, pos, vals) -> np.ndarray:
    """A zero matrix stack of ``shape`` (..., rows, cols) with the entries ``vals`` (arrays broadcast to
    the leading axes) at ``pos``."""
    J = np.zeros(shape)
    for (i, j), val in zip(pos, vals):
        J[..., i, j] = val
    return J


#: Globals of the batched numpy backend (real arrays).
NUMPY = {"cos": np.cos, "sin": np.sin, "absf": np.abs, "sgn_nn": lambda z: np.where(z < 0, -1.0, 1.0),
         "inv_floor": lambda uu, floor: 1.0 / np.maximum(uu, floor),
         "dinv_floor": lambda uu, floor: np.where(uu > floor, -1.0 / (uu * uu), 0.0)}

#: The functions of this module in dependency order (what :func:`shipid._jit.rebind` rebinds).
FUNCTIONS = {"inv_floor": inv_floor, "dinv_floor": dinv_floor, "absf": absf, "sgn_nn": sgn_nn, "planar_rates_cs": planar_rates_cs,
             "planar_jac_cs": planar_jac_cs, "kcs_rates": kcs_rates, "kcs_jac_x": kcs_jac_x,
             "kcs_jac_p": kcs_jac_p, "kcs_jac_u": kcs_jac_u, "nl_regressors": nl_regressors, "nl_rates": nl_rates,
             "nl_jac_p": nl_jac_p, "nl_jac_x": nl_jac_x, "nl_jac_u": nl_jac_u, "fill": fill}


# ------------------------------------------------------------------ the EKF kernel's protocol
# Every equations module offers three functions of one sample for shipid._kernel:
#   k_consts(p, P) -> c       constants of one parameter set (1-D float array), once per step
#   k_rhs(t, x, u, c, out)    out[:] = dx/dt
#   k_jac(t, x, u, p, P, c, cols, Jx, Jp)   Jacobians d/dx (nx, nx) and d/dp (nx, np); only the
#                              columns ``cols`` of Jp are needed; entries outside the sparsity
#                              pattern are never written (the caller zeroes the matrices once)
# ``P`` is the model's fixed constants (``Model._kernel_constants()``).
_KCS_JX = np.array(KCS_JX_POS, dtype=np.int64)
_KCS_JP = np.array(KCS_JP_POS, dtype=np.int64)
_NL_JX = np.array(NL_JX_POS, dtype=np.int64)
_NL_JP = np.array(NL_JP_POS, dtype=np.int64)


def kcs_k_consts(p, P):
    return p.copy()


def kcs_k_rhs(t, x, u, c, out):
    out[0], out[1], out[2], out[3], out[4], out[5] = kcs_rates(x[2], x[3], x[4], x[5], u[0], u[1], c)


def kcs_k_jac(t, x, u, p, P, c, cols, Jx, Jp):
    fill(Jx, _KCS_JX, kcs_jac_x(x[2], x[3], x[4], x[5], u[0], u[1], c))
    fill(Jp, _KCS_JP, kcs_jac_p(x[2], x[3], x[4], x[5], u[0], u[1], c))


def nl_k_consts(p, P):
    c = np.empty(p.shape[0] + 1)
    c[:p.shape[0]] = p
    c[p.shape[0]] = P[0]
    return c


def nl_k_rhs(t, x, u, c, out):
    out[0], out[1], out[2], out[3], out[4], out[5] = nl_rates(x[2], x[3], x[4], x[5], u[0], u[1], c, c[29])


def nl_k_jac(t, x, u, p, P, c, cols, Jx, Jp):
    fill(Jx, _NL_JX, nl_jac_x(x[2], x[3], x[4], x[5], u[0], u[1], c, c[29]))
    fill(Jp, _NL_JP, nl_jac_p(x[2], x[3], x[4], x[5], u[0], u[1], c, c[29]))


def _kernel_set(prefix: str) -> dict:
    return {**FUNCTIONS, "k_consts": globals()[prefix + "_k_consts"], "k_rhs": globals()[prefix + "_k_rhs"],
            "k_jac": globals()[prefix + "_k_jac"]}


#: The kernel-protocol function sets (dependency order) of the two models, for :mod:`shipid._jit`.
KERNEL_KCS = _kernel_set("kcs")
KERNEL_NL = _kernel_set("nl")
