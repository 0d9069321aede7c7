"""Fits that say when they are wrong: the consistency verdict of the EKF identifier on clean logs and
on each wrong-physics case, dropouts, glitches and frozen positions, and the CLI exit status."""
from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from shipid.cli import main
from shipid.identify import EKFIdentifier
from shipid.identify.diagnostics import ljung_box
from shipid.synthetic import KCS_NOISE_STD, schema_frame

DATA = Path(__file__).parents[1] / "data"


# ------------------------------------------------------------------ Ljung-Box
def test_ljung_box_formula_by_hand_and_its_null_distribution():
    x = np.array([1.0, -2.0, 0.5, 1.5, -1.0, 0.0])
    den = np.sum(x**2)
    r1 = np.sum(x[:-1] * x[1:]) / den
    r2 = np.sum(x[:-2] * x[2:]) / den
    n = 6
    Q, p, rho, nn = ljung_box([x], 2)
    assert nn == 6 and rho == pytest.approx([r1, r2], abs=1e-15)
    assert Q == pytest.approx(n * (n + 2) * (r1**2 / (n - 1) + r2**2 / (n - 2)), rel=1e-14)
    # segments: lag products never cross a segment boundary, NaN samples are left out
    Q2, _, rho2, n2 = ljung_box([x[:3], np.array([np.nan]), x[3:]], 1)
    assert n2 == 6 and rho2[0] == pytest.approx((x[0] * x[1] + x[1] * x[2] + x[3] * x[4] + x[4] * x[5]) / den)
    # white noise: p-values uniform; AR(1) with phi = 0.3: rejected
    rng = np.random.default_rng(0)
    ps = np.array([ljung_box([rng.standard_normal(400)], 20)[1] for _ in range(300)])
    from scipy.stats import kstest

    assert kstest(ps, "uniform").pvalue > 0.01
    e = rng.standard_normal(2000)
    ar = np.zeros_like(e)
    for k in range(1, e.size):
        ar[k] = 0.3 * ar[k - 1] + e[k]
    assert ljung_box([ar], 20)[1] < 1e-10


# ------------------------------------------------------------------ clean logs are consistent
def test_clean_bundled_fit_is_consistent_and_its_json_strict(kcs_fit, tmp_path):
    c = kcs_fit.diagnostics_["consistency"]
    assert c["consistent"], c["reasons"]
    for ch, row in c["channels"].items():
        assert 0.8 < row["nis_mean"] < 1.2 and row["rho_max"] < 0.15 and row["n_gated"] == 0, (ch, row)
        assert row["nis_band"][0] < 1 < row["nis_band"][1] and row["n_eff"] > 0.9 * row["n"]
    for ch in ("u", "v", "r"):
        assert c["channels"][ch]["replay_ratio"] < 1.3
    assert c["dynamic_channels"] == ["u", "v", "r"]
    path = kcs_fit.result().to_json(tmp_path / "r.json")
    text = path.read_text()
    assert "NaN" not in text and "Infinity" not in text
    assert json.loads(text)["diagnostics"]["consistency"]["consistent"] is True


# ------------------------------------------------------------------ wrong physics is flagged
def _two_logs(kcs_logs):
    return [kcs_logs["kcs_tc_m25_rpm"][0].copy(), kcs_logs["kcs_zz_p20_rpm"][0].copy()]


def _units(logs):  # rudder logged in rad/57.3 while declared rad
    for f in logs:
        f["delta"] = f["delta"] / 57.3
    return logs


def _sign(logs):  # rudder positive to port
    for f in logs:
        f["delta"] = -f["delta"]
    return logs


def _decimated(logs):
    return [f.iloc[::10].reset_index(drop=True) for f in logs]


def _noise(logs):  # the state channels are pure noise
    rng = np.random.default_rng(1)
    for f in logs:
        for ch in ("x", "y", "psi", "u", "v", "r"):
            f[ch] = rng.normal(f[ch].mean(), f[ch].std(), len(f))
    return logs


def _swapped(logs):  # v and r columns swapped
    for f in logs:
        f["r"], f["v"] = f["v"].copy(), f["r"].copy()
    return logs


