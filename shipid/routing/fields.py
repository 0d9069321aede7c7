"""Current and wind fields for routing: one interface for analytic and gridded fields.

Every field maps time and position to a horizontal velocity vector::

    w = field.velocity(t, xy)        # xy (..., 2) [m], t scalar or (...) [s] -> w (..., 2) [m/s]
    J = field.gradient(t, xy)        # (..., 2, 2), J[..., i, j] = d w_i / d x_j [1/s]

Frame: a local Cartesian frame, ``x`` east and ``y`` north [m] (the routing
modules use this frame everywhere; angles are math angles from east,
counter-clockwise; :func:`course_from_math` converts to a nautical course).
Any other consistent unit system works as long as it is used throughout
(the Zermelo paper example is also solved in nautical miles and hours in the
tests, to compare with the paper).

Fields provided
---------------
* :class:`UniformField` -- constant vector (optionally switched in time by
  :class:`PiecewiseTimeField`).
* :class:`AffineField` -- ``w = w0 + G @ (xy - xy0)``; :func:`linear_shear`
  builds the Zermelo-paper current ``w = (k y, 0)`` (Zwierzewicz).
* :class:`VortexField` -- Lamb--Oseen vortex (solid-body core, potential
  vortex outside), circulation ``Gamma`` [m^2/s], core radius ``rc`` [m].
* :class:`GridField` -- gridded ``u, v`` on a rectilinear grid, bilinear in
  space and linear in time; built from numpy arrays, from a long-format
  pandas frame (:meth:`GridField.from_dataframe`) or from an xarray-like
  dataset (:meth:`GridField.from_xarray`, duck-typed: xarray itself is not a
  dependency).
* :class:`PiecewiseTimeField` -- different fields on consecutive time
  intervals (the PSO paper's current that "turns at minute 8 and 32").
* :class:`FunctionField` -- any user callable.
* Fields add: ``current + tide`` is a :class:`SumField`.
"""
from __future__ import annotations

from typing import Callable, Sequence

import numpy as np

__all__ = [
    "Field", "UniformField", "AffineField", "linear_shear", "VortexField", "GridField",
    "PiecewiseTimeField", "FunctionField", "SumField", "as_field", "course_from_math",
    "math_from_course", "NM", "KNOT", "HOUR",
]

#: One international nautical mile [m].
NM = 1852.0
#: One knot [m/s].
KNOT = NM / 3600.0
#: One hour [s].
HOUR = 3600.0


def course_from_math(theta):
    """Nautical course (from north, clockwise, [0, 2 pi)) of a math angle [rad] (from east, ccw)."""
    return np.mod(np.pi / 2 - np.asarray(theta, dtype=float), 2 * np.pi)


def math_from_course(course):
    """Math angle (from east, counter-clockwise, (-pi, pi]) of a nautical course [rad]."""
    a = np.mod(np.pi / 2 - np.asarray(course, dtype=float), 2 * np.pi)
    return np.where(a > np.pi, a - 2 * np.pi, a)


def _bcast(w: np.ndarray, t, tail: int = 1) -> np.ndarray:
    """Broadcast ``w`` (shape (..., *tail)) against the shape of ``t`` (no copy when not needed)."""
    if np.ndim(t) == 0:
        return w
    shape = np.broadcast_shapes(w.shape[:w.ndim - tail], np.shape(t))
    if shape == w.shape[:w.ndim - tail]:
        return w
    return np.broadcast_to(w, shape + w.shape[w.ndim - tail:]).copy()


def _xy(xy) -> np.ndarray:
    xy = np.asarray(xy, dtype=float)
    if xy.shape[-1:] != (2,):
        raise ValueError(f"positions must have a last axis of length 2 (x east, y north) [m]; got shape {xy.shape}")
    return xy


