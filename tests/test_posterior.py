"""MCMC posterior sampling (shipid.uncertainty.posterior): split-R-hat, convergence verdicts, accuracy against
an exact grid posterior."""
from __future__ import annotations

import json
import sys
import warnings

import numpy as np
import pytest

from shipid.uncertainty.posterior import OutputErrorLikelihood, sample_posterior, split_rhat

pytest.importorskip("emcee")


def test_split_rhat_iid_and_shifted_chains():
    rng = np.random.default_rng(0)
    iid = rng.standard_normal((8, 1000, 2))
    assert np.all(split_rhat(iid) < 1.01)
    assert np.all(split_rhat(iid, rank_normalised=False) < 1.01)
    shifted = iid + np.arange(8)[:, None, None] * 0.5  # chains that disagree
    assert np.all(split_rhat(shifted) > 1.1)
    trend = iid + np.linspace(0, 3, 1000)[None, :, None]  # drifting chains: caught by the split
    assert np.all(split_rhat(trend) > 1.1)
    scale = iid * np.where(np.arange(8) < 4, 1.0, 3.0)[:, None, None]  # same centre, different spread: caught
    assert split_rhat(scale)[0] > 1.01 and split_rhat(scale, rank_normalised=False)[0] < split_rhat(scale)[0]


def test_split_rhat_classic_formula_by_hand():
    c = np.array([[1.0, 2.0, 3.0, 4.0], [2.0, 3.0, 4.0, 9.0]])
    # split into four chains of two draws: (1,2) (2,3) (3,4) (4,9)
    halves = np.array([[1, 2], [2, 3], [3, 4], [4, 9]], dtype=float)
    W = halves.var(axis=1, ddof=1).mean()
    B_n = halves.mean(axis=1).var(ddof=1)
    expect = np.sqrt((W / 2 + B_n) / W)
    assert split_rhat(c, rank_normalised=False) == pytest.approx(expect)
    with pytest.raises(ValueError, match="n_draws >= 4"):
        split_rhat(np.zeros((2, 3)))


@pytest.fixture(scope="module")
def small_problem(kcs_truth):
    """One short turn (20 s, 0.2 s sampling) and a fit of the two yaw coefficients c2, c3."""
    from shipid.identify import EKFIdentifier
    from shipid.synthetic import TrialRecipe, make_trial

    rec = TrialRecipe("short_tc", "turning", 25.0, 20.0, dt_s=0.2, execute_s=2.0)
    log = make_trial(kcs_truth, rec, np.random.default_rng(5))[0]
    res = EKFIdentifier(kcs_truth, estimate=["c2", "c3"], init="model", n_passes=2).fit(log).result()
    return res, log


def test_short_chain_is_not_called_converged(small_problem):
    res, log = small_problem
    with pytest.warns(RuntimeWarning, match="NOT converged"):
        s = sample_posterior(res, log, walkers=8, steps=30, seed=1)
    assert not s.converged and s.status == 1 and "NOT converged" in s.message
    assert not s.diagnostics["checks"]["length"]
    assert s.samples.shape == (8 * 20, 2)
    # start + one batched call per split of the ensemble (2 for DE, 4 for the DE snooker move), never per walker
    assert 1 + 2 * 30 <= s.diagnostics["n_likelihood_calls"] <= 1 + 4 * 30 + 20


