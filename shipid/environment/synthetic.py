"""Synthetic logs with a known wind and current (for tests, the benchmark and the docs' recovery study)."""
from __future__ import annotations

import numpy as np
import pandas as pd

from ..simulate import simulate

__all__ = ["environment_log", "NOISE_STD"]

#: Measurement noise std per channel of :func:`environment_log` (GNSS-like, model scale).
NOISE_STD = {"x": 0.01, "y": 0.01, "psi": 0.002, "u": 0.005, "v": 0.005, "r": 0.002}


def environment_log(model, *, seed: int, duration: float = 400.0, dt: float = 0.1, current=(0.0, 0.0),
                    wind_speed: float = 1.5, wind_dir: float = 0.8, hold: float = 20.0, noise: bool = True,
                    name: str | None = None) -> pd.DataFrame:
    """Simulate ``model`` (a :func:`~shipid.environment.with_environment` model or a plain ship model)
    under random piecewise-constant rudder (+-35 deg) and propeller (6, 8, 10 rps, and -8 rps astern one
    hold in ten) held ``hold`` s each, with a gusting true wind (``wind_speed`` +- 20 % over 97 s,
    direction ``wind_dir`` +- 0.2 rad over 211 s) and a constant ``current`` (earth-fixed [m/s], used
    when the model has current states); GNSS-like noise :data:`NOISE_STD` on the measured states.

    Returns a frame with ``time``, ``x, y, psi, u, v, r``, ``delta, n``, ``wind_speed_true, wind_dir_true``
    (``attrs["name"]`` set; ``attrs["truth"]`` holds the noise-free states).
    """
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, duration, dt)
    k = (t // hold).astype(int)
    delta = np.radians(rng.uniform(-35, 35, k.max() + 1))[k]
    n = rng.choice([6.0, 8.0, 10.0, -8.0], size=k.max() + 1, p=[0.3, 0.3, 0.3, 0.1])[k]
    ws = wind_speed * (1.0 + 0.2 * np.sin(2 * np.pi * t / 97.0))
    wd = wind_dir + 0.2 * np.sin(2 * np.pi * t / 211.0)
    chans = {"delta": delta, "n": n, "wind_speed_true": ws, "wind_dir_true": wd}
    U = np.column_stack([chans[c] for c in model.input_names])
    x0 = np.zeros(model.nx)
    x0[3] = 0.2
    if "cx" in model.state_names:
        x0[model.state_index("cx")], x0[model.state_index("cy")] = current
    sim = simulate(model, x0, t, U, substeps=2)
    if not sim.success:
        raise RuntimeError(f"environment_log: simulation failed ({sim.message})")
    cols = {"time": t}
    for i, s in enumerate(("x", "y", "psi", "u", "v", "r")):
        cols[s] = sim.x[:, i] + (rng.normal(0.0, NOISE_STD[s], t.size) if noise else 0.0)
    cols.update(chans)
    df = pd.DataFrame(cols)
    df.attrs["name"] = name or f"synthetic-env-{seed}"
    df.attrs["truth"] = sim.x
    return df
