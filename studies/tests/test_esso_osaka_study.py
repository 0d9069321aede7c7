"""The Esso Osaka study (:mod:`studies.esso_osaka`) in its fast mode and its diagnostics on known truths.
The full study is ``python -m studies.esso_osaka`` (docs/environment.md)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

DATA = Path(__file__).resolve().parents[2] / ".." / "shared" / "data" / "esso_osaka_frt"

pytestmark = pytest.mark.skipif(not DATA.is_dir(), reason=f"Esso Osaka data set (FRT-DS-ESSO) not found at {DATA}")


@pytest.mark.slow
def test_study_fast_mode():
    """Two random runs, two folds (about 30 s on a free core; more on a loaded machine)."""
    from studies.esso_osaka import run_study

    # fit_every=20 (2 s), as the study: at 5 s (50) the FOH fit of one fold diverges
    res = run_study(types=("random",), max_runs=2, folds=2, fit_every=20, calm_water=(), progress=False)
    h = res.horizon
    assert set(h.model) >= {"dead reckoning", "lowspeed fitted (no environment)", "lowspeed + wind + current fitted",
                            "lowspeed + wind + current fitted by type"}
    assert (h.n_starts > 0).all()
    assert all(f["success"] for fold in res.fits.values() for f in fold.values())
    # the start-current floor diagnosis: its "fold mean" case is the study's own protocol, so it reproduces it
    from studies.esso_osaka import start_current_floor

    fl = start_current_floor(res).set_index(["start", "run_type", "seconds"]).position_error_median_m
    env = h[h.model == "lowspeed + wind + current fitted"].set_index(["run_type", "seconds"]).position_error_median_m
    for (kind, sec), v in env.items():
        assert fl[("fold mean", kind, sec)] == pytest.approx(v, rel=1e-9)
        assert np.isfinite([fl[(c, kind, sec)] for c in ("zero", "own (oracle)", "smoothed start")]).all()
    t10 = res.table(10.0)
    # on held-out runs the fitted environment-aware model predicts 10 s better than dead reckoning
    assert t10.loc["lowspeed + wind + current fitted", "random"] < t10.loc["dead reckoning", "random"]
    assert set(res.currents.columns) >= {"cx", "cx_std", "cy", "cy_std"}
    assert (res.currents.cx_std > 0).all()


def test_rudder_rate_limit():
    """The steering-gear candidate of the study: a 40 deg step becomes a ramp at the given slew rate,
    slower changes pass unchanged, and the Froude-scaled IMO rate of the 3 m model is 2.32 sqrt(325/3)."""
    from studies.esso_osaka import FROUDE_RUDDER_RATE_DEG_S, rate_limit

    t = np.arange(0.0, 5.0, 0.1)
    x = np.where(t < 1.0, 20.0, -20.0)
    y = rate_limit(t, x, 24.0)
    assert y[9] == 20.0 and y[10] == pytest.approx(17.6) and np.all(np.abs(np.diff(y)) <= 2.4 + 1e-12)
    assert y[-1] == -20.0 and np.argmax(y <= -20.0) == 9 + 17  # 40 deg at 2.4 deg per sample: 17 samples
    slow = np.linspace(0.0, 10.0, t.size)  # 2 deg/s
    np.testing.assert_allclose(rate_limit(t, slow, 24.0), slow)
    assert FROUDE_RUDDER_RATE_DEG_S == pytest.approx(24.15, abs=0.01)


def test_split_position_error_attributes_each_part():
    """The diagnosis of the zigzag error (docs/environment.md): swapping one predicted quantity
    into the measured track gives the error that quantity alone makes."""
    from studies.esso_osaka import split_position_error

    t = np.arange(0.0, 30.0 + 1e-9, 0.2)
    meas = {"psi": 0.02 * t, "u": np.full(t.size, 0.3), "v": np.full(t.size, 0.01)}
    # only the sway velocity wrong, heading constant: 0.01 m/s for 30 s to the side
    straight = dict(meas, psi=np.zeros(t.size))
    e = split_position_error(0.2, straight, dict(straight, v=straight["v"] + 0.01))
    assert e["v"] == pytest.approx(0.3) and e["velocity"] == pytest.approx(0.3)
    assert e["u"] == 0.0 and e["heading"] == 0.0
    # only the heading wrong by a constant 0.1 rad: the chord of the rotated 30 s track, 2 sin(0.05) |track|
    e = split_position_error(0.2, straight, dict(straight, psi=np.full(t.size, 0.1)))
    assert e["heading"] == pytest.approx(2 * np.sin(0.05) * np.hypot(9.0, 0.3), rel=1e-12)
    assert e["velocity"] == e["u"] == e["v"] == 0.0
    # a turning track: each part alone is the full error when only that part is wrong
    e = split_position_error(0.2, meas, dict(meas, u=meas["u"] * 1.1))
    assert e["u"] == pytest.approx(e["velocity"]) and e["v"] == 0.0 and e["u"] > 0.5


def test_residual_accelerations_recover_a_missing_side_force():
    """The residual-acceleration diagnosis (docs/environment.md) on a synthetic run with a known truth: the run
    is simulated with an ahead propeller side force and yaw moment (YPf, NPf) that the "fitted" model lacks;
    the equation error regressed on the model's sensitivities recovers both, and is ~0 for the true model."""
    from types import SimpleNamespace

    import pandas as pd

    from shipid.environment import with_environment
    from shipid.models import get_model
    from shipid.simulate import simulate
    from studies.esso_osaka import EssoStudy, residual_accelerations

    fitted = with_environment(get_model("lowspeed"), wind="esso-osaka-3m", current="constant")
    truth = fitted.with_params({"YPf": 0.002, "NPf": -0.0006})
    t = np.arange(0.0, 120.0, 0.1)
    U = np.column_stack([np.radians(20.0) * np.sign(np.sin(2 * np.pi * t / 40.0)), np.full(t.size, 12.0),
                         np.full(t.size, 1.5), np.full(t.size, -1.2)])
    sim = simulate(truth, np.array([0, 0, 0, 0.3, 0, 0, 0, 0]), t, U)
    X = np.asarray(sim.x)
    data = pd.DataFrame({"time": t, "x": X[:, 0], "y": X[:, 1], "psi": np.angle(np.exp(1j * X[:, 2])), "u": X[:, 3],
                         "v": X[:, 4], "r": X[:, 5], "delta": U[:, 0], "n": U[:, 1], "wind_speed_true": U[:, 2],
                         "wind_dir_true": U[:, 3]})
    run = SimpleNamespace(name="synthetic", run_type="zigzag", data=data)
    currents = pd.DataFrame({"fold": [0], "fit": ["all types"], "cx": [0.0], "cy": [0.0]})
    for model, expect in ((fitted, (0.002, -0.0006)), (truth, (0.0, 0.0))):
        study = EssoStudy(horizon=pd.DataFrame(), coefficients=pd.DataFrame(), currents=currents,
                          turning=pd.DataFrame(), models={0: {"m": model}},
                          settings={"fold_of": {"synthetic": 0}, "prior_params": {}, "wind": "esso-osaka-3m"})
        df = residual_accelerations(study, candidates=("YPf", "NPf"), model="m", runs=[run])
        A = np.vstack([np.concatenate([df["Jv_" + c], df["Jr_" + c]]) for c in ("YPf", "NPf")]).T
        b = np.linalg.lstsq(A, np.concatenate([df.ev, df.er]), rcond=None)[0]
        np.testing.assert_allclose(b, expect, atol=0.03 * 0.002)


