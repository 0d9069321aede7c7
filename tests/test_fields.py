"""Routing fields: analytic values and gradients, gridded interpolation, builders, time switching, errors."""
import numpy as np
import pandas as pd
import pytest

from shipid.routing.fields import (AffineField, GridField, PiecewiseTimeField, UniformField, VortexField,
                                   as_field, course_from_math, linear_shear, math_from_course)


def _fd_grad(f, t, xy, h=1e-4):
    cols = []
    for j in range(2):
        d = np.zeros(2)
        d[j] = h
        cols.append((f.velocity(t, xy + d) - f.velocity(t, xy - d)) / (2 * h))
    return np.stack(cols, axis=-1)


def test_course_math_round_trip():
    th = np.radians([0, 90, 180, -90, 30])
    np.testing.assert_allclose(np.degrees(course_from_math(th)), [90, 0, 270, 180, 60])
    np.testing.assert_allclose(np.cos(math_from_course(course_from_math(th))), np.cos(th), atol=1e-12)
    np.testing.assert_allclose(np.sin(math_from_course(course_from_math(th))), np.sin(th), atol=1e-12)


def test_uniform_speed_direction_conventions():
    cur = UniformField.from_speed_direction(1.2, np.radians(0.0))  # towards north
    np.testing.assert_allclose(cur.w, [0.0, 1.2], atol=1e-12)
    wind = UniformField.from_speed_direction(7.0, np.radians(90.0), convention="from")  # from the east
    np.testing.assert_allclose(wind.w, [-7.0, 0.0], atol=1e-12)
    xy = np.zeros((3, 4, 2))
    assert cur.velocity(0.0, xy).shape == (3, 4, 2)
    assert cur.gradient(0.0, xy).shape == (3, 4, 2, 2)
    with pytest.raises(ValueError, match="convention"):
        UniformField.from_speed_direction(1, 0, convention="to")


def test_linear_shear_is_the_paper_current():
    f = linear_shear(-0.5)
    # paper: w = (0, k x1) with x1 north, x2 east -> east component k * north
    np.testing.assert_allclose(f.velocity(0.0, [3.66, -1.86]), [0.93, 0.0])
    np.testing.assert_allclose(f.gradient(0.0, [1.0, 2.0]), [[0.0, -0.5], [0.0, 0.0]])


def test_vortex_gradient_and_far_field():
    f = VortexField(gamma=50.0, rc=10.0, center=(5.0, -3.0))
    rng = np.random.default_rng(0)
    for xy in rng.normal(scale=15, size=(6, 2)):
        np.testing.assert_allclose(f.gradient(0.0, xy), _fd_grad(f, 0.0, xy), rtol=1e-6, atol=1e-9)
        assert abs(np.trace(f.gradient(0.0, xy))) < 1e-12  # divergence free
    far = np.array([5.0 + 500.0, -3.0])
    np.testing.assert_allclose(f.velocity(0.0, far), [0.0, 50.0 / (2 * np.pi * 500.0)], rtol=1e-9)
    np.testing.assert_allclose(f.velocity(0.0, [5.0, -3.0]), [0.0, 0.0])


def test_grid_reproduces_affine_field_exactly():
    truth = AffineField([[0.1, -0.3], [0.2, 0.05]], w0=(0.5, -0.2))
    x, y = np.linspace(-10, 10, 5), np.linspace(-5, 15, 7)
    X, Y = np.meshgrid(x, y)
    W = truth.velocity(0.0, np.stack([X, Y], -1))
    g = GridField(x, y, W[..., 0], W[..., 1])
    q = np.random.default_rng(1).uniform([-10, -5], [10, 15], size=(50, 2))
    np.testing.assert_allclose(g.velocity(0.0, q), truth.velocity(0.0, q), atol=1e-12)
    np.testing.assert_allclose(g.gradient(0.0, q), truth.gradient(0.0, q), atol=1e-12)
    # outside: nearest edge value (and zero gradient across the clipped axis)
    np.testing.assert_allclose(g.velocity(0.0, [20.0, 0.0]), truth.velocity(0.0, [10.0, 0.0]))
    gz = GridField(x, y, W[..., 0], W[..., 1], outside="zero")
    np.testing.assert_allclose(gz.velocity(0.0, [20.0, 0.0]), [0.0, 0.0])
    ge = GridField(x, y, W[..., 0], W[..., 1], outside="error")
    with pytest.raises(ValueError, match="x = 20.0 is outside the grid"):
        ge.velocity(0.0, [20.0, 0.0])


def test_grid_time_interpolation_is_linear():
    x, y = np.array([0.0, 1.0]), np.array([0.0, 1.0])
    U = np.stack([np.full((2, 2), 1.0), np.full((2, 2), 3.0)])
    g = GridField(x, y, U, -U, t=[0.0, 10.0])
    assert g.time_dependent
    np.testing.assert_allclose(g.velocity(2.5, [0.5, 0.5]), [1.5, -1.5])
    np.testing.assert_allclose(g.velocity(np.array([-5.0, 20.0]), np.array([[0.5, 0.5]] * 2)), [[1, -1], [3, -3]])