@pytest.mark.parametrize("case, kind, grade, needle", [
    (_units, "physics_range", "defect", "--units delta=deg"), (_sign, "physics_sign", "defect", "--rudder-sign -1"),
    (_decimated, "sampling", "defect", "full-rate"),
    pytest.param(_noise, "innovations_large", "model_error", "", marks=pytest.mark.slow),
    # v and r swapped: coefficient signs that physics rules out
    pytest.param(_swapped, "physics_sign", "defect", "", marks=pytest.mark.slow)],
    ids=lambda v: getattr(v, "__name__", "")[1:] if callable(v) else None)
def test_each_wrong_physics_case_is_flagged(kcs_truth, kcs_logs, case, kind, grade, needle):
    """The verdict grades the cases a model-form error cannot produce as defects naming the option that
    fixes them (a scaled or flipped rudder leaves the innovations white: only the coefficients' physics shows
    it); the channel checks of the reader catch the noise and swapped cases before any fit
    (tests/test_logs_consistency.py), the filter's statistics flag them here."""
    fit = EKFIdentifier(kcs_truth, n_passes=1).fit(case(_two_logs(kcs_logs)))
    assert fit.success_
    v = fit.result().verdict
    assert v.grade == grade and any(f["kind"] == kind for f in v.findings), v.to_dict()
    assert needle in " ".join(v.reasons)
    assert all(len(r) <= 300 for r in v.reasons)


def _drop(logs, t0, T):
    out = []
    for f in logs:
        t = f["time"].to_numpy()
        out.append(f.loc[~((t > t0) & (t < t0 + T))].reset_index(drop=True))
    return out


@pytest.mark.parametrize("T", [20.0, pytest.param(40.0, marks=pytest.mark.slow)])
def test_logger_dropouts_are_consistent_and_unbiased(kcs_truth, kcs_logs, T):
    """20 s and 40 s without any row (inputs unknown over the gap, zigzag reversals inside it): the ship
    state restarts after the gap, the parameters carry over."""
    fit = EKFIdentifier(kcs_truth, n_passes=1).fit(_drop(_two_logs(kcs_logs), 30.0, T))
    c = fit.diagnostics_["consistency"]
    assert fit.success_ and c["consistent"], c["reasons"]
    assert len(c["gaps"]) == 2 and f"{T:.3g} s without samples after t = 30 s" in c["gaps"][0]
    z = ((fit.coef_ - kcs_truth.params_series()) / fit.coef_std_)[fit.estimated_]
    assert np.all(np.abs(z) < 3), z[np.abs(z) >= 3]


def test_a_gap_with_steady_inputs_is_integrated_across_in_many_steps(kcs_truth, kcs_logs):
    """max_gap=None: a 40 s dropout in the steady part of a turning circle is crossed by the RK4 map
    (533 steps) without divergence or bias."""
    log = _drop([kcs_logs["kcs_tc_p35"][0]], 45.0, 40.0)
    fit = EKFIdentifier(kcs_truth, n_passes=1, estimate=["b1", "b3", "c1", "c2", "c3"], max_gap=None).fit(log)
    assert fit.success_ and fit.diagnostics_["consistency"]["consistent"], fit.diagnostics_["consistency"]["reasons"]
    assert fit.diagnostics_["consistency"]["gaps"] == []
    z = ((fit.coef_ - kcs_truth.params_series()) / fit.coef_std_)[fit.estimated_]
    assert np.all(np.abs(z) < 3), z


@pytest.mark.slow
def test_glitches_and_frozen_positions_neither_diverge_nor_bias(kcs_truth, kcs_logs):
    """Injected 30-sigma glitches on every state channel and GNSS-style freezes (x, y repeat their last
    fix for 3-14 samples on ~6 % of the samples, then jump): truth recovered within 3 sigma."""
    rng = np.random.default_rng(5)
    logs = _two_logs(kcs_logs)
    n_glitch = 0
    for f in logs:
        for ch in ("x", "y", "psi", "u", "v", "r"):
            k = rng.choice(len(f), 8, replace=False)
            f.loc[k, ch] += 30 * KCS_NOISE_STD[ch] * rng.choice([-1, 1], 8)
            n_glitch += 8
        k = 20
        while k < len(f) - 20:
            run = int(rng.integers(3, 15))
            f.loc[k + 1:k + run, ["x", "y"]] = f.loc[k, ["x", "y"]].to_numpy()
            k += run + int(rng.integers(60, 200))
    fit = EKFIdentifier(kcs_truth, n_passes=2).fit(logs)
    assert fit.success_
    noise = fit.noise_
    assert noise.loc["x", "n_frozen"] > 0.03 * sum(len(f) for f in logs)
    assert noise.loc["u", "n_frozen"] == 0
    gated = sum(fit.diagnostics_["n_gated"].values())
    assert 0.6 * n_glitch < gated < 1.5 * n_glitch
    z = ((fit.coef_ - kcs_truth.params_series()) / fit.coef_std_)[fit.estimated_]
    assert np.all(np.abs(z) < 3), z[np.abs(z) >= 3]


