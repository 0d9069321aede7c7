"""Integrate a protocol model under an input schedule or a feedback law.

:func:`simulate` is the single forward simulator of the package: fixed-step
RK4 (the same map the EKF uses, :mod:`shipid.integrate`), vectorised over a
leading batch axis, with inputs given either as samples on the time grid
(zero-order hold between samples) or as a callable ``controller(t, x) -> u``
for state feedback (zigzag rudder logic, autopilots).
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
import pandas as pd

from .integrate import rk4_step
from .models.base import Model

__all__ = ["simulate", "SimulationResult", "replay", "replay_errors"]


@dataclass
class SimulationResult:
    """Result of :func:`simulate`.

    Attributes
    ----------
    t : ndarray, shape (n_t,)
    x : ndarray, shape (n_t, nx) or (B, n_t, nx) for a batch
    u : ndarray, shape (n_t, nu) or (B, n_t, nu)
    model : Model
    success : bool
        False when the state became non-finite; ``x`` is NaN from there on.
    message : str
    """

    t: np.ndarray
    x: np.ndarray
    u: np.ndarray
    model: Model
    params: np.ndarray
    success: bool = True
    message: str = "integration finished"
    meta: dict = field(default_factory=dict)

    @property
    def batched(self) -> bool:
        return self.x.ndim == 3

    def state(self, name: str) -> np.ndarray:
        """Time history of one state, shape (n_t,) or (B, n_t)."""
        return self.x[..., self.model.state_index(name)]

    def input(self, name: str) -> np.ndarray:
        """Time history of one input."""
        return self.u[..., self.model.input_index(name)]

    def to_pandas(self, member: int | None = None) -> pd.DataFrame:
        """States and inputs as a frame indexed by time (one batch member)."""
        x, u = self.x, self.u
        if self.batched:
            if member is None:
                raise ValueError("batched result: pass member=i to choose one simulation")
            x, u = x[member], u[member]
        cols = {n: x[:, i] for i, n in enumerate(self.model.state_names)}
        cols.update({n: u[:, i] for i, n in enumerate(self.model.input_names)})
        return pd.DataFrame(cols, index=pd.Index(self.t, name="time"))

    def plot(self, ax=None, member: int | None = 0):
        """Plot the states against time on one axes per state."""
        import matplotlib.pyplot as plt

        df = self.to_pandas(member if self.batched else None)
        names = list(self.model.state_names)
        if ax is None:
            fig, axs = plt.subplots(len(names), 1, sharex=True, figsize=(7, 1.6 * len(names)))
        else:
            axs = np.atleast_1d(ax)
        for a, n in zip(axs, names):
            a.plot(df.index, df[n])
            a.set_ylabel(f"{n} [{self.model.units.get(n, '')}]")
        axs[-1].set_xlabel("time [s]")
        return axs


def simulate(
    model: Model,
    x0,
    t,
    inputs=None,
    *,
    controller: Callable | None = None,
    params=None,
    substeps: int = 1,
) -> SimulationResult:
    """Integrate ``model`` from ``x0`` over the time grid ``t``.

    Parameters
    ----------
    model : Model
    x0 : array, shape (nx,) or (B, nx)
        Initial state; a 2-D array runs a batch of B simulations at once.
    t : array, shape (n_t,)
        Strictly increasing output times [s]; steps may be non-uniform.
    inputs : array, shape (n_t, nu) or (B, n_t, nu), optional
        Inputs sampled on ``t`` and held constant over each step.
    controller : callable ``(t, x) -> u``, optional
        State feedback evaluated at the start of each step (batch-aware:
        ``x`` has shape (B, nx) in a batch).  Exactly one of ``inputs`` and
        ``controller`` must be given.
    params : array, shape (np,) or (B, np), optional
        Defaults to ``model.params``.
    substeps : int
        RK4 steps per output interval.

    Returns
    -------
    SimulationResult
    """
    t = np.asarray(t, dtype=float)
    if t.ndim != 1 or t.size < 2 or np.any(np.diff(t) <= 0):
        raise ValueError("t must be a strictly increasing 1-D array with at least two times")
    if (inputs is None) == (controller is None):
        raise ValueError("give exactly one of inputs= (sampled inputs) or controller= (feedback law)")
    if substeps < 1:
        raise ValueError(f"substeps must be >= 1, got {substeps}")
    x0 = np.asarray(x0, dtype=float)
    if x0.shape[-1] != model.nx or x0.ndim > 2:
        raise ValueError(f"x0 must have shape ({model.nx},) or (B, {model.nx}) for {model.state_names}; got {x0.shape}")
    p = model.params if params is None else np.asarray(params, dtype=float)
    batch = x0.shape[:-1]
    n_t = t.size
    if inputs is not None:
        U = np.asarray(inputs, dtype=float)
        if U.shape[-2:] != (n_t, model.nu):
            raise ValueError(f"inputs must have shape (..., {n_t}, {model.nu}) for {model.input_names}; got {U.shape}")
        U = np.broadcast_to(U, batch + (n_t, model.nu))
    X = np.full(batch + (n_t, model.nx), np.nan)
    Uout = np.full(batch + (n_t, model.nu), np.nan)
    x = x0.copy()
    X[..., 0, :] = x
    ok, msg = True, "integration finished"
    for k in range(n_t - 1):
        uk = controller(t[k], x) if controller is not None else U[..., k, :]
        uk = np.broadcast_to(np.asarray(uk, dtype=float), batch + (model.nu,))
        Uout[..., k, :] = uk
        h = (t[k + 1] - t[k]) / substeps
        tk = t[k]
        for _ in range(substeps):
            x = rk4_step(model, tk, x, uk, p, h)
            tk += h
        X[..., k + 1, :] = x
        if not np.all(np.isfinite(x)):
            ok = False
            msg = f"state became non-finite at t = {t[k + 1]:.6g} s; the model or its parameters are unstable here"
            warnings.warn(msg, RuntimeWarning, stacklevel=2)
            break
    if ok:
        last = controller(t[-1], x) if controller is not None else U[..., -1, :]
        Uout[..., -1, :] = np.broadcast_to(np.asarray(last, dtype=float), batch + (model.nu,))
    return SimulationResult(t=t, x=X, u=Uout, model=model, params=np.array(p), success=ok, message=msg)


def _log_frame(log) -> pd.DataFrame:
    data = log if isinstance(log, pd.DataFrame) else getattr(log, "data", None)
    if not isinstance(data, pd.DataFrame) or "time" not in data.columns:
        raise ValueError("replay needs a TrialLog or a DataFrame with a 'time' column")
    return data


def replay(model: Model, log, *, x0=None, substeps: int = 2) -> SimulationResult:
    """Simulate ``model`` with the recorded inputs of ``log`` from its initial state.

    Parameters
    ----------
    model : Model
        Typically a fitted model (``FitResult.to_model()``).
    log : TrialLog or DataFrame
        Must contain ``time`` and every input of the model.
    x0 : array (nx,), optional
        Initial state; default: the mean of the first five finite samples of
        each logged state (0 for states not logged).
    substeps : int
        RK4 steps per sample interval.
    """
    df = _log_frame(log)
    t = df["time"].to_numpy(dtype=float)
    missing = [n for n in model.input_names if n not in df.columns]
    if missing:
        raise ValueError(f"log lacks input channel(s) {missing} needed to replay model '{model.name}'")
    U = np.column_stack([df[n].to_numpy(dtype=float) for n in model.input_names])
    if not np.all(np.isfinite(U)):
        k = int(np.flatnonzero(~np.all(np.isfinite(U), axis=1))[0])
        raise ValueError(f"log input missing at sample {k} (t = {t[k]:.6g} s); interpolate the inputs before replaying")
    if x0 is None:
        x0 = np.zeros(model.nx)
        for i, n in enumerate(model.state_names):
            if n in df.columns:
                col = df[n].to_numpy(dtype=float)
                fin = col[np.isfinite(col)][:5]
                if fin.size:
                    x0[i] = fin.mean()
    return simulate(model, x0, t, U, substeps=substeps)


def replay_errors(sim: SimulationResult, log) -> pd.DataFrame:
    """Per-channel RMSE and NRMSE (RMSE / range of the measurement) of a replay,
    plus the track error (RMS distance between simulated and logged x, y).

    Returns a DataFrame indexed by channel with columns ``rmse``, ``nrmse``,
    ``n_samples``; the row ``track`` holds the RMS position error [m].
    """
    df = _log_frame(log)
    rows = {}
    for i, n in enumerate(sim.model.state_names):
        if n not in df.columns:
            continue
        y = df[n].to_numpy(dtype=float)
        s = sim.x[:, i]
        ok = np.isfinite(y) & np.isfinite(s)
        if not ok.any():
            continue
        e = s[ok] - y[ok]
        rmse = float(np.sqrt(np.mean(e**2)))
        rng = float(np.ptp(y[ok]))
        rows[n] = {"rmse": rmse, "nrmse": rmse / rng if rng > 0 else np.nan, "n_samples": int(ok.sum())}
    if {"x", "y"} <= set(df.columns) and {"x", "y"} <= set(sim.model.state_names):
        dx = sim.state("x") - df["x"].to_numpy(dtype=float)
        dy = sim.state("y") - df["y"].to_numpy(dtype=float)
        d2 = dx**2 + dy**2
        ok = np.isfinite(d2)
        if ok.any():
            rows["track"] = {"rmse": float(np.sqrt(np.mean(d2[ok]))), "nrmse": np.nan, "n_samples": int(ok.sum())}
    return pd.DataFrame.from_dict(rows, orient="index")
