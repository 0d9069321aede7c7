"""Wind and current as parts of the model protocol: :func:`with_environment` / :class:`EnvironmentModel`.

The wrapper turns any ship model with a mass matrix (``mmg``, ``lowspeed``) into one that

* takes the **true wind** as two more inputs, ``wind_speed_true`` [m/s] and ``wind_dir_true`` [rad]
  (the earth-fixed direction the wind comes from, measured like the heading), forms the apparent wind
  from the ship's velocity over ground, and adds Fujiwara's wind force and moment
  (:class:`~shipid.environment.wind.WindForce`) to the hull equations, ``M^-1 (X_A, Y_A, N_A)``; the ten
  Fourier components of the wind coefficients are appended to the parameters (defaults: Fujiwara's
  regression for the ship's geometry), so an identifier estimates them like any coefficient;
* with ``current`` appends a uniform earth-fixed **current** ``(cx, cy)`` [m/s] as two states with zero
  dynamics: the hydrodynamics see the velocity through the water, the kinematics the velocity over
  ground.  For a constant, irrotational current the rigid-body equations written in the relative
  velocity are exact (T. I. Fossen (2011), *Handbook of Marine Craft Hydrodynamics and Motion Control*,
  Wiley, sec. 10.3, property 10.1), so the base model's equations are used unchanged on the relative
  velocity.  A ``"random-walk"`` current is the same model with process noise on ``cx, cy`` in the
  identifier (:meth:`EnvironmentModel.identifier_settings`).

``velocities`` says what the states ``u, v`` are: ``"ground"`` (default; velocities over ground, as a
GNSS-based log gives them -- the Esso Osaka logs: their ``u, v`` rotate onto the time derivative of the
logged positions with a mean residual below 1 mm/s in every run), or ``"water"`` (through the water, as
from a log or a model basin).  With ``"ground"`` the relative velocity is ``(u, v) - R(psi)^T c`` and the
time derivative of the rotated current term is added to ``u', v'``.

The equations are one scalar source, :mod:`shipid.environment._equations`, bound to the base model's
own equations module: numpy arrays here, and compiled by numba for batched right-hand
sides and inside the EKF kernel (:mod:`shipid._kernel`; the model declares the kernel protocol
like ``mmg``).  Jacobians: complex step through the whole wrapper (base equations, wind and current terms),
exact to rounding; compiled in the kernel.
"""
from __future__ import annotations

from typing import Mapping

import numpy as np

from .._jit import compiled
from ..models import get_model
from ..models.base import ComplexStepJacobians, Model, batch_shape
from ..models.mmg import DerivedConstants, ShipEquationsModel, components
from . import _equations as _eqe
from .wind import WIND_PARAM_NAMES, WindForce

__all__ = ["EnvironmentModel", "with_environment", "takes_environment", "CURRENT_KINDS", "WIND_INPUTS", "CURRENT_STATES"]

CURRENT_KINDS = (None, "constant", "random-walk")
WIND_INPUTS = ("wind_speed_true", "wind_dir_true")
CURRENT_STATES = ("cx", "cy")


def takes_environment(model) -> bool:
    """Whether a ship model (instance or class) can carry wind and current parts: a 3-DOF model with a mass
    matrix (``mmg``, ``lowspeed``); the response models (``kcs-response``, ``response-nl``) cannot."""
    cls = model if isinstance(model, type) else type(model)
    return issubclass(cls, ShipEquationsModel)


def with_environment(model: Model, *, wind=None, current: str | None = None, velocities: str = "ground",
                     current_walk: float = 2e-4) -> "EnvironmentModel":
    """``model`` with wind forces and/or a uniform current (see the module docstring).

    Parameters
    ----------
    model : Model
        A ship model with ``mass_matrix`` (``mmg``, ``lowspeed``) and states ``x, y, psi, u, v, r``.
    wind : WindForce, mapping, "esso-osaka-3m" or None
        Above-water geometry for Fujiwara's regression; None: no wind terms.
    current : {None, "constant", "random-walk"}
    velocities : {"ground", "water"}
        What the states ``u, v`` mean (and what a log's ``u, v`` measure).
    current_walk : float
        Random-walk intensity of the current [m/s/sqrt(s)] for ``"random-walk"`` (the identifier's
        process noise on ``cx, cy``).
    """
    return EnvironmentModel(None, base=model, wind=wind, current=current, velocities=velocities,
                            current_walk=current_walk)


