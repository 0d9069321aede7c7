"""The augmented-state EKF identifier: accuracy against synthetic truth, equivalence with
filterpy, the RTS smoother against filterpy's linear smoother, diagnostics, results."""
from __future__ import annotations

import contextlib
import json
from dataclasses import replace

import numpy as np
import pandas as pd
import pytest

from shipid import _jit
from shipid.identify import EKFIdentifier, NotFittedError, load_result, rts_smooth, run_ekf
from shipid.identify.ekf import bf_smooth
from shipid.integrate import rk4_step_taylor_tangent
from shipid.models.base import Model
from shipid.simulate import replay, replay_errors
from shipid.synthetic import KCS_NOISE_STD, TrialRecipe, make_trial


# --------------------------------------------------------------- accuracy
def test_every_coefficient_within_3_sigma_and_well_determined_within_2_percent(kcs_fit, kcs_truth):
    fit = kcs_fit
    assert fit.success_, fit.message_
    truth = kcs_truth.params_series()
    z = (fit.coef_ - truth) / fit.coef_std_
    assert np.all(np.abs(z) < 3.0), f"outside 3 sigma:\n{z[np.abs(z) >= 3]}"
    rel_std = fit.coef_std_ / truth.abs()
    well = rel_std[rel_std < 0.02 / 3].index  # 3 sigma below 2 %
    assert {"c2", "c3"} <= set(well), rel_std.sort_values()
    rel_err = ((fit.coef_ - truth) / truth).abs()[well]
    assert np.all(rel_err < 0.02), rel_err
    # the filter is consistent: mean normalised innovation squared ~ number of channels
    d = fit.diagnostics_
    assert 0.8 * d["nis_expected"] < d["nis_mean"] < 1.25 * d["nis_expected"]


def test_replayed_states_match_the_log_within_noise(kcs_fit, kcs_logs):
    model = kcs_fit.to_model()
    for name, (noisy, truth) in kcs_logs.items():
        sim = replay(model, noisy)
        err = replay_errors(sim, truth)  # against the noise-free truth
        err_noisy = replay_errors(sim, noisy)
        for ch in ("u", "v", "r"):
            # prediction error smaller than the sensor noise, and the residual against the
            # noisy log is the noise itself (within 25 %)
            assert err.loc[ch, "rmse"] < KCS_NOISE_STD[ch], (name, ch, err.loc[ch, "rmse"])
            assert err_noisy.loc[ch, "rmse"] < 1.25 * np.hypot(KCS_NOISE_STD[ch], err.loc[ch, "rmse"])


def test_smoothed_states_are_closer_to_truth_than_measurements(kcs_fit, kcs_logs):
    for states, (noisy, truth) in zip(kcs_fit.states_, kcs_logs.values()):
        for ch in ("u", "r"):
            e_s = np.sqrt(np.mean((states[ch] - truth[ch]) ** 2))
            e_m = np.sqrt(np.mean((noisy[ch] - truth[ch]) ** 2))
            assert e_s < 0.6 * e_m, (ch, e_s, e_m)


def test_constant_rpm_warns_about_a1_a8_a9_and_completes(kcs_truth):
    recipes = [TrialRecipe("tc", "turning", 30.0, 60.0, ((0.0, 10.0),)),
               TrialRecipe("zz", "zigzag", 20.0, 60.0, ((0.0, 10.0),), psi_deg=20.0)]
    rng = np.random.default_rng(11)
    logs = [make_trial(kcs_truth, r, rng)[0] for r in recipes]
    fit = EKFIdentifier(kcs_truth, n_passes=1).fit(logs)
    assert fit.success_
    text = " ".join(fit.diagnostics_["warnings"])
    assert "a1, a8, a9 cannot be separated" in text and "n = 10 rps" in text
    assert np.all(np.isfinite(fit.coef_))
    # the EKF's own information analysis also flags a combination of a1 and a8
    combos = " ".join(c["combination"] for c in fit.diagnostics_["unidentified_combinations"])
    assert "a1" in combos and "a8" in combos


