"""shipid.synthetic: the recipe of the bundled logs, made with the manoeuvre laws of shipid.manoeuvres."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from shipid.logs import read_log
from shipid.models import get_model
from shipid.synthetic import KCS_MMG_RECIPES, KCS_RECIPES, make_kcs_logs, make_trial

DATA = Path(__file__).parents[1] / "data"
SEED = 20261123  # data/make_synthetic.py


@pytest.mark.parametrize("model_name, recipes, seed", [
    (("kcs-response", "synthetic-truth"), KCS_RECIPES, SEED),
    (("mmg", "kcs"), KCS_MMG_RECIPES[:1], SEED + 1),  # the noise stream runs through the recipes in order
])
def test_recipe_reproduces_the_bundled_logs(model_name, recipes, seed):
    """data/make_synthetic.py wrote the bundled CSVs from this recipe (continuous rudder, adaptive integration)."""
    logs = make_kcs_logs(get_model(*model_name), seed=seed, recipes=recipes)
    for name in (r.name for r in recipes):
        noisy, _ = logs[name]
        ref = read_log(DATA / f"{name}.csv").data
        for ch in ("x", "y", "psi", "u", "v", "r", "delta", "n"):
            # Bit-for-bit on the CPU that wrote them; elsewhere the zigzag's reversal (a root found
            # between samples) amplifies last-digit differences of the maths library: up to 8.9e-9 m
            # in y of kcs_zz_p20_rpm on an AMD EPYC (OpenBLAS Haswell kernels), 1e-13 on the turns.
            # 1e-7 is still 4-5 orders below the logs' noise (sigma 2e-2 m in x, y; 1.7e-3 rad/s in r), so any change
            # of the recipe, the seed or the noise stream fails here.
            np.testing.assert_allclose(noisy[ch].to_numpy(), ref[ch].to_numpy(), rtol=0, atol=1e-7, err_msg=f"{name}:{ch}")


def test_zigzag_trial_reverses_at_the_crossing_between_samples():
    """Continuous rudder: the reversal happens when the heading crosses the switch angle (between
    samples), and the logged rudder is the instantaneous one at the sample times."""
    recipe = next(r for r in KCS_MMG_RECIPES if r.name == "mmg_kcs_zz_p10")
    _, truth = make_trial(get_model("mmg", "kcs"), recipe)
    t = truth["time"].to_numpy()
    psi, delta = np.degrees(truth["psi"].to_numpy()), np.degrees(truth["delta"].to_numpy())
    k = int(np.argmax(psi >= 10.0))  # first sample with the heading past +10 deg
    tc = t[k - 1] + (10.0 - psi[k - 1]) / (psi[k] - psi[k - 1]) * (t[k] - t[k - 1])  # crossing time
    rate = recipe.rudder_rate_deg_s
    assert delta[k - 1] == pytest.approx(10.0)
    assert delta[k] == pytest.approx(10.0 - rate * (t[k] - tc), abs=0.01 * rate * recipe.dt_s)
    assert 0.0 < 10.0 - delta[k] < rate * recipe.dt_s  # moved part of one sample's rudder travel
    assert np.all(np.abs(np.diff(delta)) <= rate * recipe.dt_s + 1e-9)
    assert math.isclose(truth["n"].iloc[-1], recipe.rpm_steps[0][1])
    # the old recipe (sampled controller, zero-order hold) is still available and differs
    _, held = make_trial(get_model("mmg", "kcs"), recipe, rudder="sampled")
    assert np.max(np.abs(held["psi"].to_numpy() - truth["psi"].to_numpy())) > 1e-3
