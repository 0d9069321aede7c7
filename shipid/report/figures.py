"""Figures of the validation report, rendered off-screen (matplotlib Agg) to PNG data URIs.

Every function builds its own :class:`matplotlib.figure.Figure` with an Agg
canvas -- pyplot and the global backend are never touched, so the report can
be written from any program (GUI, notebook, server) without side effects.
"""
from __future__ import annotations

import base64
import io
import math

import numpy as np
import pandas as pd
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

__all__ = ["to_data_uri", "correlation_figure", "time_series_figure", "track_figure", "residual_figure",
           "innovation_figure", "TIME_SERIES_CHANNELS"]

#: Channels of the measured-vs-simulated time series: (name, label, factor to the plotted unit).
TIME_SERIES_CHANNELS = (("u", "u [m/s]", 1.0), ("v", "v [m/s]", 1.0), ("r", "r [deg/s]", 180 / math.pi),
                        ("psi", "psi [deg]", 180 / math.pi), ("delta", "delta [deg]", 180 / math.pi))
_PLOT_UNITS = {"x": ("m", 1.0), "y": ("m", 1.0), "u": ("m/s", 1.0), "v": ("m/s", 1.0),
               "r": ("deg/s", 180 / math.pi), "psi": ("deg", 180 / math.pi), "delta": ("deg", 180 / math.pi)}
_DPI = 80


def _figure(width: float, height: float) -> Figure:
    fig = Figure(figsize=(width, height), dpi=_DPI)
    FigureCanvasAgg(fig)
    return fig


def _margins(fig: Figure) -> None:
    """Fixed margins in inches (one draw per figure; ``bbox_inches='tight'`` would draw twice)."""
    w, h = fig.get_size_inches()
    fig.subplots_adjust(left=1.0 / w, right=1 - 0.2 / w, bottom=0.6 / h, top=1 - 0.5 / h, hspace=0.15)