def test_missing_measurements_are_predicted_through(kcs_truth, kcs_logs):
    noisy, truth = kcs_logs["kcs_zz_p20_rpm"]
    gappy = noisy.copy()
    gappy.loc[300:340, ["u", "v", "r"]] = np.nan  # a 4 s dropout of the speed/rate sensors
    gappy.loc[::7, "psi"] = np.nan
    fit = EKFIdentifier(kcs_truth, n_passes=1, estimate=["c1", "c2", "c3"]).fit(gappy)
    assert fit.success_
    st = fit.states_[0]
    err = np.abs(st.loc[300:340, "r"] - truth.loc[300:340, "r"])
    assert err.max() < 5 * KCS_NOISE_STD["r"]
    assert np.isnan(fit.innovations_[0].loc[320, "r"])


# ----------------------------------------------------- filterpy equivalence
def test_same_filtered_states_and_covariances_as_filterpy(kcs_truth, kcs_logs):
    from filterpy.kalman import ExtendedKalmanFilter

    noisy = kcs_logs["kcs_zz_m10"][0].iloc[:150].copy()
    noisy.loc[40:45, ["x", "y", "psi", "u", "v", "r"]] = np.nan  # whole-sample gaps: filterpy update(None)
    ident = EKFIdentifier(kcs_truth, n_passes=1, init="model", estimate=["b1", "c2", "c3", "a9"], gate=None)
    ident.fit(noisy)
    prob = ident.problem_
    out = run_ekf(prob)  # the full storage (the identifier keeps the compact one its smoother reads)
    model = kcs_truth
    nx, ne, nm = model.nx, len(prob.est_idx), len(prob.meas_idx)
    nz = nx + ne

    class EKF(ExtendedKalmanFilter):
        def predict_x(self, u=0):
            self.x = self._next.copy()

    ekf = EKF(dim_x=nz, dim_z=nm)
    ekf.x = prob.z0[0][:, None].copy()
    ekf.P = prob.P0[0].copy()
    ekf.R = np.diag(prob.R[0])
    H = np.zeros((nm, nz))
    H[np.arange(nm), prob.meas_idx] = 1.0
    t, U, Y = prob.t[0], prob.U[0], prob.Y[0]
    worst = 0.0
    for k in range(t.size):
        y = Y[k]
        ekf.update(None if np.all(np.isnan(y)) else y[:, None], lambda x: H, lambda x: H @ x)
        for a, b in ((ekf.x[:, 0], out.z_post[0, k]), (ekf.P, out.P_post[0, k])):
            worst = max(worst, np.max(np.abs(a - b) / (1e-12 + np.abs(b).max())))
        if k == t.size - 1:
            break
        z = ekf.x[:, 0]
        p = prob.p_base[0].copy()
        p[prob.est_idx] = z[nx:] * prob.scale
        xn, Fx, Fp = rk4_step_taylor_tangent(model, t[k], z[:nx], U[k], p, t[k + 1] - t[k], U[k + 1])  # foh
        F = np.eye(nz)
        F[:nx, :nx] = Fx
        F[:nx, nx:] = Fp[:, prob.est_idx] * prob.scale
        ekf.F = F
        ekf.Q = np.diag(prob.q[0] * (t[k + 1] - t[k]))
        ekf._next = np.concatenate([xn, z[nx:]])[:, None]
        ekf.predict()
        for a, b in ((ekf.x_prior[:, 0], out.z_prior[0, k + 1]), (ekf.P_prior, out.P_prior[0, k + 1])):
            worst = max(worst, np.max(np.abs(a - b) / (1e-12 + np.abs(b).max())))
    assert worst < 1e-9, worst


# ------------------------------------------------------------ RTS smoother
class _LinearTestModel(Model):
    """x' = A x + [0, theta]: linear in the augmented state, so EKF == KF."""

    name = "linear-test"
    state_names = ("p", "q")
    input_names = ("w",)
    param_names = ("theta",)

    A = np.array([[0.0, 1.0], [-0.5, -0.3]])

    def _rhs(self, t, x, u, p):
        out = x @ self.A.T
        out[..., 1] = out[..., 1] + p[..., 0] + 0.0 * u[..., 0]
        return out

    def _default_params(self):
        return np.array([0.2])