class Field:
    """Base class: a horizontal velocity field ``w(t, x, y)``.

    Subclasses implement :meth:`_velocity` (and :meth:`_gradient` where it is
    cheap; the default is a central difference with step ``fd_step`` [m]).
    """

    #: True when the field changes with time.
    time_dependent: bool = False
    #: Step [m] of the finite-difference gradient fallback.
    fd_step: float = 1e-3

    def velocity(self, t, xy) -> np.ndarray:
        """Velocity [m/s], shape ``(..., 2)``, at time ``t`` [s] and positions ``xy`` (..., 2) [m]."""
        xy = _xy(xy)
        return self._velocity(np.asarray(t, dtype=float), xy)

    __call__ = velocity

    def gradient(self, t, xy) -> np.ndarray:
        """Spatial Jacobian ``J[..., i, j] = d w_i / d x_j`` [1/s], shape ``(..., 2, 2)``."""
        xy = _xy(xy)
        return self._gradient(np.asarray(t, dtype=float), xy)

    @property
    def breakpoints(self) -> tuple[float, ...]:
        """Times [s] at which the field jumps (integrators split their steps there)."""
        return ()

    def max_speed(self, bbox: Sequence[float], t=0.0, n: int = 41) -> float:
        """Largest ``|w|`` [m/s] sampled on an ``n x n`` grid over ``bbox = (xmin, xmax, ymin, ymax)``."""
        xs = np.linspace(bbox[0], bbox[1], n)
        ys = np.linspace(bbox[2], bbox[3], n)
        X, Y = np.meshgrid(xs, ys)
        w = self.velocity(t, np.stack([X, Y], axis=-1))
        return float(np.nanmax(np.hypot(w[..., 0], w[..., 1])))

    def _velocity(self, t, xy):  # pragma: no cover - abstract
        raise NotImplementedError

    def _gradient(self, t, xy):
        h = self.fd_step
        cols = []
        for j in range(2):
            d = np.zeros(2)
            d[j] = h
            cols.append((self._velocity(t, xy + d) - self._velocity(t, xy - d)) / (2 * h))
        return np.stack(cols, axis=-1)

    def __add__(self, other: "Field") -> "SumField":
        return SumField([self, as_field(other)])

    def plot(self, bbox: Sequence[float], t: float = 0.0, n: int = 21, ax=None, **quiver_kw):
        """Quiver plot over ``bbox = (xmin, xmax, ymin, ymax)`` [m]; returns the axes."""
        import matplotlib.pyplot as plt  # only when plotting: pyplot takes ~1 s to import

        ax = ax or plt.gca()
        xs = np.linspace(bbox[0], bbox[1], n)
        ys = np.linspace(bbox[2], bbox[3], n)
        X, Y = np.meshgrid(xs, ys)
        w = self.velocity(t, np.stack([X, Y], axis=-1))
        ax.quiver(X, Y, w[..., 0], w[..., 1], **quiver_kw)
        ax.set_aspect("equal")
        return ax


class UniformField(Field):
    """Constant velocity ``(wx, wy)`` [m/s].

    Use :meth:`from_speed_direction` for a speed and a direction.
    """

    def __init__(self, wx: float = 0.0, wy: float = 0.0):
        self.w = np.array([float(wx), float(wy)])
        if not np.all(np.isfinite(self.w)):
            raise ValueError(f"UniformField: velocity must be finite, got {self.w.tolist()}")

    @classmethod
    def from_speed_direction(cls, speed: float, direction: float, *, convention: str = "towards") -> "UniformField":
        """Field of ``speed`` [m/s] along nautical ``direction`` [rad, from north, clockwise].

        ``convention="towards"`` (oceanographic, currents): the direction the
        flow goes to; ``"from"`` (meteorological, wind): where it comes from.
        """
        if convention not in ("towards", "from"):
            raise ValueError(f"convention must be 'towards' or 'from', got {convention!r}")
        th = math_from_course(direction)
        if convention == "from":
            th = th + np.pi
        return cls(speed * np.cos(th), speed * np.sin(th))

    def _velocity(self, t, xy):
        shape = np.broadcast_shapes(xy.shape[:-1], np.shape(t))
        return np.broadcast_to(self.w, shape + (2,)).copy()

    def _gradient(self, t, xy):
        shape = np.broadcast_shapes(xy.shape[:-1], np.shape(t))
        return np.zeros(shape + (2, 2))

    def __repr__(self):
        return f"UniformField(wx={self.w[0]:g}, wy={self.w[1]:g})"


