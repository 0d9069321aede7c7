"""Identification uncertainty and what it does to predictions.

* :mod:`~shipid.uncertainty.draws` -- parameter draws from a fit (its Gaussian posterior or MCMC samples),
  simulated as one batch through standard manoeuvres and replays: intervals of each metric and the
  probability of meeting each IMO MSC.137(76) criterion (:func:`predict_manoeuvres`, :func:`parameter_draws`).
* :mod:`~shipid.uncertainty.posterior` -- MCMC sampling of the coefficients' posterior over the output-error
  likelihood (emcee; Goodman & Weare 2010, Foreman-Mackey et al. 2013) with split-R-hat and ESS checks
  (:func:`sample_posterior`).
"""
from .draws import (METRIC_KEYS, ManoeuvrePrediction, ManoeuvreSpec, ci_block, imo_probability, parameter_draws,
                    parse_manoeuvre, predict_manoeuvres, replay_draws, summarise_draws)
from .posterior import (CONVERGENCE, OutputErrorLikelihood, PosteriorSamples, load_samples, sample_posterior,
                        split_rhat)

__all__ = ["ManoeuvreSpec", "parse_manoeuvre", "parameter_draws", "predict_manoeuvres", "ManoeuvrePrediction",
           "summarise_draws", "imo_probability", "METRIC_KEYS", "replay_draws", "ci_block", "sample_posterior",
           "PosteriorSamples", "load_samples", "split_rhat", "CONVERGENCE", "OutputErrorLikelihood"]