def test_rts_smoother_matches_filterpy_linear_smoother():
    from filterpy.kalman import KalmanFilter

    m = _LinearTestModel()
    rng = np.random.default_rng(5)
    h = 0.1
    t = np.arange(0, 20, h)
    x = np.zeros((t.size, 2))
    x[0] = [1.0, 0.0]
    for k in range(t.size - 1):
        x[k + 1] = x[k] + h * m.rhs(0, x[k], [0.0])
    y = x + rng.normal(0, 0.05, size=x.shape)
    frame = pd.DataFrame({"time": t, "p": y[:, 0], "q": y[:, 1], "w": 0.0})
    ident = EKFIdentifier(m, n_passes=1, init="model", method="rk4-exact", prior={"theta": 0.1},
                          meas_std={"p": 0.05, "q": 0.05}, process_std={"p": 1e-3, "q": 1e-3})
    ident.fit(frame)
    prob = ident.problem_
    out = run_ekf(prob)  # the full storage (the identifier keeps the compact one its smoother reads)
    zs, Ps = rts_smooth(out)

    # the same problem as a linear KF: the RK4 map of the augmented linear system
    Aa = np.zeros((3, 3))
    Aa[:2, :2] = m.A
    Aa[1, 2] = prob.scale[0]
    hA = h * Aa
    Phi = np.eye(3) + hA + hA @ hA / 2 + hA @ hA @ hA / 6 + hA @ hA @ hA @ hA / 24
    kf = KalmanFilter(dim_x=3, dim_z=2)
    kf.x = prob.z0[0][:, None].copy()
    kf.P = prob.P0[0].copy()
    kf.F = Phi
    kf.H = np.array([[1.0, 0, 0], [0, 1.0, 0]])
    kf.R = np.diag(prob.R[0])
    kf.Q = np.diag(prob.q[0] * h)
    # filterpy's batch_filter predicts before each update; ours updates sample 0 first,
    # so feed filterpy the first update by hand and smooth the rest
    kf.update(y[0][:, None])
    x0, P0 = kf.x.copy(), kf.P.copy()  # filterpy's own first posterior
    means, covs, _, _ = kf.batch_filter([yy[:, None] for yy in y[1:]])
    means = np.concatenate([x0[None], means])
    covs = np.concatenate([P0[None], covs])
    np.testing.assert_allclose(means[:, :, 0], out.z_post[0], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(covs, out.P_post[0], rtol=1e-9, atol=1e-14)
    xs, Pss, _, _ = kf.rts_smoother(means, covs)
    np.testing.assert_allclose(xs[:, :, 0], zs[0], rtol=1e-8, atol=1e-10)
    np.testing.assert_allclose(Pss, Ps[0], rtol=1e-8, atol=1e-12)
    # the adjoint (Bryson-Frazier) form the identifier uses: the same smoothed means, state variances, and
    # the whole covariance at sample 0 (both paths)
    for compiled in (True, False):
        with (contextlib.nullcontext() if compiled else _jit.disabled()):
            zb, var_x, Ps0 = bf_smooth(out, prob.R, prob.meas_idx, 2)
        np.testing.assert_allclose(zb[0], xs[:, :, 0], rtol=1e-8, atol=1e-10)
        np.testing.assert_allclose(var_x[0], np.diagonal(Pss[:, :2, :2], axis1=1, axis2=2), rtol=1e-8, atol=1e-12)
        np.testing.assert_allclose(Ps0[0], Pss[0], rtol=1e-8, atol=1e-12)


def _stacked(prob, B, **override):
    """The same EKF problem repeated B times along the batch axis (fields in override replace the result)."""
    rep = lambda a: np.repeat(a, B, axis=0)  # noqa: E731
    fields = dict(p_base=rep(prob.p_base), t=rep(prob.t), U=rep(prob.U), Y=rep(prob.Y), R=rep(prob.R), q=rep(prob.q),
                  z0=rep(prob.z0), P0=rep(prob.P0), reset=rep(prob.reset), x_reset=rep(prob.x_reset),
                  P_reset=rep(prob.P_reset))
    fields.update(override)
    return replace(prob, **fields)


def test_one_member_and_batch_paths_agree(kcs_truth, kcs_logs):
    """A single log takes LAPACK's Cholesky directly, a batch numpy's stacked solvers: same numbers."""
    noisy = kcs_logs["kcs_zz_p20_rpm"][0].iloc[:200].copy()
    noisy.loc[50:60, ["u", "v"]] = np.nan  # partial gaps: the masked update
    noisy.loc[90:92, ["x", "y", "psi", "u", "v", "r"]] = np.nan  # whole-sample gaps
    ident = EKFIdentifier(kcs_truth, n_passes=1, init="model", estimate=["b1", "b3", "c2", "c3"])
    ident.fit(noisy)
    one = run_ekf(ident.problem_, store=True)
    two = run_ekf(_stacked(ident.problem_, 2), store=True)
    for name in ("z_post", "P_post", "z_prior", "P_prior", "innov", "S_diag", "nis", "loglik"):
        a, b = getattr(one, name)[0], getattr(two, name)
        np.testing.assert_allclose(b[0], a, rtol=1e-10, atol=1e-14, err_msg=name)
        np.testing.assert_allclose(b[1], a, rtol=1e-10, atol=1e-14, err_msg=name)
    assert np.isfinite(one.loglik[0]) and np.isnan(one.innov[0, 55, 3]) and np.isfinite(one.innov[0, 55, 5])
    zs1, Ps1 = rts_smooth(one)
    zs2, Ps2 = rts_smooth(two)
    np.testing.assert_allclose(zs2[1], zs1[0], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(Ps2[1], Ps1[0], rtol=1e-9, atol=1e-14)


def test_a_diverging_batch_member_does_not_stop_the_others(kcs_truth, kcs_logs):
    noisy = kcs_logs["kcs_tc_p35"][0].iloc[:300]
    ident = EKFIdentifier(kcs_truth, n_passes=1, init="model", estimate=["c3"])
    ident.fit(noisy)
    prob = ident.problem_
    good = run_ekf(replace(prob, gate=None), store=False)
    Y = np.repeat(prob.Y, 3, axis=0)
    Y[1, 150:, 5] += 50.0  # member 1: an absurd yaw-rate jump at sample 150
    out = run_ekf(replace(_stacked(prob, 3, Y=Y), gate=None), store=False)  # ungated: the jump is taken
    assert list(out.diverged) == [False, True, False]
    assert out.diverged_at[1] == 150 and "diverged at sample 150" in out.message[1]
    assert np.all(np.isfinite(out.z_final)) and np.all(np.isfinite(out.P_final))
    for b in (0, 2):
        np.testing.assert_allclose(out.z_final[b], good.z_final[0], rtol=1e-10, atol=1e-14)
        assert out.loglik[b] == pytest.approx(good.loglik[0], rel=1e-10)


# ---------------------------------------------------------- robustness
def test_divergence_is_detected_and_reported_not_nan(kcs_truth, kcs_logs):
    noisy = kcs_logs["kcs_tc_p35"][0].iloc[:400]
    bad = kcs_truth.with_params({"c3": 500.0})  # absurd rudder yaw moment: innovations explode
    ident = EKFIdentifier(bad, n_passes=1, init="model", estimate=["a1"], prior_std={"a1": 1e-6})
    with pytest.warns(RuntimeWarning, match="diverged"):
        ident.fit(noisy)
    assert not ident.success_ and "diverged at sample" in ident.message_ and "smoother skipped" in ident.message_
    assert np.all(np.isfinite(ident.coef_)) and np.all(np.isfinite(ident.cov_.to_numpy()))
    # the filter stopped at the divergence sample: states up to it, nothing (NaN) after
    kd = int(ident.output_.diverged_at[0])
    st = ident.states_[0][["u", "v", "r"]].to_numpy()
    assert 0 < kd < len(st) and np.all(np.isfinite(st[:kd])) and np.all(np.isnan(st[kd:]))
    assert np.all(np.isnan(ident.output_.innov[0, kd + 1:])) and ident.output_.loglik[0] == -np.inf


def test_covariance_stays_symmetric_positive_definite(kcs_fit):
    # the fit keeps only the ship rows of the filtered covariance (compact="ship"): the whole matrices of its problem
    P = run_ekf(kcs_fit.problem_, store=True).P_post[0]
    assert np.allclose(P, P.transpose(0, 2, 1), atol=0)
    assert np.all(np.linalg.eigvalsh(P[::50]) > 0)


def test_scaling_handles_coefficients_of_very_different_size(kcs_truth, kcs_logs):
    noisy = kcs_logs["kcs_tc_m25_rpm"][0]
    ident = EKFIdentifier(kcs_truth, n_passes=1, estimate=["a9", "b4", "c3"]).fit(noisy)
    # a9 ~ 1e-3 and b4 ~ 0.85: both come back to within 3 sigma and to < 1 %
    for k in ("a9", "b4", "c3"):
        assert abs(ident.coef_[k] - kcs_truth.params_series()[k]) < 3 * ident.coef_std_[k]
        assert ident.coef_std_[k] / abs(ident.coef_[k]) < 0.01
    assert ident.scale_["a9"] < 1e-2 < ident.scale_["b4"]


def test_fixed_parameters_and_priors(kcs_truth, kcs_logs):
    noisy = kcs_logs["kcs_zz_m10"][0]
    ident = EKFIdentifier(kcs_truth, n_passes=1, fixed={"a8": -0.002, "a9": 1.19e-3},
                          estimate=["a1", "a8", "a9", "c2", "c3"]).fit(noisy)
    assert ident.estimated_ == ["a1", "c2", "c3"]
    assert ident.coef_["a8"] == -0.002 and ident.coef_std_["a8"] == 0.0
    with pytest.raises(ValueError, match="unknown parameter"):
        EKFIdentifier(kcs_truth, fixed=["zz"]).fit(noisy)
    with pytest.raises(ValueError, match="nothing to estimate"):
        EKFIdentifier(kcs_truth, fixed=list(kcs_truth.param_names)).fit(noisy)
    with pytest.raises(NotFittedError, match="not fitted"):
        EKFIdentifier(kcs_truth).summary()


def test_noise_tuning_by_likelihood(kcs_truth, kcs_logs):
    noisy = kcs_logs["kcs_zz_p20_rpm"][0].iloc[:500]
    ident = EKFIdentifier(kcs_truth, n_passes=1, tune_noise=True, estimate=["c2", "c3"]).fit(noisy)
    tab = ident.tuning_
    assert len(tab) == 18 and ident.loglik_ >= tab["loglik"].max() - 1e-6 * abs(tab["loglik"].max())
    best = tab.loc[tab["loglik"].idxmax()]
    # the data have no process noise: the likelihood prefers small process noise
    assert best["q_mult"] <= 1.0


# ------------------------------------------------------------------ results
def test_json_round_trip_and_no_silent_overwrite(kcs_fit, tmp_path):
    res = kcs_fit.result()
    path = tmp_path / "result.json"
    res.to_json(path)
    doc = json.loads(path.read_text())
    for key in ("model", "coef", "coef_std", "cov", "diagnostics", "inputs", "versions"):
        assert key in doc
    assert doc["versions"]["filterpy"].startswith("2.")
    back = load_result(path)
    assert back.coef == res.coef and back.model == "kcs-response"
    np.testing.assert_allclose(back.cov.to_numpy(), kcs_fit.cov_.to_numpy())
    np.testing.assert_allclose(back.to_model().params, kcs_fit.coef_.to_numpy())
    before = path.read_bytes()
    with pytest.raises(ValueError, match="--force"):
        res.to_json(path)
    assert path.read_bytes() == before
    res.to_json(path, force=True)


def test_load_result_errors(tmp_path):
    with pytest.raises(FileNotFoundError, match="no such result"):
        load_result(tmp_path / "nope.json")
    p = tmp_path / "bad.json"
    p.write_text("{not json")
    with pytest.raises(ValueError, match="not a JSON fit result"):
        load_result(p)
    p.write_text('{"coef": {}}')
    with pytest.raises(ValueError, match="no 'model' entry"):
        load_result(p)


def test_output_error_refinement_from_the_ekf(kcs_truth, kcs_logs):
    from shipid.identify.batch import OutputErrorRefiner

    noisy = kcs_logs["kcs_zz_p20_rpm"][0]
    est = ["b1", "b3", "c1", "c2", "c3"]
    start = kcs_truth.with_params({k: kcs_truth.params_series()[k] * 1.1 for k in est})
    ekf = EKFIdentifier(start, n_passes=1, init="model", estimate=est, prior_std=0.3).fit(noisy)
    ref = OutputErrorRefiner(ekf.to_model(), estimate=est).fit(noisy, start=ekf)
    assert ref.success_ and ref.channels_ == ["v", "r"]  # the channels whose equations hold b*, c*
    assert ref.cost_ <= ref.cost_start_
    truth = kcs_truth.params_series()[est]
    z = (ref.coef_[est] - truth) / ref.coef_std_[est]
    assert np.all(np.abs(z) < 3), z
    # the refined model predicts as well as the noise allows
    assert 0.9 < ref.rms_normalised_residual_ < 1.2
    res = ref.result()
    assert res.method == "output-error" and res.diagnostics["correlation"]["names"] == est


def test_model_options_travel_with_the_result(tmp_path):
    """An MMG fit at full scale comes back with its particulars (not the default model scale)."""
    from shipid.identify import FitResult, model_from
    from shipid.models import get_model

    full = get_model("mmg", "kvlcc2", lpp=320.0)
    res = FitResult(model="mmg", coef=full.params_series().to_dict(), coef_std={}, cov=pd.DataFrame(),
                    model_options=full.options())
    res.to_json(tmp_path / "r.json")
    back, loaded = model_from(tmp_path / "r.json")
    assert back.lpp == 320.0 and loaded.model_options["particulars"]["lpp"] == 320.0
    assert model_from("mmg:kcs")[0].lpp == pytest.approx(4.36)
    with pytest.raises(ValueError, match="expected 'glider'"):
        model_from(tmp_path / "r.json", model="glider")
    with pytest.raises(ValueError, match="neither a result file nor a registered model"):
        model_from("nope:set")


# ------------------------------------------------------ kernel contract: holds, gaps, gates
def test_interval_steps_cross_a_gap_in_many_steps_and_keep_ordinary_intervals():
    from shipid.identify.ekf import interval_steps

    t = np.array([0.0, 0.1, 0.2, 20.2, 20.3, 20.45])
    assert interval_steps(t, 2, None).tolist() == [2, 2, 2, 2, 2]
    assert interval_steps(t, 2, 0.075).tolist() == [2, 2, 267, 2, 2]
    assert interval_steps(t, 1, 0.15).tolist() == [1, 1, 134, 1, 1]  # 0.15 s exactly: one step (to rounding)
    with pytest.raises(ValueError, match="h_max"):
        interval_steps(t, 1, 0.0)


@pytest.mark.parametrize("hold", ["foh", "zoh"])
def test_prediction_is_the_documented_rk4_map_over_gaps_and_sub_steps(kcs_truth, kcs_logs, hold):
    """No measurements: the priors are the RK4 map, n_k = max(substeps, ceil(dt/h_max)) steps per interval,
    inputs linear between samples (foh) or held (zoh), stage by stage."""
    from shipid.integrate import rk4_step

    noisy = kcs_logs["kcs_zz_p20_rpm"][0].iloc[::1].iloc[:120].copy()
    noisy = noisy.drop(index=range(60, 100))  # a 4 s gap
    ident = EKFIdentifier(kcs_truth, n_passes=1, init="model", estimate=["c3"], input_hold=hold, substeps=2,
                          max_gap=None).fit(noisy)  # the gap is integrated across
    prob = replace(ident.problem_, Y=np.full_like(ident.problem_.Y, np.nan))
    assert prob.h_max == pytest.approx(0.075)
    out = run_ekf(prob, store=True)
    t, U = prob.t[0], prob.U[0]
    x = prob.z0[0, :kcs_truth.nx].copy()
    p = kcs_truth.params
    worst = 0.0
    for k in range(t.size - 1):
        n = max(2, int(np.ceil((t[k + 1] - t[k]) / 0.075 - 1e-9)))
        h = (t[k + 1] - t[k]) / n
        for i in range(n):
            w0, w1 = i / n, (i + 1) / n
            ua = (1 - w0) * U[k] + w0 * U[k + 1] if hold == "foh" else U[k]
            ub = (1 - w1) * U[k] + w1 * U[k + 1] if hold == "foh" else None
            x = rk4_step(kcs_truth, t[k] + i * h, x, ua, p, h, ub)
        worst = max(worst, np.max(np.abs(x - out.z_prior[0, k + 1, :kcs_truth.nx])))
    assert worst < 1e-10, worst


def test_a_glitch_is_gated_and_counted_and_does_not_move_the_estimate(kcs_truth, kcs_logs):
    noisy = kcs_logs["kcs_tc_p35"][0].iloc[:400]
    ident = EKFIdentifier(kcs_truth, n_passes=1, init="model", estimate=["c2", "c3"], gate=5.0).fit(noisy)
    prob = ident.problem_
    ir = list(prob.meas_idx).index(kcs_truth.state_index("r"))
    Y = prob.Y.copy()
    Y[0, 200, ir] += 50 * KCS_NOISE_STD["r"]  # one 50-sigma yaw-rate glitch
    clean = run_ekf(prob, store=False)
    hit = run_ekf(replace(prob, Y=Y), store=False)
    ungated = run_ekf(replace(prob, Y=Y, gate=None), store=False)
    assert clean.n_gated.sum() == 0
    assert hit.n_gated[0].tolist() == [int(j == ir) for j in range(len(prob.meas_idx))]
    assert hit.gated[0, 200, ir] and hit.innov[0, 200, ir] > 40 * KCS_NOISE_STD["r"]
    assert np.isfinite(hit.S_diag[0, 200, ir]) and np.isfinite(hit.innov[0, 200]).all()
    np.testing.assert_allclose(hit.z_final, clean.z_final, rtol=1e-3, atol=1e-6)
    assert np.max(np.abs(ungated.z_final - clean.z_final)) > 10 * np.max(np.abs(hit.z_final - clean.z_final))
    # the likelihood leaves the rejected measurement out
    assert hit.loglik[0] == pytest.approx(clean.loglik[0], rel=1e-3)


def test_a_persistent_jump_is_accepted_after_gate_run_rejections(kcs_truth, kcs_logs):
    noisy = kcs_logs["kcs_tc_p35"][0].iloc[:300]
    ident = EKFIdentifier(kcs_truth, n_passes=1, init="model", estimate=["c3"], gate=5.0, gate_run=4).fit(noisy)
    prob = ident.problem_
    ix = list(prob.meas_idx).index(kcs_truth.state_index("x"))
    Y = prob.Y.copy()
    Y[0, 150:, ix] += 3.0  # the position jumps by 3 m and stays (150 sigma)
    out = run_ekf(replace(prob, Y=Y), store=False)
    g = out.gated[0, :, ix]
    assert g[150:154].all() and not g[154]  # four rejections, then accepted
    assert not g[:150].any() and not out.diverged[0]


def test_the_noise_check_pass_is_the_first_pass_and_is_not_run_twice(kcs_truth, kcs_logs, monkeypatch):
    """The noise adaptation's first filter pass solves pass 1's problem; when it raises no channel's noise it is
    pass 1 (one filter run for a one-pass fit), and the fit equals the one without the adaptation."""
    import shipid.identify.identifier as ident_mod

    calls = []
    real = ident_mod.run_ekf
    monkeypatch.setattr(ident_mod, "run_ekf", lambda prob, **k: calls.append(k) or real(prob, **k))
    log = kcs_logs["kcs_zz_m10"][0]
    fit = EKFIdentifier(kcs_truth, n_passes=1, init="model").fit(log)
    assert (fit.noise_["innovation_factor"] == 1.0).all()
    assert calls == [{"store": True, "compact": "ship"}]  # the ship rows of P_post: param_walk=0
    ref = EKFIdentifier(kcs_truth, n_passes=1, init="model", adapt_noise=False).fit(log)
    np.testing.assert_array_equal(fit.coef_.to_numpy(), ref.coef_.to_numpy())
    np.testing.assert_array_equal(fit.coef_std_.to_numpy(), ref.coef_std_.to_numpy())
