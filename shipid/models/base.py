"""The one model protocol every dynamics model in shipid implements.

A model is a first-order ODE ``dx/dt = f(t, x, u, p)`` with named states ``x``,
inputs ``u`` and parameters ``p``.  Everything in the package -- the EKF
identifier, the simulator, the manoeuvre metrics, the optimal-control solvers,
routing and the glider study -- talks to models only through this class, so
each model's equations exist exactly once (in :meth:`Model._rhs`).

Conventions
-----------
* Arrays are 1-D per sample, with an optional leading batch axis:
  ``x`` has shape ``(..., nx)``, ``u`` ``(..., nu)``, ``p`` ``(..., np)``; the
  leading axes broadcast against each other.
* SI units and radians inside.
* Jacobians: ``jac_x`` -> ``(..., nx, nx)``, ``jac_p`` -> ``(..., nx, np)``,
  ``jac_u`` -> ``(..., nx, nu)``.  The base class provides central finite
  differences; models override them analytically where that is cheap.
"""
from __future__ import annotations

import copy
import json
from dataclasses import dataclass, field
from importlib import resources
from typing import Any, ClassVar, Mapping, Sequence

import numpy as np
import pandas as pd

__all__ = ["Model", "ParameterSet", "RecipeDefaults", "as_batch", "batch_shape"]


@dataclass(frozen=True)
class RecipeDefaults:
    """What the fit recipe (:func:`shipid.identify.fit_logs`) does for a model unless told otherwise.

    A model declares them as its class attribute ``recipe_defaults``, with the reason for each choice beside
    it, so that adding or changing a model touches only ``shipid/models/``.  Every field's empty value means
    "the recipe's generic rule".

    estimate : tuple of str or None
        Parameters the EKF stage estimates (None: all).
    fixed : tuple of str
        Parameters held at their start value.
    start : mapping
        Start values that replace the model's default parameter set (only when the caller names the model
        and gives no parameters of its own).
    init : str or None
        Start of the EKF stage (:class:`~shipid.identify.EKFIdentifier`'s ``init``; None: its equation-error
        start).
    samples_per_tau : int or None
        Samples per fastest time constant for the sampling step (None: the recipe's
        :data:`~shipid.identify.sampling.SAMPLES_PER_TAU`).
    sampling : (Lpp [m], step [s]) or None
        A fixed sampling step at a length, Froude-scaled (times as sqrt(L)) to the logs' Lpp; replaces the
        time-constant rule.
    substeps : int or None
        RK4 substeps per sampling interval that go with ``sampling``.
    process_std : (Lpp [m], {state: std per sqrt(s)}) or None
        Process noise at a length, Froude-scaled to the logs' Lpp (None: the identifier's default).
    neutral : bool
        Estimate the rudder's neutral angle from the straight approaches (models with ``delta0``).
    auto_refine : bool
        ``refine="auto"`` may refine (False: no refinement by default).
    seed_model : str or None
        ``start="staged"``: a registered model fitted first at the logs' scale whose coefficients start this
        one (the other terms start at 0).
    """

    estimate: tuple[str, ...] | None = None
    fixed: tuple[str, ...] = ()
    start: Mapping[str, float] = field(default_factory=dict)
    init: str | None = None
    samples_per_tau: int | None = None
    sampling: tuple[float, float] | None = None
    substeps: int | None = None
    process_std: tuple[float, Mapping[str, float]] | None = None
    neutral: bool = True
    auto_refine: bool = True
    seed_model: str | None = None


@dataclass(frozen=True)
class ParameterSet:
    """A published or documented parameter set for a model.

    Attributes
    ----------
    model : str
        Registered model name the set belongs to.
    name : str
        Short name of the set (``"table3"``, ``"synthetic-truth"``...).
    values : dict
        Parameter name -> value (SI units unless ``units`` says otherwise).
    source : str
        Citation of where the numbers come from.
    caveat : str
        What the user must know before trusting the numbers.
    extra : dict
        Anything else stored with the set (units, particulars, notes).
    """

    model: str
    name: str
    values: dict
    source: str = ""
    caveat: str = ""
    extra: dict = field(default_factory=dict)


