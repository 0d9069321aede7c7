"""Multi-start open-loop prediction: how far off is a model H seconds after it is let go?

For manoeuvres that are not standard (operator-driven random manoeuvres, berthing) the turning and
zigzag metrics do not apply.  :func:`horizon_prediction` starts the model at the *measured* state every
``start_every`` seconds of a log, runs it open loop with the *measured* inputs (rudder, propeller and,
for a model with wind inputs, the measured wind) for the longest horizon, and compares the predicted
position and heading with the measurement ``H`` seconds later.  All starts of a log are one batched
simulation; a start whose prediction becomes non-finite is a **blow-up**: it is counted
(``n_blowups``), its error is infinite (it pulls medians and percentiles up, it is never dropped), and
the other starts are finished (see :func:`shipid.simulate.simulate`).

:func:`dead_reckoning` is the reference every model must beat: constant body velocities and yaw rate
from the start sample (exact circular-arc kinematics).
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from ..identify.data import measured_states
from ..models.base import Model
from ..models.kinematics import planar_rates
from ..results import ResultMixin
from ..simulate import simulate

__all__ = ["horizon_prediction", "HorizonResult", "DeadReckoning", "dead_reckoning", "DEFAULT_HORIZONS"]

#: Horizons [s] of ``shipid validate --horizon`` by default.
DEFAULT_HORIZONS = (10.0, 30.0, 60.0)


class DeadReckoning(Model):
    """Constant body velocities and yaw rate (``u' = v' = r' = 0``): the no-model reference."""

    name = "dead-reckoning"
    state_names = ("x", "y", "psi", "u", "v", "r")
    input_names = ()
    param_names = ()

    def _rhs(self, t, x, u, p):
        psi, uu, v, r = x[..., 2], x[..., 3], x[..., 4], x[..., 5]
        z = np.zeros_like(uu)
        return np.stack([*planar_rates(psi, uu, v, r), z, z, z], axis=-1)


def dead_reckoning() -> DeadReckoning:
    """The dead-reckoning reference model."""
    return DeadReckoning()


@dataclass
class HorizonResult(ResultMixin):
    """Result of :func:`horizon_prediction` for one log.

    Attributes
    ----------
    name : str
        Log name.
    horizons : ndarray (nH,)
        Horizons [s].
    start_times : ndarray (nS,)
        Times of the starts [s].
    position_error : ndarray (nS, nH)
        Distance between predicted and measured midship position [m] (inf: blow-up; NaN: the log ends
        before the horizon or the measurement is missing there).
    heading_error : ndarray (nS, nH)
        |predicted - measured heading| wrapped to [0, 180] deg.
    blowup : ndarray (nS,) of bool
    tracks : dict
        ``t`` (nT,) relative times, ``x`` (nS, nT, nx) predicted states and ``measured`` (n, 2) the
        log's ``x, y`` [m], for track overlays.
    success : bool
        False when any prediction blew up.
    message : str
    """

    name: str
    horizons: np.ndarray
    start_times: np.ndarray
    position_error: np.ndarray
    heading_error: np.ndarray
    blowup: np.ndarray
    tracks: dict = field(default_factory=dict, repr=False)
    success: bool = True
    message: str = ""

    def summary(self) -> pd.DataFrame:
        """One row per horizon (index ``seconds``): ``n_starts``, ``n_blowups``, ``position_error_median_m``,
        ``position_error_p90_m``, ``heading_error_median_deg`` (the rows of :meth:`to_records`)."""
        return pd.DataFrame(self.to_records()).set_index("seconds")

    def _html_title(self) -> str:
        return f"Horizon prediction '{self.name}'"

    def to_records(self) -> list[dict]:
        """The per-log JSON entry: one dict per horizon with ``seconds``, ``position_error_median_m``,
        ``position_error_p90_m``, ``heading_error_median_deg``, ``n_starts``, ``n_blowups``."""
        out = []
        for j, H in enumerate(self.horizons):
            pe, he = self.position_error[:, j], self.heading_error[:, j]
            ok = ~np.isnan(pe)  # starts that reach this horizon (blow-ups are inf, kept)
            n = int(ok.sum())
            blown = int(np.isinf(pe[ok]).sum())
            row = {"seconds": float(H), "n_starts": n, "n_blowups": blown}
            if n:
                med, p90 = np.percentile(pe[ok], [50, 90]) if blown == 0 else _pct_inf(pe[ok])
                row.update(position_error_median_m=_f(med), position_error_p90_m=_f(p90),
                           heading_error_median_deg=_f(np.median(he[ok])))
            else:
                row.update(position_error_median_m=None, position_error_p90_m=None, heading_error_median_deg=None)
            out.append(row)
        return out

    def to_pandas(self) -> pd.DataFrame:
        """Per-start errors: index start time, columns ``pos_<H>s``, ``head_<H>s`` and ``blowup``."""
        cols = {}
        for j, H in enumerate(self.horizons):
            cols[f"pos_{H:g}s"] = self.position_error[:, j]
            cols[f"head_{H:g}s"] = self.heading_error[:, j]
        cols["blowup"] = self.blowup
        return pd.DataFrame(cols, index=pd.Index(self.start_times, name="start_time"))

    def plot(self, ax=None, log=None, every: int = 4):
        """Measured track with every ``every``-th predicted track overlaid (longest horizon); returns the axes.

        ``log`` (TrialLog or DataFrame with ``x, y``) replaces the measured track kept in :attr:`tracks`.
        """
        import matplotlib.pyplot as plt  # only when plotting: pyplot takes ~1 s to import

        if ax is None:
            _, ax = plt.subplots(figsize=(6, 6))
        if log is not None:
            df = log if isinstance(log, pd.DataFrame) else log.data
            xy = np.column_stack([df["x"].to_numpy(dtype=float), df["y"].to_numpy(dtype=float)])
        else:
            xy = self.tracks.get("measured")
        if xy is not None:
            ax.plot(xy[:, 1], xy[:, 0], "k-", lw=1.5, label="measured")
        X = self.tracks.get("x")
        if X is not None:
            for i in range(0, X.shape[0], every):
                ax.plot(X[i, :, 1], X[i, :, 0], "-", lw=0.8, color="C1", alpha=0.8,
                        label="predicted" if i == 0 else None)
        ax.set_xlabel("y [m]")
        ax.set_ylabel("x [m]")
        ax.set_aspect("equal")
        ax.legend()
        return ax


def _f(v):
    v = float(v)
    return v if np.isfinite(v) else None


def _pct_inf(a):
    """50th and 90th percentiles with infinite entries ranked last (np.percentile would give NaN)."""
    s = np.sort(a)
    n = s.size
    return s[min(n - 1, int(np.floor(0.5 * (n - 1) + 0.5)))], s[min(n - 1, int(np.ceil(0.9 * (n - 1))))]


def horizon_prediction(model: Model, log, *, horizons=DEFAULT_HORIZONS, start_every: float = 5.0,
                       substeps: int = 1, initial: dict | None = None, rudder_sign: float = 1.0,
                       name: str | None = None) -> HorizonResult:
    """Open-loop prediction errors of ``model`` over ``horizons`` from starts every ``start_every`` s.

    Parameters
    ----------
    model : Model
        Any model of the protocol whose states include ``x, y, psi``; its inputs must be channels of
        the log (e.g. ``delta, n`` and, with wind, ``wind_speed_true, wind_dir_true``).
    log : TrialLog or DataFrame
        Measured ``time``, states and inputs (uniform sampling assumed for the start spacing).
    horizons : sequence of float
        Prediction horizons [s] (positive).
    start_every : float
        Spacing of the starts [s] (rounded to a whole number of samples).
    substeps : int
        RK4 steps per sample interval.
    initial : dict, optional
        Values of states the log does not measure (e.g. a fitted current ``{"cx": .., "cy": ..}``);
        others not in the log start at 0.
    rudder_sign : {1, -1}
        Multiply the logged rudder angle by this (MARIN files: -1).
    name : str, optional
        Name for the result (default: the log's).
    """
    df = log if isinstance(log, pd.DataFrame) else getattr(log, "data", None)
    if df is None or "time" not in df.columns:
        raise ValueError("horizon_prediction: log must be a TrialLog or a DataFrame with a 'time' column")
    name = name or getattr(log, "name", None) or df.attrs.get("name", "log")
    H = np.asarray(horizons, dtype=float).ravel()
    if H.size == 0 or not np.all(np.isfinite(H) & (H > 0)):
        raise ValueError(f"horizons must be positive numbers of seconds, got {list(np.atleast_1d(horizons))}")
    if not start_every > 0:
        raise ValueError(f"start_every must be positive [s], got {start_every}")
    for s in ("x", "y", "psi"):
        if s not in model.state_names or s not in df.columns:
            raise ValueError(f"horizon_prediction: model '{model.name}' and log '{name}' must both have state '{s}'")
    missing = [n for n in model.input_names if n not in df.columns]
    if missing:
        raise ValueError(f"log '{name}' lacks input channel(s) {missing} of model '{model.name}' "
                         f"(inputs {list(model.input_names)})")
    t = df["time"].to_numpy(dtype=float)
    dt = float(np.median(np.diff(t)))
    U = np.column_stack([df[n].to_numpy(dtype=float) for n in model.input_names]) if model.nu else np.zeros((t.size, 0))
    if model.nu and "delta" in model.input_names:
        U[:, model.input_index("delta")] *= rudder_sign
    states = measured_states(model, df, initial)  # measured, else from `initial` (ValueError: unknown names)
    meas = {s: states[:, i] for i, s in enumerate(model.state_names) if s in df.columns}
    nH = int(round(H.max() / dt))
    step = max(1, int(round(start_every / dt)))
    fin_state = np.all([np.isfinite(meas[s]) for s in meas], axis=0)
    fin_input = np.all(np.isfinite(U), axis=1) if model.nu else np.ones(t.size, bool)
    cand = np.arange(0, t.size - 1, step)
    starts = np.array([k for k in cand if fin_state[k] and fin_input[k]], dtype=int)
    nH_eff = int(min(nH, t.size - 1))
    if starts.size == 0 or nH_eff < 1:
        raise ValueError(f"log '{name}': no start with a complete measured state (or the log is too short)")
    X0 = states[starts]
    # inputs of each start over the longest horizon (held at the last finite value past the end)
    idx = np.minimum(starts[:, None] + np.arange(nH_eff + 1)[None, :], t.size - 1)
    Ub = U[idx]
    if model.nu:
        Ub = pd.DataFrame(Ub.reshape(-1, model.nu)).ffill().to_numpy().reshape(Ub.shape)
    tt = np.arange(nH_eff + 1) * dt
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        sim = simulate(model, X0, tt, Ub, substeps=substeps)
    X = sim.x
    blow = ~np.all(np.isfinite(X), axis=(1, 2))
    ix, iy, ip = (model.state_index(s) for s in ("x", "y", "psi"))
    pe = np.full((starts.size, H.size), np.nan)
    he = np.full((starts.size, H.size), np.nan)
    for j, h in enumerate(H):
        kh = int(round(h / dt))
        if kh > nH_eff:
            continue
        tgt = starts + kh
        ok = tgt < t.size
        tg = np.minimum(tgt, t.size - 1)
        xm, ym, pm = meas["x"][tg], meas["y"][tg], meas["psi"][tg]
        ok &= np.isfinite(xm) & np.isfinite(ym) & np.isfinite(pm)
        d = np.hypot(X[:, kh, ix] - xm, X[:, kh, iy] - ym)
        a = np.degrees(np.abs(np.angle(np.exp(1j * (X[:, kh, ip] - pm)))))
        bl = ~np.all(np.isfinite(X[:, : kh + 1]), axis=(1, 2))
        pe[:, j] = np.where(ok, np.where(bl, np.inf, d), np.nan)
        he[:, j] = np.where(ok, np.where(bl, np.inf, a), np.nan)
    nb = int(blow.sum())
    msg = (f"{starts.size} starts every {step * dt:g} s, horizons {', '.join(f'{h:g}' for h in H)} s"
           + (f"; {nb} prediction(s) blew up (counted with infinite error)" if nb else ""))
    return HorizonResult(name=str(name), horizons=H, start_times=t[starts], position_error=pe, heading_error=he,
                         blowup=blow, tracks={"t": tt, "x": X, "measured": np.column_stack([meas["x"], meas["y"]])}, success=nb == 0, message=msg)
