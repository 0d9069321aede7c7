"""Report section "Prediction uncertainty": intervals of the replayed metrics from N parameter draws,
IMO probabilities, 95 % bands on the time series and a cloud of tracks, and (with MCMC samples)
posterior pair plots of the most correlated coefficients."""
from __future__ import annotations

import numpy as np

from ..uncertainty import METRIC_KEYS, parameter_draws, replay_draws
from ..uncertainty.posterior import load_samples
from ..validation.replay import _for_length
from . import figures
from ._markup import _e, _f, _fig, _table

__all__ = ["uncertainty_section", "band_figure", "pair_figure"]

_BAND_CHANNELS = (("u", "u [m/s]", 1.0), ("r", "r [deg/s]", 180 / np.pi), ("psi", "psi [deg]", 180 / np.pi))


def band_figure(log_frame, sim, title: str, lpp=None, n_tracks: int = 60):
    """Measured dots, the 2.5-97.5 % band of the replays of N draws (time series) and up to ``n_tracks``
    replayed tracks.  ``sim``: batched SimulationResult (member 0 = point estimate)."""
    model = sim.model
    fig = figures._figure(11.0, 4.2)
    gs = fig.add_gridspec(len(_BAND_CHANNELS), 2, width_ratios=(1.6, 1.0))
    t = sim.t
    for k, (ch, label, f) in enumerate(_BAND_CHANNELS):
        ax = fig.add_subplot(gs[k, 0])
        i = model.state_index(ch)
        X = f * sim.x[1:, :, i]
        lo, hi = np.nanquantile(X, [0.025, 0.975], axis=0)
        ax.fill_between(t, lo, hi, color="C3", alpha=0.35, lw=0, label="95 % band of the draws")
        ax.plot(t, f * sim.x[0, :, i], "-", color="C3", lw=0.8, label="point estimate")
        if ch in log_frame.columns:
            ax.plot(log_frame["time"], f * log_frame[ch].to_numpy(float), ".", ms=1.2, color="0.3", label="measured")
        ax.set_ylabel(label, fontsize=7)
        ax.tick_params(labelsize=6)
        ax.grid(alpha=0.3)
        if k == 0:
            ax.legend(fontsize=6, loc="lower right", bbox_to_anchor=(1.0, 1.0), ncol=3, frameon=False,
                      markerscale=4, borderaxespad=0.2)
            ax.set_title(title, fontsize=8, loc="left")
    ax.set_xlabel("time [s]", fontsize=7)
    ax = fig.add_subplot(gs[:, 1])
    s = 1.0 / lpp if lpp else 1.0
    ix, iy = model.state_index("x"), model.state_index("y")
    for b in range(1, min(sim.x.shape[0], n_tracks + 1)):
        ax.plot(s * sim.x[b, :, iy], s * sim.x[b, :, ix], "-", color="C3", lw=0.4, alpha=0.25)
    ax.plot(s * sim.x[0, :, iy], s * sim.x[0, :, ix], "-", color="C3", lw=1.0)
    if {"x", "y"} <= set(log_frame.columns):
        ax.plot(s * log_frame["y"].to_numpy(float), s * log_frame["x"].to_numpy(float), ".", ms=1.2, color="0.3")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel(f"y [{'L' if lpp else 'm'}]", fontsize=7)
    ax.set_ylabel(f"x [{'L' if lpp else 'm'}]", fontsize=7)
    ax.tick_params(labelsize=6)
    ax.grid(alpha=0.3)
    ax.set_title(f"tracks of {min(sim.x.shape[0] - 1, n_tracks)} draws", fontsize=8)
    fig.subplots_adjust(left=0.07, right=0.98, bottom=0.11, top=0.9, hspace=0.15, wspace=0.2)
    return fig


