"""Validation of an identified model against measured runs.

* :mod:`~shipid.validation.replay` -- replay each log with its recorded inputs, per-channel errors, and the
  standard-manoeuvre metrics (ITTC 7.5-04-02-01, IMO MSC.137(76)) of the run and of the model
  (:func:`validate`, :func:`validate_one`).
* :mod:`~shipid.validation.horizon` -- multi-start open-loop prediction H seconds ahead, for runs that are
  not standard manoeuvres, against dead reckoning (:func:`horizon_prediction`).
"""
from .horizon import DEFAULT_HORIZONS, DeadReckoning, HorizonResult, dead_reckoning, horizon_prediction
from .replay import (DIFF_EXCLUDE, DURATION_MULTIPLE, LogValidation, load_logs, resolve_model, standard_manoeuvre, validate,
                     validate_logs, validate_one)

__all__ = ["validate", "validate_logs", "validate_one", "LogValidation", "resolve_model", "load_logs", "DIFF_EXCLUDE",
           "standard_manoeuvre", "horizon_prediction", "HorizonResult", "DeadReckoning", "dead_reckoning",
           "DEFAULT_HORIZONS", "DURATION_MULTIPLE"]