def test_wind_driven_start_current():
    """The wind-driven start current (scored, not kept): the drift factor is the least-squares k of c = k w over runs, and each
    start's current is k x the mean air velocity of the trailing window (causal)."""
    import pandas as pd

    from studies.esso_osaka import air_velocity, drift_factor, with_drift_current

    rng = np.random.default_rng(3)
    w = rng.normal(0.0, 1.5, (12, 2))
    assert drift_factor(0.007 * w, w) == pytest.approx(0.007, rel=1e-12)
    c = 0.007 * w + rng.normal(0.0, 0.001, w.shape)
    assert abs(drift_factor(c, w) - 0.007) < 3 * 0.001 / np.sqrt(np.sum(w * w))
    assert drift_factor(np.zeros((2, 2)), np.zeros((2, 2))) == 0.0
    # wind from north (dir 0) at 2 m/s blows towards -x; from east (+pi/2) towards -y
    t = np.arange(0.0, 200.0, 0.5)
    f = pd.DataFrame({"time": t, "wind_speed_true": 2.0, "wind_dir_true": np.where(t < 100.0, 0.0, np.pi / 2)})
    np.testing.assert_allclose(air_velocity(f)[[0, -1]], [[-2.0, 0.0], [0.0, -2.0]], atol=1e-12)
    g = with_drift_current(f, 0.01, window=60.0)
    assert list(f.columns) == ["time", "wind_speed_true", "wind_dir_true"]  # not modified in place
    np.testing.assert_allclose(g[["cx", "cy"]].to_numpy()[[0, 150, -1]], [[-0.02, 0.0], [-0.02, 0.0], [0.0, -0.02]],
                               atol=1e-12)
    # half-way through the change of direction the trailing minute holds both winds equally
    i = int(np.searchsorted(t, 130.0))
    n_old = np.sum((t >= t[i] - 60.0) & (t < 100.0))
    n_all = np.sum((t >= t[i] - 60.0) & (t <= t[i]))
    np.testing.assert_allclose(g.loc[i, ["cx", "cy"]].to_numpy(dtype=float),
                               [-0.02 * n_old / n_all, -0.02 * (n_all - n_old) / n_all], atol=1e-12)
    from studies.esso_osaka import ESTIMATE, run_study

    with pytest.raises(ValueError, match="current_start"):
        run_study(current_start="measured")
    assert "CrY" in ESTIMATE  # kept by the study's cross-validation: the default


