"""The compiled EKF kernel (shipid._kernel) against the numpy path of run_ekf / rts_smooth.

Every model with compiled equations, with resets (two logs), partial and whole-sample gaps, an
irregular sampling gap, a batch of members with different noise, sub-steps, every transition method,
and a diverging member: filtered and predicted means and covariances, transitions, innovations,
their variances, NIS, log-likelihood, divergence flags and messages, smoothed means and covariances
agree to 1e-10.  Skipped when compilation is off (no numba, or SHIPID_JIT=0).
"""
from __future__ import annotations

import warnings
from dataclasses import replace

import numpy as np
import pytest

import shipid
from shipid import _jit
from shipid.datasets import bundled_kcs_logs
from shipid.identify import EKFIdentifier, rts_smooth, run_ekf
from shipid import _kernel
from shipid.identify.ekf import _run_compiled, bf_smooth
from shipid.models import get_model

pytestmark = pytest.mark.skipif(not _jit.enabled(), reason="numba not installed (extra 'fast') or SHIPID_JIT=0: "
                                "compiled EKF kernel not tested")

FIELDS = ("z_post", "P_post", "z_prior", "P_prior", "F", "innov", "S_diag", "nis", "loglik", "z_final", "P_final",
          "diverged", "diverged_at")


def _close(a, b, name):
    """Equal to 1e-10 relative to the size of the quantity (NaN where the other is NaN)."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    assert np.array_equal(np.isnan(a), np.isnan(b)), f"{name}: NaN pattern differs"
    assert np.array_equal(np.isinf(a), np.isinf(b)) and np.array_equal(a[np.isinf(a)], b[np.isinf(b)]), name
    ref = np.max(np.abs(b[np.isfinite(b)])) if np.isfinite(b).any() else 1.0
    np.testing.assert_allclose(a, b, rtol=1e-10, atol=1e-10 * max(ref, 1e-300), equal_nan=True, err_msg=name)


def _compare(prob, nis_limit=1e6):
    assert _run_compiled(prob, True, nis_limit) is not None, "the compiled path did not run"
    fast = run_ekf(prob, store=True, nis_limit=nis_limit)
    fast_nostore = run_ekf(prob, store=False, nis_limit=nis_limit)
    with _jit.disabled():
        slow = run_ekf(prob, store=True, nis_limit=nis_limit)
        slow_nostore = run_ekf(prob, store=False, nis_limit=nis_limit)
        zs0, Ps0 = rts_smooth(slow)
    for f in FIELDS:
        _close(getattr(fast, f), getattr(slow, f), f)
    for f in ("z_final", "P_final", "innov", "loglik", "diverged_at"):
        _close(getattr(fast_nostore, f), getattr(slow_nostore, f), f + " (store=False)")
    assert fast.message == slow.message and fast_nostore.message == slow_nostore.message
    zs, Ps = rts_smooth(fast)
    _close(zs, zs0, "smoothed means")
    _close(Ps, Ps0, "smoothed covariances")
    # the adjoint form of the smoother (what the identifier reports): compiled = numpy, and = the RTS form
    nx = prob.model.nx
    bf = bf_smooth(fast, prob.R, prob.meas_idx, nx)
    with _jit.disabled():
        bf0 = bf_smooth(slow, prob.R, prob.meas_idx, nx)
    rts = (zs, np.diagonal(Ps[..., :nx, :nx], axis1=2, axis2=3), Ps[:, 0])
    # the compact storage (what that smoother reads): the same rows of P_prior and F, the same smoothing
    small = run_ekf(prob, store=True, nis_limit=nis_limit, compact=True)
    with _jit.disabled():
        small0 = run_ekf(prob, store=True, nis_limit=nis_limit, compact=True)
    assert small.compact and small0.compact
    mi = np.asarray(prob.meas_idx)
    for out_ in (small, small0):
        _close(out_.P_prior, slow.P_prior[:, :, mi], "compact P_prior")
        _close(out_.F, slow.F[:, :, :nx], "compact F")
        for f in ("z_post", "P_post", "z_prior", "innov", "loglik"):
            _close(getattr(out_, f), getattr(slow, f), f + " (compact)")
    bf_small = bf_smooth(small, prob.R, prob.meas_idx, nx)
    with _jit.disabled():
        bf_small0 = bf_smooth(small0, prob.R, prob.meas_idx, nx)
    # the compiled filter keeps its gains for the smoother, which then reads them instead of solving for them:
    # the same numbers to the bit (solved alike from the same numbers); the numpy filter keeps none
    assert small.gains is not None and small0.gains is None
    for a, b in zip(bf_small, bf_smooth(replace(small, gains=None), prob.R, prob.meas_idx, nx)):
        np.testing.assert_array_equal(a, b, err_msg="smoother from the stored gains")
    # the ship-row storage (the identifier's, param_walk=0): the same ship means and variances
    ship = run_ekf(prob, store=True, nis_limit=nis_limit, compact="ship")
    with _jit.disabled():
        ship0 = run_ekf(prob, store=True, nis_limit=nis_limit, compact="ship")
    bs, bs0 = bf_smooth(ship, prob.R, prob.meas_idx, nx), _numpy(lambda: bf_smooth(ship0, prob.R, prob.meas_idx, nx))
    for a, b in zip(bs, bf_smooth(replace(ship, gains=None), prob.R, prob.meas_idx, nx)):
        np.testing.assert_array_equal(a, b, err_msg="smoother from the stored gains (ship rows)")
    for out_, b_, what in ((ship, bs, "compiled"), (ship0, bs0, "numpy")):
        assert out_.compact == "ship"
        _close(out_.P_post, slow.P_post[:, :, :nx], "ship rows of P_post, " + what)
        _close(b_[0][..., :nx], bf0[0][..., :nx], "smoothed ship means from the ship rows, " + what)
        _close(b_[1], bf0[1], "smoothed ship variances from the ship rows, " + what)
        assert np.isnan(b_[0][..., nx:]).all() and np.isnan(b_[2]).all()
    for name, a, b, c, d, e in zip(("means", "state variances", "covariance at sample 0"), bf, bf0, rts, bf_small,
                                   bf_small0):
        _close(a, b, "adjoint-form smoothed " + name)
        _close(d, b, "adjoint-form smoothed " + name + " (compact storage)")
        _close(e, b, "adjoint-form smoothed " + name + " (compact storage, numpy)")
        ok = np.isfinite(c)
        # the two forms differ in rounding only; the differences against a wide prior lose a few digits
        np.testing.assert_allclose(a[ok], c[ok], rtol=1e-7, atol=1e-9 * np.abs(c[ok]).max(),
                                   err_msg="adjoint vs RTS form: " + name)
    return fast


def _batch(prob, B, rng):
    """``prob`` repeated B times, members with other measurement noise and noise settings."""
    rep = lambda a: np.repeat(a, B, axis=0)  # noqa: E731
    sig = np.sqrt(prob.R[0])
    Y = rep(prob.Y) + rng.normal(0, 1, (B,) + prob.Y.shape[1:]) * sig
    R = rep(prob.R) * np.linspace(0.5, 2.0, B)[:, None]
    q = rep(prob.q) * np.linspace(0.1, 10.0, B)[:, None]
    return replace(prob, p_base=rep(prob.p_base), t=rep(prob.t), U=rep(prob.U), Y=Y, R=R, q=q, z0=rep(prob.z0),
                   P0=rep(prob.P0), reset=rep(prob.reset), x_reset=rep(prob.x_reset), P_reset=rep(prob.P_reset))


def _problem(model, logs, estimate, n=160):
    """The identifier's EKF problem for the first ``n`` samples of each log, with gaps."""
    frames = []
    for j, lg in enumerate(logs):
        df = lg.iloc[:n].copy().reset_index(drop=True)
        df.loc[30 + j:40, ["u", "v"]] = np.nan           # partial gaps: the masked update
        df.loc[70:72, [c for c in ("x", "y", "psi", "u", "v", "r") if c in df]] = np.nan  # whole samples
        df = df.drop(index=range(100, 104)).reset_index(drop=True)  # an irregular sampling gap
        frames.append(df)
    with _jit.disabled():
        ident = EKFIdentifier(model, n_passes=1, init="model", estimate=estimate)
        ident.fit(frames)
    return ident.problem_


