"""Propagation of identification uncertainty into standard-manoeuvre predictions.

From a fit result, N parameter sets are drawn -- from the Gaussian (Laplace)
posterior with the result's full covariance, or from MCMC samples
(:func:`shipid.uncertainty.sample_posterior`) -- and every requested standard
manoeuvre is simulated for all of them as **one batch**
(:func:`shipid.manoeuvres.turning_circle` / :func:`~shipid.manoeuvres.zigzag`
with ``params`` of shape ``(N + 1, np)``: member 0 is the point estimate).
Each metric is summarised by its mean, median, standard deviation and the
2.5 / 97.5 % quantiles of the draws (a 95 % *prediction interval of the model's
metric given the identification uncertainty*), and each IMO MSC.137(76)
criterion by the fraction of draws that meet it.

What the intervals assume (see ``docs/uncertainty.md``): the model structure
is right, the posterior of the coefficients is the Gaussian of the fit (or the
MCMC samples), the fixed parameters and the ship particulars are exact, and
the manoeuvre is run as specified (approach speed, rudder rate) in calm water.
They do not cover model-structure error, scale effects or environmental
disturbances.

Draws that do not finish a manoeuvre (unstable parameter sets, a turn that
never reaches 180 deg) are counted and reported per manoeuvre
(``n_failed``, ``failures``); quantiles use the finite values only, and the
IMO probabilities count a failed draw as *not demonstrated* (conservative),
with the probability over the evaluated draws reported beside it.
"""
from __future__ import annotations

import json
import math
import os
import re
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

import numpy as np
import pandas as pd

from .._io import atomic_write_text, check_memory
from ..identify.result import as_result
from ..manoeuvres import metrics, ship_info, turning_circle, zigzag
from ..results import ResultMixin
from ..simulate import replay
from .posterior import load_samples

__all__ = ["ManoeuvreSpec", "parse_manoeuvre", "parameter_draws", "predict_manoeuvres", "ManoeuvrePrediction",
           "summarise_draws", "imo_probability", "METRIC_KEYS", "replay_draws"]

#: Metrics summarised per manoeuvre kind (keys of ``TurningMetrics.to_dict`` / ``ZigzagMetrics.to_dict``).
METRIC_KEYS = {
    "turning": ("advance_L", "transfer_L", "tactical_diameter_L", "steady_diameter_L", "speed_loss",
                "time_90", "time_180", "initial_turning_L"),
    "zigzag": ("overshoot1_deg", "overshoot2_deg", "overshoot1_time", "overshoot2_time", "time_second_execute",
               "initial_turning_L"),
}


# ----------------------------------------------------------------------------- manoeuvres
@dataclass(frozen=True)
class ManoeuvreSpec:
    """One standard manoeuvre: ``kind`` "turning" (``rudder_deg``) or "zigzag" (``rudder_deg``/``switch_deg``),
    on ``side`` "starboard" or "port" (side of the first rudder execute)."""

    kind: str
    rudder_deg: float
    switch_deg: float | None = None
    side: str = "starboard"

    @property
    def label(self) -> str:
        if self.kind == "turning":
            return f"turning_{self.rudder_deg:g}_{self.side}"
        return f"zigzag_{self.rudder_deg:g}_{self.switch_deg:g}_{self.side}"


_SPEC_RE = re.compile(r"^\s*(turning|zigzag)\s*:\s*([0-9.]+)\s*(?:/\s*([0-9.]+))?\s*(?::\s*(starboard|port))?\s*$")


def parse_manoeuvre(spec) -> ManoeuvreSpec:
    """A :class:`ManoeuvreSpec` from itself or a string ``"turning:35[:port]"`` / ``"zigzag:10/10[:port]"``."""
    if isinstance(spec, ManoeuvreSpec):
        return spec
    m = _SPEC_RE.match(str(spec))
    if not m:
        raise ValueError(f"manoeuvre {spec!r}: write 'turning:35', 'zigzag:10/10' or 'zigzag:20/20:port'")
    kind, a, b, side = m.group(1), float(m.group(2)), m.group(3), m.group(4) or "starboard"
    if not a > 0:
        raise ValueError(f"manoeuvre {spec!r}: the rudder angle must be positive (use ':port' for the side)")
    if kind == "turning":
        if b is not None:
            raise ValueError(f"manoeuvre {spec!r}: a turning circle takes one angle, e.g. 'turning:35'")
        return ManoeuvreSpec("turning", a, None, side)
    sw = float(b) if b is not None else a
    if not sw > 0:
        raise ValueError(f"manoeuvre {spec!r}: the switch angle must be positive")
    return ManoeuvreSpec("zigzag", a, sw, side)


