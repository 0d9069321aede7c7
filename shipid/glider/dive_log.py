"""Synthetic glider dive logs with sensor noise, for identification studies.

A launch from :func:`shipid.glider.launch` sampled like a glider's sensors:
depth (pressure sensor), pitch (attitude sensor), body-axis velocities
(DVL / flow meter) and pitch rate (gyro), each with white Gaussian noise, plus
the fin incidence as the input channel.  The horizontal position is not
logged (no GPS under water).
"""
from __future__ import annotations

from typing import Mapping

import numpy as np

from ..logs import TrialLog
from ..models.base import Model
from .launch import launch

__all__ = ["dive_log", "DEFAULT_SENSOR_STD"]

#: Default sensor noise std: z [m], theta [rad], u, w [m/s], q [rad/s].
DEFAULT_SENSOR_STD: dict[str, float] = {"z": 0.01, "theta": 0.005, "u": 0.02, "w": 0.02, "q": 0.01}


def dive_log(
    speed: float,
    angle_deg: float,
    fin_deg: float = 0.0,
    cg_m: float = 0.0,
    *,
    model: Model | None = None,
    rate_hz: float = 25.0,
    sensor_std: Mapping[str, float] | None = None,
    rng: np.random.Generator | int | None = None,
    name: str | None = None,
):
    """A noisy log of one launch, from the surface back to the surface.

    Parameters
    ----------
    speed, angle_deg, fin_deg, cg_m : float
        Launch settings (see :func:`shipid.glider.launch`).
    model : Model, optional
        The true glider (default: the paper set).
    rate_hz : float
        Sampling rate [Hz]; the simulation runs at 0.01 s or finer and is
        sampled every ``round(1 / (rate_hz * dt))`` steps.
    sensor_std : mapping, optional
        Noise std per logged channel (``z, theta, u, w, q``); default
        :data:`DEFAULT_SENSOR_STD`.  Channels set to 0 are noise-free.
    rng : Generator or int, optional
    name : str, optional

    Returns
    -------
    shipid.logs.TrialLog
        Columns ``time, z, theta, u, w, q, delta`` (SI units, radians).
    """
    std = dict(DEFAULT_SENSOR_STD)
    for k, v in (sensor_std or {}).items():
        if k not in DEFAULT_SENSOR_STD:
            raise ValueError(f"sensor_std: unknown channel '{k}'; logged channels are {list(DEFAULT_SENSOR_STD)}")
        if not (np.isfinite(v) and v >= 0):
            raise ValueError(f"sensor_std['{k}'] = {v!r} must be a finite number >= 0")
        std[k] = float(v)
    if not (np.isfinite(rate_hz) and 0 < rate_hz <= 1000):
        raise ValueError(f"rate_hz = {rate_hz!r} must be in (0, 1000]")
    rng = np.random.default_rng(rng)
    dt = min(0.01, 1.0 / rate_hz)
    step = max(1, int(round(1.0 / (rate_hz * dt))))
    dt = 1.0 / (rate_hz * step)
    r = launch(speed, angle_deg, fin_deg, cg_m, model=model, dt=dt)
    if not r.success:
        raise ValueError(f"launch {speed} m/s, {angle_deg} deg did not return to the surface: {r.message}")
    df = r.to_pandas().iloc[:-1:step]              # grid samples, without the interpolated exit point
    n = len(df)
    channels = {k: df[k].to_numpy() + s * rng.standard_normal(n) for k, s in std.items()}
    channels["delta"] = np.full(n, np.deg2rad(fin_deg))
    label = name or f"launch {speed:g} m/s {angle_deg:g} deg fin {fin_deg:g} cg {cg_m:g}"
    return TrialLog.from_arrays(df.index.to_numpy(), name=label, inputs=("delta",), consistency_checks=False,
                               **channels)