@pytest.fixture(scope="module")
def kcs_problem(kcs_truth, kcs_logs):
    return _problem(kcs_truth, [kcs_logs["kcs_zz_p20_rpm"][0], kcs_logs["kcs_tc_m25_rpm"][0]], None)


@pytest.mark.parametrize("method, hold", [("rk4", "foh"), ("rk4", "zoh"), ("rk4-exact", "foh"), ("euler", "foh")])
def test_kcs_response_kernel_equals_numpy(kcs_problem, method, hold):
    """Sub-steps, more steps over the sampling gap (h_max), both input holds, gating."""
    prob = _batch(kcs_problem, 3, np.random.default_rng(5))
    Y = prob.Y.copy()
    Y[0, 20:23, 5] += 0.05  # outliers the gate rejects (member 0)
    dt = float(np.median(np.diff(prob.t[0])))
    prob = replace(prob, Y=Y, method=method, substeps=2, h_max=0.75 * dt, input_hold=hold, gate=4.0, gate_run=2)
    assert prob.reset.any() and not np.isfinite(prob.Y).all()
    out = _compare(prob)
    assert not out.diverged.any() and out.gated[0].any()


def test_diverging_member_is_frozen_alike(kcs_problem):
    prob = _batch(kcs_problem, 3, np.random.default_rng(6))
    Y = prob.Y.copy()
    Y[1, 120:, 5] += 50.0  # member 1: an absurd yaw-rate jump
    out = _compare(replace(prob, Y=Y, input_hold="foh"))
    # with the identifier's innovation gate the jump is rejected gate_run times before it is accepted
    first = 120 + (prob.gate_run if prob.gate is not None else 0)
    assert list(out.diverged) == [False, True, False] and out.diverged_at[1] == first


