"""Model protocol: every registered model's analytic Jacobians against finite differences,
batch evaluation against a loop, parameter handling."""
import numpy as np
import pytest

from shipid.models import available_models, get_model
from shipid.models.base import Model


def _sample_point(model, rng, batch=()):
    x = rng.normal(size=batch + (model.nx,)) * 0.5
    u = rng.normal(size=batch + (model.nu,)) * 0.3
    for name, scale in (("u", 1.5), ("n", 10.0)):
        for names, arr in ((model.state_names, x), (model.input_names, u)):
            if name in names:
                arr[..., names.index(name)] = scale + 0.1 * rng.normal(size=batch)
    return x, u


@pytest.mark.parametrize("name", available_models())
def test_jacobians_match_finite_differences(name):
    model = get_model(name)
    rng = np.random.default_rng(0)
    for _ in range(5):
        x, u = _sample_point(model, rng)
        p = model.params * (1 + 0.1 * rng.normal(size=model.np))
        for which in ("x", "p", "u"):
            analytic = getattr(model, f"jac_{which}")(0.0, x, u, p)
            fd = Model._fd(model, 0.0, x, u, p, which)
            np.testing.assert_allclose(analytic, fd, rtol=1e-5, atol=1e-7, err_msg=f"{name} jac_{which}")


@pytest.mark.parametrize("name", available_models())
def test_batch_rhs_equals_loop(name):
    model = get_model(name)
    rng = np.random.default_rng(1)
    x, u = _sample_point(model, rng, batch=(7,))
    P = model.params * (1 + 0.05 * rng.normal(size=(7, model.np)))
    batch = model.rhs(0.0, x, u, P)
    jb = model.jac_x(0.0, x, u, P)
    for i in range(7):
        np.testing.assert_allclose(batch[i], model.rhs(0.0, x[i], u[i], P[i]), rtol=1e-12)
        np.testing.assert_allclose(jb[i], model.jac_x(0.0, x[i], u[i], P[i]), rtol=1e-12)


def test_params_forms_and_errors():
    m = get_model("kcs-response")
    assert m.np == 16 and m.params_series()["c2"] == pytest.approx(-0.8)
    t3 = get_model("kcs-response", "table3")
    assert t3.params_series()["b2"] == pytest.approx(7.2717)
    assert "turning circle" in m.parameter_set("table3").caveat
    m2 = m.with_params({"c3": 0.5})
    assert m2.params_series()["c3"] == 0.5 and m.params_series()["c3"] == pytest.approx(0.14)
    with pytest.raises(ValueError, match="no parameter"):
        m.with_params({"zz": 1.0})
    with pytest.raises(ValueError, match="expects 16 parameters"):
        get_model("kcs-response", [1.0, 2.0])
    with pytest.raises(ValueError, match="unknown model 'nope'"):
        get_model("nope")
