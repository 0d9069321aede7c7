"""Replicate study of interval coverage (shipid.identify.coverage)."""
from __future__ import annotations

import numpy as np
import pytest

from shipid.identify.coverage import coverage_study, wilson_interval


def test_wilson_interval_known_values():
    lo, hi = wilson_interval(95, 100)
    assert lo == pytest.approx(0.8883, abs=1e-4) and hi == pytest.approx(0.9785, abs=1e-4)
    assert wilson_interval(0, 10)[0] == pytest.approx(0.0, abs=1e-12)


def test_small_study_is_reproducible_and_counts():
    kw = dict(n_replicates=3, draws=0, seed=4, estimate=["c1", "c2", "c3"], n_passes=1)
    a, b = coverage_study(**kw), coverage_study(**kw)
    assert a.table.equals(b.table)  # same seed, same numbers
    t = a.table.set_index("quantity")
    assert list(t.index) == ["c1", "c2", "c3"] and (t["n"] == 3).all()
    z = np.array([[(c - tv) / s for c, s, tv in zip(r["coef"], r["std"], (-0.2, -0.8, 0.2))] for r in a.replicates])
    np.testing.assert_allclose(t["covered"].to_numpy(), (np.abs(z) <= 1.959964).sum(axis=0))
    with pytest.raises(ValueError, match="n_replicates must be >= 2"):
        coverage_study(n_replicates=1)
    with pytest.raises(ValueError, match="refine must be None or 'output-error'"):
        coverage_study(n_replicates=2, refine="mcmc")


def test_output_error_refinement_column():
    """refine="output-error": the same data sets (same seeds) refitted by output-error ML; its z-scores are its own."""
    kw = dict(n_replicates=2, draws=0, seed=4, estimate=["c1", "c2", "c3"], n_passes=1)
    e, o = coverage_study(**kw), coverage_study(refine="output-error", **kw)
    assert set(o.table["method"]) == {"output-error"} and o.settings["refine"] == "output-error"
    assert [r["seed"] for r in e.replicates] == [r["seed"] for r in o.replicates]
    ce, co = np.array([r["coef"] for r in e.replicates]), np.array([r["coef"] for r in o.replicates])
    assert not np.allclose(ce, co, rtol=1e-9, atol=0)  # a different estimator ...
    np.testing.assert_allclose(ce, co, rtol=0.2)  # ... of the same coefficients


@pytest.mark.slow
def test_coverage_of_100_replicates():
    """100 synthetic data sets (two 40 s manoeuvres each, independent noise; about 5 CPU-minutes): the fraction
    of 95 % intervals containing the truth.  The intervals must not be over-confident anywhere (coverage >= 0.90,
    spread of the standardised errors <= 1.1) nor grossly biased (|mean z| <= 0.6).  Measured (docs/uncertainty.md):
    coverage 0.97-1.00, z spread 0.43-0.76 (conservative: the default process noise), yaw offsets up to 0.52."""
    r = coverage_study(n_replicates=100, draws=40, seed=2026)
    t = r.table.set_index("quantity")
    assert r.n_failed == 0 and (t["n"] == 100).all()
    assert (t["coverage"] >= 0.90).all(), t["coverage"].to_dict()
    coef = t[t["z_std"].notna()]
    assert len(coef) == 16
    assert (coef["z_std"] <= 1.1).all() and (coef["z_mean"].abs() <= 0.6).all(), coef[["z_mean", "z_std"]].to_dict()
    assert {"turning_35_starboard:tactical_diameter_L", "zigzag_10_10_starboard:overshoot1_deg"} <= set(t.index)
