"""shipid: identify ship manoeuvring coefficients from free-running trial logs,
validate the identified models and use them for control, routing and studies."""
from __future__ import annotations

import importlib

from . import simulate  # noqa: E402  (the module; calling it calls simulate.simulate)
from ._version import __version__  # noqa: E402
from .logs import LogError, ShipParticulars, TrialLog, read_log, read_ship  # noqa: E402
from .models import Model, available_models, get_model, register_model  # noqa: E402
from .simulate import SimulationResult  # noqa: E402

__all__ = ["__version__", "Model", "available_models", "get_model", "register_model", "simulate", "SimulationResult",
           "read_log", "TrialLog", "LogError", "ShipParticulars", "read_ship"]

#: Names exported lazily (their modules import the identifier and the validation floor).
_LAZY = {"cross_validate": "shipid.crossval", "CrossValidation": "shipid.crossval", "choose_model": "shipid.crossval"}
__all__ += list(_LAZY)


def __getattr__(name):
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'shipid' has no attribute {name!r}")
