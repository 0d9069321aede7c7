"""The compiled EKF kernel on ``lowspeed`` and on the environment wrapper (wind inputs, wind coefficients
as parameters, current states) against the numpy path: every filter and smoother output agrees to 1e-10
(the comparison helpers of ``tests/test_kernel.py``).  Skipped when compilation is off."""
from __future__ import annotations

import functools

import numpy as np
import pytest

from shipid import _jit
from shipid.environment import with_environment
from shipid.environment.synthetic import NOISE_STD, environment_log
from shipid.identify import EKFIdentifier
from shipid import _kernel
from shipid.models import get_model

import test_kernel  # noqa: E402  (tests/ is on sys.path under pytest)
from test_kernel import _batch, _compare


pytestmark = pytest.mark.skipif(not _jit.enabled(), reason="numba not installed (extra 'fast') or SHIPID_JIT=0: "
                                "compiled EKF kernel not tested")

def _problem(model, logs, estimate, n, monkeypatch):
    """``test_kernel._problem`` (gaps, resets, irregular step) with the model's identifier settings (the
    current states' noise) and the synthetic logs' measurement noise."""
    kw = dict(model.identifier_settings()) if hasattr(model, "identifier_settings") else {}
    monkeypatch.setattr(test_kernel, "EKFIdentifier", functools.partial(EKFIdentifier, meas_std=NOISE_STD, **kw))
    return test_kernel._problem(model, logs, estimate, n=n)


HYD = ["X0F", "X0A", "Yv", "Yr", "Nv", "Nr", "CD", "k0", "CTa0", "YPa", "f_alpha"]


@pytest.fixture(scope="module")
def env_truth():
    return with_environment(get_model("lowspeed"), wind="esso-osaka-3m", current="constant")


@pytest.fixture(scope="module")
def env_logs(env_truth):
    return [environment_log(env_truth, seed=s, duration=80.0, current=(0.03, -0.02)).iloc[::5].reset_index(drop=True)
            for s in (1, 2)]


@pytest.mark.parametrize("terms", ["prior", "asymmetric", "rudder"])
def test_lowspeed_kernel_equals_numpy(env_logs, monkeypatch, terms):
    model = get_model("lowspeed")
    est = HYD
    if terms == "asymmetric":  # the MMG side-dependent gamma_R and drift-dependent wake on, dgammaR estimated
        model = model.with_params({"dgammaR": 0.1225, "C1": 2.0, "C2p": 1.6, "C2m": 1.1, "xP": -0.48})
        est = HYD + ["dgammaR"]
    elif terms == "rudder":  # side-dependent rudder force and rudder stall on, dfalpha estimated
        model = model.with_params({"dfalpha": 0.1, "kstall": 2.445})
        est = HYD + ["dfalpha"]
    logs = [lg[["time", "x", "y", "psi", "u", "v", "r", "delta", "n"]] for lg in env_logs]
    prob = _problem(model, logs, est, 120, monkeypatch)
    assert _kernel.filter_functions(model) is not None
    _compare(_batch(prob, 2, np.random.default_rng(11)))


@pytest.mark.slow  # compiles the kernel for each variant (~1 min each on a fresh cache)
@pytest.mark.parametrize("current, velocities", [("constant", "ground"), ("random-walk", "water"), (None, "ground")])
def test_environment_kernel_equals_numpy(env_logs, current, velocities, monkeypatch):
    model = with_environment(get_model("lowspeed"), wind="esso-osaka-3m", current=current, velocities=velocities)
    prob = _problem(model, env_logs, HYD + ["wX1", "wY1", "wN1", "wN2"], 120, monkeypatch)
    _compare(_batch(prob, 2, np.random.default_rng(12)))


@pytest.mark.slow
def test_environment_on_mmg_kernel_equals_numpy(env_logs, monkeypatch):
    base = get_model("mmg", "kvlcc2", lpp=3.0)
    model = with_environment(base, wind="esso-osaka-3m", current="constant")
    logs = [lg.assign(u=lg.u + 0.3, n=np.abs(lg.n) + 5.0) for lg in env_logs]
    prob = _problem(model, logs, ["Yv", "Yr", "Nv", "Nr", "R0", "wY1", "wN2"], 120, monkeypatch)
    _compare(_batch(prob, 2, np.random.default_rng(13)))
