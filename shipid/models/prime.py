"""Froude (prime) system for models with dimensional SI coefficients.

A response model's coefficients are dimensional and belong to one ship length ``L``.  Each has SI
dimension ``m^a s^b`` (rps counting as 1/s); its prime (Froude non-dimensional) value is
``c' = c / (L^a (L/g)^(b/2))`` (lengths made non-dimensional by ``L``, times by ``sqrt(L/g)``, as in the
Froude number ``U / sqrt(g L)``).  Under Froude scaling to ``lam`` times the length every coefficient
therefore scales by ``lam^(a + b/2)``, and the scaled model's states, inputs and time follow
:mod:`shipid.scaling` exactly (lengths x lam, speeds and time x sqrt(lam), rates and rps / sqrt(lam)).

:class:`FroudeScaled` gives a model class ``lpp`` / ``design_speed`` / ``rudder_rate`` attributes,
:meth:`~FroudeScaled.to_prime`, :meth:`~FroudeScaled.from_prime` and :meth:`~FroudeScaled.scaled`
from one class attribute, ``prime_exponents`` (name -> ``(a, b)``).
"""
from __future__ import annotations

from typing import ClassVar

import numpy as np

__all__ = ["FroudeScaled", "G"]

G = 9.80665  # m/s^2, standard gravity (Froude non-dimensionalisation)


class FroudeScaled:
    """Mixin for a :class:`~shipid.models.base.Model` with dimensional coefficients of one ship length.

    The class sets ``prime_exponents``: for every parameter its SI dimension ``(a, b)`` = ``m^a s^b``.
    The model's ``__init__`` calls :meth:`_init_ship` after ``Model.__init__``.
    """

    prime_exponents: ClassVar[dict[str, tuple[int, int]]] = {}

    def _init_ship(self, params, lpp, design_speed=None, rudder_rate=None) -> None:
        """Set ``lpp`` [m], ``design_speed`` [m/s], ``rudder_rate`` [rad/s].  A named parameter set (or the
        default) brings its own ship (``operating_point``: ``lpp_m``, ``u0_m_s``, ``rudder_rate_deg_s``)
        and is Froude-scaled from it to ``lpp``; coefficients given as a mapping or array are taken as they
        are (they belong to the ship of length ``lpp``).  ``design_speed`` / ``rudder_rate`` given here
        replace those of the set."""
        self.lpp = self.design_speed = self.rudder_rate = None
        named = params is None or isinstance(params, str)
        op = self.parameter_set(params or self.default_parameter_set).extra.get("operating_point", {}) if named else {}
        if "lpp_m" in op:
            self.lpp = float(op["lpp_m"])
            self.design_speed = float(op["u0_m_s"]) if "u0_m_s" in op else None
            self.rudder_rate = float(np.radians(op["rudder_rate_deg_s"])) if "rudder_rate_deg_s" in op else None
            if lpp is not None:
                scaled = self.scaled(lpp)
                self.params, self.lpp = scaled.params, scaled.lpp
                self.design_speed, self.rudder_rate = scaled.design_speed, scaled.rudder_rate
        elif lpp is not None:
            if not float(lpp) > 0:
                raise ValueError(f"{self.name}: lpp must be a positive length in metres, got {lpp}")
            self.lpp = float(lpp)
        for key, val in (("design_speed", design_speed), ("rudder_rate", rudder_rate)):
            if val is not None:
                if not float(val) > 0:
                    raise ValueError(f"{self.name}: {key} must be positive, got {val}")
                setattr(self, key, float(val))

    def options(self) -> dict:
        """The ship facts travel with fit results (``get_model(name, coef, **options)``): ``lpp`` [m],
        ``design_speed`` [m/s], ``rudder_rate`` [rad/s], those that are known."""
        return {k: float(getattr(self, k)) for k in ("lpp", "design_speed", "rudder_rate") if getattr(self, k) is not None}

    def _length(self, lpp):
        L = self.lpp if lpp is None else float(lpp)
        if L is None or not L > 0:
            raise ValueError(f"{self.name}: the ship length is unknown; pass lpp= (metres) to the model or here")
        return L

    @classmethod
    def _prime_factors(cls, L: float) -> np.ndarray:
        """``L^a (L/g)^(b/2)`` per parameter (dimensional = prime x factor)."""
        return np.array([L ** cls.prime_exponents[k][0] * (L / G) ** (cls.prime_exponents[k][1] / 2)
                         for k in cls.param_names])

    def to_prime(self, lpp: float | None = None) -> dict:
        """Froude-non-dimensional coefficients ``c / (L^a (L/g)^(b/2))`` (``prime_exponents``)."""
        vals = np.asarray(self.params, dtype=float) / self._prime_factors(self._length(lpp))
        return {k: float(v) for k, v in zip(self.param_names, vals)}

    @classmethod
    def from_prime(cls, prime, lpp: float):
        """The model of a ship of length ``lpp`` [m] from prime coefficients (missing ones are 0)."""
        unknown = sorted(set(prime) - set(cls.param_names))
        if unknown:
            raise ValueError(f"{cls.name}: unknown prime coefficient(s) {unknown}")
        L = float(lpp)
        if not L > 0:
            raise ValueError(f"{cls.name}: lpp must be a positive length in metres, got {lpp}")
        vals = np.array([float(prime.get(k, 0.0)) for k in cls.param_names]) * cls._prime_factors(L)
        return cls(vals, lpp=L)

    def scaled(self, lpp_new: float):
        """The Froude-similar model of the geometrically similar ship of length ``lpp_new`` [m]
        (design speed x sqrt(lam), rudder rate / sqrt(lam), ``lam = lpp_new / lpp``)."""
        new = self.from_prime(self.to_prime(), lpp_new)
        lam = new.lpp / self._length(None)
        new.design_speed = None if self.design_speed is None else self.design_speed * np.sqrt(lam)
        new.rudder_rate = None if self.rudder_rate is None else self.rudder_rate / np.sqrt(lam)
        return new
