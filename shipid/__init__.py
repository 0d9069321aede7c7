"""shipid: identify ship manoeuvring coefficients from free-running trial logs,
validate the identified models and use them for control, routing and studies."""
from __future__ import annotations

from ._version import __version__  # noqa: E402

from .models import Model, available_models, get_model, register_model  # noqa: E402
from .simulate import SimulationResult, simulate  # noqa: E402
from .logs import LogError, ShipParticulars, TrialLog, read_log, read_ship  # noqa: E402

__all__ = ["__version__", "Model", "available_models", "get_model", "register_model", "simulate", "SimulationResult",
           "read_log", "TrialLog", "LogError", "ShipParticulars", "read_ship"]