@pytest.mark.slow
def test_pre_filtered_channels_get_noise_from_the_innovations(kcs_truth, kcs_logs):
    """u, v, r smoothed by a 1 s moving average (as a logger's filter does): the second-difference noise
    estimate collapses; the first-pass innovations raise it so that the fit converges."""
    logs = _two_logs(kcs_logs)
    for f in logs:
        for ch in ("u", "v", "r"):
            f[ch] = f[ch].rolling(11, center=True, min_periods=1).mean()
    fit = EKFIdentifier(kcs_truth, n_passes=1).fit(logs)
    assert fit.success_
    nz = fit.noise_
    for ch in ("u", "v", "r"):
        assert nz.loc[ch, "innovation_factor"] > 1.5 and nz.loc[ch, "used"] > nz.loc[ch, "second_difference"]
    for ch in ("x", "y", "psi"):  # untouched channels keep their estimate
        assert nz.loc[ch, "innovation_factor"] == 1.0
    fixed = EKFIdentifier(kcs_truth, n_passes=1, meas_std={"r": 2e-3}).fit(logs)  # a given level is kept
    assert fixed.noise_.loc["r", "used"] == 2e-3


@pytest.mark.slow
def test_tuning_grid_grows_past_an_edge(kcs_truth, kcs_logs):
    """r declared 5x too small: the best measurement multiplier of the start grid (x0.5..x2) is its edge,
    so the grid grows; the reported optimum is inside the grown grid."""
    logs = [kcs_logs["kcs_zz_m10"][0]]
    fit = EKFIdentifier(kcs_truth, n_passes=1, estimate=["c2", "c3"], meas_std={"r": 0.2 * KCS_NOISE_STD["r"]},
                        adapt_noise=False, tune_noise=True).fit(logs)
    tab = fit.tuning_
    start = tab[(tab["r_mult"] <= 2.0) & (tab["q_mult"] >= 1e-3) & (tab["q_mult"] <= 1e2)]
    first = start.loc[start["loglik"].idxmax()]
    assert first["r_mult"] == 2.0 and tab["r_mult"].max() > 2.0
    best = tab.loc[tab["loglik"].idxmax()]
    assert best["loglik"] >= first["loglik"]
    qs, rs = np.unique(tab["q_mult"]), np.unique(tab["r_mult"])
    interior = qs[0] < best["q_mult"] < qs[-1] and rs[0] < best["r_mult"] < rs[-1]
    assert interior or "edge" in fit.tuning_note_


def test_a_covariance_that_broke_down_is_no_success(kcs_truth, kcs_logs, monkeypatch):
    """A filter that runs to the end but whose smoothed parameter covariance is not finite and positive (seen
    with tune_noise and rk4-exact on replicate data) has no uncertainty to report: success False, named."""
    real = EKFIdentifier._smooth

    def broken(self, *a, **k):
        zs, var_x, Ps0 = real(self, *a, **k)
        nx = kcs_truth.nx
        Ps0[..., nx + 1, nx + 1] = -1e-9  # c3's variance negative: numerical breakdown
        return zs, var_x, Ps0

    monkeypatch.setattr(EKFIdentifier, "_smooth", broken)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fit = EKFIdentifier(kcs_truth, n_passes=1, estimate=["c2", "c3"]).fit([kcs_logs["kcs_zz_m10"][0]])
    assert fit.success_ is False
    assert "covariance of c3 is not finite and positive" in fit.message_


