"""Planar (3-DOF) kinematics shared by the ship models -- one copy.

Earth-fixed position ``x`` (north), ``y`` (east) and heading ``psi`` of a ship
with body-axis surge ``u``, sway ``v`` and yaw rate ``r``::

    x' = u cos psi - v sin psi,   y' = u sin psi + v cos psi,   psi' = r
"""
from __future__ import annotations

import numpy as np

__all__ = ["planar_rates", "planar_rates_cs", "planar_jac_cs", "planar_jacobian", "PLANAR_JAC_POS"]


def planar_rates_cs(u, v, r, c, s):
    """``(x', y', psi')`` from ``c = cos psi``, ``s = sin psi`` (plain arithmetic: numpy, floats, or
    compiled by :mod:`shipid._jit`)."""
    return u * c - v * s, u * s + v * c, r


def planar_rates(psi, u, v, r, xp=np):
    """``(x', y', psi')``; ``xp`` is the array namespace (numpy, or one for complex steps)."""
    return planar_rates_cs(u, v, r, xp.cos(psi), xp.sin(psi))


#: (row, column) of the entries of :func:`planar_jac_cs` in the state Jacobian (states x y psi u v r).
PLANAR_JAC_POS = ((0, 2), (0, 3), (0, 4), (1, 2), (1, 3), (1, 4), (2, 5))


def planar_jac_cs(u, v, c, s):
    """The non-zero entries of d(x', y', psi')/d(psi, u, v, r) at :data:`PLANAR_JAC_POS`, from
    ``c = cos psi``, ``s = sin psi`` (plain arithmetic: numpy, floats, or compiled)."""
    return -u * s - v * c, c, -s, u * c - v * s, s, c, 1.0


def planar_jacobian(J, psi, u, v, ipsi: int = 2, iu: int = 3, iv: int = 4, ir: int = 5) -> None:
    """Fill rows 0-2 (x, y, psi) of the state Jacobian ``J`` (..., nx, nx) in place."""
    cols = {2: ipsi, 3: iu, 4: iv, 5: ir}
    for (i, j), val in zip(PLANAR_JAC_POS, planar_jac_cs(u, v, np.cos(psi), np.sin(psi))):
        J[..., i, cols[j]] = val
