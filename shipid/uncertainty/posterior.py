# Why one file: the likelihood, the sampler's moves, its convergence checks and the samples' result are one MCMC method.
"""Posterior sampling of model coefficients by MCMC over the output-error likelihood.

The EKF's Gaussian (Laplace) posterior is an approximation; for non-linear,
correlated coefficients the exact posterior of the coefficients given the logs
can be skewed or wider.  :func:`sample_posterior` samples it with emcee's
affine-invariant ensemble sampler (Goodman & Weare 2010; Foreman-Mackey et al.
2013), started from the EKF posterior, with **vectorised walkers**: every
evaluation of the log-probability simulates all proposed walkers of a half
ensemble (emcee's red-blue split) and all logs as one batched simulation
(:func:`shipid.simulate.simulate` with ``params`` of shape ``(B, np)``).

Likelihood (output error): each log is simulated with its recorded inputs from
its initial state (mean of the first five samples of each measured state);
the residuals of the channels in ``channels`` (default ``u, v, r``) are
independent Gaussian with the fit's measurement-noise standard deviations
(``result.settings["meas_std"]``, else estimated from the data).  This is the
exact likelihood when the logs have sensor noise only (no process noise);
with process noise or model error it is over-confident (see
``docs/uncertainty.md``).  Prior: the EKF's own, i.e. independent Gaussians
centred on the values its first pass started from (``result.settings["prior_mean"]``)
with its prior standard deviations (``result.settings["prior_std"]``, >= 100 % of
each start value).  A result without a recorded prior (written before the centre
was recorded, or an output-error refinement) is sampled under a flat prior, with a
warning: centring the prior on the fit's own estimate would use the
data twice (with 16 coefficients it moved posterior means by up to 0.4 sigma,
docs/uncertainty.md sect. 2).  ``use_prior=False`` samples the likelihood alone.

Convergence is judged, never assumed: the mean acceptance fraction, the
integrated autocorrelation time tau per coefficient (Sokal's automatic window,
:func:`emcee.autocorr.integrated_time`), the effective sample size
``n_kept * n_walkers / tau`` and the rank-normalised split-R-hat of Vehtari,
Gelman, Simpson, Carpenter & Buerkner (2021, Bayesian Analysis 16(2),
"Rank-normalization, folding, and localization: an improved R-hat"), which
extends the split-R-hat of Gelman et al., *Bayesian Data Analysis* 3rd ed.
(2013) sect. 11.4, computed treating each walker as a chain.  The chain is
called converged only when every check passes (:data:`CONVERGENCE`).
"""
from __future__ import annotations

import json
import logging
import os
import signal
import threading
import warnings
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.special import ndtri
from scipy.stats import rankdata

from .._io import atomic_write_text, check_memory, read_json
from ..identify.data import noise_std_from_data, prepare_logs
from ..identify.result import as_result
from ..results import ResultMixin
from ..simulate import simulate

__all__ = ["sample_posterior", "PosteriorSamples", "load_samples", "split_rhat", "CONVERGENCE",
           "OutputErrorLikelihood"]

#: Convergence thresholds: split-R-hat below 1.01 and bulk ESS of at least 400 (Vehtari et al. 2021,
#: sect. 4), chain length at least 50 integrated autocorrelation times (emcee's guidance), mean acceptance
#: fraction in [0.1, 0.9] (outside it the stretch move is not exploring).
CONVERGENCE = {"rhat_max": 1.01, "ess_min": 400.0, "tau_factor": 50.0, "acceptance": (0.1, 0.9)}

#: Independence proposal of ``moves="independence"``: multivariate Student-t with ``df`` degrees of freedom
#: (tails heavier than a near-Gaussian posterior's, so the importance ratio stays bounded) and scale matrix
#: ``scale**2`` times the covariance of the burn-in's second half (wider than the target, for the same reason).
INDEPENDENCE_T = {"df": 10.0, "scale": 1.2}


def _independence_move(emcee, mean: np.ndarray, cov: np.ndarray):
    """emcee move proposing every walker from one fixed multivariate t (mean, INDEPENDENCE_T scale**2 cov)."""
    df, d = INDEPENDENCE_T["df"], mean.size
    L = np.linalg.cholesky(INDEPENDENCE_T["scale"] ** 2 * cov + 1e-300 * np.eye(d))
    Li = np.linalg.inv(L)

    def logq(x):
        z = (x - mean) @ Li.T
        return -0.5 * (df + d) * np.log1p(np.sum(z * z, axis=1) / df)

    def propose(coords, random):
        n = coords.shape[0]
        z = random.standard_normal((n, d)) / np.sqrt(random.chisquare(df, n) / df)[:, None]
        q = mean + z @ L.T
        return q, logq(coords) - logq(q)

    return emcee.moves.MHMove(propose, ndim=d)


# ----------------------------------------------------------------------------- diagnostics
def _rhat_classic(chains: np.ndarray) -> np.ndarray:
    """Potential scale reduction of ``chains (m, n, k)`` (BDA3 eq. 11.4 without the split)."""
    m, n = chains.shape[:2]
    means = chains.mean(axis=1)
    W = chains.var(axis=1, ddof=1).mean(axis=0)
    B_over_n = means.var(axis=0, ddof=1)
    var_plus = (n - 1) / n * W + B_over_n
    with np.errstate(divide="ignore", invalid="ignore"):
        r = np.sqrt(var_plus / W)
    return np.where(W > 0, r, np.where(B_over_n > 0, np.inf, 1.0))