class AffineField(Field):
    """Linear field ``w = w0 + G @ (xy - origin)`` with constant gradient ``G`` [1/s]."""

    def __init__(self, G, w0=(0.0, 0.0), origin=(0.0, 0.0)):
        self.G = np.asarray(G, dtype=float).reshape(2, 2)
        self.w0 = np.asarray(w0, dtype=float).reshape(2)
        self.origin = np.asarray(origin, dtype=float).reshape(2)

    def _velocity(self, t, xy):
        w = self.w0 + (xy - self.origin) @ self.G.T
        return _bcast(w, t)

    def _gradient(self, t, xy):
        if np.ndim(t) == 0:
            return np.broadcast_to(self.G, xy.shape[:-1] + (2, 2))
        shape = np.broadcast_shapes(xy.shape[:-1], np.shape(t))
        return np.broadcast_to(self.G, shape + (2, 2))

    def __repr__(self):
        return f"AffineField(G={self.G.tolist()}, w0={self.w0.tolist()})"


def linear_shear(k: float) -> AffineField:
    """The Zermelo paper's current (Zwierzewicz): east component ``k * y``, no north component.

    In the paper's coordinates (``x1`` north, ``x2`` east, heading from
    ``x1`` towards ``x2`` = nautical course) the current is ``w = (0, k x1)``;
    in this package's east/north frame that is ``w = (k y, 0)``.  ``k`` [1/s]
    (the paper's -0.5 1/h is ``-0.5 / 3600``).
    """
    return AffineField([[0.0, float(k)], [0.0, 0.0]])


class VortexField(Field):
    """Lamb--Oseen vortex centred at ``center`` [m].

    Tangential speed ``v(r) = Gamma / (2 pi r) (1 - exp(-r^2 / rc^2))``
    (counter-clockwise for ``Gamma > 0``); peak speed ~ ``0.1 Gamma / rc`` at
    ``r ~ 1.12 rc``.  Smooth everywhere, so the PMP costates are defined.
    """

    def __init__(self, gamma: float, rc: float, center=(0.0, 0.0)):
        if rc <= 0:
            raise ValueError(f"VortexField: core radius rc must be > 0 m, got {rc}")
        self.gamma = float(gamma)
        self.rc = float(rc)
        self.center = np.asarray(center, dtype=float).reshape(2)

    def _velocity(self, t, xy):
        d = xy - self.center
        r2 = np.sum(d * d, axis=-1)
        r2s = np.where(r2 > 0, r2, 1.0)
        f = np.where(r2 > 0, self.gamma / (2 * np.pi * r2s) * -np.expm1(-r2 / self.rc**2),
                     self.gamma / (2 * np.pi * self.rc**2))
        w = np.stack([-f * d[..., 1], f * d[..., 0]], axis=-1)
        return _bcast(w, t)

    def _gradient(self, t, xy):
        d = xy - self.center
        r2 = np.sum(d * d, axis=-1)
        a2 = self.rc**2
        r2s = np.where(r2 > 1e-12 * a2, r2, 1.0)
        e = np.exp(-r2 / a2)
        f = np.where(r2 > 1e-12 * a2, self.gamma / (2 * np.pi * r2s) * (1 - e), self.gamma / (2 * np.pi * a2))
        # df/d(r2)
        fp = np.where(r2 > 1e-12 * a2,
                      self.gamma / (2 * np.pi) * (e / (a2 * r2s) - (1 - e) / r2s**2),
                      -self.gamma / (4 * np.pi * a2**2))
        dx, dy = d[..., 0], d[..., 1]
        J = np.empty(d.shape[:-1] + (2, 2))
        J[..., 0, 0] = -2 * fp * dx * dy
        J[..., 0, 1] = -f - 2 * fp * dy * dy
        J[..., 1, 0] = f + 2 * fp * dx * dx
        J[..., 1, 1] = 2 * fp * dx * dy
        return _bcast(J, t, 2)