def test_odd_sizes_kernel_equals_numpy(kcs_truth, kcs_logs):
    """An odd augmented state (6 + 15) and odd channel counts: the kernel's loops over pairs of rows."""
    est = [n for n in kcs_truth.param_names if n != "a8"]
    prob = _problem(kcs_truth, [kcs_logs["kcs_zz_p20_rpm"][0], kcs_logs["kcs_tc_m25_rpm"][0]], est)
    assert (prob.z0.shape[1] % 2) == 1
    prob = _batch(prob, 2, np.random.default_rng(9))
    Y = prob.Y.copy()
    Y[:, 50:60, 4] = np.nan  # five channels at these samples
    _compare(replace(prob, Y=Y))


def test_response_nl_kernel_equals_numpy(kcs_logs):
    model = get_model("response-nl")
    logs = [f for f, _ in kcs_logs.values()][:2]
    prob = _problem(model, logs, ["b1", "b2", "b3", "b6", "c1", "c2", "c3", "c7", "a1", "a9"])
    _compare(_batch(prob, 2, np.random.default_rng(7)))


def test_mmg_kernel_equals_numpy():
    truth = shipid.get_model("mmg", "kcs")
    logs = [shipid.read_log(p).data for p in bundled_kcs_logs("mmg")][:2]
    prob = _problem(truth, logs, ["Yv", "Yr", "Nv", "Nr", "Nvvr", "R0", "tP", "f_alpha"], n=120)
    _compare(_batch(prob, 2, np.random.default_rng(8)))


def test_models_without_compiled_equations_fall_back_with_one_notice(kcs_truth):
    class Plain(type(kcs_truth)):
        name = "plain-kcs"
        _equations = None

    model = Plain(kcs_truth.params)
    _kernel._noticed.discard("Plain")
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        assert _kernel.filter_functions(model) is None
        assert _kernel.filter_functions(model) is None
    msgs = [str(w.message) for w in rec]
    assert len(msgs) == 1 and "plain-kcs" in msgs[0] and "numpy path" in msgs[0]