def _rank_normalise(x: np.ndarray) -> np.ndarray:
    """Normal scores of the pooled ranks of ``x (m, n, k)`` per last-axis column (Blom's offsets 3/8)."""
    m, n, k = x.shape
    flat = x.reshape(m * n, k)
    z = np.empty_like(flat)
    for j in range(k):
        r = rankdata(flat[:, j], method="average")
        z[:, j] = ndtri((r - 0.375) / (m * n + 0.25))
    return z.reshape(m, n, k)


def split_rhat(chains, *, rank_normalised: bool = True) -> np.ndarray:
    """Split-R-hat per parameter.

    Parameters
    ----------
    chains : array (n_chains, n_draws) or (n_chains, n_draws, n_params)
    rank_normalised : bool
        True (default): Vehtari et al. (2021) -- the maximum of the split-R-hat of the rank-normalised
        draws (bulk) and of the rank-normalised folded draws ``|x - median|`` (tails).  False: the
        classic split-R-hat of BDA3 sect. 11.4 on the draws themselves.

    Returns
    -------
    ndarray (n_params,) (a float for 2-D input)
    """
    c = np.asarray(chains, dtype=float)
    two_d = c.ndim == 2
    if two_d:
        c = c[..., None]
    if c.ndim != 3 or c.shape[1] < 4:
        raise ValueError(f"chains must have shape (n_chains, n_draws[, n_params]) with n_draws >= 4, got {np.shape(chains)}")
    half = c.shape[1] // 2
    split = np.concatenate([c[:, :half], c[:, c.shape[1] - half:]], axis=0)
    if rank_normalised:
        bulk = _rhat_classic(_rank_normalise(split))
        fold = np.abs(split - np.median(split.reshape(-1, split.shape[2]), axis=0))
        tail = _rhat_classic(_rank_normalise(fold))
        r = np.maximum(bulk, tail)
    else:
        r = _rhat_classic(split)
    return float(r[0]) if two_d else r