def test_current_vs_wind_projects_on_the_mean_air_velocity():
    import pandas as pd

    from studies.esso_osaka import EssoStudy, current_vs_wind

    class Run:
        def __init__(self, name, speed, came_from):
            self.name, self.run_type = name, "turning"
            self.data = pd.DataFrame({"wind_speed_true": [speed] * 3, "wind_dir_true": [came_from] * 3})

    # wind from x's direction (blows to -x) at 2 m/s; the current (-0.01, 0.004) m/s (mean of the two folds)
    # is 0.01 downwind and (wx cy - wy cx)/|w| = -0.004 across
    cur = pd.DataFrame({"fold": [0, 1], "fit": "all types", "run": "a", "cx": [-0.011, -0.009], "cy": [0.004, 0.004]})
    st = EssoStudy(horizon=pd.DataFrame(), coefficients=pd.DataFrame(), currents=cur, turning=pd.DataFrame())
    r = current_vs_wind(st, runs=[Run("a", 2.0, 0.0), Run("b", 1.0, 0.0)]).iloc[0]
    assert len(current_vs_wind(st, runs=[Run("b", 1.0, 0.0)])) == 0  # no current estimated for it
    assert (r.c_down, r.c_cross, r.ratio) == pytest.approx((0.01, -0.004, 0.005))