# ----------------------------------------------------------------------------- draws
#: Bytes one parameter draw costs per simulated sample and state: the batched RK4 keeps about four state
#: arrays alive (stages) and the trajectory; one more for the metrics' frames.
_DRAW_BYTES_PER_SAMPLE_STATE = 8 * 6
#: A standard manoeuvre's length in samples for the estimate before it is simulated (a 35 deg turning circle
#: or a 20/20 zigzag of the KCS model at dt = 0.1 s: 1000-3000).
MANOEUVRE_SAMPLES = 3000


def check_draws_memory(draws: int, samples: int = MANOEUVRE_SAMPLES, states: int = 8, what: str = "draws") -> None:
    """Refuse ``draws`` whose batched simulations of ``samples`` samples need more memory than
    :func:`shipid._io.memory_limit_bytes` (one line with the estimate, the limit and the option)."""
    shown = f"{draws}" if draws < 10**12 else f"{draws:.3g}"
    check_memory(float(draws) * max(samples, 1) * max(states, 1) * _DRAW_BYTES_PER_SAMPLE_STATE,
                 f"{what}={shown} ({max(samples, 1)} samples each)", "use fewer draws (--draws, or 'draws' in a campaign)")


def parameter_draws(result, draws: int, *, seed=None, samples=None, inflation: float = 1.0) -> np.ndarray:
    """``draws`` full parameter vectors (N, np) of the result's model.

    Parameters
    ----------
    result : FitResult, dict or path to a result JSON
    draws : int
        Number of parameter sets N (>= 1).
    seed : int or numpy Generator, optional
    samples : PosteriorSamples, dict or path to a samples JSON, optional
        MCMC samples (:func:`shipid.uncertainty.sample_posterior`); N rows are drawn from them without
        replacement (with replacement when N exceeds their number).  Default: the Gaussian posterior
        ``N(coef, inflation**2 * cov)`` over the estimated coefficients (the result's ``cov``).
    inflation : float
        Factor on the standard deviations of the Gaussian draws (1 = the fit's covariance as it is;
        see ``docs/uncertainty.md`` for when a factor is justified).  Not applied to MCMC samples.

    The fixed parameters keep the result's values.
    """
    res = as_result(result)
    n = int(draws)
    if n < 1:
        raise ValueError(f"draws must be a positive integer, got {draws!r}")
    check_draws_memory(n, 1, 1)
    if not (inflation > 0 and math.isfinite(inflation)):
        raise ValueError(f"inflation must be a positive factor, got {inflation!r}")
    rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
    model = res.to_model()
    base = model.params.astype(float).copy()
    if samples is not None:
        s = load_samples(samples)
        if s.model != res.model:
            raise ValueError(f"samples are for model '{s.model}', the result for '{res.model}'")
        idx = np.array([model.param_index(k) for k in s.names])
        rows = rng.choice(s.samples.shape[0], size=n, replace=n > s.samples.shape[0])
        P = np.broadcast_to(base, (n, model.np)).copy()
        P[:, idx] = s.samples[rows]
        return P
    names = list(res.cov.index)
    if not names:
        raise ValueError("result has no covariance of estimated coefficients: nothing to draw")
    idx = np.array([model.param_index(k) for k in names])
    cov = res.cov.to_numpy(dtype=float) * inflation**2
    if not np.all(np.isfinite(cov)):
        raise ValueError("result covariance has non-finite entries: cannot draw parameter sets")
    w, V = np.linalg.eigh(0.5 * (cov + cov.T))
    if w.min() < -1e-9 * max(w.max(), 0.0):
        warnings.warn(f"result covariance is not positive semi-definite (smallest eigenvalue {w.min():.3g}); "
                      "negative eigenvalues set to 0 for the draws", RuntimeWarning, stacklevel=2)
    A = V * np.sqrt(np.clip(w, 0.0, None))
    P = np.broadcast_to(base, (n, model.np)).copy()
    P[:, idx] = base[idx] + rng.standard_normal((n, idx.size)) @ A.T
    return P


