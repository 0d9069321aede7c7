"""Calibration of the reported uncertainty by replicates: does a 95 % interval contain the truth 95 % of the time?

:func:`coverage_study` makes ``n_replicates`` synthetic data sets from a known
truth (:func:`shipid.synthetic.make_trial`: the standard-manoeuvre input laws
applied as a sampled controller, independent Gaussian sensor noise per data
set), fits each one from a perturbed start with :class:`EKFIdentifier`, and
counts per coefficient how often ``coef +- z * std`` (the Gaussian 95 %
interval of the fit) contains the true value.  For the predicted tactical
diameter (35 deg turn) and first overshoot (10/10 zigzag) it counts how often
the 2.5-97.5 % interval of :func:`shipid.uncertainty.predict_manoeuvres`
contains the truth model's value, and optionally (``mcmc_replicates``) the same
for the MCMC posterior of :func:`shipid.uncertainty.sample_posterior`.

``refine="output-error"`` tables the output-error fit that also estimates each log's initial u, v, r
(``estimate_x0``); the MCMC column (docs/uncertainty.md sect. 3) samples the 3 yaw coefficients and
the initial states (``mcmc_kwargs=dict(steps=1000, burn=300, moves="independence", sample_x0=True)``);
``checkpoint=`` makes a long study resumable.  The 16-coefficient MCMC column
(``python -m studies.run_mcmc16_coverage``) samples all coefficients and the initial states with the
independence proposal taken from the replicate's output-error Laplace approximation
(``mcmc_kwargs=dict(..., proposal="output-error", use_prior=False)``, needs ``refine="output-error"``).
``refine="ekf-sensor-noise"`` tables the EKF's estimates with their covariance re-evaluated under sensor
noise only (:meth:`EKFIdentifier.sensor_noise_cov`).

With ``n`` replicates a true coverage of 0.95 is observed between about
0.95 -+ 1.96 sqrt(0.95 * 0.05 / n) (0.91-0.99 for n = 100); the table gives the
Wilson score interval of each observed fraction.  The replicates are
independent members of a :class:`shipid.campaign.Engine` (Dask or serial) with
seeds spawned from ``seed``: the numbers do not depend on the engine.
"""
from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

__all__ = ["coverage_study", "CoverageResult", "COVERAGE_RECIPES", "wilson_interval"]


def _recipes():
    from shipid.synthetic import TrialRecipe

    # short data sets (40 s each, 0.1 s sampling) so that 100 fits take minutes: a 35 deg turn with an
    # rpm step (separates the surge terms) and a 20/20 zigzag
    return (TrialRecipe("cov_tc_p35_rpm", "turning", 35.0, 40.0, ((0.0, 10.0), (20.0, 8.0))),
            TrialRecipe("cov_zz_p20", "zigzag", 20.0, 40.0, ((0.0, 10.0), (25.0, 12.0)), psi_deg=20.0))


#: The default data sets of one replicate.
COVERAGE_RECIPES = _recipes()