def test_anemometer_check_recovers_a_sensor_offset_and_gain():
    """The anemometer data check (docs/environment.md): a synthetic turning run whose apparent wind is
    measured by an anemometer turned by 20 deg with gain 0.9, the logged true wind converted from it with the
    ship's motion as the logs do; the per-run coefficient of the logged air velocity on the ship's velocity is
    1 - 0.9 e^{i 20 deg}, and 0 for a correct sensor."""
    from types import SimpleNamespace

    import pandas as pd

    from shipid.environment.wind import true_wind_from_apparent
    from studies.esso_osaka import anemometer_check

    rng = np.random.default_rng(8)
    t = np.arange(0.0, 600.0, 0.1)
    psi = 0.05 * t
    u, v = np.full(t.size, 0.3), np.full(t.size, -0.02)
    W = (-1.2 + 0.5j) + 0.02 * (rng.normal(size=t.size) + 1j * rng.normal(size=t.size))  # air velocity, earth
    Vb = u + 1j * v
    A = (W - Vb * np.exp(1j * psi)) * np.exp(-1j * psi)             # apparent air velocity, body axes
    runs = []
    for name, g in (("offset", 0.9 * np.exp(1j * np.radians(20.0))), ("correct", 1.0)):
        Am = g * A
        ws, wd = true_wind_from_apparent(np.abs(Am), np.angle(-Am), psi, u, v)
        data = pd.DataFrame({"time": t, "psi": psi, "u": u, "v": v, "wind_speed_true": ws, "wind_dir_true": wd})
        runs.append(SimpleNamespace(name=name, run_type="turning", data=data))
    a = anemometer_check(runs=runs).set_index("run")
    m = 1.0 - 0.9 * np.exp(1j * np.radians(20.0))
    assert a.loc["offset", "m_re"] == pytest.approx(m.real, abs=0.01)
    assert a.loc["offset", "m_im"] == pytest.approx(m.imag, abs=0.01)
    assert abs(a.loc["correct", "m_re"]) < 0.01 and abs(a.loc["correct", "m_im"]) < 0.01


def test_path_relative_error_of_a_perfect_model_is_zero_and_the_path_is_measured():
    """path_relative_error: a run simulated by the model that predicts it has no error (below 0.1 %
    of the path: integration steps), and the path is the distance the logged positions cover in the horizon."""
    from types import SimpleNamespace

    import pandas as pd

    from shipid.models import get_model
    from shipid.simulate import simulate
    from studies.esso_osaka import EssoStudy, path_relative_error

    m = get_model("lowspeed")
    t = np.arange(0.0, 80.0, 0.1)
    U = np.column_stack([np.radians(10.0) * np.sin(2 * np.pi * t / 40.0), np.full(t.size, 10.0)])
    X = np.asarray(simulate(m, np.array([0, 0, 0, 0.3, 0, 0]), t, U).x)
    data = pd.DataFrame({"time": t, "x": X[:, 0], "y": X[:, 1], "psi": np.angle(np.exp(1j * X[:, 2])), "u": X[:, 3],
                         "v": X[:, 4], "r": X[:, 5], "delta": U[:, 0], "n": U[:, 1]})
    run = SimpleNamespace(name="synthetic", run_type="zigzag", data=data)
    study = EssoStudy(horizon=pd.DataFrame(), coefficients=pd.DataFrame(),
                      currents=pd.DataFrame({"fold": [0], "fit": ["all types"], "cx": [0.0], "cy": [0.0]}),
                      turning=pd.DataFrame(), models={0: {"m": m}}, settings={"fold_of": {"synthetic": 0}, "eval_every": 2})
    p = path_relative_error(study, model="m", runs=[run])
    # error_diagnosis shares the held-out prediction: a perfect model's errors stay below every threshold
    from studies.esso_osaka import error_diagnosis
    e = error_diagnosis(study, model="m", runs=[run])
    assert len(e) == len(p) and (e.error < 1e-3 * 0.35 * 30.0).all() and e.t_v.isna().all() and e.t_psi.isna().all()
    assert np.allclose(e.error, p.error, rtol=0, atol=1e-12)
    assert len(p) >= 9 and (p.n == 10.0).all()
    assert (p.error / p.path).max() < 1e-3    # the 0.2 s RK4 steps of the prediction against simulate()'s
    i = p.index[0]
    d = data.iloc[::2]
    seg = d[d.time <= 30.0 + 1e-9]
    assert p.loc[i, "path"] == pytest.approx(np.sum(np.hypot(np.diff(seg.x), np.diff(seg.y))), rel=1e-9)
    assert 0.25 * 30.0 < p.loc[i, "path"] < 0.35 * 30.0