# ----------------------------------------------------------------------------- summaries
def summarise_draws(values, *, level: float = 0.95) -> dict:
    """Mean, median, std and the central ``level`` quantile interval of finite ``values``;
    ``n`` finite values, ``n_nonfinite`` others (never silently dropped)."""
    v = np.asarray([np.nan if x is None else x for x in values], dtype=float)
    ok = np.isfinite(v)
    lo_q, hi_q = (1 - level) / 2, 1 - (1 - level) / 2
    out = {"n": int(ok.sum()), "n_nonfinite": int((~ok).sum())}
    if ok.any():
        f = v[ok]
        out.update(mean=float(f.mean()), median=float(np.median(f)), std=float(f.std(ddof=1)) if f.size > 1 else 0.0,
                   low=float(np.quantile(f, lo_q)), high=float(np.quantile(f, hi_q)))
    else:
        out.update(mean=None, median=None, std=None, low=None, high=None)
    return out


def imo_probability(imo_dicts: Sequence[dict]) -> dict:
    """Per IMO criterion (``*_pass`` keys): fraction of draws meeting it.

    ``probability`` counts a draw whose criterion could not be evaluated (None) as not met;
    ``probability_evaluated`` is over the evaluated draws only; ``mc_std_error`` is the binomial
    Monte-Carlo standard error sqrt(p (1 - p) / N) of ``probability``.
    """
    keys = sorted({k for d in imo_dicts for k in d if k.endswith("_pass")})
    out = {}
    N = len(imo_dicts)
    for k in keys:
        vals = [d.get(k) for d in imo_dicts]
        ev = [v for v in vals if v is not None]
        n_pass = sum(bool(v) for v in ev)
        p = n_pass / N if N else None
        limit = next((d.get(k.replace("_pass", "_limit_deg"), d.get(k.replace("_pass", "_limit_L")))
                      for d in imo_dicts if d), None)
        out[k.replace("_pass", "")] = {
            "probability": p, "probability_evaluated": (n_pass / len(ev)) if ev else None,
            "n_met": int(n_pass), "n_evaluated": len(ev), "n_not_evaluated": N - len(ev),
            "mc_std_error": math.sqrt(p * (1 - p) / N) if N else None, "limit": limit,
        }
    return out


