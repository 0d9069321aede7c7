"""Launch simulation with surface-return event detection (shipid.glider.launch)."""
import numpy as np
import pandas as pd
import pytest

from shipid.glider import launch, paper_reference_case
from shipid.glider.study import PAPER_REFERENCE
from shipid.models import get_model

NO_HYDRO = {"a": 0.0, "b": 0.0, "c": 0.0, "CL_alpha": 0.0, "CM_alpha": 0.0, "fin_span": 1e-12}


@pytest.mark.parametrize("speed,angle", [(3.0, 30.0), (1.0, 60.0), (5.0, 15.0)])
def test_ballistic_launch_event_matches_the_parabola(speed, angle):
    m = get_model("glider", NO_HYDRO)
    p = m.params_series()
    gnet = (p["rho"] * p["volume"] - p["m"]) * p["g"] / p["m"]
    g = np.deg2rad(angle)
    vx, vz = speed * np.sin(g), speed * np.cos(g)
    r = launch(speed, angle, 0.0, 0.0, model=m)
    assert r.success and r.scalar
    T = 2 * vz / gnet
    assert r.duration_s == pytest.approx(T, rel=1e-9)
    assert r.horizontal_m == pytest.approx(vx * T, rel=1e-9)
    assert r.max_depth_m == pytest.approx(vz**2 / (2 * gnet), rel=1e-4)    # grid maximum, no refinement
    assert r.exit_angle_deg == pytest.approx(90.0 - angle, abs=1e-7)      # mirror image of the entry
    assert r.exit_speed_m_s == pytest.approx(speed, rel=1e-9)
    assert r.exit_pitch_deg == pytest.approx(-(90.0 - angle), abs=1e-9)   # pitch never changes
    df = r.to_pandas()
    assert df["z"].iloc[-1] == 0.0 and df.index[-1] == pytest.approx(T)
    assert (df["z"].iloc[1:-1] > 0).all()


def test_paper_reference_launch_depth_within_15_percent_horizontal_not():
    """Divsalar et al., section 6-3-1: 5 m/s, 45 deg, fin 0, CG 0.01 m -> max depth 1.68 m, horizontal 4.73 m.

    With the paper's printed data and the choices stated in the 'paper' parameter set, the
    maximum depth is reproduced (+2.5 %), the horizontal travel is 21 % short (3.74 m).  The
    horizontal travel depends on quantities the paper does not print: in fresh water
    (rho = 1000 instead of 1025) it is 4.09 m (-13.5 %); with spheroid added mass, which the
    paper says it neglects, 4.11 m (-13 %, depth 1.84 m, +9.5 %).  Depth and travel cannot be matched more closely
    without fitting the unprinted quantities to the two reported numbers (docs/glider.md).
    """
    ref = paper_reference_case()
    assert abs(ref["depth_rel_diff"]) < 0.15
    assert ref["max_depth_m"] == pytest.approx(1.721, abs=0.005)
    assert ref["horizontal_m"] == pytest.approx(3.737, abs=0.005)
    assert -0.25 < ref["horizontal_rel_diff"] < -0.15          # the documented shortfall
    fresh = paper_reference_case(get_model("glider").with_params({"rho": 1000.0}))
    added = paper_reference_case(get_model("glider", "paper-added-mass"))
    for alt in (fresh, added):
        assert abs(alt["depth_rel_diff"]) < 0.15 and abs(alt["horizontal_rel_diff"]) < 0.15
        assert alt["horizontal_m"] - ref["horizontal_m"] > 0.3   # unprinted choices move it by > 8 %
    assert fresh["horizontal_m"] == pytest.approx(4.09, abs=0.01)
    assert added["horizontal_m"] == pytest.approx(4.11, abs=0.01)
    # the sign of the CG offset (the paper writes both 0.01 and -0.01 for this case) matters less
    aft = paper_reference_case(cg_m=-0.01)
    assert aft["max_depth_m"] == pytest.approx(1.564, abs=0.005)
    assert PAPER_REFERENCE["max_depth_m"] == 1.68 and PAPER_REFERENCE["horizontal_m"] == 4.73


def test_step_size_convergence_and_batch_equals_loop():
    r = launch(5.0, 45.0, 0.0, 0.01)
    fine = launch(5.0, 45.0, 0.0, 0.01, dt=0.005)   # RK4: 2^4 = 16x smaller error
    assert r.dt <= 0.01
    assert r.max_depth_m == pytest.approx(fine.max_depth_m, abs=1e-3)
    assert r.horizontal_m == pytest.approx(fine.horizontal_m, abs=1e-4)
    assert r.duration_s == pytest.approx(fine.duration_s, abs=1e-4)
    sp = np.array([1.0, 3.0, 5.0, 5.0])
    an = np.array([15.0, 30.0, 45.0, 60.0])
    fi = np.array([0.0, 5.0, 10.0, 0.0])
    cg = np.array([0.0, -0.01, -0.03, -0.05])
    b = launch(sp, an, fi, cg, dt=0.01)
    assert not b.scalar and len(b) == 4 and b.success
    for i in range(4):
        s = launch(sp[i], an[i], fi[i], cg[i], dt=0.01)
        for k in ("max_depth_m", "horizontal_m", "duration_s", "exit_angle_deg"):
            assert b.launches[k].iloc[i] == pytest.approx(getattr(s, k), rel=1e-10, abs=1e-12)
        np.testing.assert_allclose(b.to_pandas(i).to_numpy(), s.to_pandas().to_numpy(), rtol=1e-10, atol=1e-12)