def test_equations_without_reference_counting_and_the_fallback(kcs_problem, monkeypatch):
    """The equations that allocate nothing run without numba's reference counting (k_consts, which returns a
    new array, and equations calling helpers compiled elsewhere keep it); should a build not compile that way
    (here: k_consts forced into it, which numba refuses), the reference-counted build runs instead, with the
    same results to the bit, and is used from then on."""
    for name, kept in (("kcs-response", {"k_consts"}), ("response-nl", {"k_consts"}),
                       ("mmg", {"k_consts", "k_jac", "rhs_one", "rhs_rows"})):
        model = get_model(name)
        ns = model._equations_namespace()
        assert set(model._equations) - _kernel._refcount_free(model._equations, ns) - set(ns) == kept, name
    ref = run_ekf(kcs_problem, store=False)

    class Forced(type(kcs_problem.model)):
        name = "kcs-forced-refcount-free"  # (its own build and disk cache: numba's cache key has no _nrt flag)

    prob = replace(kcs_problem, model=Forced(kcs_problem.model.params))
    monkeypatch.setattr(_kernel, "_cache", {})
    monkeypatch.setattr(_kernel, "_refcounted", set())
    monkeypatch.setattr(_kernel, "_base_of", {})
    monkeypatch.setattr(_kernel, "_refcount_free", lambda eq, ns: frozenset(eq) - set(ns))
    out = run_ekf(prob, store=False)
    assert len(_kernel._refcounted) == 1  # the first build did not compile: the fallback ran
    for f in ("z_final", "P_final", "innov", "loglik"):
        np.testing.assert_array_equal(getattr(out, f), getattr(ref, f), err_msg=f)
    np.testing.assert_array_equal(run_ekf(prob, store=False).z_final, ref.z_final)  # (the fallback, again)


def test_no_refcount_without_numbas_private_option(monkeypatch):
    """``_nrt`` is a private numba option (0.68 has it).  A numba without it would reject the option at the
    first call with a KeyError, which no fallback catches: ``rebind`` then compiles with reference counting."""
    def add_into(out, a, b):
        for i in range(out.shape[0]):
            out[i] = a[i] + b[i]

    a, b = np.arange(3.0), np.ones(3)
    for known in (True, False):
        monkeypatch.setattr(_jit, "_has_nrt_option", lambda: known)
        f = _jit.rebind({"add_into": add_into}, {}, jit=True, tag=f"_nrt_test_{known}",
                        no_refcount={"add_into"})["add_into"]
        assert f.targetoptions.get("_nrt", True) is not known
        out = np.empty(3)
        f(out, a, b)
        np.testing.assert_array_equal(out, a + b)


@pytest.mark.parametrize("name", ["kcs-response", "response-nl"])
def test_linear_equation_error_start_equals_the_iterated_one(name, kcs_logs):
    """Models linear in their parameters take one least-squares solve for the start values; it lands
    where the iterative solver converges (relative to the standard errors)."""
    from shipid.identify.data import prepare_logs
    from shipid.identify.initial import equation_error_fit

    model = get_model(name)
    arrays, meas = prepare_logs(model, [f for f, _ in kcs_logs.values()])
    est = np.arange(model.np)
    p0 = model.params * 1.2
    prior = np.where(p0 != 0, 0.5 * np.abs(p0), 1.0)
    lin = equation_error_fit(model, arrays, meas, est, p0, prior, linear="auto")
    it = equation_error_fit(model, arrays, meas, est, p0, prior, linear=False, max_nfev=200)
    assert lin[2] == it[2]
    ok = np.isfinite(lin[1]) & (lin[1] > 0)
    assert ok.sum() >= model.np - 2
    dz = np.abs(lin[0] - it[0])[ok] / lin[1][ok]
    print(name, "max |linear - iterated| / se:", dz.max())
    assert dz.max() < 1e-6, dz
    np.testing.assert_allclose(lin[1], it[1], rtol=1e-4)