def test_too_small_a_budget_stops_early_and_says_how_many_steps(small_problem, caplog, monkeypatch):
    from shipid.uncertainty import posterior

    res, log = small_problem
    # this 2-coefficient posterior mixes in a few steps: stop as soon as 50 tau exceeds half the budget
    monkeypatch.setattr(posterior, "EARLY_STOP_FACTOR", 0.5)
    lines = []
    with pytest.warns(RuntimeWarning, match="NOT converged: stopped after"):
        s = sample_posterior(res, log, walkers=8, steps=60, seed=1, check_every=10, log=lines.append)
    stop = s.diagnostics["stopped_early"]
    assert stop["at"] < 60 and s.diagnostics["n_steps_run"] == stop["at"] and not s.converged
    assert stop["at"] == 40  # the first check with 20 kept steps: 20 + 50 tau >= 70 > 30
    assert stop["needed"] > 0.5 * 60 and stop["suggest"] >= stop["needed"]
    assert f"run again with --steps {stop['suggest']}" in s.message and "\n" not in s.message
    assert not [r for r in caplog.records if r.name.startswith("emcee")]  # emcee's own text never reaches the user
    assert lines[0] == "sampling: 8 walkers x 60 steps (2 dimensions, 20 steps of burn-in), checked every 10 steps ..."
    assert len(lines) == 1 + stop["at"] // 10


def test_vectorised_and_serial_likelihood_agree(small_problem, kcs_truth):
    res, log = small_problem
    like = OutputErrorLikelihood(res.to_model(), log, ["c2", "c3"])
    th = np.array([[res.coef["c2"], res.coef["c3"]], [res.coef["c2"] * 1.01, res.coef["c3"]]])
    batch = like(th)
    np.testing.assert_allclose(batch, [like(th[0]), like(th[1])], rtol=1e-12)
    assert batch[0] > batch[1]


def test_missing_emcee_is_a_clear_error(small_problem, monkeypatch):
    res, log = small_problem
    monkeypatch.setitem(sys.modules, "emcee", None)
    with pytest.raises(ValueError, match=r"pip install 'shipid\[mcmc\]'"):
        sample_posterior(res, log, steps=20)


def test_sample_cli_writes_samples_and_exit_code(small_problem, tmp_path, capsys):
    from shipid.cli import main
    from shipid.synthetic import schema_frame

    res, log = small_problem
    rp = res.to_json(tmp_path / "res.json")
    lp = tmp_path / "log.csv"
    schema_frame(log).to_csv(lp, index=False)
    out = tmp_path / "s.json"
    assert main(["sample", str(rp), str(lp), "-o", str(out), "--walkers", "8", "--steps", "30", "--no-progress"]) == 1
    doc = json.loads(out.read_text())
    assert doc["names"] == ["c2", "c3"] and doc["converged"] is False and len(doc["samples"]) == 160
    assert "split-R-hat_max" in capsys.readouterr().out
    mo = tmp_path / "m.json"  # the samples feed the propagation
    assert main(["simulate", str(rp), "--turning", "35", "--side", "starboard", "--draws", "10", "--samples", str(out),
                 "--metrics-output", str(mo)]) == 0
    doc = json.loads(mo.read_text())
    assert doc["source"] == "mcmc" and doc["manoeuvres"]["turning_35_starboard"]["draws"]["n"] == 10
    assert main(["sample", str(rp), str(lp), "-o", str(out), "--steps", "30"]) == 2  # exists, no --force


@pytest.mark.slow
def test_mcmc_matches_the_exact_grid_posterior(small_problem):
    """Two coefficients: the posterior on a fine grid (one batched evaluation) is exact; the converged chain
    must reproduce its means (within 0.1 posterior std) and std (within 10 %)."""
    res, log = small_problem
    s = sample_posterior(res, log, walkers=32, steps=3000, burn=600, seed=2)  # 1500 steps ended at R-hat 1.011-1.02
    assert s.converged, s.message
    like = OutputErrorLikelihood(res.to_model(), log, ["c2", "c3"],
                                 meas_std=res.settings["meas_std"],
                                 prior_mean=[res.settings["prior_mean"]["c2"], res.settings["prior_mean"]["c3"]],
                                 prior_std=[res.settings["prior_std"]["c2"], res.settings["prior_std"]["c3"]])
    m, sd = s.samples.mean(axis=0), s.samples.std(axis=0)
    g = [np.linspace(m[j] - 6 * sd[j], m[j] + 6 * sd[j], 81) for j in range(2)]
    G2, G3 = np.meshgrid(*g, indexing="ij")
    lp = like(np.column_stack([G2.ravel(), G3.ravel()]))
    w = np.exp(lp - lp.max())
    w /= w.sum()
    pts = np.column_stack([G2.ravel(), G3.ravel()])
    gm = w @ pts
    gsd = np.sqrt(w @ (pts - gm) ** 2)
    np.testing.assert_array_less(np.abs(m - gm) / gsd, 0.1)
    np.testing.assert_allclose(sd, gsd, rtol=0.10)