def test_unfinished_and_unstable_launches_are_reported_not_raised():
    with pytest.warns(RuntimeWarning, match="still submerged"):
        r = launch(5.0, 45.0, t_max=0.5)
    assert not r.success and r.status == 1 and r.launches["status"].iloc[0] == "t_max"
    assert np.isnan(r.horizontal_m) and r.max_depth_m > 0.5
    big = get_model("glider").with_params({"fin_span": 1.0})   # stiff pitch damping
    with pytest.warns(RuntimeWarning, match="non-finite"):
        r = launch([0.5, 5.0], 45.0, model=big, dt=0.02)
    assert r.status == 2 and list(r.launches["status"]) == ["surfaced", "non-finite"]
    ok = launch(0.5, 45.0, model=big, dt=0.02)
    assert r.launches["horizontal_m"].iloc[0] == pytest.approx(ok.horizontal_m, rel=1e-12)
    auto = launch(5.0, 45.0, model=big)                        # automatic step handles it
    assert auto.success and auto.dt < 0.005


def test_bad_arguments_name_the_value():
    with pytest.raises(ValueError, match=r"speed = -1.0 is outside"):
        launch(-1.0, 45.0)
    with pytest.raises(ValueError, match=r"angle_deg = 95.0"):
        launch(5.0, [30.0, 95.0])
    with pytest.raises(ValueError, match="cg_m = 0.5"):
        launch(5.0, 45.0, cg_m=0.5)
    with pytest.raises(ValueError, match="needs a 'glider' model"):
        launch(5.0, 45.0, model=get_model("kcs-response"))
    with pytest.raises(ValueError, match="dt = 0"):
        launch(5.0, 45.0, dt=0.0)
    r = launch([5.0, 3.0], 45.0, keep_trajectories=False)
    with pytest.raises(ValueError, match="not kept"):
        r.to_pandas(0)
    both = launch([5.0, 3.0], 45.0)
    df = both.to_pandas()  # a batch: every launch's rows, labelled
    assert sorted(df["launch"].unique()) == [0, 1]
    pd.testing.assert_frame_equal(df[df["launch"] == 1].drop(columns="launch"), both.to_pandas(1))


def test_plot_draws_trajectories():
    import matplotlib

    matplotlib.use("Agg")
    r = launch([3.0, 5.0], [30.0, 45.0])
    ax = r.plot()
    assert len(ax.lines) == 3 and ax.yaxis_inverted()


@pytest.mark.parametrize("speed,angle,fin,cg", [(5.0, 45.0, 0.0, 0.01), (3.0, 30.0, 5.0, -0.03)])
def test_event_agrees_with_an_adaptive_integrator(speed, angle, fin, cg):
    """Oracle: scipy's DOP853 at rtol 1e-10 with a terminal z = 0 event, on the same model.rhs."""
    from scipy.integrate import solve_ivp

    from shipid.glider import launch_state

    m = get_model("glider").with_params({"x_g": cg})
    u = np.array([np.deg2rad(fin)])
    ev = lambda t, x: x[1]  # noqa: E731
    ev.terminal, ev.direction = True, -1
    x0 = launch_state(speed, angle)
    t0 = 1e-6
    sol = solve_ivp(lambda t, x: m.rhs(t, x, u), (0.0, t0), x0, method="DOP853", rtol=1e-12, atol=1e-14)
    sol = solve_ivp(lambda t, x: m.rhs(t, x, u), (t0, 30.0), sol.y[:, -1], method="DOP853", rtol=1e-10,
                    atol=1e-12, events=ev, dense_output=True)
    te, xe = sol.t_events[0][0], sol.y_events[0][0]
    tt = np.linspace(t0, te, 20001)
    zmax = sol.sol(tt)[1].max()
    r = launch(speed, angle, fin, cg)
    assert r.duration_s == pytest.approx(te, abs=2e-4)
    assert r.horizontal_m == pytest.approx(xe[0], abs=2e-4)
    assert r.max_depth_m == pytest.approx(zmax, abs=1e-3)
    assert np.deg2rad(r.exit_pitch_deg) == pytest.approx(xe[2], abs=1e-4)
