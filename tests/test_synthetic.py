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
    """The bundled CSVs were made before the rudder/rpm laws moved to shipid.manoeuvres: the shared laws
    reproduce them to rounding (rudder, rps schedule with ramps, zigzag reversals, noise stream)."""
    logs = make_kcs_logs(get_model(*model_name), seed=seed, recipes=recipes)
    for name in (r.name for r in recipes):
        noisy, _ = logs[name]
        ref = read_log(DATA / f"{name}.csv").data
        for ch in ("x", "y", "psi", "u", "v", "r", "delta", "n"):
            np.testing.assert_allclose(noisy[ch].to_numpy(), ref[ch].to_numpy(), rtol=0, atol=1e-11, err_msg=f"{name}:{ch}")


def test_zigzag_trial_reverses_at_the_first_sample_past_the_switch_heading():
    recipe = next(r for r in KCS_MMG_RECIPES if r.name == "mmg_kcs_zz_p10")
    _, truth = make_trial(get_model("mmg", "kcs"), recipe)
    psi, delta = np.degrees(truth["psi"].to_numpy()), np.degrees(truth["delta"].to_numpy())
    k = int(np.argmax(psi >= 10.0))  # first sample with the heading past +10 deg
    rate_step = recipe.rudder_rate_deg_s * recipe.dt_s
    assert delta[k - 1] == pytest.approx(10.0) and delta[k] == pytest.approx(10.0 - rate_step)
    assert np.all(np.abs(np.diff(delta)) <= rate_step + 1e-9)
    assert math.isclose(truth["n"].iloc[-1], recipe.rpm_steps[0][1])