def to_data_uri(fig: Figure) -> str:
    """PNG of ``fig`` as a ``data:image/png;base64,...`` URI."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=_DPI, metadata={"Software": None})
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode("ascii")


def correlation_figure(names: list[str], matrix) -> Figure:
    """Heat-map of the posterior correlation matrix (values printed where |rho| >= 0.5)."""
    C = np.asarray(matrix, dtype=float)
    n = len(names)
    size = max(4.0, 0.5 * n + 1.8)
    fig = _figure(size + 1.9, size)  # room on the right for the colour bar, its tick labels and its label
    ax = fig.add_subplot()
    im = ax.imshow(C, cmap="RdBu_r", vmin=-1, vmax=1)
    ax.set_xticks(range(n), names, rotation=90, fontsize=11)
    ax.set_yticks(range(n), names, fontsize=11)
    for i in range(n):
        for j in range(n):
            if i != j and np.isfinite(C[i, j]) and abs(C[i, j]) >= 0.5:
                ax.text(j, i, f"{C[i, j]:+.1f}" if n > 12 else f"{C[i, j]:+.2f}", ha="center", va="center",
                        fontsize=8 if n > 12 else 9, color="white" if abs(C[i, j]) > 0.8 else "black")
    cb = fig.colorbar(im, ax=ax, fraction=0.046, pad=0.04)
    cb.set_label("correlation coefficient (-1 .. +1)", fontsize=11)
    cb.ax.tick_params(labelsize=10)
    ax.set_title("posterior correlation of the estimated coefficients", fontsize=12)
    w, h = fig.get_size_inches()
    fig.subplots_adjust(left=1.0 / w, right=1 - 1.6 / w, bottom=1.0 / h, top=1 - 0.5 / h)
    return fig


#: Inputs plotted under the time series when they vary during the log: (name, label, factor to the plotted unit).
VARYING_INPUTS = (("n", "n [rpm]", 60.0), ("wind_speed_true", "true wind [m/s]", 1.0),
                  ("wind_speed_rel", "apparent wind [m/s]", 1.0), ("wind_dir_true", "true wind from [deg]", 180 / math.pi))


def _varies(values: np.ndarray) -> bool:
    """A channel worth a plot: it changes by more than 2 % of its largest magnitude (or changes sign)."""
    v = values[np.isfinite(values)]
    if v.size < 2:
        return False
    big = float(np.max(np.abs(v)))
    return big > 0 and (float(np.ptp(v)) > 0.02 * big or (v.min() < 0 < v.max()))


def _legend_above(ax, **kw) -> None:
    """The legend in a row above the axes, right-aligned, where it cannot cover data."""
    ax.legend(loc="lower right", bbox_to_anchor=(1.0, 1.0), ncol=4, frameon=False, borderaxespad=0.2, **kw)


def time_series_figure(log_frame: pd.DataFrame, sim_frame: pd.DataFrame, title: str) -> Figure:
    """Measured (dots) vs replayed (line) u, v, r, psi and delta against time, and below them the propeller
    rate and the wind where they vary during the log (e.g. berthing runs that go astern)."""
    chans = [c for c in TIME_SERIES_CHANNELS if c[0] in log_frame.columns or c[0] in sim_frame.columns]
    chans += [c for c in VARYING_INPUTS if c[0] in log_frame.columns and _varies(log_frame[c[0]].to_numpy(float))]
    wrap = {"wind_dir_true"}  # directions in (-180, 180] deg: a wind from about north does not jump 0 <-> 360
    fig = _figure(8.5, 1.45 * len(chans) + 0.8)
    axs = fig.subplots(len(chans), 1, sharex=True, squeeze=False)[:, 0]
    t_log = log_frame["time"].to_numpy(float)
    t_sim = sim_frame["time"].to_numpy(float)
    for ax, (ch, label, f) in zip(axs, chans):
        if ch in log_frame.columns:
            y = f * log_frame[ch].to_numpy(float)
            if ch in wrap:
                y = 180.0 - np.mod(180.0 - y, 360.0)
            ax.plot(t_log, y, ".", ms=1.5, color="0.35", label="measured")
        if ch in sim_frame.columns and ch not in ("delta", "n") and not ch.startswith("wind"):
            ax.plot(t_sim, f * sim_frame[ch].to_numpy(float), "-", lw=1.2, color="C3", label="replay (model)")
        ax.set_ylabel(label, fontsize=11)
        ax.tick_params(labelsize=10)
        ax.grid(alpha=0.3)
    _legend_above(axs[0], fontsize=10, markerscale=4)
    axs[0].set_title(title, fontsize=12, loc="left")
    axs[-1].set_xlabel("time [s]", fontsize=11)
    _margins(fig)
    return fig


def track_figure(log_frame: pd.DataFrame, sim_frame: pd.DataFrame, title: str) -> Figure:
    """Measured vs replayed track (north x up, east y right) in metres, as every track of the report."""
    s, unit = 1.0, "m"
    fig = _figure(5.0, 5.6)
    ax = fig.add_subplot()
    if {"x", "y"} <= set(log_frame.columns):
        ax.plot(s * log_frame["y"].to_numpy(float), s * log_frame["x"].to_numpy(float), ".", ms=1.5, color="0.35",
                label="measured")
    if {"x", "y"} <= set(sim_frame.columns):
        ax.plot(s * sim_frame["y"].to_numpy(float), s * sim_frame["x"].to_numpy(float), "-", lw=1.2, color="C3",
                label="replay (model)")
        ax.plot(s * sim_frame["y"].iloc[0], s * sim_frame["x"].iloc[0], "o", color="k", ms=4, label="start")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel(f"y (east) [{unit}]", fontsize=11)
    ax.set_ylabel(f"x (north) [{unit}]", fontsize=11)
    ax.tick_params(labelsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=10, markerscale=3, loc="upper center", bbox_to_anchor=(0.5, -0.1), ncol=3, frameon=False)
    ax.set_title(title, fontsize=12)
    fig.subplots_adjust(left=0.18, right=0.97, bottom=0.2, top=0.93)
    return fig


def residual_figure(log_frame: pd.DataFrame, sim_frame: pd.DataFrame, title: str,
                    channels=("u", "v", "r", "psi")) -> Figure:
    """Replay residuals (measured - replay) of the state channels against time."""
    chans = [c for c in channels if c in log_frame.columns and c in sim_frame.columns]
    fig = _figure(8.5, 1.25 * max(1, len(chans)) + 0.6)
    axs = fig.subplots(max(1, len(chans)), 1, sharex=True, squeeze=False)[:, 0]
    t = log_frame["time"].to_numpy(float)
    for ax, ch in zip(axs, chans):
        unit, f = _PLOT_UNITS.get(ch, ("", 1.0))
        e = f * (log_frame[ch].to_numpy(float) - sim_frame[ch].to_numpy(float))
        ax.plot(t, e, "-", lw=0.8, color="C0")
        ax.axhline(0, color="k", lw=0.6)
        ax.set_ylabel(f"{ch} [{unit}]", fontsize=11)
        ax.tick_params(labelsize=10)
        ax.grid(alpha=0.3)
    axs[0].set_title(title, fontsize=12)
    axs[-1].set_xlabel("time [s]", fontsize=11)
    _margins(fig)
    return fig


def innovation_figure(innov: pd.DataFrame, title: str) -> Figure:
    """EKF innovations (measured minus the filter's one-step prediction) with the band of
    +-2 predicted standard deviations (``2 sqrt(S)``, S the innovation variance)."""
    chans = [c for c in innov.columns if c != "time" and not c.endswith("_S") and f"{c}_S" in innov.columns]
    fig = _figure(8.5, 1.25 * max(1, len(chans)) + 0.6)
    axs = fig.subplots(max(1, len(chans)), 1, sharex=True, squeeze=False)[:, 0]
    t = innov["time"].to_numpy(float)
    for ax, ch in zip(axs, chans):
        unit, f = _PLOT_UNITS.get(ch, ("", 1.0))
        e = f * innov[ch].to_numpy(float)
        band = 2 * f * np.sqrt(np.clip(innov[f"{ch}_S"].to_numpy(float), 0, None))
        ax.fill_between(t, -band, band, color="C1", alpha=0.25, lw=0, label="filter's predicted ±2σ")
        ax.plot(t, e, "-", lw=0.7, color="C0", label="innovation")
        # the first samples (filter start-up) can be far larger than the rest: scale to the bulk
        fin = np.abs(e[np.isfinite(e)])
        bnd = band[np.isfinite(band)]
        lim = max(np.percentile(fin, 99.5) if fin.size else 0.0, np.percentile(bnd, 99.5) if bnd.size else 0.0)
        if lim > 0:
            ax.set_ylim(-1.3 * lim, 1.3 * lim)
        ax.set_ylabel(f"{ch} [{unit}]", fontsize=11)
        ax.tick_params(labelsize=10)
        ax.grid(alpha=0.3)
    _legend_above(axs[0], fontsize=10)
    axs[0].set_title(title, fontsize=12, loc="left")
    axs[-1].set_xlabel("time [s]", fontsize=11)
    _margins(fig)
    return fig