# ----------------------------------------------------------------------------- likelihood
class OutputErrorLikelihood:
    """Log-posterior of coefficient batches: Gaussian output-error likelihood of the logs plus
    independent Gaussian priors (see the module docstring).

    Parameters
    ----------
    model : Model  (its parameters are the values of the coefficients not sampled)
    logs : TrialLog, DataFrame or list of them
    names : list of str  -- sampled coefficients
    meas_std : mapping channel -> std, optional  (default: from the data)
    channels : list of str, optional  (default: measured u, v, r where present, else every measured state)
    prior_mean, prior_std : arrays (n_names,), optional  (no prior when ``prior_std`` is None)
    substeps : int  -- RK4 steps per sample
    input_hold : {"foh", "zoh"}  -- inputs between samples (:func:`shipid.simulate.simulate`); default "foh",
        the identifier's default, so that the likelihood treats the inputs as the fit did
    x0_states : sequence of str or True, optional
        States whose initial value in every log is a further (nuisance) parameter: ``theta`` then has
        ``len(names) + n_logs * len(x0_states)`` columns (True: the ``channels``), the coefficients followed by, per log, the
        offsets of these initial states from ``x0`` (the mean of the first five samples), with a flat
        prior.  Default: none (the initial states are held at ``x0``, which the coefficients' posterior
        then does not account for).
    """

    def __init__(self, model, logs, names, *, meas_std=None, channels=None, prior_mean=None, prior_std=None,
                 substeps: int = 1, input_hold: str = "foh", x0_states=None):
        self.model = model
        self.names = list(names)
        self.idx = np.array([model.param_index(n) for n in self.names])
        arrays, meas = prepare_logs(model, logs)
        sig = noise_std_from_data(arrays)
        for k, v in (meas_std or {}).items():
            if k in meas:
                sig[meas.index(k)] = float(v)
        if channels is None:
            channels = [c for c in ("u", "v", "r") if c in meas] or list(meas)
        unknown = [c for c in channels if c not in meas]
        if unknown:
            raise ValueError(f"channels {unknown} are not measured in the logs (measured: {meas})")
        self.channels = list(channels)
        cj = [meas.index(c) for c in self.channels]
        self.st_idx = [model.state_index(c) for c in self.channels]
        self.sig = sig[cj]
        self.arrays = arrays
        self.Y = [a.Y[:, cj] for a in arrays]
        self.masks = [np.isfinite(y) for y in self.Y]
        self.n_obs = int(sum(m.sum() for m in self.masks))
        self.x0 = []
        for a in arrays:
            x0 = np.zeros(model.nx)
            for j, s in enumerate(meas):
                col = a.Y[:5, j]
                if np.isfinite(col).any():
                    x0[model.state_index(s)] = np.nanmean(col)
            self.x0.append(x0)
        self.x0_states = list(self.channels) if x0_states is True else list(x0_states or [])
        self.x0_idx = np.array([model.state_index(c) for c in self.x0_states], dtype=int)
        self.n_x0 = len(arrays) * self.x0_idx.size
        self.prior_mean = None if prior_mean is None else np.asarray(prior_mean, dtype=float)
        self.prior_std = None if prior_std is None else np.asarray(prior_std, dtype=float)
        self.substeps = int(substeps)
        if input_hold not in ("foh", "zoh"):
            raise ValueError(f"input_hold must be 'foh' or 'zoh', got {input_hold!r}")
        self.input_hold = input_hold
        self.base = model.params.astype(float).copy()
        self.n_calls = 0
        self.n_sims = 0
        # logs on one uniform sampling interval run as ONE batch (B walkers x G logs): the shorter logs
        # are padded to the longest with their last input held and the padding masked out
        self.groups = self._groups()

    def _groups(self):
        arrays = self.arrays
        dts = [np.diff(a.t) for a in arrays]
        h = float(np.median(dts[0]))
        if all(np.allclose(d, h, rtol=1e-9, atol=0.0) for d in dts):
            n = max(a.t.size for a in arrays)
            t = arrays[0].t[0] + h * np.arange(n)
            U = np.stack([np.vstack([a.U, np.repeat(a.U[-1:], n - a.t.size, axis=0)]) for a in arrays])
            Y = np.stack([np.vstack([y, np.full((n - y.shape[0], y.shape[1]), np.nan)]) for y in self.Y])
            return [(t, U, Y, np.isfinite(Y), np.stack(self.x0), np.arange(len(arrays)))]
        return [(a.t, a.U[None], y[None], m[None], x0[None], np.array([i]))
                for i, (a, y, m, x0) in enumerate(zip(arrays, self.Y, self.masks, self.x0))]

    def __call__(self, theta):
        """Log-posterior (up to a constant) of ``theta (B, n_names)`` -> (B,), or of one vector -> float."""
        th = np.asarray(theta, dtype=float)
        single = th.ndim == 1
        th = np.atleast_2d(th)
        B = th.shape[0]
        k, nk = self.idx.size, self.x0_idx.size
        if th.shape[1] != k + self.n_x0:
            raise ValueError(f"theta must have {k + self.n_x0} columns (coefficients, then initial-state offsets), got {th.shape[1]}")
        P = np.broadcast_to(self.base, (B, self.model.np)).copy()
        P[:, self.idx] = th[:, :k]
        lp = np.zeros(B)
        if self.prior_std is not None:
            lp -= 0.5 * np.sum(((th[:, :k] - self.prior_mean) / self.prior_std) ** 2, axis=1)
        self.n_calls += 1
        nx = self.model.nx
        for t, U, Y, m, x0, which in self.groups:
            G = U.shape[0]
            X0 = np.broadcast_to(x0, (B, G, nx)).copy()
            if nk:
                off = th[:, k:].reshape(B, -1, nk)[:, which]
                X0[:, :, self.x0_idx] += off
            X0 = X0.reshape(B * G, nx)
            Ub = np.broadcast_to(U, (B,) + U.shape).reshape((B * G,) + U.shape[1:])
            with warnings.catch_warnings(), np.errstate(all="ignore"):
                warnings.simplefilter("ignore", RuntimeWarning)
                sim = simulate(self.model, X0, t, Ub, params=np.repeat(P, G, axis=0), substeps=self.substeps,
                               input_hold=self.input_hold)
            self.n_sims += B * G
            xs = sim.x.reshape((B, G) + sim.x.shape[1:])[..., self.st_idx]
            e = np.where(m[None], (xs - Y[None]) / self.sig, 0.0)
            lp -= 0.5 * np.sum(e * e, axis=(1, 2, 3))
        lp = np.where(np.isfinite(lp), lp, -np.inf)
        return float(lp[0]) if single else lp