def pair_figure(samples, k: int = 4):
    """Pair plot of the ``k`` most correlated coefficients of MCMC samples (histograms on the diagonal)."""
    names = samples.most_correlated(k)
    S = samples.to_pandas()[names].to_numpy()
    n = len(names)
    fig = figures._figure(1.9 * n + 0.6, 1.9 * n + 0.4)
    axs = fig.subplots(n, n, squeeze=False)
    for i in range(n):
        for j in range(n):
            ax = axs[i, j]
            if i == j:
                ax.hist(S[:, i], bins=40, color="C0")
            elif i > j:
                ax.plot(S[:, j], S[:, i], ",", color="C0", alpha=0.3)
            else:
                ax.axis("off")
                r = np.corrcoef(S[:, i], S[:, j])[0, 1]
                ax.text(0.5, 0.5, f"rho = {r:+.2f}", ha="center", va="center", fontsize=8, transform=ax.transAxes)
            ax.tick_params(labelsize=5)
            if i == n - 1:
                ax.set_xlabel(names[j], fontsize=7)
            if j == 0 and i > 0:
                ax.set_ylabel(names[i], fontsize=7)
    fig.suptitle("MCMC posterior: the most correlated coefficients", fontsize=8)
    return fig


def uncertainty_section(res, validations, *, draws: int, seed: int = 0, samples=None) -> str:
    """HTML of the section (see the module docstring); ``res`` a FitResult, ``validations`` LogValidations."""
    P = parameter_draws(res, draws, seed=seed, samples=samples)
    src = "MCMC samples" if samples is not None else "the fit's Gaussian posterior (full covariance)"
    parts = ["<h2 id=\"uncertainty\">Prediction uncertainty</h2>",
             f"<p class=\"note\">{draws} parameter sets drawn from {_e(src)} (seed {seed}); each log replayed with "
             "all of them as one batch.  Intervals are the 2.5-97.5 % quantiles of the replayed metric; they cover "
             "the identification uncertainty only (not model-structure error or disturbances).</p>"]
    rows, imo_rows, figs = [], [], []
    for v in validations:
        if v.measured is None or v.lpp is None or not v.simulation.success:
            continue
        kind = v.measured.manoeuvre
        m = _for_length(res.to_model(), v.lpp, [])
        blk = replay_draws(m, v.log, P, lpp=v.lpp, kind=kind, switch_deg=getattr(v.measured, "switch_deg", None),
                           rudder_sign=v.rudder_sign, with_nominal=True)
        meas = v.measured.to_dict()
        pred = v.predicted.to_dict() if v.predicted is not None else {}
        name = getattr(v.log, "name", "log")
        for key in METRIC_KEYS[kind]:
            lo, hi = blk.get(f"{key}_ci", [None, None])
            if lo is None:
                continue
            mv = meas.get(key)
            inside = None if mv is None else bool(lo <= mv <= hi)
            cell = ("&ndash;", "na") if inside is None else (("yes", "pass") if inside else ("no", "fail"))
            rows.append([_e(name), _e(key), _f(mv), _f(pred.get(key)), f"{_f(lo)} &ndash; {_f(hi)}", cell])
        for crit, p in blk["imo_probability"].items():
            imo_rows.append([_e(name), _e(crit), _f(p["probability"], "{:.3f}"), _e(f"{p['n_met']}/{draws}"),
                             _e(p["n_not_evaluated"])])
        if blk["draws"]["n_failed"]:
            parts.append(f"<p class=\"warn\">{_e(name)}: {blk['draws']['n_failed']} draws did not finish: "
                         f"{_e(blk['draws']['messages'])}</p>")
        figs.append(_fig(band_figure(v.log.data, blk["simulation"], f"{name}: replays of {draws} draws"),
                         f"uncertainty bands {name}"))
    if rows:
        parts.append(_table(["log", "metric", "measured", "predicted", "95 % interval", "measured inside"], rows, left=2))
    if imo_rows:
        parts.append("<h3>Probability that each IMO MSC.137(76) criterion is met (replayed manoeuvre)</h3>" +
                     _table(["log", "criterion", "probability", "met", "not evaluated"], imo_rows, left=2))
    parts += figs
    if samples is not None:
        s = load_samples(samples)
        parts.append(f"<h3>Posterior samples</h3><p class=\"note\">{_e(s.message)}</p>")
        parts.append(_fig(pair_figure(s), "posterior pair plot"))
    return "\n".join(parts)