# ------------------------------------------------------------------ CLI exit status
def _write_csv(path, frame):
    lines = ["# shipid-log: {\"name\": \"%s\"}" % path.stem]
    path.write_text("\n".join(lines) + "\n" + schema_frame(frame).to_csv(index=False))
    return path


def test_cli_defect_fit_exits_3_with_one_warning_and_strict_json(tmp_path, capsys, kcs_logs):
    f = kcs_logs["kcs_zz_m10"][0].copy()
    f["delta"] = -f["delta"]
    p = _write_csv(tmp_path / "flipped.csv", f)
    out = tmp_path / "r.json"
    # the reader's own rudder-sign check refuses this file first (exit 2): switched off, the fit's verdict still
    # finds the flipped rudder (from the log's channels and from the coefficients' physical signs)
    rc = main(["fit", str(p), "--model", "kcs-response:synthetic-truth", "--passes", "1", "-o", str(out), "--no-progress",
               "--lpp", "4.36", "--no-consistency-checks"])
    cap = capsys.readouterr()
    assert rc == 3
    lines = [ln for ln in cap.err.splitlines() if ln.startswith("warning: defect")]
    assert len(lines) == 1 and "--rudder-sign -1" in lines[0] and len(lines[0]) <= 300, cap.err
    assert "verdict: defect" in cap.out
    text = out.read_text()
    assert "NaN" not in text and "Infinity" not in text
    doc = json.loads(text)
    assert doc["verdict"]["grade"] == "defect" and doc["verdict"]["reasons"]


def test_cli_diverged_fit_exits_4_and_refinement_from_it_fails(tmp_path, capsys, kcs_truth, kcs_logs):
    from shipid.identify.batch import OutputErrorRefiner

    noisy = kcs_logs["kcs_tc_p35"][0].iloc[:400]
    bad = kcs_truth.with_params({"c3": 500.0})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        ident = EKFIdentifier(bad, n_passes=1, init="model", estimate=["a1"], prior_std={"a1": 1e-6}).fit(noisy)
        assert not ident.success_ and not ident.diagnostics_["consistency"]["consistent"]
        ref = OutputErrorRefiner(ident.to_model(), estimate=["a1"], max_nfev=3).fit(noisy, start=ident)
    assert not ref.success_ and "diverged" in ref.message_ and ref.result().success is False
    assert ident.result().to_dict()["loglik"] == -np.inf
    path = ident.result().to_json(tmp_path / "d.json")
    assert json.loads(path.read_text())["loglik"] is None
    # the CLI: an absurd start that diverges
    p = _write_csv(tmp_path / "tc.csv", noisy)
    (tmp_path / "start.json").write_text(json.dumps({"model": "kcs-response", "coef": bad.params_series().to_dict()}))
    rc = main(["fit", str(p), "--model", str(tmp_path / "start.json"), "--estimate", "a1", "--passes", "1",
               "-o", str(tmp_path / "r.json"), "--no-progress", "--lpp", "4.36"])
    assert rc == 4


# ------------------------------------------------------------------ slow: false alarms, measured data
@pytest.mark.slow
def test_false_alarm_rate_on_clean_logs():
    """50 seeds of two clean bundled-recipe logs (tc_m25_rpm, zz_p20_rpm), default settings, one pass:
    the verdict flags at most 2 of them (rate measured for the docs: see the report)."""
    from shipid.models import get_model
    from shipid.synthetic import KCS_RECIPES, make_kcs_logs

    m = get_model("kcs-response", "synthetic-truth")
    rec = [r for r in KCS_RECIPES if r.name in ("kcs_tc_m25_rpm", "kcs_zz_p20_rpm")]
    flagged = []
    for seed in range(50):
        logs = make_kcs_logs(m, seed=1000 + seed, recipes=rec)
        fit = EKFIdentifier(m, n_passes=1).fit([a for a, _ in logs.values()])
        assert fit.success_
        if not fit.diagnostics_["consistency"]["consistent"]:
            flagged.append((seed, fit.diagnostics_["consistency"]["reasons"]))
    assert len(flagged) <= 2, flagged


