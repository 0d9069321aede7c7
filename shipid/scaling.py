"""Froude scaling between geometrically similar ships.

With the scale ratio ``lam = L_target / L_source`` and equal Froude number
``U / sqrt(g L)``: lengths scale by ``lam``, time by ``sqrt(lam)``, linear
speeds by ``sqrt(lam)``, angular rates (yaw rate, rudder rate) and propeller
rps by ``1/sqrt(lam)``, forces by ``lam^3`` (same density), angles are
unchanged.  A model whose parameters are non-dimensional (prime system, like
:class:`shipid.models.mmg.MMGModel`) then predicts the same non-dimensional
manoeuvre at any scale; :func:`scale_states`/:func:`scale_inputs`/
:func:`scale_time` map states, inputs and time grids between scales.

Reynolds-number effects (frictional resistance, wake, rudder stall) do not
follow Froude scaling; the scaled prediction inherits the source scale's
values of those coefficients.
"""
from __future__ import annotations

import math

import numpy as np

__all__ = ["froude_factors", "scale_states", "scale_inputs", "scale_time", "scale_ratio"]

_STATE_DIMS = {"x": "length", "y": "length", "psi": "angle", "u": "speed", "v": "speed", "r": "rate",
               "p": "rate", "phi": "angle"}
_INPUT_DIMS = {"delta": "angle", "n": "rate"}


def scale_ratio(lpp_from: float, lpp_to: float) -> float:
    """``lam = lpp_to / lpp_from`` (ValueError unless both are positive)."""
    if not (lpp_from > 0 and lpp_to > 0):
        raise ValueError(f"ship lengths must be positive, got lpp_from={lpp_from}, lpp_to={lpp_to}")
    return float(lpp_to) / float(lpp_from)


def froude_factors(lam: float) -> dict:
    """Multipliers from the source to the target scale for each kind of quantity.

    Returns
    -------
    dict
        ``{"length": lam, "time": sqrt(lam), "speed": sqrt(lam), "rate": 1/sqrt(lam),
        "angle": 1, "acceleration": 1, "force": lam**3, "moment": lam**4, "area": lam**2,
        "volume": lam**3}``.
    """
    if not lam > 0:
        raise ValueError(f"scale ratio must be positive, got {lam}")
    s = math.sqrt(lam)
    return {"length": lam, "time": s, "speed": s, "rate": 1.0 / s, "angle": 1.0, "acceleration": 1.0,
            "force": lam**3, "moment": lam**4, "area": lam**2, "volume": lam**3}


def _scale(values, names, dims, lam, what):
    f = froude_factors(lam)
    a = np.array(values, dtype=float, copy=True)
    if a.shape[-1] != len(names):
        raise ValueError(f"{what}: last axis has {a.shape[-1]} entries but {len(names)} names {list(names)} were given")
    for i, n in enumerate(names):
        if n not in dims:
            raise ValueError(f"{what}: don't know how '{n}' scales; known: {sorted(dims)}")
        a[..., i] *= f[dims[n]]
    return a


def scale_states(x, state_names, lam: float) -> np.ndarray:
    """Froude-scale states ``x (..., nx)`` named ``state_names`` by the ratio ``lam``."""
    return _scale(x, state_names, _STATE_DIMS, lam, "scale_states")


def scale_inputs(u, input_names, lam: float) -> np.ndarray:
    """Froude-scale inputs ``u (..., nu)`` (``delta`` unchanged, ``n`` by 1/sqrt(lam))."""
    return _scale(u, input_names, _INPUT_DIMS, lam, "scale_inputs")


def scale_time(t, lam: float) -> np.ndarray:
    """Froude-scale times [s] by sqrt(lam)."""
    return np.asarray(t, dtype=float) * froude_factors(lam)["time"]