@dataclass
class ManoeuvrePrediction(ResultMixin):
    """Predicted standard manoeuvres with their uncertainty (from :func:`predict_manoeuvres`).

    Attributes
    ----------
    manoeuvres : list of ManoeuvreSpec
    runs : dict label -> ManoeuvreResult
        The batched simulations (member 0 = point estimate, members 1..N = draws).
    params : ndarray (N, np)
        The drawn parameter sets.
    source : str
        "gaussian" (fit covariance, with ``inflation``) or "mcmc".
    metrics : DataFrame
        One row per (manoeuvre, metric): nominal, mean, median, std, low, high, n, n_nonfinite.
    imo : dict label -> dict criterion -> probability block (see :func:`imo_probability`)
    failures : dict label -> {"n_failed": int, "messages": {message: count}}
    success : bool  -- every draw finished every manoeuvre
    status : int    -- 0 all finished, 1 some draws failed (counted), 2 the point estimate failed
    message : str
    """

    manoeuvres: list
    runs: dict
    params: np.ndarray
    source: str
    level: float
    inflation: float
    seed: Any
    metrics: pd.DataFrame
    imo: dict
    failures: dict
    nominal: dict
    success: bool = True
    status: int = 0
    message: str = ""
    settings: dict = field(default_factory=dict)

    @property
    def draws(self) -> int:
        return int(self.params.shape[0])

    def summary(self) -> pd.DataFrame:
        """One row per manoeuvre and metric: nominal, mean, median, std, interval ``low``/``high``, counts."""
        return self.metrics.copy()

    def to_pandas(self) -> pd.DataFrame:
        """Every simulated member's settings and metrics (member 0 = point estimate, 1..N = draws), with a
        ``manoeuvre`` column."""
        return pd.concat([self.runs[s.label].to_pandas().rename_axis("member").reset_index().assign(manoeuvre=s.label)
                          for s in self.manoeuvres], ignore_index=True)

    def _html_title(self) -> str:
        return f"Manoeuvre prediction ({self.draws} draws, {self.source})"

    def plot(self, ax=None):
        """One panel per manoeuvre with every draw (turning: tracks; zigzag: heading and rudder [deg]);
        returns the axes."""
        import matplotlib.pyplot as plt  # only when plotting: pyplot takes ~1 s to import

        n = len(self.manoeuvres)
        if ax is None:
            _, axs = plt.subplots(1, n, figsize=(5 * n, 4), squeeze=False)
            axs = axs[0]
        else:
            axs = np.resize(np.atleast_1d(ax).ravel(), n)
        for a, spec in zip(axs, self.manoeuvres):
            self.runs[spec.label].plot(ax=a)
            a.set_title(spec.label)
        return axs

    def metrics_of(self, label: str) -> pd.DataFrame:
        """Per-draw metrics of one manoeuvre (rows = draws 1..N; the point estimate is row 0)."""
        return self.runs[label].to_pandas()

    def to_dict(self) -> dict:
        """JSON-able: per manoeuvre the point-estimate metrics, ``"<metric>_ci": [low, high]``,
        ``"<metric>_mean"``, ``"<metric>_median"``, ``"<metric>_std"``, ``"imo_probability"`` and
        ``"draws"`` (count, failures)."""
        out = {"draws": self.draws, "source": self.source, "level": self.level, "inflation": self.inflation,
               "seed": self.seed if isinstance(self.seed, (int, type(None))) else str(self.seed),
               "success": self.success, "status": self.status, "message": self.message,
               "settings": self.settings, "manoeuvres": {}}
        for spec in self.manoeuvres:
            lab = spec.label
            block = dict(self.nominal[lab])
            rows = self.metrics[self.metrics["manoeuvre"] == lab]
            block.update(ci_block(rows))
            block["imo_probability"] = self.imo[lab]
            block["draws"] = {"n": self.draws, **self.failures[lab]}
            out["manoeuvres"][lab] = block
        return out

    def to_json(self, path, *, force: bool = False) -> Path:
        return atomic_write_text(path, json.dumps(self.to_dict(), indent=2, allow_nan=False) + "\n", force=force)


def ci_block(rows: pd.DataFrame) -> dict:
    """``{"<metric>_ci": [low, high], "<metric>_mean": ..., "<metric>_median": ..., "<metric>_std": ...}``
    from summary rows (columns metric, low, high, mean, median, std)."""
    out = {}
    for _, r in rows.iterrows():
        k = r["metric"]
        f = (lambda v: None if v is None or not np.isfinite(v) else float(v))
        out[f"{k}_ci"] = [f(r["low"]), f(r["high"])]
        out[f"{k}_mean"], out[f"{k}_median"], out[f"{k}_std"] = f(r["mean"]), f(r["median"]), f(r["std"])
    return out


def _summary_rows(label: str, kind: str, metric_dicts: list[dict], nominal: dict, level: float) -> list[dict]:
    rows = []
    for k in METRIC_KEYS[kind]:
        if k not in nominal and not any(k in d for d in metric_dicts):
            continue
        s = summarise_draws([d.get(k) for d in metric_dicts], level=level)
        rows.append({"manoeuvre": label, "metric": k, "nominal": nominal.get(k), **s})
    return rows


def _unfinished(m, kind: str | None, target: dict) -> str | None:
    """Why a member did not finish its manoeuvre (None when it did)."""
    if not m.success:
        return m.message or "failed"
    if kind == "turning" and not (getattr(m, "max_heading_change_deg", np.nan) >= target["heading_change_deg"] - 1e-6):
        return f"heading change did not reach {target['heading_change_deg']:g} deg within t_max"
    if kind == "zigzag":
        need = ("overshoot1_deg", "overshoot2_deg") if target["zigzag_executes"] >= 4 else ("overshoot1_deg",)
        miss = [k for k in need if not np.isfinite(getattr(m, k, np.nan))]
        if miss:
            return f"zigzag did not reach {' and '.join(miss)}"
    return None


