"""Planar (3-DOF) kinematics shared by the ship models -- one copy.

Earth-fixed position ``x`` (north), ``y`` (east) and heading ``psi`` of a ship
with body-axis surge ``u``, sway ``v`` and yaw rate ``r``::

    x' = u cos psi - v sin psi,   y' = u sin psi + v cos psi,   psi' = r
"""
from __future__ import annotations

import numpy as np

__all__ = ["planar_rates", "planar_rates_cs", "planar_jacobian"]


def planar_rates_cs(u, v, r, c, s):
    """``(x', y', psi')`` from ``c = cos psi``, ``s = sin psi`` (plain arithmetic: numpy, floats, or
    compiled by :mod:`shipid._jit`)."""
    return u * c - v * s, u * s + v * c, r


def planar_rates(psi, u, v, r, xp=np):
    """``(x', y', psi')``; ``xp`` is the array namespace (numpy, or one for complex steps)."""
    return planar_rates_cs(u, v, r, xp.cos(psi), xp.sin(psi))


def planar_jacobian(J, psi, u, v, ipsi: int = 2, iu: int = 3, iv: int = 4, ir: int = 5) -> None:
    """Fill rows 0-2 (x, y, psi) of the state Jacobian ``J`` (..., nx, nx) in place."""
    c, s = np.cos(psi), np.sin(psi)
    J[..., 0, ipsi] = -u * s - v * c
    J[..., 0, iu] = c
    J[..., 0, iv] = -s
    J[..., 1, ipsi] = u * c - v * s
    J[..., 1, iu] = s
    J[..., 1, iv] = c
    J[..., 2, ir] = 1.0