def test_a_run_that_would_not_fit_is_refused_with_the_numbers(kcs_problem, monkeypatch):
    """The smoother's storage is estimated before the filter starts; above the limit the run is refused
    with a message naming the need, the limit and what avoids it (a ValueError too: CLI exit 2)."""
    from shipid.identify._memory import MemoryLimitError, ekf_bytes

    B, N, nx, ne, nm = kcs_problem.shape
    need = ekf_bytes(B, N, nx + ne, nm, True)
    need32 = ekf_bytes(B, N, nx + ne, nm, True, itemsize=4)
    assert need > N * 4 * (nx + ne) ** 2 * 8 and need32 > N * (3 * 4 + 8) * (nx + ne) ** 2
    monkeypatch.setenv("SHIPID_MEMORY_LIMIT", str(need32 - 1))
    with pytest.raises(MemoryLimitError, match=r"needs ~.* GB .*float32.*above the limit .*SHIPID_MEMORY_LIMIT.*store=False"):
        run_ekf(kcs_problem, store=True)
    # float64 does not fit, float32 does: "auto" stores float32 and says so; "float64" refuses and names the way out
    monkeypatch.setenv("SHIPID_MEMORY_LIMIT", str(need - 1))
    with pytest.warns(RuntimeWarning, match="float32"):
        assert run_ekf(kcs_problem, store=True).P_post.dtype == np.float32
    with pytest.raises(MemoryLimitError, match=r"store_dtype='float32'"):
        run_ekf(kcs_problem, store=True, store_dtype="float64")
    assert isinstance(MemoryLimitError("x"), ValueError)
    run_ekf(kcs_problem, store=False)  # the filter alone fits
    monkeypatch.setenv("SHIPID_MEMORY_LIMIT", "1G")
    run_ekf(kcs_problem, store=True)
    monkeypatch.setenv("SHIPID_MEMORY_LIMIT", "lots")
    with pytest.raises(ValueError, match="SHIPID_MEMORY_LIMIT='lots'"):
        run_ekf(kcs_problem, store=True)


@pytest.mark.parametrize("hold", ["foh", "zoh"])
def test_benchmark_reference_solves_the_same_problem(kcs_truth, hold):
    """``benchmarks/bench_ekf.py``'s filterpy loop is the same filter as ``run_ekf`` (both paths), under
    the problem's input hold.  It once held the input (zero-order) while the identifier's problem is
    first-order hold: the printed "final-state agreement" was 9e-2, which looked like a state bug."""
    import importlib.util
    from pathlib import Path

    from shipid.synthetic import TrialRecipe, make_trial

    path = Path(__file__).resolve().parents[1] / "benchmarks" / "bench_ekf.py"
    spec = importlib.util.spec_from_file_location("bench_ekf", path)
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    log, _ = make_trial(kcs_truth, TrialRecipe("zz", "zigzag", 20.0, 40.0, ((0.0, 10.0), (20.0, 12.0)), psi_deg=20.0),
                        np.random.default_rng(1))
    with _jit.disabled():
        prob = EKFIdentifier(kcs_truth, n_passes=1, init="model").fit(log).problem_
    prob = replace(prob, input_hold=hold, gate=None)
    x_fp = bench.filterpy_loop(prob)
    for z in (run_ekf(prob, store=False).z_final[0], _numpy(lambda: run_ekf(prob, store=False)).z_final[0]):
        np.testing.assert_allclose(x_fp, z, rtol=1e-10, atol=1e-10 * np.abs(z).max())


def _numpy(fn):
    with _jit.disabled():
        return fn()