def _failures(metric_objs, kind: str | None = None, target: dict | None = None) -> dict:
    """Count of members that did not finish, by reason (see :func:`_unfinished`)."""
    target = target or {"heading_change_deg": 540.0, "zigzag_executes": 4}
    msgs: dict[str, int] = {}
    n = 0
    for m in metric_objs:
        why = _unfinished(m, kind, target)
        if why is not None:
            n += 1
            msgs[why] = msgs.get(why, 0) + 1
    return {"n_failed": n, "messages": msgs}


def predict_manoeuvres(result, manoeuvres: Sequence = ("turning:35", "zigzag:10/10", "zigzag:20/20"), *,
                       draws: int = 500, seed=0, samples=None, inflation: float = 1.0, speed: float | None = None,
                       lpp: float | None = None, rudder_rate: float | None = None, level: float = 0.95,
                       method: str = "rk4", dt: float | None = None, zigzag_executes: int = 4,
                       params: np.ndarray | None = None) -> ManoeuvrePrediction:
    """Standard manoeuvres of a fitted model with their identification uncertainty.

    Parameters
    ----------
    result : FitResult, dict or path to a result JSON
    manoeuvres : sequence of str or ManoeuvreSpec
        e.g. ``("turning:35", "zigzag:10/10", "zigzag:20/20:port")``.
    draws : int
        Number N of parameter sets (each manoeuvre runs N + 1 members as one batch).
    seed : int, optional
        Seed of the draws (same seed, same numbers).
    samples : PosteriorSamples or samples JSON, optional
        Draw from MCMC samples instead of the Gaussian posterior (see :func:`parameter_draws`).
    inflation : float
        Standard-deviation factor of the Gaussian draws (default 1).
    speed : float, optional
        Approach speed [m/s] (default: the model's design speed).
    lpp, rudder_rate : optional
        Ship length [m] and rudder rate [rad/s] (default: the model's, :func:`shipid.manoeuvres.ship_info`).
    level : float
        Central probability of the intervals (default 0.95: 2.5 and 97.5 % quantiles).
    method, dt : integrator and step of :func:`shipid.manoeuvres.turning_circle` / ``zigzag``.
    zigzag_executes : int
        Rudder executes a zigzag runs to (4 gives the second overshoot; 3 is enough for the first).
    params : ndarray (N, np), optional
        Use these parameter sets instead of drawing (``draws``/``seed``/``samples`` ignored).

    Returns
    -------
    ManoeuvrePrediction
    """
    res = as_result(result)
    if not 0 < level < 1:
        raise ValueError(f"level must be in (0, 1), got {level!r}")
    specs = [parse_manoeuvre(s) for s in manoeuvres]
    if not specs:
        raise ValueError("manoeuvres: give at least one, e.g. ['turning:35']")
    model = res.to_model()
    if params is None:
        P = parameter_draws(res, draws, seed=seed, samples=samples, inflation=inflation)
        source = "mcmc" if samples is not None else "gaussian"
    else:
        P = np.asarray(params, dtype=float)
        if P.ndim != 2 or P.shape[1] != model.np:
            raise ValueError(f"params must have shape (N, {model.np}), got {P.shape}")
        source = "given"
    Pall = np.vstack([model.params[None], P])
    B = Pall.shape[0]
    runs, summary, imo, fails, nominal = {}, [], {}, {}, {}
    status = 0
    for spec in specs:
        spd = None if speed is None else np.full(B, float(speed))
        if spd is None:
            u0 = ship_info(model).get("design_speed")
            if u0 is None:
                raise ValueError(f"model '{model.name}': approach speed unknown; pass speed= [m/s]")
            spd = np.full(B, float(u0))
        with warnings.catch_warnings():  # unstable draws are counted below, not warned about one by one
            warnings.simplefilter("ignore", RuntimeWarning)
            try:
                if spec.kind == "turning":
                    run = turning_circle(model, spec.rudder_deg, speed=spd, side=spec.side, rudder_rate=rudder_rate,
                                         lpp=lpp, params=Pall, method=method, dt=dt)
                else:
                    run = zigzag(model, spec.rudder_deg, spec.switch_deg, speed=spd, first=spec.side,
                                 rudder_rate=rudder_rate, lpp=lpp, params=Pall, method=method, dt=dt,
                                 n_executes=zigzag_executes)
            except ValueError as exc:
                raise ValueError(f"{spec.label}: {exc}") from None
        runs[spec.label] = run
        dicts = [m.to_dict() for m in run.metrics]
        nominal[spec.label] = dicts[0]
        summary += _summary_rows(spec.label, spec.kind, dicts[1:], dicts[0], level)
        imo[spec.label] = imo_probability([d["imo"] for d in dicts[1:]])
        target = {"heading_change_deg": 540.0, "zigzag_executes": int(zigzag_executes)}
        fails[spec.label] = _failures(run.metrics[1:], spec.kind, target)
        if _unfinished(run.metrics[0], spec.kind, target) is not None:
            status = 2
        if fails[spec.label]["n_failed"] and status == 0:
            status = 1
    n_fail = {k: v["n_failed"] for k, v in fails.items() if v["n_failed"]}
    if status == 2:
        msg = "the point estimate did not finish every manoeuvre; intervals are of the draws that did"
    elif n_fail:
        msg = "draws that did not finish: " + ", ".join(f"{k} {v}/{P.shape[0]}" for k, v in n_fail.items())
    else:
        msg = f"all {P.shape[0]} draws finished every manoeuvre"
    settings = {"speed": None if speed is None else float(speed), "lpp": lpp,
                "rudder_rate_deg_s": None if rudder_rate is None else math.degrees(rudder_rate), "method": method,
                "dt": dt, "zigzag_executes": int(zigzag_executes), "result_model": res.model,
                "result_method": res.method}
    return ManoeuvrePrediction(specs, runs, P, source, float(level), float(inflation), seed, pd.DataFrame(summary),
                               imo, fails, nominal, success=status == 0, status=status, message=msg, settings=settings)


