"""The EKF covariance re-evaluated with the filter's own gains under other process noise
(shipid.identify.ekf.gain_covariance, EKFIdentifier.sensor_noise_cov, coverage_study(refine="ekf-sensor-noise"))."""
from __future__ import annotations

import warnings

import numpy as np
import pytest

from shipid.identify import EKFIdentifier
from studies.coverage import COVERAGE_RECIPES, coverage_study
from shipid.identify.ekf import gain_covariance, run_ekf
from shipid.synthetic import make_trial


@pytest.fixture(scope="module")
def two_log_fit(kcs_truth):
    rng = np.random.default_rng(11)
    logs = [make_trial(kcs_truth, r, rng)[0] for r in COVERAGE_RECIPES]
    start = kcs_truth.with_params(kcs_truth.params * (1 + 0.3 * rng.standard_normal(kcs_truth.np)))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        return EKFIdentifier(start, estimate=["b1", "b2", "c1", "c2", "c3"], n_passes=2).fit(logs)


def test_own_process_noise_reproduces_the_filter_covariance(two_log_fit):
    """With the filter's own q the recursion (Joseph form, the filter's gains) is the filter's covariance: the last
    posterior P of the run (two logs, so one reset) to 1e-8 relative.  Without process noise the coefficients'
    variances are smaller (the filter assumed state noise the data do not have), and positive."""
    ident = two_log_fit
    prob = ident.problem_
    out = run_ekf(prob, store=True, compact=False, store_dtype="float64")
    assert prob.reset.any()
    own = gain_covariance(prob, out, q=prob.q)[0]
    P = out.P_post[0, -1]
    np.testing.assert_allclose(own, P, rtol=1e-8, atol=1e-12 * np.abs(P).max())
    nx = prob.model.nx
    none = gain_covariance(prob, out)[0]
    d0, d1 = np.diag(none)[nx:], np.diag(P)[nx:]
    assert np.all(d0 > 0) and np.all(d0 < d1)
    C = ident.sensor_noise_cov()
    sc = ident.scale_.to_numpy()
    np.testing.assert_allclose(C.to_numpy(), none[nx:, nx:] * np.outer(sc, sc), rtol=1e-12)
    assert list(C.index) == ident.estimated_
    with pytest.raises(ValueError, match="store=True, compact=False"):
        gain_covariance(prob, run_ekf(prob, store=True, compact=True))


def test_sensor_noise_column_machinery():
    """refine="ekf-sensor-noise": the EKF's estimates, with narrower intervals than its own posterior."""
    kw = dict(n_replicates=3, draws=0, seed=2026, estimate=["c1", "c2", "c3"])
    e, s = coverage_study(**kw), coverage_study(refine="ekf-sensor-noise", **kw)
    assert set(s.table["method"]) == {"ekf-sensor-noise"}
    for a, b in zip(e.replicates, s.replicates):
        np.testing.assert_array_equal(a["coef"], b["coef"])
        assert np.all(np.array(b["std"]) < np.array(a["std"]))


@pytest.mark.slow
def test_sensor_noise_covariance_covers_and_is_never_over_confident_on_100_replicates():
    """100 replicates (seed 2026, all 16 coefficients, about 30 CPU-seconds): the covariance re-evaluated under
    sensor noise only covers 0.89-1.00 for every coefficient, each inside the binomial spread of 100 replicates of
    a calibrated 95 % interval. Its sway and yaw intervals have the size of the scatter (z spread 0.98-1.12);
    the surge ones (a1-a9) are conservative, 1.4-1.6x wider than the scatter (z spread 0.63-0.70), never
    narrower (python -m studies.diag_ekf_actual_covariance)."""
    r = coverage_study(n_replicates=100, draws=0, seed=2026, refine="ekf-sensor-noise")
    t = r.table.set_index("quantity")
    assert r.n_failed == 0 and len(t) == 16
    # calibrated within sampling error: each coverage of 100 replicates inside the binomial band of a 95 % interval
    # at a family-wise 1 % over the 16 coefficients
    from scipy.stats import binom
    lo, hi = binom.ppf([0.005 / 16, 1 - 0.005 / 16], 100, 0.95) / 100
    assert t["coverage"].between(lo, hi).all(), (lo, hi, t)
    sway_yaw = [q for q in t.index if q[0] in "bc"]
    surge = [q for q in t.index if q[0] == "a"]
    assert t.loc[sway_yaw, "z_std"].between(0.85, 1.2).all(), t
    assert t.loc[surge, "z_std"].between(0.5, 0.85).all(), t  # conservative, not over-confident