@pytest.mark.parametrize("name", ["kcs-response", "response-nl", "mmg"])
def test_simulate_on_the_compiled_equations_equals_numpy(name, kcs_logs):
    """``simulate`` with sampled inputs (the fit's consistency replay, ``replay``) runs the model's
    compiled equations: same trajectory as the numpy path to 1e-10, for one ship and a batch with
    per-member parameters, both input holds, sub-steps and a longer interval (h_max)."""
    from shipid.simulate import simulate

    model = shipid.get_model(name, "kcs") if name == "mmg" else get_model(name)
    frame = kcs_logs["kcs_zz_p20_rpm"][0].iloc[:300]
    t = frame["time"].to_numpy().copy()
    t[150:] += 0.35  # one long interval: more steps there
    U = frame[list(model.input_names)].to_numpy()
    if name == "mmg":
        U = np.column_stack([U[:, 0], np.full(len(t), 10.0)])
    x0 = frame[list(model.state_names)].to_numpy()[0]
    x0b = np.stack([x0, x0 * 1.01])
    pb = np.stack([model.params, model.params * 1.02])
    assert _kernel.replay_compiled(model, x0[None], t, U[None], model.params, np.full(len(t) - 1, 2), True) is not None
    for hold in ("foh", "zoh"):
        for args in ((x0, None), (x0b, pb)):
            kw = dict(substeps=2, input_hold=hold, h_max=0.06, params=args[1])
            fast = simulate(model, args[0], t, U if args[1] is None else np.stack([U, U]), **kw)
            slow = _numpy(lambda: simulate(model, args[0], t, U if args[1] is None else np.stack([U, U]), **kw))
            assert fast.success and slow.success and fast.meta == slow.meta
            _close(fast.x, slow.x, f"{name} {hold} states")
            _close(fast.u, slow.u, f"{name} {hold} inputs")


def test_float32_storage_and_the_error_it_puts_on_the_smoother(kcs_problem):
    """Covariances and transitions stored in float32 (the filter computes in float64): the filter's own
    outputs are unchanged (innovations, log-likelihood, final state: bit for bit), the stored arrays are
    the float64 ones rounded, and both smoothers (compiled and numpy) land within the stated errors of the
    float64 smoother within an error budget of 1e-3 smoothed standard deviations for the means and 1e-3 of
    the diagonal scale ``sqrt(P_ii P_jj)`` for the covariances -- negligible against the estimates' own
    uncertainty (measured on this problem: 1.3e-4 and 1.2e-4, printed; a first guess of 1e-6 did not hold:
    float32 keeps 7 digits of covariances whose condition number is large)."""
    prob = _batch(kcs_problem, 2, np.random.default_rng(9))
    ref = run_ekf(prob, store=True, store_dtype="float64")
    zs0, Ps0 = rts_smooth(ref)
    for fast in (True, False):
        if fast:
            out = run_ekf(prob, store=True, store_dtype="float32")
            zs, Ps = rts_smooth(out)
        else:
            out = _numpy(lambda: run_ekf(prob, store=True, store_dtype="float32"))
            zs, Ps = _numpy(lambda: rts_smooth(out))
        assert out.P_post.dtype == out.P_prior.dtype == out.F.dtype == np.float32 and out.z_post.dtype == np.float64
        assert zs.dtype == Ps.dtype == np.float64
        for f in ("innov", "loglik", "z_final", "P_final", "z_post"):
            _close(getattr(out, f), getattr(ref, f), f)
        for f in ("P_post", "P_prior", "F"):  # float64 rounded to float32 (one float32 ulp: 2^-23 relative)
            a, b = getattr(out, f).astype(float), getattr(ref, f)
            big = np.nanmax(np.abs(b))
            np.testing.assert_allclose(a, b, rtol=2.0 ** -22, atol=1e-12 * big, err_msg=f)
        sd = np.sqrt(np.diagonal(Ps0, axis1=2, axis2=3))
        ez = np.max(np.abs(zs - zs0) / sd)
        scale = np.sqrt(np.einsum("bnii,bnjj->bnij", np.abs(Ps0), np.abs(Ps0)))
        eP = np.max(np.abs(Ps - Ps0) / scale)
        print(f"float32 storage ({'compiled' if fast else 'numpy'}): smoothed means {ez:.2e} std, covariances {eP:.2e}")
        assert ez < 1e-3 and eP < 1e-3, (ez, eP)