# ----------------------------------------------------------------------------- samples
@dataclass
class PosteriorSamples(ResultMixin):
    """MCMC samples of a model's coefficients and the diagnostics of the chain.

    Attributes
    ----------
    model : str
    names : list of str  -- sampled coefficients
    samples : ndarray (n, n_names)  -- kept draws (after burn-in and thinning, walkers pooled)
    chain : ndarray (n_kept_steps, n_walkers, n_names) or None  -- the kept chain (not stored in JSON)
    diagnostics : dict  -- acceptance, tau, ess, rhat per coefficient and the checks
    converged : bool
    message : str
    settings : dict
    success : bool (alias of ``converged``), status : 0 converged / 1 not converged
    """

    model: str
    names: list
    samples: np.ndarray
    diagnostics: dict
    converged: bool
    message: str
    settings: dict = field(default_factory=dict)
    chain: np.ndarray | None = None
    created: str = ""

    @property
    def success(self) -> bool:
        return bool(self.converged)

    @property
    def status(self) -> int:
        return 0 if self.converged else 1

    def to_pandas(self) -> pd.DataFrame:
        """The kept draws, one row per draw, one column per coefficient."""
        return pd.DataFrame(self.samples, columns=self.names)

    def summary(self) -> pd.DataFrame:
        """Per coefficient: mean, std, 2.5/50/97.5 % quantiles, tau, ESS, split-R-hat."""
        s = self.samples
        d = self.diagnostics
        return pd.DataFrame({
            "mean": s.mean(axis=0), "std": s.std(axis=0, ddof=1), "q2.5": np.quantile(s, 0.025, axis=0),
            "median": np.median(s, axis=0), "q97.5": np.quantile(s, 0.975, axis=0),
            "tau": [d["tau"][n] for n in self.names], "ess": [d["ess"][n] for n in self.names],
            "rhat": [d["rhat"][n] for n in self.names]}, index=self.names)

    def _html_title(self) -> str:
        return f"Posterior samples of '{self.model}' ({len(self.samples)} draws)"

    def plot(self, ax=None):
        """Histograms of the marginal draws of the (at most six) most correlated coefficients; returns the axes."""
        import matplotlib.pyplot as plt  # only when plotting: pyplot takes ~1 s to import

        names = self.most_correlated(6)
        if ax is None:
            _, axs = plt.subplots(1, len(names), figsize=(2.6 * len(names), 2.4), squeeze=False)
            axs = axs[0]
        else:
            axs = np.resize(np.atleast_1d(ax).ravel(), len(names))
        for a, n in zip(axs, names):
            a.hist(self.samples[:, self.names.index(n)], bins=30, color="C0", alpha=0.8)
            a.set_xlabel(n)
        axs[0].set_ylabel("draws")
        return axs

    def cov(self) -> pd.DataFrame:
        return pd.DataFrame(np.cov(self.samples, rowvar=False), index=self.names, columns=self.names)

    def most_correlated(self, k: int = 4) -> list[str]:
        """The ``k`` coefficients with the largest absolute posterior correlation with another one."""
        c = np.corrcoef(self.samples, rowvar=False)
        np.fill_diagonal(c, 0.0)
        score = np.nanmax(np.abs(c), axis=0)
        order = np.argsort(-score, kind="stable")[: min(k, len(self.names))]
        return [self.names[i] for i in sorted(order)]

    def to_dict(self) -> dict:
        return {"kind": "shipid posterior samples", "model": self.model, "names": list(self.names),
                "samples": self.samples.tolist(), "diagnostics": self.diagnostics, "converged": bool(self.converged),
                "message": self.message, "settings": self.settings, "created": self.created}

    def to_json(self, path, *, force: bool = False) -> Path:
        return atomic_write_text(path, json.dumps(self.to_dict(), indent=1, allow_nan=True) + "\n", force=force)

    @classmethod
    def from_dict(cls, doc: dict, source: str = "samples") -> "PosteriorSamples":
        for k in ("model", "names", "samples"):
            if k not in doc:
                raise ValueError(f"{source}: not a shipid samples file (no '{k}' entry); write it with `shipid sample`")
        S = np.asarray(doc["samples"], dtype=float)
        if S.ndim != 2 or S.shape[1] != len(doc["names"]) or S.shape[0] < 1:
            raise ValueError(f"{source}: 'samples' must be a list of rows with one value per name ({len(doc['names'])})")
        return cls(model=doc["model"], names=list(doc["names"]), samples=S, diagnostics=doc.get("diagnostics", {}),
                   converged=bool(doc.get("converged", False)), message=doc.get("message", ""),
                   settings=doc.get("settings", {}), created=doc.get("created", ""))


def load_samples(obj) -> PosteriorSamples:
    """PosteriorSamples from itself, its dict or a JSON path written by ``shipid sample``."""
    if isinstance(obj, PosteriorSamples):
        return obj
    if isinstance(obj, dict):
        return PosteriorSamples.from_dict(obj)
    if isinstance(obj, (str, os.PathLike)):
        p = Path(obj)
        if not p.exists():
            raise FileNotFoundError(f"{p}: no such samples file; write it with `shipid sample`")
        doc = read_json(p, "JSON samples file", advice="pass the file written by `shipid sample -o`")
        if not isinstance(doc, dict):
            raise ValueError(f"{p}: not a shipid samples file (top level is not an object)")
        return PosteriorSamples.from_dict(doc, source=str(p))
    raise ValueError(f"samples: expected PosteriorSamples, a dict or a JSON path, got {type(obj).__name__}")


def _tau(chain: np.ndarray) -> np.ndarray:
    """emcee's integrated autocorrelation time per parameter of ``chain (n_steps, n_walkers, n_params)``, without
    its multi-line "chain is shorter than 50 tau" log record (the length check of :func:`chain_diagnostics`
    says that in one line)."""
    from emcee.autocorr import integrated_time  # optional (the mcmc extra)

    log = logging.getLogger("emcee.autocorr")
    level = log.level
    log.setLevel(logging.ERROR)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return np.asarray(integrated_time(chain, quiet=True), dtype=float)
    finally:
        log.setLevel(level)


#: Early stop of :func:`sample_posterior`: the kept chain is checked every ``check_every`` steps (default
#: ``max(50, steps // 10)``); once the estimated autocorrelation time says the chain would need more than
#: ``EARLY_STOP_FACTOR`` times the steps asked for to reach 50 tau (after at least a third of them), sampling
#: stops and the message says how many steps it would take.  The tau estimated from a short chain is biased
#: low (Sokal 1997; emcee's documentation), so that number is a lower bound.
EARLY_STOP_FACTOR = 2.0