def wilson_interval(k: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """Wilson score interval of a binomial proportion ``k / n`` (Wilson 1927)."""
    if n == 0:
        return (math.nan, math.nan)
    p = k / n
    d = 1 + z * z / n
    c = (p + z * z / (2 * n)) / d
    h = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / d
    return (c - h, c + h)


def _replicate(task: dict) -> dict:
    """One replicate (runs on a worker): data, fit, coefficient z-scores, predicted-metric intervals."""
    from shipid.synthetic import make_trial
    from shipid.uncertainty import predict_manoeuvres
    from shipid.identify.identifier import EKFIdentifier
    from shipid.uncertainty.posterior import sample_posterior

    cpu0 = time.process_time()
    truth = task["truth"]
    rng = np.random.default_rng(task["seed"])
    logs = [make_trial(truth, r, rng, task["noise_std"])[0] for r in task["recipes"]]
    # only the estimated coefficients start away from the truth; the fixed ones are the truth's (a
    # perturbed fixed coefficient would be model error, which no interval of the fit covers)
    factor = 1 + task["perturb"] * rng.standard_normal(truth.np)
    if task["estimate"] is not None:
        keep = np.array([n not in set(task["estimate"]) for n in truth.param_names])
        factor[keep] = 1.0
    start = truth.with_params(truth.params * factor)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        ident = EKFIdentifier(start, estimate=task["estimate"], n_passes=task["n_passes"],
                              **task["identifier_kwargs"]).fit(logs)
    res = ident.result()
    fit = res
    if task["refine"] == "ekf-sensor-noise":
        # the same EKF estimate, its covariance re-evaluated with the filter's own gains under sensor noise only
        import dataclasses

        C = ident.sensor_noise_cov()
        fit = dataclasses.replace(res, cov=C, coef_std={**res.coef_std, **{n: float(np.sqrt(max(C.loc[n, n], 0.0)))
                                                                           for n in C.index}})
    if task["refine"] == "output-error":
        # the output-error maximum-likelihood estimate started from the EKF: weights = the EKF's noise levels,
        # exact RK4 sensitivities, Laplace covariance (J^T J)^-1 s^2
        from shipid.identify.batch import OutputErrorRefiner

        # the channels of the MCMC likelihood (measured u, v, r): with a few yaw coefficients estimated, u and v
        # still carry information on them through the coupling
        chans = [c for c in ("u", "v", "r") if c in ident.meas_std_.index]
        ref = OutputErrorRefiner(ident.to_model(), estimate=ident.estimated_, meas_std=ident.meas_std_.to_dict(),
                                 channels=chans or None,
                                 jacobian="tangent", max_nfev=task["max_nfev"], input_hold=ident.input_hold,
                                 estimate_x0=task.get("estimate_x0", True))
        ref.fit(logs, start=ident)
        fit = ref.result()
    names = list(fit.cov.index)
    out = {"seed": task["seed"], "success": bool(fit.success), "names": names,
           "coef": [fit.coef[n] for n in names], "std": [fit.coef_std[n] for n in names],
           "cov": fit.cov.loc[names, names].to_numpy().tolist(),
           "poorly_determined": list(res.diagnostics.get("poorly_determined", []))}
    if task["draws"] > 0:
        pred = predict_manoeuvres(fit, task["manoeuvres"], draws=task["draws"], seed=task["seed"] % (2**32),
                                  zigzag_executes=3, inflation=task["inflation"])
        out["metrics"] = {f"{r.manoeuvre}:{r.metric}": [r.low, r.high, r.nominal] for r in pred.metrics.itertuples()}
        out["n_failed_draws"] = {k: v["n_failed"] for k, v in pred.failures.items()}
    if task["mcmc"]:
        kw = dict(task["mcmc_kwargs"])
        if kw.get("proposal") == "output-error":
            # the independence proposal from this replicate's output-error Laplace approximation (the chain
            # still starts from the EKF posterior ``res``)
            if task["refine"] != "output-error":
                raise ValueError("mcmc_kwargs proposal='output-error' needs refine='output-error'")
            kw["proposal"] = ref
        s = sample_posterior(res, logs, seed=task["seed"] % (2**31), **kw)
        lo, hi = np.quantile(s.samples, [0.025, 0.975], axis=0)
        out["mcmc"] = {"low": lo.tolist(), "high": hi.tolist(), "converged": bool(s.converged),
                       "mean": s.samples.mean(axis=0).tolist(), "std": s.samples.std(axis=0, ddof=1).tolist(),
                       "rhat_max": s.diagnostics["rhat_max"], "ess_min": s.diagnostics["ess_min"],
                       "tau_max": s.diagnostics["tau_max"], "acceptance": s.diagnostics["acceptance_mean"],
                       "n_likelihood_calls": s.diagnostics["n_likelihood_calls"], "message": s.message}
        if task["draws"] > 0:
            pm = predict_manoeuvres(res, task["manoeuvres"], draws=task["draws"], seed=task["seed"] % (2**32),
                                    samples=s, zigzag_executes=3)
            out["mcmc"]["metrics"] = {f"{r.manoeuvre}:{r.metric}": [r.low, r.high] for r in pm.metrics.itertuples()}
    out["cpu_s"] = time.process_time() - cpu0
    if task.get("checkpoint"):
        _append_line(task["checkpoint"], {"key": task["key"], **out})
    return out


def _task_keys(task: dict, truth) -> tuple[str, str]:
    """Checkpoint key of a replicate task: the replicate's seed and every setting it depends on, as canonical JSON;
    and the key of older checkpoint files (a pickle, which depends on whether equal strings of the settings
    are one object, so a call from another script could find nothing; such files are still read)."""
    import hashlib
    import json
    import pickle

    settings_t = {k: v for k, v in task.items() if k not in ("truth", "key", "checkpoint")}
    tail = truth.params.tobytes() + truth.name.encode()
    new = hashlib.sha256(json.dumps(settings_t, sort_keys=True, default=repr).encode() + tail).hexdigest()[:24]
    return new, hashlib.sha256(pickle.dumps(settings_t) + tail).hexdigest()[:24]


def _append_line(path, doc: dict) -> None:
    """Append one JSON line (one ``write`` of a line opened with O_APPEND: whole lines from several workers)."""
    import json
    import os

    line = (json.dumps(doc, allow_nan=True, default=lambda o: o.item() if hasattr(o, "item") else str(o))
            + "\n").encode()
    fd = os.open(path, os.O_RDWR | os.O_APPEND | os.O_CREAT, 0o644)
    try:
        size = os.fstat(fd).st_size
        if size and os.pread(fd, 1, size - 1) != b"\n":  # a line torn by an interrupted run: end it
            line = b"\n" + line
        os.write(fd, line)
    finally:
        os.close(fd)


def _read_checkpoint(path) -> dict:
    """Replicate outcomes already in a checkpoint file, by key (a truncated last line is ignored)."""
    import json
    from pathlib import Path

    done = {}
    p = Path(path)
    if p.is_file():
        for line in p.read_text(encoding="utf-8").splitlines():
            try:
                d = json.loads(line)
            except json.JSONDecodeError:
                continue
            if isinstance(d, dict) and "key" in d:
                done[d.pop("key")] = d
    return done


@dataclass
class _Done:
    """A replicate read back from a checkpoint file."""

    value: dict
    ok: bool = True
    error: str | None = None


@dataclass
class CoverageResult:
    """Outcome of :func:`coverage_study`.

    Attributes
    ----------
    table : DataFrame
        One row per quantity (coefficients, then predicted metrics) and method ("ekf", "mcmc"):
        ``n``, ``covered``, ``coverage``, ``wilson_low``, ``wilson_high``, ``z_mean``, ``z_std``
        (standardised error (estimate - truth) / std; 0 and 1 when calibrated), ``identifiable``
        (not 'poorly determined' in most fits), ``in_goal`` (coverage in [0.90, 0.99]).
    replicates : list of dict  -- per replicate outcome (or error)
    n_failed : int  -- replicates that raised (errors in ``errors``)
    truth_metrics : dict
    success : bool  -- every identifiable coefficient and metric in the goal band
    message : str
    """

    table: pd.DataFrame
    replicates: list
    truth_metrics: dict
    n_failed: int = 0
    errors: list = field(default_factory=list)
    success: bool = True
    message: str = ""
    settings: dict = field(default_factory=dict)

    def to_pandas(self) -> pd.DataFrame:
        return self.table.copy()


def _row(quantity, method, inside, z=None, identifiable=True):
    inside = np.asarray(inside, dtype=bool)
    n, k = inside.size, int(inside.sum())
    lo, hi = wilson_interval(k, n)
    cov = k / n if n else math.nan
    return {"quantity": quantity, "method": method, "n": n, "covered": k, "coverage": cov, "wilson_low": lo,
            "wilson_high": hi, "z_mean": float(np.mean(z)) if z is not None and len(z) else math.nan,
            "z_std": float(np.std(z, ddof=1)) if z is not None and len(z) > 1 else math.nan,
            "identifiable": bool(identifiable), "in_goal": bool(0.90 <= cov <= 0.99) if n else False}


def coverage_study(truth=None, recipes=None, *, n_replicates: int = 100, seed: int = 0, noise_std: dict | None = None,
                   estimate=None, n_passes: int = 2, perturb: float = 0.3, identifier_kwargs: dict | None = None,
                   draws: int = 100, manoeuvres=("turning:35", "zigzag:10/10"), inflation: float = 1.0,
                   mcmc_replicates: int = 0, mcmc_kwargs: dict | None = None, engine=None,
                   level: float = 0.95, refine: str | None = None, max_nfev: int = 50,
                   estimate_x0: bool = True, checkpoint=None, run: bool = True) -> CoverageResult:
    """Replicate study of interval coverage (see the module docstring).

    Parameters
    ----------
    truth : Model, optional  -- default ``kcs-response`` with its ``synthetic-truth`` set
    recipes : sequence of TrialRecipe, optional  -- data sets of one replicate (default :data:`COVERAGE_RECIPES`)
    n_replicates : int
    seed : int  -- replicate seeds are spawned from it
    noise_std : dict, optional  -- sensor noise (default :data:`shipid.synthetic.KCS_NOISE_STD`)
    estimate : list of str, optional  -- coefficients to estimate (default all)
    n_passes, identifier_kwargs : settings of :class:`EKFIdentifier`
    perturb : float  -- relative Gaussian perturbation of the start values (per replicate)
    draws : int  -- parameter draws per replicate for the predicted metrics (0: coefficients only)
    manoeuvres : predicted manoeuvres (the tactical diameter and the first overshoot are tabled)
    inflation : float  -- standard-deviation factor of the Gaussian draws and coefficient intervals
    mcmc_replicates : int  -- the first so many replicates are also sampled by MCMC (emcee)
    mcmc_kwargs : dict  -- keyword arguments of :func:`sample_posterior` (steps, walkers, burn ...)
    engine : shipid.campaign.Engine, optional  -- default serial
    level : float  -- interval probability (0.95)
    refine : {None, "output-error", "ekf-sensor-noise"}
        None: the intervals of the EKF posterior (method "ekf" in the table).  "output-error": the EKF
        fit is followed by the output-error maximum-likelihood fit of the same coefficients
        (:class:`~shipid.identify.batch.OutputErrorRefiner`, weights = the EKF's noise levels, exact RK4
        sensitivities, initial states from the EKF smoother and, with ``estimate_x0``, estimated with the
        coefficients, at most ``max_nfev`` evaluations) and its Laplace covariance ``s^2 (J^T J)^-1``
        gives the intervals (method "output-error").  "ekf-sensor-noise": the EKF estimate with its covariance
        re-evaluated under sensor noise only (:meth:`EKFIdentifier.sensor_noise_cov`, the filter's own gains;
        method "ekf-sensor-noise").  The MCMC
        column does not depend on it (the sampler starts from the EKF posterior).
    max_nfev : int  -- evaluation limit of that refinement
    checkpoint : path, optional
        JSON-lines file: every finished replicate is appended to it, and replicates already in it (same
        seed and settings) are not run again -- a long study (the MCMC column) can be stopped and resumed.
    run : bool
        False: run nothing, tabulate the replicates found in ``checkpoint`` (``n`` may then be below
        ``n_replicates``; ``settings["n_done"]`` says how many).
    estimate_x0 : bool
        The output-error fit also estimates each log's initial u, v, r (nuisance parameters; the
        coefficients' covariance is marginal over them).  False holds them at the EKF smoother's
        values: the joint covariance is then too tight (the predicted tactical
        diameter covered 0.85 of 100 replicates, docs/uncertainty.md sect. 3).

    Returns
    -------
    CoverageResult
    """
    from shipid.campaign import Engine, member_seeds
    from shipid.manoeuvres import turning_circle, zigzag
    from shipid.models import get_model
    from shipid.synthetic import KCS_NOISE_STD
    from shipid.uncertainty import parse_manoeuvre

    if int(n_replicates) < 2:
        raise ValueError(f"n_replicates must be >= 2, got {n_replicates}")
    if refine not in (None, "output-error", "ekf-sensor-noise"):
        raise ValueError(f"refine must be None, 'output-error' or 'ekf-sensor-noise', got {refine!r}")
    method = "ekf" if refine is None else refine
    truth = get_model("kcs-response", "synthetic-truth") if truth is None else truth
    recipes = COVERAGE_RECIPES if recipes is None else tuple(recipes)
    z = float(abs(__import__("scipy.stats", fromlist=["norm"]).norm.ppf((1 - level) / 2)))
    seeds = member_seeds(seed, n_replicates)
    if not run and checkpoint is None:
        raise ValueError("run=False tabulates a checkpoint file: give checkpoint=")
    tasks = [{"truth": truth, "recipes": recipes, "seed": s, "noise_std": dict(noise_std or KCS_NOISE_STD),
              "estimate": estimate, "n_passes": int(n_passes), "identifier_kwargs": dict(identifier_kwargs or {}),
              "perturb": float(perturb), "draws": int(draws), "manoeuvres": list(manoeuvres),
              "inflation": float(inflation), "mcmc": i < int(mcmc_replicates), "mcmc_kwargs": dict(mcmc_kwargs or {}),
              "refine": refine, "max_nfev": int(max_nfev), "estimate_x0": bool(estimate_x0)}
             for i, s in enumerate(seeds)]
    eng = engine or Engine(1, progress=False)
    if checkpoint is not None:
        legacy = {}
        for t in tasks:
            t["key"], legacy_key = _task_keys(t, truth)
            legacy[t["key"]] = legacy_key
            t["checkpoint"] = str(checkpoint)
        def read_done():  # the checkpoint, replicates stored under a legacy key also found by the new one
            d = _read_checkpoint(checkpoint)
            d.update({key: d[old] for key, old in legacy.items() if key not in d and old in d})
            return d

        done = read_done()
        todo = [t for t in tasks if t["key"] not in done] if run else []
        new = {t["key"]: o for t, o in zip(todo, eng.map(_replicate, todo, desc="coverage replicates"))}
        done = read_done()
        outs = [new[t["key"]] if t["key"] in new else _Done(done[t["key"]]) for t in tasks
                if t["key"] in new or t["key"] in done]
    else:
        outs = eng.map(_replicate, tasks, desc="coverage replicates")
    good = [o.value for o in outs if o.ok]
    errors = [o.error for o in outs if not o.ok]
    if not good and not errors and not run:
        return CoverageResult(pd.DataFrame(columns=["quantity", "method", "n", "covered", "coverage"]), [], {}, 0, [],
                              False, "no replicate of these settings in the checkpoint yet",
                              {"n_replicates": int(n_replicates), "n_done": 0, "checkpoint": str(checkpoint)})
    if not good:
        raise ValueError(f"every replicate failed; first error: {errors[0] if errors else '?'}")
    # truth values of the tabled metrics
    truth_metrics = {}
    for spec in map(parse_manoeuvre, manoeuvres if draws > 0 else ()):
        if spec.kind == "turning":
            m = turning_circle(truth, spec.rudder_deg, side=spec.side).metrics[0]
            truth_metrics[f"{spec.label}:tactical_diameter_L"] = m.tactical_diameter_L
        else:
            m = zigzag(truth, spec.rudder_deg, spec.switch_deg, first=spec.side, n_executes=3).metrics[0]
            truth_metrics[f"{spec.label}:overshoot1_deg"] = m.overshoot1_deg
    names = good[0]["names"]
    tv = truth.params_series()[names].to_numpy()
    C = np.array([g["coef"] for g in good])
    S = np.array([g["std"] for g in good]) * inflation
    Z = (C - tv) / S
    poor = {n: sum(n in g["poorly_determined"] for g in good) for n in names}
    rows = [_row(n, method, np.abs(Z[:, j]) <= z, Z[:, j], poor[n] <= len(good) / 2) for j, n in enumerate(names)]
    for key, tval in truth_metrics.items():
        iv = np.array([g["metrics"].get(key, [np.nan, np.nan])[:2] for g in good if "metrics" in g], dtype=float)
        if iv.size:
            rows.append(_row(key, method, (iv[:, 0] <= tval) & (tval <= iv[:, 1])))
    mc = [g["mcmc"] for g in good if "mcmc" in g]
    if mc:
        lo, hi = np.array([m["low"] for m in mc]), np.array([m["high"] for m in mc])
        zm = (np.array([m["mean"] for m in mc]) - tv) / np.array([m["std"] for m in mc]) if "mean" in mc[0] else None
        for j, n in enumerate(names):
            rows.append(_row(n, "mcmc", (lo[:, j] <= tv[j]) & (tv[j] <= hi[:, j]), None if zm is None else zm[:, j],
                             poor[n] <= len(good) / 2))
        for key, tval in truth_metrics.items():
            iv = np.array([m["metrics"][key] for m in mc if "metrics" in m and key in m["metrics"]], dtype=float)
            if iv.size:
                rows.append(_row(key, "mcmc", (iv[:, 0] <= tval) & (tval <= iv[:, 1])))
    table = pd.DataFrame(rows)
    chk = table[table["identifiable"]]
    off = chk[~chk["in_goal"]]
    ok = off.empty and not errors
    msg = (f"{len(good)} replicates ({len(errors)} failed); " +
           ("every identifiable quantity covered 0.90-0.99" if off.empty else
            "outside 0.90-0.99: " + ", ".join(f"{r.quantity} [{r.method}] {r.coverage:.2f}" for r in off.itertuples())))
    n_unsucc = sum(not g["success"] for g in good)
    if n_unsucc:
        msg += f"; {n_unsucc} fits reported success=False (their intervals are counted)"
    if mc:
        msg += f"; MCMC on {len(mc)} replicates ({sum(m['converged'] for m in mc)} converged)"
    settings = {"n_replicates": int(n_replicates), "seed": int(seed), "recipes": [r.name for r in recipes],
                "draws": int(draws), "inflation": float(inflation), "perturb": float(perturb), "n_passes": int(n_passes),
                "mcmc_replicates": int(mcmc_replicates), "mcmc_kwargs": dict(mcmc_kwargs or {}), "level": level,
                "refine": refine, "max_nfev": int(max_nfev), "estimate_x0": bool(estimate_x0),
                "identifier_kwargs": dict(identifier_kwargs or {}),
                "engine": eng.describe(), "n_done": len(good) + len(errors),
                "cpu_s_per_replicate": float(np.mean([g["cpu_s"] for g in good if "cpu_s" in g] or [math.nan]))}
    return CoverageResult(table, good, truth_metrics, len(errors), errors, ok, msg, settings)