def test_initial_states_as_nuisance_parameters(small_problem):
    """x0_states: per log the offsets of the initial states follow the coefficients in theta; zero offsets give
    the held-state likelihood, the batch equals single calls, a wrong column count is a clear error."""
    res, log = small_problem
    base = OutputErrorLikelihood(res.to_model(), log, ["c2", "c3"])
    like = OutputErrorLikelihood(res.to_model(), log, ["c2", "c3"], x0_states=True)
    assert like.x0_states == ["u", "v", "r"] and like.n_x0 == 3
    c = [res.coef["c2"], res.coef["c3"]]
    th = np.array([c + [0.0, 0.0, 0.0], c + [0.0, 0.0, 2e-3], c + [1e-3, -1e-3, 0.0]])
    lp = like(th)
    assert lp[0] == pytest.approx(base(np.array(c)), rel=1e-12)
    np.testing.assert_allclose(lp, [like(t) for t in th], rtol=1e-12)
    assert lp[1] < lp[0]  # an initial yaw rate 1 sigma off (sensor: 1.7e-3 rad/s) costs likelihood
    with pytest.raises(ValueError, match="theta must have 5 columns"):
        like(np.array(c))


def test_independence_sampler_with_initial_states_matches_exact_posteriors(small_problem):
    """moves="independence" passes the unchanged convergence rules in a few hundred steps.  With the initial states
    held, its draws match the exact grid posterior of c2, c3 (means within 0.1 sigma, std within 10 %); with them
    sampled (5 dimensions), its c2, c3 marginal matches the output-error fit that estimates the initial states
    (OutputErrorRefiner(estimate_x0=True), the Laplace marginal: an independent implementation) within 10 % in std
    and 0.2 sigma in mean."""
    from shipid.identify.batch import OutputErrorRefiner

    res, log = small_problem
    s = sample_posterior(res, log, walkers=32, steps=900, burn=300, seed=3, moves="independence", sample_x0=True)
    assert s.converged, s.message
    d = s.diagnostics
    assert set(d["tau"]) == {"c2", "c3", "u0[0]", "v0[0]", "r0[0]"} and d["tau_max"] < 10
    assert s.samples.shape == (32 * 600, 2) and s.names == ["c2", "c3"]
    h = sample_posterior(res, log, walkers=32, steps=900, burn=300, seed=3, moves="independence")
    assert h.converged, h.message
    like = OutputErrorLikelihood(res.to_model(), log, ["c2", "c3"], meas_std=res.settings["meas_std"],
                                 prior_mean=[res.settings["prior_mean"]["c2"], res.settings["prior_mean"]["c3"]],
                                 prior_std=[res.settings["prior_std"]["c2"], res.settings["prior_std"]["c3"]])
    m, sd = h.samples.mean(axis=0), h.samples.std(axis=0)
    g = [np.linspace(m[j] - 6 * sd[j], m[j] + 6 * sd[j], 81) for j in range(2)]
    pts = np.column_stack([a.ravel() for a in np.meshgrid(*g, indexing="ij")])
    lp = like(pts)
    w = np.exp(lp - lp.max())
    w /= w.sum()
    gm = w @ pts
    gsd = np.sqrt(w @ (pts - gm) ** 2)
    np.testing.assert_array_less(np.abs(m - gm) / gsd, 0.1)
    np.testing.assert_allclose(sd, gsd, rtol=0.10)
    oe = OutputErrorRefiner(res.to_model(), estimate=["c2", "c3"], channels=["u", "v", "r"], jacobian="tangent",
                            meas_std=res.settings["meas_std"], estimate_x0=True, max_nfev=30).fit(log)
    osd = oe.coef_std_[["c2", "c3"]].to_numpy()
    ms, ss = s.samples.mean(axis=0), s.samples.std(axis=0)
    np.testing.assert_allclose(ss, osd, rtol=0.10)
    np.testing.assert_array_less(np.abs(ms - oe.coef_[["c2", "c3"]].to_numpy()) / osd, 0.2)
    assert np.all(ss >= 0.95 * gsd)  # the marginal is not narrower than the held-state posterior