def test_refine_on_windows_recovers_a_coefficient_with_each_runs_current():
    """The windowed refinement (``refine_on_windows``) on two synthetic runs of ``lowspeed`` + a constant current,
    each run with its own current: from Nr 30 % off it recovers Nr with the runs' own currents; with
    ``current="mean"`` every window starts with the mean current; ``balance`` weighs each run type the same."""
    from types import SimpleNamespace

    import pandas as pd

    from shipid.environment import with_environment
    from shipid.models import get_model
    from shipid.simulate import simulate
    from studies.esso_osaka import refine_on_windows

    truth = with_environment(get_model("lowspeed"), current="constant")
    runs, cur = [], [{"cx": 0.02, "cy": 0.0}, {"cx": -0.01, "cy": 0.015}]
    for j, (kind, T) in enumerate((("zigzag", 80.0), ("turning", 160.0))):
        t = np.round(np.arange(0.0, T, 0.1), 9)
        delta = np.radians(20.0) * np.sign(np.sin(2 * np.pi * np.floor(t) / (25.0 + 10 * j)))  # changes on whole seconds
        U = np.column_stack([delta, np.full(t.size, 10.0)])
        X = np.asarray(simulate(truth, np.array([0, 0, 0, 0.3, 0, 0, cur[j]["cx"], cur[j]["cy"]]), t, U).x)
        data = pd.DataFrame({"time": t, "x": X[:, 0], "y": X[:, 1], "psi": np.angle(np.exp(1j * X[:, 2])),
                             "u": X[:, 3], "v": X[:, 4], "r": X[:, 5], "delta": U[:, 0], "n": U[:, 1]})
        runs.append(SimpleNamespace(name=kind, run_type=kind, data=data))
    nr = float(truth.params_series()["Nr"])
    start = truth.with_params({"Nr": 1.3 * nr})
    own = refine_on_windows(start, runs, cur, estimate=("Nr",), max_nfev=20)
    assert own.coef_["Nr"] == pytest.approx(nr, rel=2e-3) and own.cost_ < 1e-3 * own.cost_start_
    mean = refine_on_windows(start, runs, cur, estimate=("Nr",), max_nfev=2, current="mean", balance=True)
    assert np.allclose(mean.x0_[["cx", "cy"]].to_numpy(), [0.005, 0.0075])
    w = np.asarray(mean.log_weights)
    assert w.size == 5 + 13 and w[:5].sum() == pytest.approx(w[5:].sum()) and w.sum() == pytest.approx(w.size)
    assert own.log_weights is None
    # the refinement's options: a held coefficient keeps the start model's value while the others are refined; the
    # position-only cost and the robust loss reach the refiner
    held = refine_on_windows(start.with_params({"Yv": 1.1 * float(truth.params_series()["Yv"])}), runs, cur,
                             estimate=("Nr", "Yv"), hold=("Yv",), channels=("x", "y"), loss="soft_l1", max_nfev=20)
    assert held.estimated_ == ["Nr"] and held.channels_ == ["x", "y"] and held.loss == "soft_l1"
    assert held.coef_["Yv"] == pytest.approx(1.1 * float(truth.params_series()["Yv"]), rel=1e-12)
    assert held.coef_["Nr"] != pytest.approx(1.3 * nr, rel=1e-3)
    with pytest.raises(ValueError, match="hold"):
        refine_on_windows(start, runs, cur, estimate=("Nr",), hold=("aH",))
    # in_sample_errors judges models on the runs they were fitted on, each with its own current: the truth and
    # the refined model predict these runs to integration accuracy, the start model does not
    from studies.esso_osaka import in_sample_errors

    e = in_sample_errors({"truth": truth, "refined": own.to_model(), "start": start}, runs, cur)
    med = e.groupby("model").position_error.max()
    assert len(e) == 3 * (5 + 13) and med["truth"] < 1e-3 and med["refined"] < 5e-3 and med["start"] > 0.1