def chain_diagnostics(chain: np.ndarray, acceptance: np.ndarray, names, n_total_steps: int) -> dict:
    """Diagnostics of an ensemble chain ``(n_steps, n_walkers, n_params)`` and the convergence verdict."""
    n, w, k = chain.shape
    tau = _tau(chain)
    ess = n * w / tau
    rhat = split_rhat(np.moveaxis(chain, 1, 0)) if n >= 4 else np.full(k, np.inf)
    acc = float(np.mean(acceptance))
    lo, hi = CONVERGENCE["acceptance"]
    checks = {
        "acceptance": bool(lo <= acc <= hi),
        "rhat": bool(np.all(rhat < CONVERGENCE["rhat_max"])),
        "ess": bool(np.all(ess >= CONVERGENCE["ess_min"])),
        "length": bool(n >= CONVERGENCE["tau_factor"] * np.max(tau)),
    }
    why = []
    if not checks["acceptance"]:
        why.append(f"mean acceptance {acc:.3f} outside [{lo}, {hi}]")
    if not checks["rhat"]:
        j = int(np.argmax(rhat))
        why.append(f"split-R-hat {rhat[j]:.3f} >= {CONVERGENCE['rhat_max']} ({names[j]})")
    if not checks["ess"]:
        j = int(np.argmin(ess))
        why.append(f"ESS {ess[j]:.0f} < {CONVERGENCE['ess_min']:.0f} ({names[j]})")
    if not checks["length"]:
        why.append(f"kept chain of {n} steps < {CONVERGENCE['tau_factor']:.0f} x tau_max = {CONVERGENCE['tau_factor'] * np.max(tau):.0f}")
    return {"acceptance_mean": acc, "acceptance_min": float(np.min(acceptance)),
            "tau": dict(zip(names, map(float, tau))), "ess": dict(zip(names, map(float, ess))),
            "rhat": dict(zip(names, map(float, rhat))), "tau_max": float(np.max(tau)),
            "ess_min": float(np.min(ess)), "rhat_max": float(np.max(rhat)), "n_kept_steps": int(n),
            "n_walkers": int(w), "n_steps": int(n_total_steps), "checks": checks, "thresholds": CONVERGENCE,
            "not_converged_because": why}