# ----------------------------------------------------------------------------- replays (validate)
def replay_draws(model, log, params: np.ndarray, *, lpp: float, kind: str, switch_deg=None,
                 rudder_sign: float = 1.0, substeps: int = 2, level: float = 0.95,
                 with_nominal: bool = False) -> dict:
    """Open-loop replays of one log with N parameter sets as one batch, and the interval of each
    predicted metric (the ``predicted`` block of :func:`shipid.validation.validate` gains
    ``"<metric>_ci"`` and ``"imo_probability"``).

    ``with_nominal``: also replay ``model.params`` as member 0 of the batch (for plots); the
    statistics are always over the N draws only.

    Returns ``{"<metric>_ci": [low, high], ..., "imo_probability": {...}, "draws": {...},
    "simulation": SimulationResult}``.
    """
    data = log.data if hasattr(log, "data") else log
    if rudder_sign == -1 and "delta" in data.columns:
        data = data.assign(delta=-data["delta"])
    P = np.asarray(params, dtype=float)
    check_draws_memory(P.shape[0], len(data), model.nx + model.nu)
    if with_nominal:
        P = np.vstack([model.params[None], P])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        sim = replay(model, data, substeps=substeps, params=P)
    dicts, objs = [], []
    for b in range(1 if with_nominal else 0, P.shape[0]):
        frame = pd.DataFrame({n: sim.x[b, :, i] for i, n in enumerate(model.state_names)})
        for i, n in enumerate(model.input_names):
            frame[n] = sim.u[b, :, i]
        frame.insert(0, "time", sim.t)
        if rudder_sign == -1:
            frame["delta"] = -frame["delta"]
        good = np.all(np.isfinite(sim.x[b]), axis=1)
        try:
            m = metrics(frame[good], lpp=lpp, kind=kind, switch_deg=switch_deg)
            if not good.all():
                m.success, m.message = False, "replay became non-finite; " + m.message
        except ValueError as exc:
            dicts.append({"imo": {}})
            objs.append(type("Failed", (), {"success": False, "message": str(exc)})())
            continue
        dicts.append(m.to_dict())
        objs.append(m)
    rows = _summary_rows("replay", kind, dicts, {}, level)
    out = ci_block(pd.DataFrame(rows)) if rows else {}
    out["imo_probability"] = imo_probability([d.get("imo", {}) for d in dicts])
    out["draws"] = {"n": len(dicts), **_failures(objs)}  # a replay is as long as its log: no 540 deg rule
    out["simulation"] = sim
    return out
