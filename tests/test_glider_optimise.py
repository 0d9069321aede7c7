"""Launch optimisation by differential evolution (shipid.glider.optimise)."""
import numpy as np
import pandas as pd
import pytest

from shipid.glider import launch_objective, optimise_launch


def test_objective_is_the_stated_max_min_with_exit_penalty():
    df = pd.DataFrame({
        "max_depth_m": [2.0, 1.0, 2.0, 2.0],
        "horizontal_m": [2.0, 4.0, 4.0, np.nan],
        "exit_angle_deg": [60.0, 60.0, 84.0, np.nan],
        "surfaced": [True, True, True, False],
    })
    J = launch_objective(df, depth_ref=2.0, horizontal_ref=4.0, max_exit_angle_deg=75.0)
    np.testing.assert_allclose(J, [0.5, 0.5, 1.0 - 10 * 9 / 90, -1.0])
    J0 = launch_objective(df, 2.0, 4.0, max_exit_angle_deg=None)
    assert J0[2] == 1.0


def test_one_free_variable_finds_the_known_optimum():
    """Depth and travel both grow with launch speed (test_glider_study), so with only the speed
    free the optimum is the upper bound."""
    res = optimise_launch(bounds={"speed": (1.0, 5.0), "angle_deg": (45.0, 45.0), "fin_deg": (0.0, 0.0), "cg_m": (0.0, 0.0)},
                          popsize=4, maxiter=4, seed=1)
    assert res.x["speed"] > 4.8
    assert res.x["angle_deg"] == 45.0 and res.x["fin_deg"] == 0.0 and res.x["cg_m"] == 0.0
    assert res.objective == pytest.approx(launch_objective(res.launch.to_frame().T.infer_objects(), res.depth_ref, res.horizontal_ref)[0])
    d = res.as_dict()
    assert d["x"]["angle_deg"] == 45.0 and d["nfev"] > 0 and isinstance(d["launch"]["surfaced"], bool)


def test_bad_bounds_are_rejected():
    with pytest.raises(ValueError, match="unknown variable 'depth'"):
        optimise_launch(bounds={"depth": (0, 1)})
    with pytest.raises(ValueError, match=r"bounds\['fin_deg'\]"):
        optimise_launch(bounds={"fin_deg": (10.0, 0.0)})


@pytest.mark.slow
def test_full_optimisation_against_the_papers_choice():
    """Divsalar et al. chooses 5 m/s, 30 deg, fin 5 deg, CG 0 or -1 cm.  Under the stated max-min
    trade-off this model chooses 5 m/s and CG ~0 (agrees), but a launch of about 40 deg with
    a fin of 0-2 deg: at 30 deg / fin 5 the horizontal travel is only 56 % of the best
    reachable, against 78 % for both depth and travel at the optimum."""
    res = optimise_launch(popsize=10, maxiter=30, seed=0)
    assert res.objective >= res.grid_best["J"] - 1e-9
    assert res.x["speed"] > 4.9
    assert -0.01 <= res.x["cg_m"] <= 0.0
    assert 35.0 < res.x["angle_deg"] < 45.0 and res.x["fin_deg"] < 5.0
    assert res.objective == pytest.approx(0.78, abs=0.02)
    from shipid.glider import launch

    p = launch(5.0, 30.0, 5.0, 0.0).launches
    Jp = launch_objective(p, res.depth_ref, res.horizontal_ref)[0]
    assert Jp == pytest.approx(0.56, abs=0.02)
