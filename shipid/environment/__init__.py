"""Environment: wind forces, current (as model parts and as independent estimates).

* :class:`WindForce` -- Fujiwara et al. (1998) wind coefficients from the above-water geometry;
  :func:`apparent_wind`, :func:`true_wind_from_apparent` convert at the edges.
* :func:`with_environment` / :class:`EnvironmentModel` -- any ship model with wind inputs and wind
  coefficients as parameters, and a uniform current as extra states the EKF estimates.
* :func:`current_from_turn` -- the IMO MSC/Circ.1053 drift method on a long turning circle.
"""
from .current import CurrentEstimate, current_from_turn
from .model import CURRENT_STATES, WIND_INPUTS, EnvironmentModel, with_environment
from .wind import RHO_AIR, WIND_PARAM_NAMES, WindForce, apparent_wind, fujiwara_components, true_wind_from_apparent

__all__ = ["WindForce", "fujiwara_components", "apparent_wind", "true_wind_from_apparent", "WIND_PARAM_NAMES",
           "RHO_AIR", "with_environment", "EnvironmentModel", "WIND_INPUTS", "CURRENT_STATES", "current_from_turn",
           "CurrentEstimate"]
