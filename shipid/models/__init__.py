"""Models implementing the shipid model protocol, and the model registry.

Models are registered by name with a lazy ``"module:Class"`` target so that
importing :mod:`shipid` does not import every model.  Use
:func:`get_model` to build one and :func:`available_models` to list them.
"""
from __future__ import annotations

import importlib

from .base import Model, ParameterSet, RecipeDefaults

__all__ = ["Model", "ParameterSet", "RecipeDefaults", "register_model", "get_model", "model_class", "available_models"]

_REGISTRY: dict[str, str] = {
    "kcs-response": "shipid.models.response:KCSResponseModel",
    "mmg": "shipid.models.mmg:MMGModel",
    "glider": "shipid.models.glider:GliderModel",
    "planing-boat": "shipid.models.planing:PlaningBoatModel",
    "response-nl": "shipid.models.response_nl:ResponseNLModel",
    "lowspeed": "shipid.models.lowspeed:LowSpeedModel",
    "with-environment": "shipid.environment.model:EnvironmentModel",
}


def register_model(name: str, target: str | type) -> None:
    """Register a model class under ``name`` (a class or a ``"module:Class"`` string)."""
    if isinstance(target, type):
        target = f"{target.__module__}:{target.__qualname__}"
    _REGISTRY[name] = target


def model_class(name: str) -> type[Model]:
    """The model class registered as ``name``."""
    if name not in _REGISTRY:
        raise ValueError(f"unknown model '{name}'; available models: {', '.join(sorted(_REGISTRY))}")
    mod, cls = _REGISTRY[name].split(":")
    return getattr(importlib.import_module(mod), cls)


def get_model(name: str, params=None, **options) -> Model:
    """Instantiate the model registered as ``name`` with ``params``."""
    return model_class(name)(params, **options)


def available_models() -> list[str]:
    """Names of all registered models."""
    return sorted(_REGISTRY)