def test_the_prior_is_the_one_the_ekf_started_from(small_problem, kcs_truth):
    """The result records the EKF's prior (the first pass's start and its widths) and the sampler uses it by
    default, not the fit's own estimate (which would use the data twice); the JSON round trip keeps it."""
    from shipid.identify import FitResult

    res, log = small_problem
    pm = res.settings["prior_mean"]
    assert pm == {n: float(kcs_truth.params_series()[n]) for n in ("c2", "c3")}  # init="model": the model's values
    assert pm != {n: res.coef[n] for n in ("c2", "c3")}
    assert FitResult.from_dict(json.loads(json.dumps(res.to_dict()))).settings["prior_mean"] == pm
    with warnings.catch_warnings():
        warnings.simplefilter("error", UserWarning)  # a recorded prior: no warning
        s = sample_posterior(res, log, walkers=32, steps=20, burn=10, seed=1)
    pr = s.settings["prior"]
    assert pr["kind"] == "gaussian" and pr["mean"] == pm and pr["std"] == res.settings["prior_std"]
    like = OutputErrorLikelihood(res.to_model(), log, ["c2", "c3"], meas_std=res.settings["meas_std"],
                                 prior_mean=list(pm.values()), prior_std=list(res.settings["prior_std"].values()))
    flat = OutputErrorLikelihood(res.to_model(), log, ["c2", "c3"], meas_std=res.settings["meas_std"])
    th = s.samples[:5]
    z = (th - np.array(list(pm.values()))) / np.array(list(res.settings["prior_std"].values()))
    np.testing.assert_allclose(like(th) - flat(th), -0.5 * np.sum(z**2, axis=1), rtol=1e-6, atol=1e-12)


def test_a_result_without_a_recorded_prior_is_sampled_flat_with_a_warning(small_problem):
    """Results written before the prior's centre was recorded: a one-line warning and a flat prior (never the
    fit's estimate as the centre); --no-prior / use_prior=False stays silent."""
    from shipid.identify import FitResult

    res, log = small_problem
    doc = json.loads(json.dumps(res.to_dict()))  # a copy: to_dict shares the (module-scoped) result's settings
    del doc["settings"]["prior_mean"]
    old = FitResult.from_dict(doc)
    with pytest.warns(UserWarning, match=r"records no prior centre and width for c2, c3 .*: flat prior"):
        s = sample_posterior(old, log, walkers=32, steps=20, burn=10, seed=1)
    assert s.settings["prior"] == {"kind": "flat"}
    with warnings.catch_warnings():
        warnings.simplefilter("error", UserWarning)
        f = sample_posterior(res, log, walkers=32, steps=20, burn=10, seed=1, use_prior=False)
    assert f.settings["prior"] == {"kind": "flat"}
    np.testing.assert_array_equal(f.samples, s.samples)  # flat is flat, whichever way it was asked for