class GridField(Field):
    """Gridded velocity, bilinear in space, linear in time.

    Parameters
    ----------
    x : array (nx,)
        Strictly increasing east coordinates of the grid [m].
    y : array (ny,)
        Strictly increasing north coordinates [m].
    u, v : array (ny, nx) or (nt, ny, nx)
        East and north components [m/s], indexed ``[time, y, x]`` (the
        ``meshgrid(x, y)`` layout).
    t : array (nt,), optional
        Strictly increasing times [s] when ``u``/``v`` have a time axis;
        before the first and after the last time the end values hold.
    outside : {"nearest", "zero", "error"}
        Positions outside the grid take the nearest edge value (default),
        zero velocity, or raise ``ValueError``.
    """

    def __init__(self, x, y, u, v, t=None, *, outside: str = "nearest"):
        self.x = self._axis(x, "x")
        self.y = self._axis(y, "y")
        u = np.asarray(u, dtype=float)
        v = np.asarray(v, dtype=float)
        if t is None:
            want = (self.y.size, self.x.size)
            self.t = None
        else:
            self.t = self._axis(t, "t", min_len=1)
            want = (self.t.size, self.y.size, self.x.size)
        for name, arr in (("u", u), ("v", v)):
            if arr.shape != want:
                raise ValueError(
                    f"GridField: {name} has shape {arr.shape}, expected {want} "
                    f"({'(nt, ny, nx)' if t is not None else '(ny, nx)'}, indexed [time, y, x])"
                )
            bad = np.argwhere(~np.isfinite(arr))
            if bad.size:
                raise ValueError(f"GridField: {name} has a non-finite value at index {tuple(int(i) for i in bad[0])}; fill or drop it")
        if outside not in ("nearest", "zero", "error"):
            raise ValueError(f"GridField: outside must be 'nearest', 'zero' or 'error', got {outside!r}")
        self.outside = outside
        self.uv = np.stack([u, v], axis=-1)  # (..., ny, nx, 2)
        self.time_dependent = self.t is not None and self.t.size > 1

    @staticmethod
    def _axis(a, name, min_len=2):
        a = np.asarray(a, dtype=float).reshape(-1)
        if a.size < min_len:
            raise ValueError(f"GridField: axis {name} needs at least {min_len} values, got {a.size}")
        if not np.all(np.isfinite(a)):
            raise ValueError(f"GridField: axis {name} has non-finite values")
        if a.size > 1 and not np.all(np.diff(a) > 0):
            i = int(np.argmax(np.diff(a) <= 0))
            raise ValueError(f"GridField: axis {name} must be strictly increasing; value {a[i + 1]} at index {i + 1} follows {a[i]}")
        return a

    # -------------------------------------------------------------- builders
    @classmethod
    def from_dataframe(cls, df, *, x: str = "x", y: str = "y", u: str = "u", v: str = "v",
                       t: str | None = None, outside: str = "nearest", name: str = "data frame") -> "GridField":
        """Build from a long-format frame with one row per grid node (and time).

        Columns ``x, y, u, v`` (and ``t``) by default; every (t, y, x)
        combination must appear exactly once.
        """
        cols = [c for c in (x, y, u, v, t) if c is not None]
        missing = [c for c in cols if c not in df.columns]
        if missing:
            raise ValueError(f"{name}: missing column(s) {missing}; columns are {list(df.columns)}")
        for c in cols:
            vals = np.asarray(df[c], dtype=float)
            bad = np.flatnonzero(~np.isfinite(vals))
            if bad.size:
                raise ValueError(f"{name}: column '{c}' row {int(bad[0])}: value {vals[bad[0]]} is not finite; fill or drop the row")
        keys = [k for k in (t, y, x) if k is not None]
        dup = df.duplicated(subset=keys)
        if dup.any():
            row = int(np.flatnonzero(dup.to_numpy())[0])
            raise ValueError(f"{name}: row {row} repeats the grid node {df.iloc[row][keys].to_dict()}; each node must appear once")
        xs = np.unique(np.asarray(df[x], dtype=float))
        ys = np.unique(np.asarray(df[y], dtype=float))
        ts = None if t is None else np.unique(np.asarray(df[t], dtype=float))
        shape = (ys.size, xs.size) if t is None else (ts.size, ys.size, xs.size)
        if len(df) != int(np.prod(shape)):
            raise ValueError(f"{name}: {len(df)} rows do not fill a {' x '.join(map(str, shape))} grid; some nodes are missing")
        ix = np.searchsorted(xs, np.asarray(df[x], dtype=float))
        iy = np.searchsorted(ys, np.asarray(df[y], dtype=float))
        U = np.empty(shape)
        V = np.empty(shape)
        if t is None:
            U[iy, ix] = np.asarray(df[u], dtype=float)
            V[iy, ix] = np.asarray(df[v], dtype=float)
        else:
            it = np.searchsorted(ts, np.asarray(df[t], dtype=float))
            U[it, iy, ix] = np.asarray(df[u], dtype=float)
            V[it, iy, ix] = np.asarray(df[v], dtype=float)
        return cls(xs, ys, U, V, ts, outside=outside)

    @classmethod
    def from_xarray(cls, ds, *, u: str = "u", v: str = "v", x: str = "x", y: str = "y",
                    time: str | None = None, outside: str = "nearest") -> "GridField":
        """Build from an xarray-like dataset (``ds[name].transpose(*dims).values``, ``ds[coord].values``).

        Time coordinates that are datetimes are converted to seconds since
        the first time.
        """
        dims = (time, y, x) if time is not None else (y, x)
        try:
            U = np.asarray(ds[u].transpose(*dims).values, dtype=float)
            V = np.asarray(ds[v].transpose(*dims).values, dtype=float)
            xs = np.asarray(ds[x].values, dtype=float)
            ys = np.asarray(ds[y].values, dtype=float)
            ts = None
            if time is not None:
                tv = np.asarray(ds[time].values)
                if np.issubdtype(tv.dtype, np.datetime64):
                    ts = (tv - tv[0]) / np.timedelta64(1, "s")
                else:
                    ts = tv.astype(float)
        except KeyError as exc:
            raise ValueError(f"dataset has no variable/coordinate {exc}; pass u=, v=, x=, y=, time= names") from None
        return cls(xs, ys, U, V, ts, outside=outside)

    # -------------------------------------------------------------- evaluate
    def _locate(self, axis, q, name):
        n = axis.size
        if self.outside == "error":
            bad = (q < axis[0]) | (q > axis[-1])
            if np.any(bad):
                val = np.asarray(q)[bad].ravel()[0]
                raise ValueError(f"GridField: {name} = {val} is outside the grid [{axis[0]}, {axis[-1]}]")
        qc = np.clip(q, axis[0], axis[-1])
        i = np.clip(np.searchsorted(axis, qc, side="right") - 1, 0, n - 2)
        h = axis[i + 1] - axis[i]
        s = (qc - axis[i]) / h
        inside = (q >= axis[0]) & (q <= axis[-1])
        return i, s, h, inside

    def _time_slices(self, t, shape):
        if self.t is None:
            return [(self.uv, np.ones(shape), None)]
        if self.t.size == 1:
            return [(self.uv[0], np.ones(shape), None)]
        tt = np.broadcast_to(np.clip(t, self.t[0], self.t[-1]), shape)
        k = np.clip(np.searchsorted(self.t, tt, side="right") - 1, 0, self.t.size - 2)
        a = (tt - self.t[k]) / (self.t[k + 1] - self.t[k])
        return [(self.uv, 1 - a, k), (self.uv, a, k + 1)]

    def _eval(self, t, xy, want_grad):
        shape = np.broadcast_shapes(xy.shape[:-1], np.shape(t))
        X = np.broadcast_to(xy[..., 0], shape)
        Y = np.broadcast_to(xy[..., 1], shape)
        i, sx, hx, inx = self._locate(self.x, X, "x")
        j, sy, hy, iny = self._locate(self.y, Y, "y")
        w = np.zeros(shape + (2,))
        dwx = np.zeros(shape + (2,))
        dwy = np.zeros(shape + (2,))
        for arr, wt, k in self._time_slices(t, shape):
            if k is None:
                c00, c10, c01, c11 = arr[j, i], arr[j, i + 1], arr[j + 1, i], arr[j + 1, i + 1]
            else:
                c00, c10, c01, c11 = arr[k, j, i], arr[k, j, i + 1], arr[k, j + 1, i], arr[k, j + 1, i + 1]
            a, b = sx[..., None], sy[..., None]
            wt = wt[..., None]
            w += wt * ((1 - a) * (1 - b) * c00 + a * (1 - b) * c10 + (1 - a) * b * c01 + a * b * c11)
            if want_grad:
                dwx += wt * ((1 - b) * (c10 - c00) + b * (c11 - c01)) / hx[..., None]
                dwy += wt * ((1 - a) * (c01 - c00) + a * (c11 - c10)) / hy[..., None]
        inside = inx & iny
        if self.outside == "zero":
            w = np.where(inside[..., None], w, 0.0)
        if want_grad:
            # outside the grid the ("nearest") value is constant along the clipped axis
            dwx = np.where(inx[..., None], dwx, 0.0)
            dwy = np.where(iny[..., None], dwy, 0.0)
            if self.outside == "zero":
                dwx = np.where(inside[..., None], dwx, 0.0)
                dwy = np.where(inside[..., None], dwy, 0.0)
            return np.stack([dwx, dwy], axis=-1)
        return w

    def _velocity(self, t, xy):
        return self._eval(t, xy, False)

    def _gradient(self, t, xy):
        return self._eval(t, xy, True)

    def __repr__(self):
        nt = "" if self.t is None else f", nt={self.t.size}"
        return f"GridField(nx={self.x.size}, ny={self.y.size}{nt})"


