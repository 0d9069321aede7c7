"""The numpy path's shortcuts give what the general numpy code gives, with or without numba.

- ``simulate`` of one trajectory with sampled inputs runs the model's kernel equations in the
  interpreter on floats when the model sets ``_python_replay`` (kcs-response, response-nl, the
  environment wrapper): the same trajectory as the numpy RK4 loop, and the loop's failure semantics.
- ``run_ekf`` with one member calls the model on unbatched arrays: the same filter as a batch.
- ``run_ekf(compact="ship")`` stores the ship rows of the filtered covariance; ``bf_smooth`` then gives
  the same ship means and variances as from the full storage (the parameters' means and the sample-0
  covariance are not computed: NaN), and the identifier reports the same fit.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from shipid import _jit, _kernel
from shipid.environment import with_environment
from shipid.identify import EKFIdentifier, run_ekf
from shipid.identify.ekf import bf_smooth
from shipid.models import get_model
from shipid.simulate import simulate


def _close(a, b, name, rtol=1e-10):
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    assert np.array_equal(np.isnan(a), np.isnan(b)), f"{name}: NaN pattern differs"
    ref = np.max(np.abs(b[np.isfinite(b)])) if np.isfinite(b).any() else 1.0
    np.testing.assert_allclose(a, b, rtol=rtol, atol=rtol * ref, equal_nan=True, err_msg=name)


def _numpy_loop(model):
    """The same model with the interpreted replay switched off (the numpy RK4 loop of ``simulate``)."""
    model._python_replay = False
    return model


def _model(name):
    if name == "mmg+env":
        return with_environment(get_model("mmg", "kvlcc2", lpp=3.0), wind="esso-osaka-3m", current="constant")
    return get_model(name)


@pytest.mark.parametrize("name", ["kcs-response", "response-nl", "with-environment", "mmg+env"])
def test_interpreted_replay_equals_the_numpy_loop(name, kcs_logs):
    model, loop = _model(name), _numpy_loop(_model(name))
    assert model._python_replay and not loop._python_replay
    frame = kcs_logs["kcs_zz_p20_rpm"][0].iloc[:300]
    t = frame["time"].to_numpy().copy()
    t[150:] += 0.35  # one long interval: more steps there
    U = np.column_stack([frame[c].to_numpy() if c in frame else np.full(len(t), 0.5 + 0.1 * i)
                         for i, c in enumerate(model.input_names)])
    x0 = np.array([frame[c].iloc[0] if c in frame else 0.0 for c in model.state_names])
    with _jit.disabled():
        assert _kernel.replay_compiled(model, x0[None], t, U[None], model.params, np.full(len(t) - 1, 2),
                                       True) is not None, "the interpreted replay did not run"
        for hold in ("foh", "zoh"):
            kw = dict(substeps=2, input_hold=hold, h_max=0.06)
            fast, slow = simulate(model, x0, t, U, **kw), simulate(loop, x0, t, U, **kw)
            assert fast.success and slow.success and np.isfinite(slow.x).all()
            _close(fast.x, slow.x, f"{name} {hold} states")
            _close(fast.u, slow.u, f"{name} {hold} inputs")


def test_interpreted_replay_that_blows_up_reports_like_the_numpy_loop(kcs_logs):
    model = get_model("kcs-response")
    p = model.params.copy()
    p[model.param_index("c2")] = 50.0  # yaw rate grows without bound
    model, loop = model.with_params(p), _numpy_loop(model.with_params(p))
    frame = kcs_logs["kcs_zz_p20_rpm"][0].iloc[:400]
    t, U = frame["time"].to_numpy(), frame[list(model.input_names)].to_numpy()
    x0 = frame[list(model.state_names)].to_numpy()[0]
    with _jit.disabled(), pytest.warns(RuntimeWarning):
        fast = simulate(model, x0, t, U, substeps=2, input_hold="foh")
    with _jit.disabled(), pytest.warns(RuntimeWarning):
        slow = simulate(loop, x0, t, U, substeps=2, input_hold="foh")
    assert not fast.success and not slow.success and fast.message == slow.message
    _close(fast.x, slow.x, "states up to the failure")


@pytest.fixture(scope="module")
def fit_and_problem(kcs_truth, kcs_logs):
    frames = []
    for j, key in enumerate(["kcs_zz_p20_rpm", "kcs_tc_m25_rpm"]):
        df = kcs_logs[key][0].iloc[:300].copy().reset_index(drop=True)
        df.loc[30 + j:40, ["u", "v"]] = np.nan
        df = df.drop(index=range(100, 104)).reset_index(drop=True)
        frames.append(df)
    with _jit.disabled():
        ident = EKFIdentifier(kcs_truth, n_passes=1, init="model").fit(frames)
    return ident, frames


def test_one_member_filter_equals_the_batched_filter(fit_and_problem):
    ident, _ = fit_and_problem
    prob = ident.problem_
    rep = lambda a: np.repeat(a, 2, axis=0)  # noqa: E731
    two = replace(prob, p_base=rep(prob.p_base), t=rep(prob.t), U=rep(prob.U), Y=rep(prob.Y), R=rep(prob.R),
                  q=rep(prob.q), z0=rep(prob.z0), P0=rep(prob.P0), reset=rep(prob.reset), x_reset=rep(prob.x_reset),
                  P_reset=rep(prob.P_reset))
    with _jit.disabled():
        one, both = run_ekf(prob, store=True), run_ekf(two, store=True)
    for f in ("z_post", "P_post", "z_prior", "P_prior", "F", "innov", "S_diag", "nis", "loglik", "z_final", "P_final"):
        _close(getattr(one, f)[0], getattr(both, f)[1], f)


@pytest.mark.parametrize("compiled", [False, True])
def test_ship_rows_storage_smooths_the_same(fit_and_problem, compiled):
    if compiled and not _jit.enabled():
        pytest.skip("numba not installed (extra 'fast') or SHIPID_JIT=0")
    ident, frames = fit_and_problem
    prob, nx = ident.problem_, ident.model.nx
    run = (lambda fn: fn()) if compiled else (lambda fn: _numpy(fn))
    full = run(lambda: run_ekf(prob, store=True, compact=True))
    ship = run(lambda: run_ekf(prob, store=True, compact="ship"))
    assert ship.compact == "ship" and ship.P_post.shape[2] == nx
    _close(ship.P_post, full.P_post[:, :, :nx], "ship rows of P_post")
    for f in ("z_post", "P_prior", "F", "innov", "loglik"):
        _close(getattr(ship, f), getattr(full, f), f)
    zs_f, var_f, _ = run(lambda: bf_smooth(full, prob.R, prob.meas_idx, nx))
    zs_s, var_s, Ps0_s = run(lambda: bf_smooth(ship, prob.R, prob.meas_idx, nx))
    _close(zs_s[..., :nx], zs_f[..., :nx], "smoothed ship means")
    _close(var_s, var_f, "smoothed ship variances")
    assert np.isnan(zs_s[..., nx:]).all() and np.isnan(Ps0_s).all()
    # the identifier (param_walk=0 stores the ship rows) reports the fit of the full storage
    with pytest.raises(ValueError, match="compact"):
        run_ekf(prob, compact="rows")


def _numpy(fn):
    with _jit.disabled():
        return fn()