def test_grid_from_dataframe_shuffled_and_errors():
    x, y = np.linspace(0, 3, 4), np.linspace(0, 2, 3)
    X, Y = np.meshgrid(x, y)
    df = pd.DataFrame({"x": X.ravel(), "y": Y.ravel(), "u": (X + 2 * Y).ravel(), "v": (X * Y).ravel()})
    df = df.sample(frac=1.0, random_state=3).reset_index(drop=True)
    g = GridField.from_dataframe(df)
    np.testing.assert_allclose(g.velocity(0.0, [2.0, 1.0]), [4.0, 2.0])
    bad = df.copy()
    bad.loc[5, "u"] = np.nan
    with pytest.raises(ValueError, match=r"column 'u' row 5"):
        GridField.from_dataframe(bad, name="currents.csv")
    with pytest.raises(ValueError, match="missing column"):
        GridField.from_dataframe(df.drop(columns="v"))
    with pytest.raises(ValueError, match="nodes are missing"):
        GridField.from_dataframe(df.drop(index=3))
    with pytest.raises(ValueError, match="repeats the grid node"):
        GridField.from_dataframe(pd.concat([df, df.iloc[[0]]], ignore_index=True))


class _DA:  # the slice of xarray's DataArray API that from_xarray uses
    def __init__(self, values, dims):
        self.values, self.dims = np.asarray(values), dims

    def transpose(self, *dims):
        return _DA(np.transpose(self.values, [self.dims.index(d) for d in dims]), dims)


def test_grid_from_xarray_like_transposes_and_converts_datetimes():
    x, y = np.array([0.0, 10.0, 20.0]), np.array([0.0, 5.0])
    times = np.array(["2024-01-01T00:00", "2024-01-01T01:00"], dtype="datetime64[s]")
    u = np.zeros((3, 2, 2))  # stored as (x, y, time)
    u[..., 1] = 2.0
    ds = {"u": _DA(u, ("x", "y", "time")), "v": _DA(-u, ("x", "y", "time")), "x": _DA(x, ("x",)),
          "y": _DA(y, ("y",)), "time": _DA(times, ("time",))}
    g = GridField.from_xarray(ds, time="time")
    np.testing.assert_allclose(g.t, [0.0, 3600.0])
    np.testing.assert_allclose(g.velocity(1800.0, [5.0, 2.0]), [1.0, -1.0])
    with pytest.raises(ValueError, match="no variable"):
        GridField.from_xarray(ds, u="east")


def test_grid_validation_messages():
    with pytest.raises(ValueError, match="strictly increasing"):
        GridField([0, 2, 1], [0, 1], np.zeros((2, 3)), np.zeros((2, 3)))
    with pytest.raises(ValueError, match=r"expected \(2, 3\)"):
        GridField([0, 1, 2], [0, 1], np.zeros((3, 2)), np.zeros((3, 2)))
    u = np.zeros((2, 3))
    u[1, 2] = np.inf
    with pytest.raises(ValueError, match=r"index \(1, 2\)"):
        GridField([0, 1, 2], [0, 1], u, np.zeros((2, 3)))


def test_piecewise_time_field_switches_and_reports_breakpoints():
    f = PiecewiseTimeField([0.0, 48.0, 192.0], [UniformField(1, 0), UniformField(0, 1), linear_shear(0.1)])
    assert f.breakpoints == (48.0, 192.0)
    np.testing.assert_allclose(f.velocity(10.0, [0.0, 5.0]), [1, 0])
    np.testing.assert_allclose(f.velocity(48.0, [0.0, 5.0]), [0, 1])
    np.testing.assert_allclose(f.velocity(200.0, [0.0, 5.0]), [0.5, 0])
    t = np.array([0.0, 100.0, 300.0])
    np.testing.assert_allclose(f.velocity(t, np.array([[0.0, 5.0]] * 3)), [[1, 0], [0, 1], [0.5, 0]])
    np.testing.assert_allclose(f.gradient(300.0, [0.0, 0.0]), [[0, 0.1], [0, 0]])
    with pytest.raises(ValueError, match="increase strictly"):
        PiecewiseTimeField([0.0, 0.0], [UniformField(), UniformField()])


def test_sum_and_coercion():
    f = UniformField(1.0, 0.0) + (0.0, 2.0)
    np.testing.assert_allclose(f.velocity(0.0, [3.0, 3.0]), [1.0, 2.0])
    g = as_field(lambda t, xy: np.stack([xy[..., 1], -xy[..., 0]], -1))
    np.testing.assert_allclose(g.gradient(0.0, [1.0, 2.0]), [[0, 1], [-1, 0]], atol=1e-8)
    with pytest.raises(ValueError, match="cannot use str"):
        as_field("east")
    with pytest.raises(ValueError, match="last axis of length 2"):
        UniformField().velocity(0.0, [1.0, 2.0, 3.0])