class PiecewiseTimeField(Field):
    """``fields[i]`` holds on ``times[i] <= t < times[i+1]`` (``times[0]`` may be ``-inf``).

    Parameters
    ----------
    times : sequence of float
        Strictly increasing start times [s] of each piece.
    fields : sequence of Field
        One field per start time.
    """

    time_dependent = True

    def __init__(self, times: Sequence[float], fields: Sequence[Field]):
        self.times = np.asarray(times, dtype=float).reshape(-1)
        self.fields = [as_field(f) for f in fields]
        if self.times.size != len(self.fields) or not self.fields:
            raise ValueError(f"PiecewiseTimeField: need one start time per field, got {self.times.size} times and {len(self.fields)} fields")
        if np.any(np.diff(self.times) <= 0):
            raise ValueError(f"PiecewiseTimeField: start times must increase strictly, got {self.times.tolist()}")

    @property
    def breakpoints(self):
        bps = set(float(t) for t in self.times[1:])
        for f in self.fields:
            bps.update(f.breakpoints)
        return tuple(sorted(bps))

    def at(self, t: float) -> Field:
        """The field piece active at time ``t`` [s]."""
        k = int(np.clip(np.searchsorted(self.times, t, side="right") - 1, 0, len(self.fields) - 1))
        return self.fields[k]

    def _piecewise(self, t, xy, method):
        shape = np.broadcast_shapes(xy.shape[:-1], np.shape(t))
        k = np.clip(np.searchsorted(self.times, np.broadcast_to(t, shape), side="right") - 1, 0, len(self.fields) - 1)
        out = None
        for i, f in enumerate(self.fields):
            mask = k == i
            if not np.any(mask):
                continue
            val = getattr(f, method)(t, xy)
            val = np.broadcast_to(val, shape + val.shape[len(val.shape) - (1 if method == "_velocity" else 2):])
            if out is None:
                out = np.zeros(val.shape)
            m = mask.reshape(mask.shape + (1,) * (val.ndim - mask.ndim))
            out = np.where(m, val, out)
        return out

    def _velocity(self, t, xy):
        return self._piecewise(t, xy, "_velocity")

    def _gradient(self, t, xy):
        return self._piecewise(t, xy, "_gradient")


