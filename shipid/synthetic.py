"""Synthetic trial logs with known truth (for tests, the bundled data and demos).

The recipe of the bundled KCS logs lives here so that ``data/make_synthetic.py``,
the tests and the notebooks all make the same data from one place.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from .models.base import Model
from .simulate import simulate

__all__ = ["TrialRecipe", "KCS_RECIPES", "KCS_NOISE_STD", "steady_surge_speed", "make_trial", "make_kcs_logs",
           "SCHEMA_UNITS"]

#: Default CSV schema: channel -> unit written in the header.
SCHEMA_UNITS = {"time": "s", "x": "m", "y": "m", "psi": "rad", "u": "m/s", "v": "m/s", "r": "rad/s",
                "delta": "rad", "n": "rps"}

#: Sensor noise (standard deviation) of the bundled logs, SI units: a DGPS/RTK
#: position, a fibre-optic gyro heading and rate, and a speed log typical of
#: free-running model tests.
KCS_NOISE_STD = {"x": 0.02, "y": 0.02, "psi": np.deg2rad(0.2), "u": 0.01, "v": 0.005, "r": np.deg2rad(0.1)}


@dataclass(frozen=True)
class TrialRecipe:
    """One synthetic manoeuvre.

    kind : "turning" or "zigzag"
    delta_deg : rudder angle (sign = side; + turns to starboard)
    psi_deg : zigzag heading deviation that triggers the rudder reversal
    duration_s, dt_s : length and sampling interval
    rpm_steps : ((t_s, n_rps), ...) propeller-rate set points (ramped at ``n_rate``)
    """

    name: str
    kind: str
    delta_deg: float
    duration_s: float
    rpm_steps: tuple = ((0.0, 10.0),)
    psi_deg: float = 0.0
    dt_s: float = 0.1
    rudder_rate_deg_s: float = 16.8  # KCS model, SPEC section 1
    n_rate: float = 1.0  # rps per second
    execute_s: float = 5.0


#: The bundled KCS model-scale trials (data/README.md).
KCS_RECIPES = (
    TrialRecipe("kcs_tc_p35", "turning", 35.0, 100.0, ((0.0, 10.0),)),
    TrialRecipe("kcs_tc_m25_rpm", "turning", -25.0, 110.0, ((0.0, 10.0), (40.0, 8.0), (75.0, 12.0))),
    TrialRecipe("kcs_zz_p20_rpm", "zigzag", 20.0, 110.0, ((0.0, 10.0), (55.0, 12.5)), psi_deg=20.0),
    TrialRecipe("kcs_zz_m10", "zigzag", -10.0, 110.0, ((0.0, 9.0),), psi_deg=10.0),
)


def steady_surge_speed(model: Model, n: float, delta: float = 0.0) -> float:
    """Straight-running speed ``u`` with ``du/dt = 0`` at rudder ``delta`` and rate ``n`` (v = r = 0).

    Solved generically through the protocol (bracketing root search on the
    surge equation), so it works for any model with states u, v, r and inputs
    delta, n.
    """
    from scipy.optimize import brentq

    iu = model.state_index("u")
    x = np.zeros(model.nx)
    uin = np.zeros(model.nu)
    uin[model.input_index("delta")] = delta
    uin[model.input_index("n")] = n

    def f(u):
        x[iu] = u
        return model.rhs(0.0, x, uin)[iu]

    grid = np.linspace(0.01, 50.0, 2000)
    vals = np.array([f(g) for g in grid])
    sign = np.flatnonzero(np.sign(vals[:-1]) != np.sign(vals[1:]))
    if sign.size == 0:
        raise ValueError(f"model '{model.name}' has no steady surge speed in 0..50 m/s at n = {n} rps")
    i = sign[0]
    return float(brentq(f, grid[i], grid[i + 1], xtol=1e-12))


def _rpm(recipe: TrialRecipe, t: float, n_now: float, h: float) -> float:
    target = recipe.rpm_steps[0][1]
    for ts, n in recipe.rpm_steps:
        if t >= ts:
            target = n
    return n_now + np.clip(target - n_now, -recipe.n_rate * h, recipe.n_rate * h)


def make_trial(model: Model, recipe: TrialRecipe, rng: np.random.Generator | None = None,
               noise_std: dict | None = None) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Simulate one trial; returns (noisy log, noise-free truth) as frames in the default schema.

    The rudder moves at the rudder rate; a zigzag reverses the rudder when the
    heading deviation from the initial course reaches ``psi_deg`` in the
    direction of the current rudder.
    """
    t = np.arange(0.0, recipe.duration_s + 1e-9, recipe.dt_s)
    h = recipe.dt_s
    n0 = recipe.rpm_steps[0][1]
    u0 = steady_surge_speed(model, n0)
    x0 = np.zeros(model.nx)
    x0[model.state_index("u")] = u0
    ipsi, id_, in_ = model.state_index("psi"), model.input_index("delta"), model.input_index("n")
    rate = np.deg2rad(recipe.rudder_rate_deg_s)
    side = np.sign(recipe.delta_deg) or 1.0
    amp = np.deg2rad(abs(recipe.delta_deg))
    trig = np.deg2rad(recipe.psi_deg)
    state = {"delta": 0.0, "n": n0, "target": 0.0}

    def controller(tk, x):
        if tk >= recipe.execute_s:
            if recipe.kind == "turning":
                state["target"] = side * amp
            else:
                if state["target"] == 0.0:
                    state["target"] = side * amp
                dpsi = x[ipsi]
                if state["target"] > 0 and dpsi >= trig:
                    state["target"] = -amp
                elif state["target"] < 0 and dpsi <= -trig:
                    state["target"] = amp
        state["delta"] += np.clip(state["target"] - state["delta"], -rate * h, rate * h)
        state["n"] = _rpm(recipe, tk, state["n"], h)
        u = np.zeros(model.nu)
        u[id_], u[in_] = state["delta"], state["n"]
        return u

    res = simulate(model, x0, t, controller=controller, substeps=4)
    truth = res.to_pandas().reset_index()
    noisy = truth.copy()
    rng = np.random.default_rng(0) if rng is None else rng
    for ch, sd in (noise_std or KCS_NOISE_STD).items():
        if ch in noisy:
            noisy[ch] = noisy[ch] + rng.normal(0.0, sd, size=len(noisy))
    return noisy, truth


def make_kcs_logs(model: Model | None = None, seed: int = 20261123, recipes=KCS_RECIPES,
                  noise_std: dict | None = None) -> dict[str, tuple[pd.DataFrame, pd.DataFrame]]:
    """The bundled KCS logs: {name: (noisy frame, truth frame)} from ``KCS_RECIPES``.

    ``model`` defaults to ``kcs-response`` with its ``synthetic-truth`` set.
    """
    if model is None:
        from .models import get_model

        model = get_model("kcs-response", "synthetic-truth")
    rng = np.random.default_rng(seed)
    return {r.name: make_trial(model, r, rng, noise_std) for r in recipes}


def schema_frame(df: pd.DataFrame) -> pd.DataFrame:
    """Rename columns to the default CSV schema headers (``"time [s]"``...)."""
    return df.rename(columns={c: f"{c} [{u}]" for c, u in SCHEMA_UNITS.items() if c in df.columns})