def _early_stop(sampler, done: int, steps: int, burn: int, every: int, thin: int):
    """None to go on, or a dict (``at``, ``tau_max``, ``needed``, ``suggest``) when the chain sampled so far says
    ``steps`` are far too few (:data:`EARLY_STOP_FACTOR`)."""
    if done < max(steps // 3, burn + every):
        return None
    kept = sampler.get_chain(discard=burn, thin=thin)
    if kept.shape[0] < 20:
        return None
    tau_max = float(np.max(_tau(kept))) * thin
    needed = int(np.ceil(burn + CONVERGENCE["tau_factor"] * tau_max))
    if not np.isfinite(tau_max) or needed <= EARLY_STOP_FACTOR * steps:
        return None
    # with the default burn (a third of the steps) the kept two thirds must hold 50 tau: steps >= 75 tau
    suggest = int(np.ceil(max(needed, 1.5 * CONVERGENCE["tau_factor"] * tau_max) / 1000.0) * 1000)
    return {"at": int(done), "tau_max": tau_max, "needed": needed, "suggest": suggest}


def _proposal_in_sampler_coordinates(proposal, all_names, like):
    """Mean and covariance of a Laplace ``proposal`` (refiner or dict) over ``all_names``, the initial states
    as offsets from the likelihood's ``x0`` (the mean of each log's first five samples)."""
    if hasattr(proposal, "cov_joint_"):
        mean = dict(proposal.coef_.items())
        for i in range(len(like.arrays)):
            for c in like.x0_states:
                mean[f"{c}0[{i}]"] = float(proposal.x0_.iloc[i][c])
        cov = proposal.cov_joint_
    elif isinstance(proposal, dict) and "mean" in proposal and "cov" in proposal:
        mean, cov = dict(proposal["mean"]), pd.DataFrame(proposal["cov"])
    else:
        raise ValueError("proposal must be a fitted OutputErrorRefiner (estimate_x0=True for sample_x0) or a dict "
                         "{'mean': ..., 'cov': DataFrame}")
    missing = [n for n in all_names if n not in mean or n not in cov.index]
    if missing:
        raise ValueError(f"proposal lacks sampled dimension(s) {missing} (an initial state or a coefficient the "
                         "refinement held?): give a Laplace approximation over every sampled dimension")
    m = np.array([mean[n] for n in all_names], dtype=float)
    off = {f"{c}0[{i}]": like.x0[i][like.model.state_index(c)]
           for i in range(len(like.arrays)) for c in like.x0_states}
    m -= np.array([off.get(n, 0.0) for n in all_names])
    C = cov.loc[all_names, all_names].to_numpy(dtype=float)
    C = 0.5 * (C + C.T)
    if not (np.all(np.isfinite(m)) and np.all(np.isfinite(C)) and np.all(np.linalg.eigvalsh(C) > 0)):
        raise ValueError("proposal: the Laplace covariance is not finite and positive definite")
    return m, C


def _recorded_prior(res, names):
    """``(mean, std)`` arrays of the Gaussian prior the result's EKF started from, or ``(None, None)``
    (flat, with a warning) when the result does not record both for every name."""
    st = res.settings or {}
    pm, ps = st.get("prior_mean") or {}, st.get("prior_std") or {}
    mean = np.array([pm.get(n, np.nan) for n in names], dtype=float)
    std = np.array([ps.get(n, np.nan) for n in names], dtype=float)
    if np.all(np.isfinite(mean)) and np.all(np.isfinite(std) & (std > 0)):
        return mean, std
    warnings.warn(f"sample_posterior: the {res.method} result records no prior centre and width for "
                  f"{', '.join(n for n, m, s in zip(names, mean, std) if not (np.isfinite(m) and s > 0))} "
                  "(an older result, or a refinement): flat prior", UserWarning, stacklevel=3)
    return None, None


#: Fewest kept steps per walker (after burn-in and thinning) the chain diagnostics need (split-R-hat halves
#: the chain, the autocorrelation estimate needs a few lags).
MIN_KEPT_STEPS = 4


def _run_mcmc(sampler, state, steps: int, progress):
    """``sampler.run_mcmc(state, steps)`` with Ctrl-C taken between steps: emcee prints a traceback for any
    exception raised inside the likelihood (KeyboardInterrupt included) before passing it on, so the
    interrupt is noted by a handler and raised here, outside the likelihood.  Returns the last state."""
    hit: list = []
    previous = None
    if threading.current_thread() is threading.main_thread() and \
            signal.getsignal(signal.SIGINT) is signal.default_int_handler:
        previous = signal.signal(signal.SIGINT, lambda signum, frame: hit.append(signum))
    try:
        last = state
        for last in sampler.sample(state, iterations=steps, progress=progress):
            if hit:
                raise KeyboardInterrupt
        return last
    finally:
        if previous is not None:
            signal.signal(signal.SIGINT, previous)


def _check_sample_size(nw: int, steps: int, burn: int, thin: int, k: int, logs, like) -> None:
    """Refuse before anything is allocated: a thinning that keeps fewer than :data:`MIN_KEPT_STEPS` steps, and
    a run whose chain and batched simulations need more memory than :func:`shipid._io.memory_limit_bytes`."""
    kept = -(-(steps - burn) // thin)
    if kept < MIN_KEPT_STEPS:
        raise ValueError(f"thin={thin}: keeps {kept} of the {steps - burn} steps after burn-in (steps={steps}, "
                         f"burn={burn}); the diagnostics need at least {MIN_KEPT_STEPS}: use a smaller thin "
                         "(--thin) or more steps (--steps)")
    n_samples = sum(int(np.size(getattr(lg, "t", ()))) for lg in logs) or 1
    nx = len(getattr(like.model, "state_names", ())) or 6
    # emcee's chain and log-probabilities (steps x walkers x (dims + 1)), the proposal and its batched
    # simulation (walkers x samples x states, ~4 arrays of it alive in one RK4 step)
    need = 8.0 * (steps * nw * (k + 1) + 4 * nw * k + 4 * nw * n_samples * nx)
    check_memory(need, f"sampling with walkers={nw} x steps={steps}",
                 "use fewer walkers or steps (--walkers, --steps; the default walkers is max(4 x coefficients, 32))")


def sample_posterior(result, logs, *, walkers: int | None = None, steps: int = 2000, burn: int | None = None,
                     thin: int = 1, seed=0, vectorize: bool = True, channels=None, substeps: int = 1,
                     start_scale: float = 1.0, use_prior: bool = True, moves: str = "de",
                     input_hold: str | None = None, sample_x0: bool = False, proposal=None,
                     progress: bool = False, early_stop: bool = True, check_every: int | None = None,
                     log=None) -> PosteriorSamples:
    """Sample the posterior of a fit's estimated coefficients with emcee (optional extra ``mcmc``).

    Parameters
    ----------
    result : FitResult, dict or path to a result JSON
        Supplies the model, the estimated coefficients (``cov`` names), the start (the Gaussian
        ``N(coef, start_scale**2 cov)``), the noise levels (``settings["meas_std"]``) and the prior (the
        EKF's: ``settings["prior_mean"]``, ``settings["prior_std"]``; flat with a warning when not recorded).
    logs : TrialLog, DataFrame or list of them (the logs of the fit, or others)
    walkers : int, optional  -- ensemble size (default ``max(4 * n_coef, 32)``, even)
    steps : int  -- steps per walker
    burn : int, optional  -- steps discarded (default ``steps // 3``)
    thin : int  -- keep every ``thin``-th step
    seed : int  -- seeds the start and emcee's moves (same seed, same chain)
    vectorize : bool  -- one batched simulation per half ensemble (True) or one simulation per walker
    channels : list of str, optional  -- output-error channels (default u, v, r)
    substeps : int  -- RK4 steps per log sample
    start_scale : float  -- spread of the start relative to the EKF posterior
    use_prior : bool  -- include the prior the result's EKF started from (see module docstring)
    moves : {"de", "stretch", "independence"}
        emcee proposal: "de" (default) the mixture 0.8 differential evolution + 0.2 DE snooker
        (ter Braak 2006; ter Braak & Vrugt 2008), which decorrelates faster than "stretch", the
        Goodman & Weare (2010) move, on these near-Gaussian, strongly correlated posteriors
        (benchmarks/bench_uncertainty.py measures both).  "independence": the ``burn`` steps run the
        "de" mixture; then the proposal is frozen to a multivariate Student-t (:data:`INDEPENDENCE_T`)
        fitted to the walkers of the burn's second half, and the kept steps are independence
        Metropolis-Hastings (Tierney 1994, *Ann. Statist.* 22(4), 1701-1728): every walker is its own
        Markov chain, all walkers are proposed and evaluated in one batched call per step, and on a
        near-Gaussian posterior tau is a few steps instead of tens.  The proposal is fixed before the
        kept part starts, so the kept chain is a plain Metropolis-Hastings chain with the exact target;
        the same convergence checks apply (a poor proposal shows as low acceptance and long tau).
    input_hold : {"foh", "zoh"}, optional  -- inputs between samples; default the fit's
        (``result.settings["input_hold"]`` when recorded, else "foh", the identifier's default)
    sample_x0 : bool
        Also sample each log's initial values of the likelihood's channels (e.g. u, v, r) as nuisance
        parameters (flat prior, walkers started within ``sigma / sqrt(5)`` of the mean of the first five
        samples); the returned samples are the coefficients' marginal.  Default False: the initial
        states are held at that mean, and the coefficients' posterior is conditional on them (too narrow
        along the directions the initial states move; docs/uncertainty.md sect. 3).  The convergence
        checks cover every sampled dimension.
    proposal : fitted OutputErrorRefiner or dict, optional
        Only with ``moves="independence"``: the multivariate t of the independence proposal is centred on
        this Laplace approximation and scaled by its covariance (:data:`INDEPENDENCE_T`) instead of being
        fitted to a DE burn-in, and it is fixed from the first step (every step, the burn-in included, is
        then the same Metropolis-Hastings kernel with the exact target; ``burn`` only discards the walk
        away from the EKF start).  A refiner (``OutputErrorRefiner(..., estimate_x0=True)`` fitted to the
        same logs, e.g. started from ``result``) gives ``coef_``, its initial states ``x0_`` and the joint
        covariance ``cov_joint_``; a dict gives ``{"mean": {name: value}, "cov": DataFrame}`` over the
        sampled names (initial states as absolute values ``u0[i]`` ...).  Every sampled dimension must be in
        it.  The walkers still start from the EKF posterior ``N(coef, cov)`` of ``result``.
    progress : bool  -- emcee's tqdm progress bar
    early_stop : bool
        With "de" or "stretch": check the chain every ``check_every`` steps (default ``max(50, steps // 10)``)
        and stop when, after at least a third of ``steps``, the estimated autocorrelation time says 50 tau
        would need more than :data:`EARLY_STOP_FACTOR` times ``steps``; the result is then not converged and
        its message says how many steps to ask for (a lower bound: tau from a short chain is biased low).
    check_every : int, optional  -- steps between those checks
    log : callable, optional  -- called with one line as sampling starts and one per check (e.g. ``print``)

    Returns
    -------
    PosteriorSamples  (``converged`` False, with the reasons in ``message``, when any check fails)
    """
    try:
        import emcee  # optional (the mcmc extra)
    except ImportError:
        raise ValueError("MCMC sampling needs emcee: pip install 'shipid[mcmc]' (or pip install emcee)") from None
    res = as_result(result)
    model = res.to_model()
    names = list(res.cov.index)
    if not names:
        raise ValueError("result has no estimated coefficients (empty covariance): nothing to sample")
    k0 = len(names)
    steps, thin = int(steps), int(thin)
    burn = steps // 3 if burn is None else int(burn)
    if steps < 10 or thin < 1 or not 0 <= burn < steps:
        raise ValueError(f"need steps >= 10, thin >= 1 and 0 <= burn < steps; got steps={steps}, burn={burn}, thin={thin}")
    mu = np.array([res.coef[n] for n in names], dtype=float)
    cov = res.cov.loc[names, names].to_numpy(dtype=float)
    meas_std = (res.settings or {}).get("meas_std") or None
    prior_mean, prior_std = _recorded_prior(res, names) if use_prior else (None, None)
    like = OutputErrorLikelihood(model, logs, names, meas_std=meas_std, channels=channels,
                                 prior_mean=prior_mean, prior_std=prior_std,
                                 substeps=substeps,
                                 input_hold=input_hold or (res.settings or {}).get("input_hold") or "foh",
                                 x0_states=True if sample_x0 else None)
    x0_names = [f"{c}0[{i}]" for i in range(len(like.arrays)) for c in like.x0_states]
    all_names = names + x0_names
    k = len(all_names)
    nw = int(walkers) if walkers is not None else max(4 * k, 32)
    nw += nw % 2
    if nw < 2 * k:
        raise ValueError(f"walkers={nw}: emcee needs at least 2 x {k} sampled dimensions = {2 * k} walkers")
    _check_sample_size(nw, steps, burn, thin, k, logs, like)
    rng = np.random.default_rng(seed)
    w, V = np.linalg.eigh(0.5 * (cov + cov.T))
    A = V * np.sqrt(np.clip(w, 0, None))
    # the initial-state offsets start within the standard error of the mean of the first five samples
    x0_sd = np.tile(like.sig[[like.channels.index(c) for c in like.x0_states]] / np.sqrt(5.0), len(like.arrays))
    A = np.block([[A, np.zeros((k0, k - k0))], [np.zeros((k - k0, k0)), np.diag(x0_sd)]])
    mu = np.concatenate([mu, np.zeros(k - k0)])
    p0 = mu + start_scale * rng.standard_normal((nw, k)) @ A.T
    lp0 = like(p0)
    for _ in range(20):  # re-draw walkers that start where the simulation fails
        bad = ~np.isfinite(lp0)
        if not bad.any():
            break
        p0[bad] = mu + 0.5 * start_scale * rng.standard_normal((int(bad.sum()), k)) @ A.T
        lp0[bad] = like(p0[bad])
    if not np.all(np.isfinite(lp0)):
        raise ValueError("the EKF posterior gives non-finite likelihoods for some walkers after 20 re-draws; "
                         "check the fit (success, covariance) and the logs")
    fn = like if vectorize else (lambda th: like(th))
    if moves not in ("de", "stretch", "independence"):
        raise ValueError(f"moves={moves!r}: use 'de', 'stretch' or 'independence'")
    if proposal is not None and moves != "independence":
        raise ValueError(f"proposal= is the independence proposal: use moves='independence' (got {moves!r})")
    if moves == "independence" and proposal is None and burn < 20:
        raise ValueError(f"moves='independence' fits its proposal to the burn-in: need burn >= 20, got {burn}")
    mv = emcee.moves.StretchMove() if moves == "stretch" else [(emcee.moves.DEMove(), 0.8), (emcee.moves.DESnookerMove(), 0.2)]
    sampler = emcee.EnsembleSampler(nw, k, fn, vectorize=vectorize, moves=mv)
    sampler._random = np.random.mtrand.RandomState(int(rng.integers(2**31 - 1)))  # emcee's own stream, seeded
    stop, steps_run = None, steps  # early stop (de, stretch): the reason, and the steps sampled
    if moves == "independence" and proposal is not None:
        pm, pc = _proposal_in_sampler_coordinates(proposal, all_names, like)
        kept = emcee.EnsembleSampler(nw, k, fn, vectorize=vectorize, moves=_independence_move(emcee, pm, pc))
        kept._random = sampler._random
        _run_mcmc(kept, emcee.State(p0, log_prob=lp0), steps, progress)
        chain, acceptance = kept.get_chain(discard=burn, thin=thin), kept.acceptance_fraction
    elif moves == "independence":
        state = _run_mcmc(sampler, emcee.State(p0, log_prob=lp0), burn, progress)
        pts = sampler.get_chain(discard=burn // 2).reshape(-1, k)
        kept = emcee.EnsembleSampler(nw, k, fn, vectorize=vectorize,
                                     moves=_independence_move(emcee, pts.mean(axis=0), np.cov(pts, rowvar=False)))
        kept._random = sampler._random
        _run_mcmc(kept, state, steps - burn, progress)
        chain, acceptance = kept.get_chain(thin=thin), kept.acceptance_fraction
    else:
        done, state = 0, emcee.State(p0, log_prob=lp0)  # start values evaluated once
        every = max(50, steps // 10) if check_every is None else max(1, int(check_every))
        if log is not None:
            log(f"sampling: {nw} walkers x {steps} steps ({k} dimensions, {burn} "
                f"steps of burn-in), checked every {every} steps ...")
        while done < steps:
            n = min(every, steps - done)
            state = _run_mcmc(sampler, state, n, progress)  # Ctrl-C between steps
            done += n
            if log is not None:
                log(f"sampling: {done} of {steps} steps, mean acceptance {np.mean(sampler.acceptance_fraction):.2f}")
            stop = _early_stop(sampler, done, steps, burn, every, thin) if early_stop and done < steps else None
            if stop is not None:
                break
        steps_run = done
        chain, acceptance = sampler.get_chain(discard=burn, thin=thin), sampler.acceptance_fraction
    diag = chain_diagnostics(chain, acceptance, all_names, steps)
    diag["n_simulations"] = int(like.n_sims)
    diag["n_likelihood_calls"] = int(like.n_calls)
    ok = all(diag["checks"].values())
    diag["n_steps_run"] = int(steps_run)
    if stop is not None:
        ok = False
        diag["stopped_early"] = stop
        diag["checks"]["length"] = False
        msg = (f"NOT converged: stopped after {stop['at']} of {steps} steps: tau_max ~{stop['tau_max']:.0f} steps, so "
               f"50 tau needs at least {stop['needed']} steps; run again with --steps {stop['suggest']} (steps="
               f"{stop['suggest']}), or check the fit if that is out of reach")
    else:
        msg = "converged: " + ", ".join(f"{c} ok" for c in diag["checks"]) if ok else \
            "NOT converged: " + "; ".join(diag["not_converged_because"]) + " -- run longer (more steps) or check the fit"
    if not ok:
        warnings.warn(f"sample_posterior: {msg}", RuntimeWarning, stacklevel=2)
    settings = {"walkers": nw, "steps": steps, "moves": moves, "burn": burn,
                "proposal": ("laplace (given)" if proposal is not None else
                             "t fitted to the DE burn-in" if moves == "independence" else None), "thin": thin, "seed": seed if isinstance(seed, int) else None,
                "vectorize": bool(vectorize), "channels": like.channels, "substeps": int(substeps),
                "input_hold": like.input_hold, "sample_x0": bool(sample_x0), "x0_sampled": x0_names,
                "meas_std": dict(zip(like.channels, map(float, like.sig))), "start_scale": float(start_scale),
                "prior": ({"kind": "gaussian", "source": "the EKF's start (result settings prior_mean, prior_std)",
                           "mean": dict(zip(names, map(float, prior_mean))),
                           "std": dict(zip(names, map(float, prior_std)))}
                          if prior_std is not None else {"kind": "flat"}),
                "likelihood": "output error, independent Gaussian residuals", "n_obs": like.n_obs,
                "logs": [a.meta for a in like.arrays], "result_method": res.method,
                "coef": {kk: float(v) for kk, v in res.coef.items()}}
    return PosteriorSamples(model=res.model, names=names, samples=chain[..., :k0].reshape(-1, k0), diagnostics=diag,
                            converged=ok, message=msg, settings=settings, chain=chain[..., :k0],
                            created=datetime.now(timezone.utc).isoformat(timespec="seconds"))