class FunctionField(Field):
    """A user callable ``func(t, xy) -> (..., 2)`` [m/s], with an optional ``jac(t, xy) -> (..., 2, 2)``."""

    def __init__(self, func: Callable, jac: Callable | None = None, *, time_dependent: bool = True):
        self.func = func
        self.jac = jac
        self.time_dependent = time_dependent

    def _velocity(self, t, xy):
        return np.asarray(self.func(t, xy), dtype=float)

    def _gradient(self, t, xy):
        if self.jac is None:
            return super()._gradient(t, xy)
        return np.asarray(self.jac(t, xy), dtype=float)


class SumField(Field):
    """Sum of fields (e.g. a tidal stream plus an eddy)."""

    def __init__(self, fields: Sequence[Field]):
        self.fields = [as_field(f) for f in fields]
        self.time_dependent = any(f.time_dependent for f in self.fields)

    @property
    def breakpoints(self):
        return tuple(sorted({b for f in self.fields for b in f.breakpoints}))

    def _velocity(self, t, xy):
        return sum(f._velocity(t, xy) for f in self.fields)

    def _gradient(self, t, xy):
        return sum(f._gradient(t, xy) for f in self.fields)


def as_field(obj) -> Field:
    """Coerce ``obj`` to a :class:`Field`: a Field, ``None`` (still water), a 2-vector, or a callable."""
    if isinstance(obj, Field):
        return obj
    if obj is None:
        return UniformField(0.0, 0.0)
    if callable(obj):
        return FunctionField(obj)
    try:
        arr = np.asarray(obj, dtype=float)
    except (TypeError, ValueError):
        arr = None
    if arr is not None and arr.shape == (2,):
        return UniformField(*arr)
    raise ValueError(f"cannot use {type(obj).__name__} {obj!r} as a field; pass a Field, a (wx, wy) pair [m/s] or a callable(t, xy)")