def as_batch(a: Any) -> np.ndarray:
    """Return ``a`` as a float array (no copy when already float64)."""
    return np.asarray(a, dtype=float)


def batch_shape(*arrays: np.ndarray) -> tuple:
    """Broadcast leading (batch) shape of arrays whose last axis is a vector axis.

    ``batch_shape(x (B, nx), u (nu,), p (B, np))`` -> ``(B,)``.  Equivalent to
    ``np.broadcast_shapes(*(a.shape[:-1] for a in arrays))`` at a fraction of
    its cost (numpy's C broadcasting instead of a Python loop), which matters
    in right-hand sides evaluated per integration stage.
    """
    shape = arrays[0].shape[:-1]
    for a in arrays[1:]:
        if a.shape[:-1] != shape:
            return np.broadcast(*[a[..., :1] for a in arrays]).shape[:-1]
    return shape


class Model:
    """Base class of the model protocol.

    Subclasses set the class attributes ``name``, ``state_names``,
    ``input_names`` and ``param_names`` (or set the instance attributes of the
    same names in ``__init__`` for configurable models) and implement
    :meth:`_rhs`.  They may override :meth:`_jac_x`, :meth:`_jac_p` and
    :meth:`_jac_u` with analytic Jacobians.

    Parameters
    ----------
    params : mapping, array-like, str or None
        Parameter values: a ``{name: value}`` mapping (unnamed parameters take
        their defaults), an array in ``param_names`` order, the name of a
        parameter set shipped with the model, or ``None`` for the model's
        default parameter set.
    """

    name: ClassVar[str] = "model"
    state_names: tuple[str, ...] = ()
    input_names: tuple[str, ...] = ()
    param_names: tuple[str, ...] = ()
    #: Units of states/inputs/params for tables and reports (name -> unit).
    units: ClassVar[dict[str, str]] = {}
    #: Name of the parameter set used when ``params`` is None.
    default_parameter_set: ClassVar[str | None] = None
    #: Coefficients that are pure damping of their own motion (sway force in v, yaw moment in r: the
    #: linear and cross-flow terms), so dissipative, i.e. <= 0 in the model's sign convention, for any
    #: conventional hull.  The identifiers can keep them at their physical sign (``sign_bounds``).
    dissipative: ClassVar[tuple[str, ...]] = ()
    #: Signs that physics fixes under shipid's conventions (x ahead, y to starboard, positive rudder and yaw
    #: rate to starboard, n > 0 ahead): name -> ``(sign, why, channels, what to do)``.  A fit whose
    #: well-determined coefficient has the other sign has a data or set-up defect
    #: (:func:`shipid.identify.plausibility.physics_findings`).  Never a comparison with another ship's values.
    physics_signs: ClassVar[dict[str, tuple]] = {}
    #: Non-dimensional ranges (ITTC prime: lengths by L, times by L/U; models with non-dimensional
    #: coefficients as they are) spanned by the published ship sets the project holds: name ->
    #: ``(low, high, channels, what to do)``; the verdict widens them by
    #: :data:`shipid.identify.plausibility.RANGE_FACTOR`, so they hold at any scale and catch a unit confusion.
    physics_ranges: ClassVar[dict[str, tuple]] = {}
    #: The fit recipe's defaults for this model (:class:`RecipeDefaults`; the generic rules by default).
    recipe_defaults: ClassVar[RecipeDefaults] = RecipeDefaults()
    #: Package-relative folder of parameter-set JSON files.
    _parameter_dir: ClassVar[str] = "shipid.models.parameters"

    def __init__(self, params: Mapping[str, float] | Sequence[float] | np.ndarray | str | None = None):
        self.params = self._coerce_params(params)

    # ------------------------------------------------------------------ sizes
    @property
    def nx(self) -> int:
        """Number of states."""
        return len(self.state_names)

    @property
    def nu(self) -> int:
        """Number of inputs."""
        return len(self.input_names)

    @property
    def np(self) -> int:
        """Number of parameters."""
        return len(self.param_names)

    def state_index(self, name: str) -> int:
        """Index of state ``name`` (``ValueError`` naming the known states otherwise)."""
        return _index(self.state_names, name, "state", self.name)

    def input_index(self, name: str) -> int:
        """Index of input ``name``."""
        return _index(self.input_names, name, "input", self.name)

    def param_index(self, name: str) -> int:
        """Index of parameter ``name``."""
        return _index(self.param_names, name, "parameter", self.name)

    # ------------------------------------------------------------- parameters
    @classmethod
    def parameter_sets(cls) -> dict[str, ParameterSet]:
        """Parameter sets shipped for this model, keyed by set name."""
        out: dict[str, ParameterSet] = {}
        folder = resources.files(cls._parameter_dir)
        for entry in sorted(folder.iterdir(), key=lambda e: e.name):
            if not entry.name.endswith(".json"):
                continue
            doc = json.loads(entry.read_text(encoding="utf-8"))
            if doc.get("model") != cls.name:
                continue
            extra = {k: v for k, v in doc.items() if k not in ("model", "name", "params", "source", "caveat")}
            out[doc["name"]] = ParameterSet(
                model=doc["model"], name=doc["name"], values=dict(doc["params"]),
                source=doc.get("source", ""), caveat=doc.get("caveat", ""), extra=extra,
            )
        return out

    @classmethod
    def parameter_set(cls, name: str) -> ParameterSet:
        """One shipped parameter set by name."""
        sets = cls.parameter_sets()
        if name not in sets:
            raise ValueError(
                f"model '{cls.name}' has no parameter set '{name}'; available: {sorted(sets) or 'none'}"
            )
        return sets[name]

    def _default_params(self) -> np.ndarray:
        if self.default_parameter_set is not None:
            vals = self.parameter_set(self.default_parameter_set).values
            return np.array([float(vals.get(k, 0.0)) for k in self.param_names])
        return np.zeros(self.np)

    def _coerce_params(self, params) -> np.ndarray:
        if params is None:
            return self._default_params()
        if isinstance(params, str):
            vals = self.parameter_set(params).values
            return np.array([float(vals.get(k, 0.0)) for k in self.param_names])
        if isinstance(params, (Mapping, pd.Series)):
            items = dict(params.items())
            unknown = sorted(set(items) - set(self.param_names))
            if unknown:
                names = list(self.param_names)
                shown = ", ".join(names) if len(names) <= 8 else ", ".join(names[:6]) + f", ... ({len(names)} in all)"
                raise ValueError(f"model '{self.name}' has no parameter(s) {unknown[:5]}; its parameters are {shown} "
                                 f"(`shipid models` lists them)")
            base = self._default_params()
            for k, v in items.items():
                base[self.param_index(k)] = float(v)
            return base
        arr = np.array(params, dtype=float).reshape(-1)
        if arr.shape != (self.np,):
            raise ValueError(
                f"model '{self.name}' expects {self.np} parameters {list(self.param_names)}, got an array of shape {np.shape(params)}"
            )
        return arr

    def with_params(self, params) -> "Model":
        """A copy of this model with other parameter values (same forms as ``__init__``).

        A mapping updates only the named parameters of *this* model's values.
        """
        new = copy.copy(self)
        if isinstance(params, (Mapping, pd.Series)):
            vals = self.params.copy()
            for k, v in dict(params.items()).items():
                vals[self.param_index(k)] = float(v)
            new.params = vals
        else:
            new.params = self._coerce_params(params)
        return new

    def params_series(self) -> pd.Series:
        """Current parameters as a named :class:`pandas.Series`."""
        return pd.Series(self.params, index=list(self.param_names), name=self.name)

    # --------------------------------------------------------------- dynamics
    def _p(self, params) -> np.ndarray:
        return self.params if params is None else as_batch(params)

    def rhs(self, t, x, u, params=None) -> np.ndarray:
        """State derivative ``dx/dt``.

        Parameters
        ----------
        t : float or array
            Time [s] (models here are time-invariant unless stated).
        x : array, shape (..., nx)
        u : array, shape (..., nu)
        params : array, shape (..., np), optional
            Defaults to the model's own parameters.

        Returns
        -------
        array, shape (broadcast(...), nx)
        """
        return self._rhs(t, as_batch(x), as_batch(u), self._p(params))

    def jac_x(self, t, x, u, params=None) -> np.ndarray:
        """``d rhs / d x``, shape ``(..., nx, nx)``."""
        return self._jac_x(t, as_batch(x), as_batch(u), self._p(params))

    def jac_p(self, t, x, u, params=None, columns=None) -> np.ndarray:
        """``d rhs / d params``, shape ``(..., nx, np)``; with ``columns`` (parameter indices) only those
        columns, shape ``(..., nx, len(columns))`` (a model whose Jacobian costs per column computes no
        other, e.g. ``mmg``'s complex step)."""
        if columns is None:
            return self._jac_p(t, as_batch(x), as_batch(u), self._p(params))
        return self._jac_p_columns(t, as_batch(x), as_batch(u), self._p(params), np.asarray(columns, dtype=np.int64))

    def _jac_p_columns(self, t, x, u, p, columns):
        return self._jac_p(t, x, u, p)[..., columns]

    def jac_u(self, t, x, u, params=None) -> np.ndarray:
        """``d rhs / d u``, shape ``(..., nx, nu)``."""
        return self._jac_u(t, as_batch(x), as_batch(u), self._p(params))

    def _rhs_bound(self, p):
        """``f(t, x, u)`` equal to ``self._rhs(t, x, u, p)`` for the fixed parameters ``p``.

        Integrators call this once per run; a model may return a faster specialised callable
        (e.g. :class:`~shipid.models.mmg.MMGModel`'s compiled kernels with the parameter constants
        folded once).
        """
        rhs = self._rhs
        return lambda t, x, u: rhs(t, x, u, p)

    #: The model's equations for the compiled EKF kernel (:mod:`shipid._kernel`): functions
    #: (name -> function, dependency order, rebound by :func:`shipid._jit.rebind`) including the
    #: kernel protocol ``k_consts``, ``k_rhs``, ``k_jac`` (see :mod:`shipid.models._response_equations`).
    #: ``None``: no compiled path (the EKF uses numpy and says so once).
    _equations: ClassVar[dict | None] = None
    #: Without numba, replay one trajectory (:func:`shipid.simulate.simulate` with sampled inputs) by
    #: running :attr:`_equations` in the interpreter on floats (:func:`shipid._kernel.replay_compiled`):
    #: set where that was measured faster than the numpy path (small equations; the same values).
    _python_replay: ClassVar[bool] = False

    def _equations_namespace(self) -> dict:
        """Extra globals of :attr:`_equations` (e.g. already compiled helpers)."""
        return {}

    def _kernel_constants(self) -> np.ndarray:
        """Fixed constants ``P`` the kernel protocol receives (e.g. MMG particulars)."""
        return np.zeros(0)

    def _rhs(self, t, x, u, p) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError(f"{type(self).__name__} must implement _rhs")

    # finite-difference defaults -------------------------------------------
    def _fd(self, t, x, u, p, which: str) -> np.ndarray:
        args = [x, u, p]
        k = {"x": 0, "u": 1, "p": 2}[which]
        base = args[k]
        shape = batch_shape(x, u, p)
        n = base.shape[-1]
        cols = []
        for j in range(n):
            h = 1e-6 * (1.0 + np.abs(base[..., j]))
            plus, minus = base.copy(), base.copy()
            plus[..., j] += h
            minus[..., j] -= h
            a_p = list(args)
            a_m = list(args)
            a_p[k], a_m[k] = plus, minus
            d = (self._rhs(t, *a_p) - self._rhs(t, *a_m)) / (2 * h)[..., None]
            cols.append(np.broadcast_to(d, shape + (self.nx,)))
        if not cols:
            return np.zeros(shape + (self.nx, 0))
        return np.stack(cols, axis=-1)

    def _jac_x(self, t, x, u, p):
        return self._fd(t, x, u, p, "x")

    def _jac_p(self, t, x, u, p):
        return self._fd(t, x, u, p, "p")

    def _jac_u(self, t, x, u, p):
        return self._fd(t, x, u, p, "u")

    # ------------------------------------------------------------ conveniences
    def options(self) -> dict:
        """Keyword arguments (JSON-friendly) that rebuild this model besides its parameters,
        e.g. MMG particulars; stored in fit results as ``model_options``."""
        return {}

    def identifiability_notes(self, arrays, estimated) -> list[str]:
        """Model-specific identifiability warnings for a set of logs.

        ``arrays`` are :class:`shipid.identify.data.LogArrays` (inputs in
        ``.U`` columns ordered as ``input_names``); ``estimated`` the names
        of the estimated parameters.  The base model has none.
        """
        return []

    def describe(self) -> pd.DataFrame:
        """Table of the parameters: name, value, unit."""
        return pd.DataFrame(
            {"value": self.params, "unit": [self.units.get(k, "") for k in self.param_names]},
            index=pd.Index(list(self.param_names), name="parameter"),
        )

    def __repr__(self) -> str:
        return f"<{type(self).__name__} '{self.name}': states {list(self.state_names)}, inputs {list(self.input_names)}, {self.np} parameters>"