class EnvironmentModel(DerivedConstants, ComplexStepJacobians, Model):
    """A ship model with wind inputs/parameters and current states (build with :func:`with_environment`).

    Parameters
    ----------
    params : mapping, array or None
        All parameters (base model's, then the wind components); None: the base model's values and
        Fujiwara's regression.
    base : Model or str
        The ship model, or a registered model name (built with ``base_options``).
    base_options : mapping, optional
    wind, current, velocities, current_walk
        See :func:`with_environment`.
    """

    name = "with-environment"

    def __init__(self, params=None, *, base="lowspeed", base_options: Mapping | None = None, wind=None,
                 current: str | None = None, velocities: str = "ground", current_walk: float = 2e-4,
                 base_params=None):
        if isinstance(base, str):
            base = get_model(base, base_params, **dict(base_options or {}))
        if not takes_environment(base):
            raise ValueError(f"with_environment: base must be a 3-DOF ship model with a mass matrix (mmg, lowspeed), got "
                             f"{getattr(base, 'name', type(base).__name__)!r}")
        if tuple(base.state_names[:6]) != ("x", "y", "psi", "u", "v", "r"):
            raise ValueError(f"with_environment: base model '{base.name}' must have states x, y, psi, u, v, r")
        if current not in CURRENT_KINDS:
            raise ValueError(f"current={current!r}: use one of {CURRENT_KINDS}")
        if velocities not in ("ground", "water"):
            raise ValueError(f"velocities={velocities!r}: use 'ground' or 'water'")
        if wind == "esso-osaka-3m":
            wind = WindForce.esso_osaka_3m()
        elif isinstance(wind, Mapping):
            wind = WindForce.from_mapping(wind)
        elif wind is not None and not isinstance(wind, WindForce):
            raise ValueError(f"wind must be a WindForce, a mapping of its fields, 'esso-osaka-3m' or None, got {wind!r}")
        if not current_walk >= 0:
            raise ValueError(f"current_walk must be >= 0, got {current_walk}")
        self.base, self.wind, self.current, self.velocities = base, wind, current, velocities
        self.current_walk = float(current_walk)
        self.state_names = tuple(base.state_names) + (CURRENT_STATES if current else ())
        self.input_names = tuple(base.input_names) + (WIND_INPUTS if wind is not None else ())
        self.param_names = tuple(base.param_names) + (WIND_PARAM_NAMES if wind is not None else ())
        self.units = {**base.units, "cx": "m/s", "cy": "m/s", "wind_speed_true": "m/s", "wind_dir_true": "rad",
                      **{k: "-" for k in WIND_PARAM_NAMES}}
        self._nb = base.np
        super().__init__(params)

    def _default_params(self) -> np.ndarray:
        wind = [self.wind.components()[k] for k in WIND_PARAM_NAMES] if self.wind is not None else []
        return np.concatenate([self.base.params, wind])

    lpp = property(lambda self: self.base.lpp)
    rudder_rate = property(lambda self: self.base.rudder_rate)
    design_speed = property(lambda self: self.base.design_speed)

    def options(self) -> dict:
        return {"base": self.base.name, "base_options": self.base.options(),
                "wind": self.wind.to_dict() if self.wind is not None else None, "current": self.current,
                "velocities": self.velocities, "current_walk": self.current_walk}

    def base_model(self) -> Model:
        """The base ship model with this model's base parameters (no environment terms)."""
        return self.base.with_params(self.params[: self._nb])

    def identifier_settings(self, current_std: float = 0.05) -> dict:
        """Keyword arguments for :class:`~shipid.identify.EKFIdentifier` that make the current states
        behave as declared: process noise ``current_walk`` (random walk) or 1e-7 m/s/sqrt(s)
        (constant) on ``cx, cy``, and an initial std ``current_std`` [m/s] at each log's start."""
        if not self.current:
            return {}
        q = self.current_walk if self.current == "random-walk" else 1e-7
        return {"process_std": {"cx": q, "cy": q}, "initial_state_std": {"cx": current_std, "cy": current_std}}

    def mass_matrix(self, params=None) -> np.ndarray:
        p = self._p(params)
        return self.base.mass_matrix(p[..., : self._nb])

    # ------------------------------------------------------------- equations
    particulars = property(lambda self: self.base.particulars, doc="The base ship's particulars.")
    #: The equation sets on the base model's equations (module-level cache; not stored: models pickle).
    _sets = property(lambda self: _eqe.equation_sets(self.base._eqm))

    def _kernel_constants(self) -> np.ndarray:
        """``P`` of :func:`shipid.environment._equations.env_derived`: base particulars, the number of base
        parameters, the flags (wind, current, ground velocities) and the wind force scales."""
        scales = self.wind.scales() if self.wind is not None else (0.0, 0.0, 0.0)
        return np.array(self.base._particulars_tuple() + (float(self._nb), float(self.wind is not None),
                                                          float(bool(self.current)),
                                                          float(self.velocities == "ground")) + tuple(scales))

    def _derived(self, p) -> tuple:
        return self._sets["numpy"]["env_derived"](p, tuple(self._kernel_constants().tolist()))

    def _compiled(self):
        return compiled(self._sets["real"], tag=self._sets["tag"])

    def _rhs(self, t, x, u, p):
        real = x.dtype.kind == "f" and u.dtype.kind == "f" and p.dtype.kind == "f"
        fast = self._compiled() if real else None
        if fast is not None:  # numba: one compiled loop over the samples
            lead = batch_shape(x, u, p)
            X = np.broadcast_to(x, lead + (self.nx,)).reshape(-1, self.nx)
            U = np.broadcast_to(u, lead + (self.nu,)).reshape(-1, self.nu)
            return fast["env_rhs_rows"](X, U, self._constant_rows(p, lead)).reshape(lead + (self.nx,))
        xc, uc = components(x), components(u)
        zero = 0.0 * xc[0]
        cx, cy = (xc[6], xc[7]) if self.current else (zero, zero)
        nb = self.base.nu
        ws, wd = (uc[nb], uc[nb + 1]) if self.wind is not None else (0.0, 0.0)
        rates = self._sets["numpy" if real else "complex"]["env_rates"]
        out = list(rates(xc[2], xc[3], xc[4], xc[5], cx, cy, uc[0], uc[1], ws, wd, self._derived_of(p, "arrays")))
        if self.current:
            out += [0.0 * cx, 0.0 * cy]
        shape = np.broadcast_shapes(*[np.shape(o) for o in out])
        return np.stack([np.broadcast_to(o, shape) for o in out], axis=-1)

    _python_replay = True  # 326 against 2344 us per sample (kcs-response with wind and current)

    # the compiled EKF kernel (shipid._kernel) runs the same equations
    @property
    def _equations(self):
        return self._sets["kernel"]

    def _equations_namespace(self) -> dict:
        cs = compiled(self._sets["cs"], self._sets["cmath"], tag=self._sets["tag"] + "__cs")
        return {} if cs is None else {"env_cs_columns": cs["env_cs_columns"], "env_derived_cs": cs["env_derived"]}

    def __repr__(self) -> str:
        return (f"<EnvironmentModel '{self.base.name}' + wind={'fujiwara' if self.wind is not None else None}, "
                f"current={self.current}, velocities={self.velocities}: {self.np} parameters>")