def test_sample_cli_moves_and_initial_states(small_problem, tmp_path):
    from shipid.cli import main
    from shipid.synthetic import schema_frame

    res, log = small_problem
    rp = res.to_json(tmp_path / "res.json")
    lp = tmp_path / "log.csv"
    schema_frame(log).to_csv(lp, index=False)
    out = tmp_path / "s.json"
    rc = main(["sample", str(rp), str(lp), "-o", str(out), "--steps", "40", "--burn", "20", "--moves", "independence",
               "--sample-x0", "--no-progress"])
    doc = json.loads(out.read_text())
    assert rc in (0, 1) and rc == (0 if doc["converged"] else 1)
    assert doc["names"] == ["c2", "c3"] and len(doc["samples"][0]) == 2 and len(doc["samples"]) == 32 * 20
    assert doc["settings"]["moves"] == "independence" and doc["settings"]["x0_sampled"] == ["u0[0]", "v0[0]", "r0[0]"]
    assert doc["settings"]["prior"]["kind"] == "gaussian"
    flat = tmp_path / "flat.json"
    main(["sample", str(rp), str(lp), "-o", str(flat), "--steps", "20", "--burn", "10", "--no-prior", "--no-progress"])
    assert json.loads(flat.read_text())["settings"]["prior"] == {"kind": "flat"}
    assert set(doc["diagnostics"]["rhat"]) == {"c2", "c3", "u0[0]", "v0[0]", "r0[0]"}


def test_independence_sampler_with_a_laplace_proposal(small_problem):
    """proposal=OutputErrorRefiner: the t proposal comes from the output-error Laplace approximation (coefficients
    and initial states) and is fixed from the first step; the walkers still start from the EKF posterior.  The
    chain passes the unchanged rules and its marginal matches that Laplace approximation (std within 10 %, means
    within 0.2 sigma).  A proposal 10x too narrow in every direction is refused by the same rules, never called
    converged; a proposal without the sampled initial states, or with other moves, is an error."""
    from shipid.identify.batch import OutputErrorRefiner

    res, log = small_problem
    oe = OutputErrorRefiner(res.to_model(), estimate=["c2", "c3"], channels=["u", "v", "r"], jacobian="tangent",
                            meas_std=res.settings["meas_std"], estimate_x0=True, max_nfev=30).fit(log)
    assert list(oe.cov_joint_.index) == ["c2", "c3", "u0[0]", "v0[0]", "r0[0]"]
    np.testing.assert_allclose(oe.cov_joint_.loc[["c2", "c3"], ["c2", "c3"]], oe.cov_, rtol=1e-12)
    s = sample_posterior(res, log, walkers=32, steps=400, burn=50, seed=3, moves="independence", sample_x0=True,
                         proposal=oe)
    assert s.converged, s.message
    assert s.settings["proposal"] == "laplace (given)" and s.samples.shape == (32 * 350, 2)
    assert s.diagnostics["acceptance_mean"] > 0.3 and s.diagnostics["tau_max"] < 6
    osd = oe.coef_std_[["c2", "c3"]].to_numpy()
    np.testing.assert_allclose(s.samples.std(axis=0), osd, rtol=0.10)
    np.testing.assert_array_less(np.abs(s.samples.mean(axis=0) - oe.coef_[["c2", "c3"]].to_numpy()) / osd, 0.2)
    names = list(oe.cov_joint_.index)
    mean = {**oe.coef_.to_dict(), **{f"{c}0[0]": float(oe.x0_.iloc[0][c]) for c in "uvr"}}
    narrow = {"mean": mean, "cov": oe.cov_joint_.loc[names, names] / 100.0}
    with pytest.warns(RuntimeWarning, match="NOT converged"):
        bad = sample_posterior(res, log, walkers=32, steps=400, burn=50, seed=3, moves="independence",
                               sample_x0=True, proposal=narrow)
    assert not bad.converged and bad.diagnostics["acceptance_mean"] < s.diagnostics["acceptance_mean"]
    with pytest.raises(ValueError, match="lacks sampled dimension"):
        sample_posterior(res, log, walkers=32, steps=40, burn=10, moves="independence", sample_x0=True,
                         proposal={"mean": mean, "cov": oe.cov_joint_.loc[["c2", "c3"], ["c2", "c3"]]})
    with pytest.raises(ValueError, match="use moves='independence'"):
        sample_posterior(res, log, walkers=32, steps=40, proposal=oe)