ESSO = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "esso_osaka_frt"
ESSO_COLS = {"t [s]": "time", "x_position_mid [m]": "x", "y_position_mid [m]": "y", "psi_hat [rad]": "psi",
             "u_velo [m/s]": "u", "vm_velo [m/s]": "v", "r_angvelo [rad/s]": "r", "n_prop [rps]": "n",
             "delta_rudder [rad]": "delta"}


def _esso(path):
    """One Esso Osaka run read by hand (README column order; body-axis u, v; heading unwrapped; rudder
    + = starboard as in shipid: delta * r > 0 in every turn) until the esso-frt preset lands."""
    df = pd.read_csv(path).rename(columns=ESSO_COLS)[list(ESSO_COLS.values())]
    df = df.dropna(subset=["time"]).reset_index(drop=True)
    df["psi"] = np.unwrap(df["psi"].to_numpy())
    df.attrs["name"] = path.name
    return df


@pytest.mark.slow
def test_every_default_kcs_response_fit_on_the_esso_runs_converges():
    """Pre-filtered channels (second-difference noise u 1e-4 m/s, r 1.8e-5 rad/s), GNSS freezes, wind:
    default settings converge on every zigzag and berthing run and one turning and one random run
    (33 of 33 runs measured for the docs), and say they are not consistent (wind is missing physics)."""
    from shipid.models import get_model

    if not ESSO.is_dir():
        pytest.skip(f"Esso Osaka data not found at {ESSO}")
    paths = (sorted((ESSO / "zigzag").glob("*.csv")) + sorted((ESSO / "berthing").glob("*.csv"))
             + sorted((ESSO / "turning").glob("turn_cut_*.csv"))[:1] + sorted((ESSO / "random").glob("*.csv"))[:1])
    assert len(paths) == 14
    for p in paths:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            fit = EKFIdentifier(get_model("kcs-response"), n_passes=2).fit(_esso(p))
        assert fit.success_, (p.name, fit.message_)
        assert (fit.noise_["innovation_factor"] > 1.5).any(), p.name
        assert not fit.diagnostics_["consistency"]["consistent"]


@pytest.mark.slow
def test_held_out_style_log_with_a_continuously_moving_rudder_recovers_its_truth(kcs_truth):
    """A log unlike the bundled recipes: rudder a sum of sinusoids, rpm varying, integrated adaptively on
    a 0.01 s input grid and logged at 10 Hz with the bundled sensor noise.  First-order hold: every
    coefficient within 3 sigma; zero-order hold: the rudder coefficient c3 is not."""
    from shipid.simulate import simulate
    from shipid.synthetic import steady_surge_speed

    tf = np.arange(0.0, 150.0 + 1e-9, 0.01)
    ramp = np.clip((tf - 5.0) / 5.0, 0.0, 1.0)
    delta = ramp * np.radians(18.0 * np.sin(2 * np.pi * tf / 23.0) + 8.0 * np.sin(2 * np.pi * tf / 9.0))
    n = 10.0 + 2.0 * np.sin(2 * np.pi * tf / 70.0)
    x0 = np.zeros(kcs_truth.nx)
    x0[kcs_truth.state_index("u")] = steady_surge_speed(kcs_truth, 10.0)
    sim = simulate(kcs_truth, x0, tf, np.column_stack([delta, n]), method="dopri5", rtol=1e-10, atol=1e-12,
                   input_hold="foh")
    k = np.arange(0, tf.size, 10)
    rng = np.random.default_rng(21)
    frame = pd.DataFrame({"time": tf[k], "delta": delta[k], "n": n[k]})
    for j, ch in enumerate(kcs_truth.state_names):
        frame[ch] = sim.x[k, j] + rng.normal(0.0, KCS_NOISE_STD[ch], k.size)
    truth = kcs_truth.params_series()
    z = {}
    for hold in ("foh", "zoh"):
        fit = EKFIdentifier(kcs_truth, n_passes=2, input_hold=hold).fit(frame)
        assert fit.success_
        z[hold] = ((fit.coef_ - truth) / fit.coef_std_)[fit.estimated_]
    assert np.all(np.abs(z["foh"]) < 3), z["foh"][np.abs(z["foh"]) >= 3]
    assert abs(z["zoh"]["c3"]) > 3, z["zoh"]
