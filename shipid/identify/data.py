"""Bring trial logs into the arrays the identifier works on.

Accepts :class:`shipid.logs.TrialLog` objects or plain DataFrames with a
``time`` column, maps their channels onto the model's state and input names,
and estimates default measurement-noise levels from the data.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from ..models.base import Model

__all__ = ["LogArrays", "prepare_logs", "measured_states", "noise_std_from_data", "resolution_std", "frozen_mask"]


@dataclass
class LogArrays:
    """One log as arrays aligned with a model."""

    name: str
    t: np.ndarray  # (N,)
    U: np.ndarray  # (N, nu)
    Y: np.ndarray  # (N, nm), NaN = missing
    meta: dict = field(default_factory=dict)


def _frame(log) -> tuple[pd.DataFrame, dict]:
    if isinstance(log, pd.DataFrame):
        meta = {"name": log.attrs.get("name", "frame"), "path": None, "sha256": None}
        return log, meta
    data = getattr(log, "data", None)
    if not isinstance(data, pd.DataFrame):
        raise ValueError(f"expected a TrialLog or a pandas DataFrame, got {type(log).__name__}")
    meta = {"name": getattr(log, "name", "log"), "path": str(getattr(log, "path", "") or "") or None,
            "sha256": getattr(log, "sha256", None)}
    ship = getattr(log, "ship", None)
    if ship is not None:
        meta["lpp"] = getattr(ship, "lpp", None)
        meta["ship"] = ship.to_dict() if hasattr(ship, "to_dict") else {"lpp": meta["lpp"]}
    return data, meta


def prepare_logs(model: Model, logs) -> tuple[list[LogArrays], list[str]]:
    """Align logs with ``model``.

    Returns the per-log arrays and the names of the measured channels (model
    states present in at least one log; columns absent from a log are NaN).

    Raises
    ------
    ValueError
        When a log lacks an input channel, has NaN inputs, or no log measures
        any state.
    """
    if isinstance(logs, (pd.DataFrame,)) or hasattr(logs, "data"):
        logs = [logs]
    logs = list(logs)
    if not logs:
        raise ValueError("no logs given: pass one or more trial logs to fit")
    frames = [_frame(lg) for lg in logs]
    # (on the column's array: pandas' Series.notna costs ~25 us a column)
    meas = [s for s in model.state_names if any(s in f.columns and pd.notna(f[s].to_numpy()).any() for f, _ in frames)]
    if not meas:
        raise ValueError(
            f"none of the logs measures a state of model '{model.name}' ({', '.join(model.state_names)})"
        )
    out = []
    for (f, meta) in frames:
        name = meta["name"]
        if "time" not in f.columns:
            raise ValueError(f"log '{name}' has no 'time' column")
        t = f["time"].to_numpy(dtype=float)
        if t.size < 3 or np.any(np.diff(t) <= 0):
            raise ValueError(f"log '{name}': time must be strictly increasing with at least 3 samples")
        cols = []
        for inp in model.input_names:
            if inp not in f.columns:
                raise ValueError(
                    f"log '{name}' has no input channel '{inp}' needed by model '{model.name}' "
                    f"(inputs: {', '.join(model.input_names)})"
                )
            col = f[inp].to_numpy(dtype=float)
            bad = np.flatnonzero(~np.isfinite(col))
            if bad.size:
                raise ValueError(
                    f"log '{name}' input '{inp}' is missing at sample {bad[0]} (t = {t[bad[0]]:.6g} s): "
                    "inputs must be complete; read the log with interpolate_inputs=True to fill gaps"
                )
            cols.append(col)
        U = np.column_stack(cols) if cols else np.zeros((t.size, 0))
        Y = np.column_stack([
            f[s].to_numpy(dtype=float) if s in f.columns else np.full(t.size, np.nan) for s in meas
        ])
        out.append(LogArrays(name=name, t=t, U=U, Y=Y, meta=meta))
    return out, meas


def measured_states(model: Model, frame: pd.DataFrame, initial: dict | None = None) -> np.ndarray:
    """The model's state at every sample of ``frame``, for open-loop starts from the measurement.

    A state the frame has as a column is its measured channel; any other is its value in ``initial``
    (states the log does not measure, e.g. a fitted current ``{"cx": .., "cy": ..}``), else 0.  Returns
    an array ``(len(frame), model.nx)`` (one copy for :func:`shipid.identify.batch.prediction_windows`
    and :func:`shipid.validation.horizon.horizon_prediction`).

    Raises
    ------
    ValueError
        ``initial`` names a state the model does not have.
    """
    init = dict(initial or {})
    unknown = sorted(set(init) - set(model.state_names))
    if unknown:
        raise ValueError(f"initial: model '{model.name}' has no state(s) {unknown}")
    n = len(frame)
    return np.column_stack([frame[s].to_numpy(dtype=float) if s in frame.columns
                            else np.full(n, float(init.get(s, 0.0))) for s in model.state_names])


def resolution_std(logs: list[LogArrays]) -> np.ndarray:
    """Quantisation floor of the noise per channel: ``q / sqrt(12)`` with ``q`` the smallest non-zero
    step between consecutive recorded values (the channel's resolution), pooled over logs.

    A channel recorded with resolution ``q`` carries at least the rounding error of a uniform variable
    of width ``q`` (Widrow & Kollar, *Quantization Noise*, 2008, ch. 4).  NaN when a channel never
    changes.
    """
    nm = logs[0].Y.shape[1]
    out = np.full(nm, np.nan)
    for j in range(nm):
        steps = []
        for lg in logs:
            y = lg.Y[:, j]
            y = y[np.isfinite(y)]
            d = np.abs(np.diff(y))
            d = d[d > 0]
            if d.size:
                steps.append(d.min())
        if steps:
            out[j] = min(steps) / np.sqrt(12.0)
    return out


def frozen_mask(y: np.ndarray, min_changing: float = 0.9) -> np.ndarray:
    """Samples of a channel that repeat the previous value exactly in a channel that otherwise changes.

    A sensor that freezes (a GNSS receiver without a new fix repeats its last position) repeats the
    value bit for bit; in a channel whose values change at ``min_changing`` or more of the samples
    such repeats are not measurements.  A quantised, often-steady channel (repeats are normal) gives
    no mask.  ``y (N,)`` -> bool ``(N,)`` (the first sample of a frozen run is kept: it was a real fix).
    """
    y = np.asarray(y, dtype=float)
    fin = np.isfinite(y)
    same = np.zeros(y.size, dtype=bool)
    same[1:] = fin[1:] & fin[:-1] & (y[1:] == y[:-1])
    n_pairs = int((fin[1:] & fin[:-1]).sum())
    if n_pairs == 0 or 1.0 - same.sum() / n_pairs < min_changing:
        return np.zeros(y.size, dtype=bool)
    return same


def noise_std_from_data(logs: list[LogArrays], floor: float = 1e-9) -> np.ndarray:
    """Measurement-noise standard deviation per channel from the data.

    For white noise ``e`` on a smooth signal sampled fast, the second
    difference is dominated by ``e[k+1] - 2 e[k] + e[k-1]`` with variance
    ``6 sigma^2``; a robust (median absolute deviation) estimate of its
    spread divided by ``sqrt(6)`` estimates ``sigma``.  Pooled over logs.
    Floors: ``1e-4`` of the channel's range, its resolution
    (:func:`resolution_std`) and ``floor``.  A pre-filtered channel makes the
    second differences far smaller than the real prediction error; the
    identifier raises such levels from the innovations of a first pass.
    """
    nm = logs[0].Y.shape[1]
    sig = np.zeros(nm)
    res = resolution_std(logs)
    for j in range(nm):
        d2 = []
        scale = []
        for lg in logs:
            y = lg.Y[:, j]
            ok = np.isfinite(y[2:]) & np.isfinite(y[1:-1]) & np.isfinite(y[:-2])
            d2.append((y[2:] - 2 * y[1:-1] + y[:-2])[ok])
            fin = y[np.isfinite(y)]
            if fin.size:
                scale.append(np.ptp(fin))
        d = np.concatenate(d2) if d2 else np.array([])
        if d.size < 5:
            sig[j] = np.nan
            continue
        mad = np.median(np.abs(d - np.median(d))) / 0.6745
        rng = max(scale) if scale else 1.0
        sig[j] = max(mad / np.sqrt(6.0), 1e-4 * rng, res[j] if np.isfinite(res[j]) else 0.0, floor)
    return sig