def _index(names: Sequence[str], name: str, kind: str, model: str) -> int:
    try:
        return list(names).index(name)
    except ValueError:
        raise ValueError(f"model '{model}' has no {kind} '{name}'; its {kind}s are {list(names)}") from None


def complex_step_jacobian(rhs, t, x, u, p, which: str, h: float = 1e-30) -> np.ndarray:
    """Jacobian of ``rhs(t, x, u, p)`` w.r.t. ``which`` (``"x"``, ``"u"`` or ``"p"``) by the complex step,
    all columns in one vectorised call: shape ``(..., nx, k)``, exact to rounding for equations written
    with complex-safe operations (branches on real parts)."""
    args = {"x": x, "u": u, "p": p}
    base = args[which]
    pert = base[..., None, :] + 1j * h * np.eye(base.shape[-1])
    a = {w: (pert if w == which else arr[..., None, :]) for w, arr in args.items()}
    return np.swapaxes(np.imag(rhs(t, a["x"], a["u"], a["p"])) / h, -1, -2)


class ComplexStepJacobians:
    """Mixin: a model's Jacobians by complex step of its own ``_rhs`` (:func:`complex_step_jacobian`),
    for models whose equations accept complex arrays and have no analytic Jacobians."""

    def _jac_x(self, t, x, u, p):
        return complex_step_jacobian(self._rhs, t, x, u, p, "x")

    def _jac_u(self, t, x, u, p):
        return complex_step_jacobian(self._rhs, t, x, u, p, "u")

    def _jac_p(self, t, x, u, p):
        return complex_step_jacobian(self._rhs, t, x, u, p, "p")


#: What fixes a rudder with the other sign, and one in the wrong unit (shared by the ship models).
RUDDER_SIGN_FIX = "rudder logged positive to port? pass --rudder-sign -1"
RUDDER_UNIT_FIX = "is the rudder in the unit the log declares? declare it (--units delta=deg) or convert the column"
#: A stern rudder (shipid: y to starboard, positive rudder to starboard): its lift pushes the stern to port, so
#: its sway force is negative and its yaw moment (bow to starboard) positive.
STERN_RUDDER_SIGNS = {
    "yaw": (+1, "positive (starboard) rudder must turn the ship to starboard", ("delta",), RUDDER_SIGN_FIX),
    "sway": (-1, "a stern rudder's sway force is to port for positive (starboard) rudder", ("delta",),
             RUDDER_SIGN_FIX),
}
OWN_DAMPING_SIGNS = {
    "sway": (-1, "a hull's own sway damping is negative", ("v",),
             "the fitted model is not physical (missing wind or current, drift beyond its range?): do not predict with it"),
    "yaw": (-1, "a hull's own yaw damping is negative", ("r",),
            "the fitted model is not physical (missing wind or current, drift beyond its range?): do not predict with it"),
}

