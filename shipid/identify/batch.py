"""Batch refinement: an output-error least-squares fit started from the EKF.

The EKF estimates coefficients recursively; an output-error fit instead
simulates each log with its recorded inputs and adjusts the coefficients to
minimise the weighted simulation error of the measured dynamic channels
(``scipy.optimize.least_squares``).  It is the classical check of a recursive
estimate and usually the better predictor on long manoeuvres.  Sensitivities
come from one *batched* simulation per log and iteration (the nominal
parameters and one forward-difference perturbation per coefficient run
together along the batch axis); logs that share one time grid are simulated
as one batch.  With ``jacobian="tangent"`` the sensitivities are instead the
exact derivatives of the RK4 map (:func:`shipid.integrate.rk4_step_tangent`),
propagated along the nominal trajectory; this needs the model's analytic (or
complex-step) ``_jac_x``/``_jac_p`` to be cheap.
"""
from __future__ import annotations

import math
import warnings
from datetime import datetime, timezone

import numpy as np
import pandas as pd
from scipy.linalg import qr
from scipy.optimize import least_squares
from tqdm.auto import tqdm

from .._blas import one_blas_thread
from ..integrate import hold_steps, rk4_step_tangent
from ..models.base import Model
from ..simulate import simulate
from .data import measured_states, noise_std_from_data, prepare_logs
from .diagnostics import identifiability
from .identifier import NotFittedError
from .result import FitResult, _inputs, diagnostics_to_json, fitted_ship, software_versions

__all__ = ["OutputErrorRefiner", "identifiable_subset", "prediction_windows", "FTOL"]

#: Relative cost-change tolerance of the refinement's ``least_squares`` (``ftol``, with ``xtol`` the same): it stops
#: when a step lowers the cost by less than this fraction.  It also sets :func:`identifiable_subset`'s threshold.
FTOL = 1e-8


def identifiable_subset(J, cost: float, ftol: float = FTOL):
    """Which columns of a scaled Jacobian the least-squares solver can resolve, and which it cannot.

    ``J`` (n_res, ne) is the Jacobian of the residuals with respect to the *scaled* parameters (one unit = the
    coefficient's own size, ``theta = p / scale``) at the start, ``cost`` = 0.5 * sum(residuals**2) there.
    Moving the scaled parameters by one unit along a right singular vector of ``J`` with singular value ``s``
    changes the (locally quadratic) cost by ``0.5 s**2``.  When that is below ``ftol * cost``, the solver's own
    stopping test (a step that lowers the cost by less than ``ftol * cost`` ends the fit) cannot tell a change of
    the coefficients by their whole size along that direction from none: where the fit stops along it is decided
    by rounding (e.g. the BLAS thread count), not by the data.  The threshold is therefore
    ``s_min = sqrt(2 * ftol * cost)``.  Of the ``ne`` columns, ``r`` = (number of singular values above it) are kept
    by Golub-Klema-Stewart subset selection (QR with column pivoting of the leading ``r`` right singular vectors;
    Golub & Van Loan, *Matrix Computations*, sec. 5.5.7), the others are held; repeated on the kept columns
    until all their singular values exceed the threshold.

    Returns ``(keep, held, info)``: sorted column indices kept and held, and a dict with ``threshold``,
    ``singular_values`` (of the whole ``J``), ``condition`` of ``J^T J`` before and ``condition_kept`` after.
    """
    J = np.asarray(J, dtype=float)
    ne = J.shape[1]
    thr = math.sqrt(2.0 * ftol * max(float(cost), 0.0))
    s_all = np.linalg.svd(J, compute_uv=False) if np.all(np.isfinite(J)) else np.full(ne, np.nan)

    def cond2(s):
        return float((s.max() / s.min()) ** 2) if s.size and s.min() > 0 else math.inf

    keep = np.arange(ne)
    if not np.all(np.isfinite(J)):
        return keep, np.array([], dtype=int), {"threshold": thr, "singular_values": s_all.tolist(),
                                               "condition": math.nan, "condition_kept": math.nan}
    while keep.size:
        _, s, Vt = np.linalg.svd(J[:, keep], full_matrices=False)
        r = int(np.sum(s > thr))
        if r == keep.size:
            break
        if r == 0:
            keep = keep[:0]
            break
        _, _, piv = qr(Vt[:r], pivoting=True, mode="economic")
        keep = np.sort(keep[piv[:r]])
    held = np.setdiff1d(np.arange(ne), keep)
    s_keep = np.linalg.svd(J[:, keep], compute_uv=False) if keep.size else np.array([])
    return keep, held, {"threshold": thr, "singular_values": s_all.tolist(), "condition": cond2(s_all),
                        "condition_kept": cond2(s_keep)}


def prediction_windows(model: Model, logs, horizon: float, every: float, *, sample_every: int = 1, initial=None):
    """Slice long logs into open-loop prediction windows for :class:`OutputErrorRefiner` (multiple shooting).

    Whole-log output error is meaningless on logs minutes long in gusting wind (a replay drifts off after a
    minute whatever the coefficients); what a user predicts is ``horizon`` seconds from a measured state.
    Each window starts at a measured sample every ``every`` s, is ``horizon`` s long (windows that would run
    past the log's end, or over a gap in its sampling, are left out), keeps every ``sample_every``-th sample,
    has its time counted from 0 (so all windows share one time grid and the refiner simulates them as one
    batch) and its heading unwrapped from the start.  Refine with
    ``OutputErrorRefiner(model, ...).fit(windows, x0=x0)``: every window starts at its measured state, the
    cost is the open-loop prediction error over ``horizon`` s, as :func:`shipid.validation.horizon.horizon_prediction`
    judges it (which holds the inputs between samples: pass ``input_hold="zoh"`` to match it).  The start
    states are measured, not estimated: their noise enters the estimate (negligible when it is small against
    what the window's error is made of), and overlapping windows make the residuals correlated, so the
    refiner's formal standard deviations are too small (the synthetic test in ``tests/test_batch.py``).

    ``logs``: TrialLogs or DataFrames with ``time``, the measured states and the model's inputs.
    ``initial``: values of the states the logs do not measure (e.g. a fitted current ``{"cx": .., "cy": ..}``),
    one dict for all logs or a list with one dict per log; others start at 0.
    Returns ``(windows, x0)``: DataFrames (``attrs["name"]`` = ``"<log>@<start time>s"``, ``attrs["log"]`` the
    log's index) and their start states, arrays of shape ``(model.nx,)``.
    """
    if isinstance(logs, pd.DataFrame) or hasattr(logs, "data"):
        logs = [logs]
    logs = list(logs)
    if not (horizon > 0 and every > 0 and int(sample_every) >= 1):
        raise ValueError(f"horizon and every must be positive [s], sample_every >= 1; got {horizon}, {every}, "
                         f"{sample_every}")
    inits = initial if isinstance(initial, (list, tuple)) else [initial] * len(logs)
    if len(inits) != len(logs):
        raise ValueError(f"initial: expected one dict per log ({len(logs)}), got {len(inits)}")
    windows, x0s = [], []
    for li, (lg, init) in enumerate(zip(logs, inits)):
        df = lg if isinstance(lg, pd.DataFrame) else lg.data
        name = getattr(lg, "name", None) or df.attrs.get("name", f"log{li}")
        X = measured_states(model, df, init)  # the start state at each sample (ValueError: unknown initial)
        t = df["time"].to_numpy(dtype=float)
        if t.size < 3:
            continue
        dt = float(np.median(np.diff(t)))
        n_h, step = int(round(horizon / dt)), max(1, int(round(every / dt)))
        grid = np.arange(0, n_h + 1, int(sample_every))
        rel = np.round(grid * dt, 9)  # one shared grid (exactly equal arrays: one batch)
        for k in range(0, t.size - n_h, step):
            rows = df.iloc[k + grid]
            if not np.allclose(rows["time"].to_numpy(dtype=float) - t[k], grid * dt, atol=0.25 * dt):
                continue  # a gap in the sampling
            w = rows.reset_index(drop=True).copy()
            w["time"] = rel
            if "psi" in w:
                w["psi"] = np.unwrap(w["psi"].to_numpy(dtype=float))
            x0 = X[k].copy()
            if not np.all(np.isfinite(x0)):
                continue
            w.attrs["name"], w.attrs["log"] = f"{name}@{t[k]:g}s", li
            windows.append(w)
            x0s.append(x0)
    return windows, x0s


#: The robust losses of ``scipy.optimize.least_squares``: ``z -> (rho(z), rho'(z))`` of the squared scaled
#: residual ``z`` (as scipy defines them; the cost is ``0.5 * f_scale**2 * sum(rho(z))``).
_ROBUST_RHO = {
    "linear": lambda z: (z, np.ones_like(z)),
    "soft_l1": lambda z: (2.0 * (np.sqrt(1.0 + z) - 1.0), 1.0 / np.sqrt(1.0 + z)),
    "huber": lambda z: (np.where(z <= 1.0, z, 2.0 * np.sqrt(z) - 1.0), np.where(z <= 1.0, 1.0, 1.0 / np.sqrt(np.maximum(z, 1.0)))),
    "cauchy": lambda z: (np.log1p(z), 1.0 / (1.0 + z)),
    "arctan": lambda z: (np.arctan(z), 1.0 / (1.0 + z**2)),
}


class OutputErrorRefiner:
    """Output-error (simulation-error) least-squares refinement.

    Parameters
    ----------
    model : Model
        Start values are the model's parameters (e.g. ``EKFIdentifier.to_model()``).
    estimate : sequence of str, optional
        Parameters to adjust (default: all).
    channels : sequence of str, optional
        Measured states in the cost (default: the measured states whose
        equations contain estimated parameters, e.g. u, v, r).
    meas_std : mapping, optional
        Weights (noise std) per channel; default from the data.
    max_nfev : int
        Iteration limit of the least-squares solver.
    substeps : int
        RK4 steps per sample.
    input_hold : {"foh", "zoh"}
        Inputs between samples in the simulations: linear between the logged values (default, as
        the EKF's) or held (see :func:`shipid.simulate.simulate`).
    jacobian : {"fd", "tangent"}
        Sensitivities by forward differences in one batched simulation (default) or
        by the exact tangent of the RK4 map.
    log_weights : sequence of float, optional
        One non-negative weight per log passed to :meth:`fit`: the cost is
        ``sum_i w_i * sum(normalised residuals of log i ** 2)`` (default: all 1, a plain
        sum, in which long logs dominate).  E.g. ``1 / n_samples_i`` makes every log
        weigh equally.  The reported covariance then treats the weighted residuals as
        white noise (a scaling, not a noise model).
    extra_residuals : callable, optional
        ``f(params) -> array (B, m)`` of further residuals appended to the simulation
        errors, for a batch of full parameter vectors ``params`` of shape (B, np) (the
        nominal one and its forward-difference perturbations in one call, so ``f`` can
        simulate them as one batch), e.g. a prior or the errors of closed-loop manoeuvre
        metrics against measured ones, already divided by their tolerances.
        Differentiated by forward differences; non-finite values count as 1e6.
    estimate_x0 : bool or sequence of str
        Estimate each log's initial state of these states (True: the fitted channels, e.g. u, v, r)
        jointly with the coefficients, as nuisance parameters (default False: held at the start's
        smoothed states or ``x0``).  The coefficients' covariance is then the coefficient block of the
        joint inverse ``s^2 (J^T J)^-1``, i.e. marginalised over the initial states (a fixed, estimated
        initial state makes it too tight; docs/uncertainty.md sect. 3).  ``x0_`` / ``x0_std_`` hold them.
    hold_unresolved : bool
        Hold at their start values the coefficients the solver cannot resolve from the start's Jacobian
        (:func:`identifiable_subset`; default False: fit every estimated coefficient).  The held ones are
        listed in ``held_`` and in the result's settings, with the threshold and the condition numbers.
    sign_bounds : bool
        Keep the model's dissipative coefficients (``model.dissipative``: the pure sway and yaw damping
        terms) at their physical sign, <= 0 (default False), by an active set: the unconstrained
        solution first; coefficients on the wrong side are held at 0 and the rest solved again (each
        solve up to ``max_nfev`` evaluations); a held one is released when its cost gradient points into
        the allowed side.  The held ones are listed in ``at_bound_`` and in the result's settings and
        have no standard deviation (like the identifiable subset's).
    loss : {"linear", "soft_l1", "huber", "cauchy", "arctan"}
        Loss of the normalised residuals, as ``scipy.optimize.least_squares``' (default ``"linear"``,
        least squares).  A robust loss (e.g. ``"soft_l1"``) lets a few large residuals (a gust, a glitch)
        pull the fit less; ``f_scale`` is the normalised residual where it turns from quadratic to linear
        (1: at one ``meas_std``).  ``cost_``, ``cost_start_`` are then that loss's cost, and the covariance is
        the Gauss-Newton one of the robust cost (``least_squares``' modified Jacobian) times the raw
        residuals' variance (conservative when there are outliers).
    f_scale : float
        Soft margin of the robust loss in normalised residuals (default 1).
    """

    def __init__(self, model: Model, *, estimate=None, channels=None, meas_std=None, max_nfev: int = 30,
                 substeps: int = 1, jacobian: str = "fd", log_weights=None,
                 extra_residuals=None, input_hold: str = "foh", estimate_x0=False,
                 hold_unresolved: bool = False, sign_bounds: bool = False, loss: str = "linear",
                 f_scale: float = 1.0, progress: bool = False):
        self.model = model
        self.progress = progress
        self.estimate = estimate
        self.channels = channels
        self.meas_std = meas_std
        self.max_nfev = max_nfev
        self.substeps = substeps
        self.jacobian = jacobian
        self.log_weights = log_weights
        self.extra_residuals = extra_residuals
        self.input_hold = input_hold
        self.estimate_x0 = estimate_x0
        self.hold_unresolved = hold_unresolved
        self.sign_bounds = sign_bounds
        self.loss = loss
        self.f_scale = f_scale

    def fit(self, logs, start=None, x0=None) -> "OutputErrorRefiner":
        """Refine on ``logs``; ``start`` may be a fitted :class:`EKFIdentifier` whose
        smoothed initial states and prior are used.  ``x0`` (sequence of arrays of shape
        (nx,), one per log) gives the initial states explicitly (e.g. the exact ones of
        simulated logs); by default they are the mean of each log's first five samples.

        Runs with one BLAS thread (:func:`shipid._blas.one_blas_thread`): on an ill-conditioned
        problem the solver's path, and so its answer, would otherwise follow the thread count."""
        with one_blas_thread():
            return self._fit(logs, start, x0)

    def _fit(self, logs, start, x0) -> "OutputErrorRefiner":
        if self.jacobian not in ("fd", "tangent"):
            raise ValueError(f"jacobian must be 'fd' or 'tangent', got {self.jacobian!r}")
        if self.input_hold not in ("foh", "zoh"):
            raise ValueError(f"input_hold must be 'foh' or 'zoh', got {self.input_hold!r}")
        if self.loss not in _ROBUST_RHO:
            raise ValueError(f"loss must be one of {tuple(_ROBUST_RHO)}, got {self.loss!r}")
        if not (np.isfinite(self.f_scale) and self.f_scale > 0):
            raise ValueError(f"f_scale must be finite and > 0, got {self.f_scale!r}")
        fs2 = float(self.f_scale) ** 2
        rho = _ROBUST_RHO[self.loss]

        def cost_of(f):  # least_squares' cost: 0.5 * f_scale^2 * sum(rho((f / f_scale)^2))
            return float(0.5 * fs2 * np.sum(rho(f**2 / fs2)[0]))

        model = self.model
        arrays, meas = prepare_logs(model, logs)
        # time of each log's last measured sample (logs padded onto a common grid are NaN after it)
        ends_of = [float(ar.t[np.flatnonzero(np.isfinite(ar.Y).any(axis=1))[-1]]) if np.isfinite(ar.Y).any()
                   else float(ar.t[-1]) for ar in arrays]
        if self.log_weights is None:
            wlog = np.ones(len(arrays))
        else:
            wlog = np.asarray(self.log_weights, dtype=float).reshape(-1)
            if wlog.size != len(arrays):
                raise ValueError(f"log_weights: expected one weight per log ({len(arrays)}), got {wlog.size}")
            bad = np.flatnonzero(~np.isfinite(wlog) | (wlog < 0))
            if bad.size:
                raise ValueError(f"log_weights[{bad[0]}] = {wlog[bad[0]]!r}: weights must be finite and >= 0")
        rw = np.sqrt(wlog)  # residual multipliers
        names = list(self.estimate) if self.estimate is not None else list(model.param_names)
        est_idx = np.array([model.param_index(n) for n in names])
        p0 = model.params.copy()
        sig = noise_std_from_data(arrays)
        if self.meas_std:
            for k, v in dict(self.meas_std).items():
                sig[meas.index(k)] = float(v)
        Jp = np.abs(model.jac_p(0.0, np.ones(model.nx), np.ones(model.nu), p0))
        dyn = [s for s in meas if Jp[model.state_index(s), est_idx].max() > 0]
        chans = list(self.channels) if self.channels is not None else dyn
        if not chans:
            raise ValueError("no measured channel depends on the estimated parameters; nothing to fit")
        ch_idx = [meas.index(c) for c in chans]
        st_idx = [model.state_index(c) for c in chans]
        ex0 = self.estimate_x0
        x0_names = (list(chans) if ex0 is True else [] if ex0 is False or ex0 is None else list(ex0))
        x0_idx = np.array([model.state_index(c) for c in x0_names], dtype=int)
        nk, ne = x0_idx.size, est_idx.size
        # initial-state offsets are scaled by the state's noise level (else by 1)
        x0_scale = np.array([sig[meas.index(c)] if c in meas else 1.0 for c in x0_names])
        x0s = []
        given_x0 = x0
        if given_x0 is not None and len(given_x0) != len(arrays):
            raise ValueError(f"x0: expected one initial state per log ({len(arrays)}), got {len(given_x0)}")
        for i, a in enumerate(arrays):
            if given_x0 is not None:
                xi = np.asarray(given_x0[i], dtype=float)
                if xi.shape != (model.nx,):
                    raise ValueError(f"x0[{i}] must have shape ({model.nx},) for {model.state_names}, got {xi.shape}")
                x0s.append(xi)
            elif start is not None and hasattr(start, "states_"):
                x0s.append(start.states_[i][list(model.state_names)].to_numpy()[0])
            else:
                x0 = np.zeros(model.nx)
                for j, s in enumerate(meas):
                    col = a.Y[:5, j]
                    if np.isfinite(col).any():
                        x0[model.state_index(s)] = np.nanmean(col)
                x0s.append(x0)
        scale = np.where(np.abs(p0[est_idx]) > 0, np.abs(p0[est_idx]), 1.0)
        if start is not None and hasattr(start, "scale_"):
            scale = start.scale_.reindex(names).fillna(pd.Series(scale, index=names)).to_numpy()

        # logs sharing one time grid run as one batch
        groups: list[list[int]] = []
        for i, a in enumerate(arrays):
            for g in groups:
                if arrays[g[0]].t.shape == a.t.shape and np.array_equal(arrays[g[0]].t, a.t):
                    g.append(i)
                    break
            else:
                groups.append([i])

        def params_of(theta_batch):
            """Full parameter vectors (B, np) for scaled estimates (B, ne[ + n_logs nk])."""
            P = np.broadcast_to(p0, (theta_batch.shape[0], model.np)).copy()
            P[:, est_idx] = theta_batch[:, :ne] * scale
            return P

        def x0_of(theta_batch, i):
            """Initial states (B, nx) of log ``i``."""
            X = np.broadcast_to(x0s[i], (theta_batch.shape[0], model.nx)).copy()
            if nk:
                X[:, x0_idx] += theta_batch[:, ne + i * nk: ne + (i + 1) * nk] * x0_scale
            return X

        def simulate_all(theta_batch):
            """theta_batch (B, ne) scaled -> list of (B, N, nchan) simulated channels."""
            B = theta_batch.shape[0]
            P = params_of(theta_batch)
            out: list = [None] * len(arrays)
            for g in groups:
                t, G = arrays[g[0]].t, len(g)
                X0 = np.stack([x0_of(theta_batch, i) for i in g], axis=1).reshape(B * G, model.nx)
                Ug = np.stack([arrays[i].U for i in g])
                Ug = np.broadcast_to(Ug, (B,) + Ug.shape).reshape((B * G,) + Ug.shape[1:])
                Pg = np.repeat(P, G, axis=0)
                with np.errstate(all="ignore"), warnings.catch_warnings(record=True) as caught:
                    warnings.simplefilter("always")
                    res = simulate(model, X0, t, Ug, params=Pg, substeps=self.substeps, input_hold=self.input_hold)
                # a log padded to a longer one's grid (recipe.common_grid) may blow up after its own last
                # sample, where nothing is fitted: warn only about failures inside a log's measured span
                ends = np.tile([ends_of[i] for i in g], B)
                failed = res.meta.get("failed", [])
                past_end = bool(failed) and all(tf > ends[m] for m, tf in zip(failed, res.meta.get("failed_at", [])))
                for w in caught:
                    if not (past_end and "became non-finite" in str(w.message)):
                        warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
                xs = res.x.reshape((B, G) + res.x.shape[1:])
                for j, i in enumerate(g):
                    out[i] = xs[:, j][:, :, st_idx]
            return out

        def tangent_jac(th):
            """Exact sensitivities of the RK4 map along the nominal trajectory, (n_res, ne)."""
            p = p0.copy()
            p[est_idx] = th[:ne] * scale
            blocks: list = [None] * len(arrays)
            for g in groups:
                t = arrays[g[0]].t
                x = np.stack([x0_of(th[None], i)[0] for i in g])
                Ug = np.stack([arrays[i].U for i in g])
                # parameter sensitivities, then those to the estimated initial states (identity at t0)
                S = np.concatenate([np.zeros((len(g), model.nx, model.np)),
                                    np.broadcast_to(np.eye(model.nx)[:, x0_idx], (len(g), model.nx, nk))], axis=2)
                cols = np.concatenate([est_idx, model.np + np.arange(nk)])
                J = np.zeros((len(g), t.size, len(st_idx), cols.size))
                with np.errstate(all="ignore"):
                    for k in range(t.size - 1):
                        h = (t[k + 1] - t[k]) / self.substeps
                        u1 = Ug[:, k + 1] if self.input_hold == "foh" else None
                        for m, (ua, ub) in enumerate(hold_steps(Ug[:, k], u1, self.substeps)):
                            x, Fx, Fp = rk4_step_tangent(model, t[k] + m * h, x, ua, p, h, ub)
                            S = Fx @ S
                            S[:, :, :model.np] += Fp
                        J[:, k + 1] = S[:, st_idx][:, :, cols]
                J[:, 0, :, ne:] = np.eye(model.nx)[st_idx][:, x0_idx]
                J = J * np.concatenate([scale, x0_scale]) / sig[ch_idx][:, None]
                for j, i in enumerate(g):
                    Ji = np.zeros((t.size, len(st_idx), ne + len(arrays) * nk))
                    Ji[:, :, :ne] = J[j][:, :, :ne]
                    Ji[:, :, ne + i * nk: ne + (i + 1) * nk] = J[j][:, :, ne:]
                    blocks[i] = rw[i] * np.where(masks[i][:, :, None], Ji, 0.0).reshape(-1, Ji.shape[-1])
            Jt = np.concatenate(blocks, axis=0)
            return np.where(np.isfinite(Jt), Jt, 0.0)

        masks = [np.isfinite(a.Y[:, ch_idx]) for a in arrays]

        def residual_batch(theta_batch):
            sims = simulate_all(theta_batch)
            rs = []
            for a, s, m, w in zip(arrays, sims, masks, rw):
                e = w * (s - a.Y[None, :, ch_idx]) / sig[ch_idx]
                rs.append(np.where(m[None], e, 0.0).reshape(theta_batch.shape[0], -1))
            if self.extra_residuals is not None:
                rs.append(extra_batch(theta_batch))
            r = np.concatenate(rs, axis=1)
            # a diverging simulation: finite residuals capped at 1e6 (squares must not overflow), others 1e6
            return np.where(np.isfinite(r), np.clip(r, -1e6, 1e6), 1e6)

        if self.progress:  # a bar counting the replays (one per parameter set), on stderr; closed below
            bar = tqdm(desc="output-error refinement", unit="replay", leave=False)
            _residual_batch = residual_batch

            def residual_batch(theta_batch):
                bar.update(theta_batch.shape[0])
                return _residual_batch(theta_batch)

        def extra_batch(theta_batch):
            P = params_of(theta_batch)
            out = np.asarray(self.extra_residuals(P), dtype=float).reshape(P.shape[0], -1)
            return np.where(np.isfinite(out), np.clip(out, -1e6, 1e6), 1e6)

        h = 1e-6
        th0 = np.concatenate([p0[est_idx] / scale, np.zeros(len(arrays) * nk)])
        free = np.arange(th0.size)  # the columns the solver moves (all, unless some are held)
        def full(t):
            th = th0.copy()
            th[free] = t
            return th

        def fun(t):
            return residual_batch(full(t)[None])[0]

        def jac(t):
            th = full(t)
            if self.jacobian == "tangent":
                Jt = tangent_jac(th)[:, free]
                if self.extra_residuals is None:
                    return Jt
                E = extra_batch(np.vstack([th, th + h * np.eye(th.size)[free]]))
                return np.vstack([Jt, ((E[1:] - E[0]) / h).T])
            batch = np.vstack([th, th + h * np.eye(th.size)[free]])
            R = residual_batch(batch)
            last_f[:] = [t.copy(), R[0]]
            return ((R[1:] - R[0]) / h).T

        # physical signs (scaled coordinates: coef = th * scale; +1: the coefficient must be <= 0)
        self.sign_bounded_ = []
        side = np.zeros(th0.size)
        if self.sign_bounds:
            for i, n in enumerate(names):
                if n in getattr(model, "dissipative", ()):
                    self.sign_bounded_.append(n)
                    side[i] = 1.0 if scale[i] > 0 else -1.0
        self.held_, self.subset_ = [], None
        col_names = list(names) + [f"{c}0[{i}]" for i in range(len(arrays)) for c in x0_names]
        last_f: list = [None, None]  # the nominal residuals of the last forward-difference Jacobian
        if self.hold_unresolved and th0.size > 1:
            J0 = jac(th0)
            f0 = last_f[1] if last_f[0] is not None and np.array_equal(last_f[0], th0) else fun(th0)
            keep, held, info = identifiable_subset(J0, 0.5 * float(np.sum(f0**2)))
            self.subset_ = {**info, "held": [col_names[i] for i in held], "ftol": FTOL}
            if held.size:
                free = keep
                self.held_ = [col_names[i] for i in held]
                warnings.warn(f"output-error refinement: {', '.join(self.held_)} held at their start values: along "
                              f"{held.size} direction(s) of the start's Jacobian a change of the coefficients by their "
                              f"own size changes the cost by less than the solver's tolerance ({FTOL:g} of it), so the "
                              "fit could not resolve them (scaled J^T J condition "
                              f"{info['condition']:.3g} -> {info['condition_kept']:.3g})", UserWarning, stacklevel=2)
        def solve(free_now):
            return least_squares(fun, th0[free_now], jac=jac, method="trf", max_nfev=self.max_nfev, x_scale=1.0,
                                 ftol=FTOL, xtol=FTOL, loss=self.loss, f_scale=self.f_scale)

        sol = solve(free)
        nfev = int(sol.nfev)
        # Physical signs by an active set (not by least_squares' bounds, whose interior scaling slows the
        # steps of a coefficient near its bound until xtol stops the solver early, at a point that follows
        # the rounding): fix every coefficient that ends on the wrong side at 0 and solve for the others;
        # release a fixed one whose cost gradient points into the allowed side; repeat.  Nothing changes
        # when no coefficient leaves its side (the unconstrained solution is the constrained one).
        self.at_bound_ = []
        cost_start = None
        if side.any():
            cost_start = cost_of(fun(th0[free]))  # before the active set moves th0
            free_all, fixed = free.copy(), []
            for _ in range(2 * int((side != 0).sum()) + 1):
                th_now = full(sol.x)
                viol = [int(i) for i in free if side[i] and th_now[i] * side[i] > 0]
                if not viol and fixed:
                    th0[:] = th_now
                    free = np.array(fixed)
                    f_now = fun(th0[free])
                    g = jac(th0[free]).T @ (rho(f_now**2 / fs2)[1] * f_now)  # d cost / d th of the fixed ones
                    nfev += 1
                    release = [i for i, gi in zip(fixed, g) if gi * side[i] > 0]
                    if not release:
                        free = np.array([i for i in free_all if i not in fixed])
                        break
                    fixed = [i for i in fixed if i not in release]
                elif not viol:
                    break
                else:
                    th0[:] = th_now
                    th0[viol] = 0.0
                    fixed = sorted(set(fixed) | set(viol))
                free = np.array([i for i in free_all if i not in fixed])
                sol = solve(free)
                nfev += int(sol.nfev)
            self.at_bound_ = [col_names[i] for i in fixed]
            if fixed:
                warnings.warn(f"output-error refinement: {', '.join(self.at_bound_)} held on the physical-sign "
                              "bound 0 (dissipative terms must be <= 0): the logs pull them to the wrong sign, "
                              "so the model's other terms carry that part of the dynamics", UserWarning, stacklevel=2)
        J = sol.jac
        self.jac_ = J  # at the solution, scaled parameters (columns: the refined ones)
        names_all = names
        fcoef = free[free < ne]  # the refined coefficients (the rest of ``free``: initial states)
        names = [names_all[i] for i in fcoef]
        n_obs = int(sum(m.sum() for m, w in zip(masks, wlog) if w > 0))
        dof = max(n_obs - free.size, 1)
        s2 = float(np.sum(sol.fun**2) / dof)
        if np.all(np.isfinite(J)):
            # (J^T J)^+ from the SVD of J: positive semi-definite by construction (the pseudo-inverse of the
            # product itself squares J's condition and, near 1e13, gives rounding-negative eigenvalues, which the
            # diagnostics reported as a condition number of ~1e291)
            _, sv, Vt = np.linalg.svd(J, full_matrices=False)
            inv = np.where(sv > sv.max() * max(J.shape) * np.finfo(float).eps, 1.0 / np.maximum(sv, 1e-300) ** 2, 0.0)
            cov_all = (Vt.T * inv) @ Vt * s2
        else:
            cov_all = np.full((free.size, free.size), np.nan)
        # with estimated initial states: the coefficients' block, i.e. marginal over them (Laplace)
        cpos = np.flatnonzero(free < ne)
        cov_s = cov_all[np.ix_(cpos, cpos)]
        th_full = full(sol.x)
        theta = th_full[:ne] * scale
        x0_fit = [x0_of(th_full[None], i)[0] for i in range(len(arrays))]
        x0_var = np.zeros(th_full.size)
        x0_var[free] = np.clip(np.diag(cov_all), 0, None)
        x0_sd = np.sqrt(x0_var[ne:]).reshape(len(arrays), nk) * x0_scale
        self.x0_ = pd.DataFrame(x0_fit, columns=list(model.state_names))
        self.x0_std_ = pd.DataFrame(x0_sd, columns=x0_names)
        scale_f = scale[fcoef]  # (the closures above keep the full scale and est_idx)
        cov = cov_s * np.outer(scale_f, scale_f)
        coef = p0.copy()
        coef[est_idx] = theta
        self.coef_ = pd.Series(coef, index=list(model.param_names), name="coef")
        std = np.zeros(model.np)
        std[est_idx[fcoef]] = np.sqrt(np.clip(np.diag(cov), 0, None))
        self.coef_std_ = pd.Series(std, index=list(model.param_names), name="coef_std")
        self.cov_ = pd.DataFrame(cov, index=names, columns=names)
        # the joint Laplace covariance of everything refined (coefficients, then initial states), physical units:
        # the independence proposal of sample_posterior(proposal=refiner) uses it with ``theta_``
        # (held columns and coefficients on a sign bound are not in it: a proposal then lacks them, which
        # sample_posterior refuses)
        units = np.concatenate([scale, np.tile(x0_scale, len(arrays))])[free]
        self.cov_joint_ = pd.DataFrame(cov_all * np.outer(units, units), index=[col_names[i] for i in free],
                                       columns=[col_names[i] for i in free])
        self.estimated_ = names
        self.channels_ = chans
        self.cost_ = float(sol.cost)
        self.cost_start_ = cost_start if cost_start is not None else cost_of(fun(th0[free]))
        self.rms_normalised_residual_ = float(np.sqrt(s2))
        finite = bool(np.all(np.isfinite(sol.x)) and np.isfinite(sol.cost))
        capped = finite and bool(np.any(np.abs(sol.fun) >= 1e6))  # a replay still diverges at the end
        self.success_ = bool(sol.success) and finite and not capped
        self.nfev_ = nfev
        if not finite:
            self.message_ = f"refinement failed: non-finite coefficients or cost ({sol.message}); the start model's replay diverges?"
        elif capped:
            self.message_ = (f"refinement failed: the refined model's replay of some logs still diverges ({sol.message}); "
                             "the model cannot follow these logs")
        else:
            self.message_ = _least_squares_words(sol)
        if start is not None and getattr(start, "success_", True) is False:
            # a start from a diverged filter is not a result, whatever the optimiser says
            self.success_ = False
            self.message_ = (f"started from a diverged EKF fit ({getattr(start, 'message_', 'diverged')}); "
                             f"refinement reported as failed (optimiser: {sol.message})")
        if start is not None and hasattr(start, "prior_std_"):
            prior_cov_s = np.diag((start.prior_std_.reindex(names).to_numpy() / scale_f) ** 2)
        else:
            prior_cov_s = np.eye(len(names)) * max(1.0, 100 * np.max(np.diag(cov_s)))
        notes = list(model.identifiability_notes(arrays, names))
        self.diagnostics_ = identifiability(names, cov_s, prior_cov_s, notes=notes)
        self.diagnostics_["note"] = ("output-error covariance from J^T J with white-residual weights: "
                                     "optimistic when simulation errors are correlated in time")
        self.logs_ = [a.meta for a in arrays]
        if self.progress:
            bar.close()
        return self

    def to_model(self) -> Model:
        if not hasattr(self, "coef_"):
            raise NotFittedError("this OutputErrorRefiner is not fitted yet: call fit(logs) first")
        return self.model.with_params(self.coef_.to_numpy())

    def result(self) -> FitResult:
        if not hasattr(self, "coef_"):
            raise NotFittedError("this OutputErrorRefiner is not fitted yet: call fit(logs) first")
        diag = diagnostics_to_json(self.diagnostics_)
        opts, ship = fitted_ship(self.model, self.logs_)
        return FitResult(
            model=self.model.name, coef={k: float(v) for k, v in self.coef_.items()},
            coef_std={k: float(v) for k, v in self.coef_std_.items()}, cov=self.cov_.copy(), diagnostics=diag,
            inputs=_inputs(self.logs_), method="output-error",
            settings={"estimated": self.estimated_, "channels": self.channels_, "max_nfev": self.max_nfev,
                      "input_hold": self.input_hold, "loss": self.loss, "f_scale": float(self.f_scale),
                      "estimate_x0": list(self.x0_std_.columns),
                      "log_weights": None if self.log_weights is None else [float(w) for w in self.log_weights],
                      "extra_residuals": self.extra_residuals is not None,
                      **({"sign_bounds": list(self.sign_bounded_), "at_bound": list(self.at_bound_)}
                         if self.sign_bounds else {}),
                      **({"held": list(self.held_), "hold_rule": {
                          "threshold": self.subset_["threshold"], "ftol": self.subset_["ftol"],
                          "condition_before": self.subset_["condition"],
                          "condition_after": self.subset_["condition_kept"]}} if self.subset_ else {})},
            loglik=None, success=self.success_, message=self.message_, versions=software_versions(),
            created=datetime.now(timezone.utc).isoformat(timespec="seconds"),
            extra={"cost_start": self.cost_start_, "cost": self.cost_,
                   "rms_normalised_residual": self.rms_normalised_residual_},
            model_options=opts, ship=ship,
        )


def _least_squares_words(sol) -> str:
    """scipy's least_squares status in words (its own message names its options in backquotes)."""
    return {1: "converged: gradient below the tolerance (gtol)",
            2: "converged: the cost no longer decreases by more than the tolerance (ftol)",
            3: "converged: the step is below the tolerance (xtol)",
            4: "converged: cost change and step below their tolerances (ftol, xtol)",
            0: f"stopped at the evaluation limit ({sol.nfev} evaluations; raise max_nfev / --max-nfev)"}.get(
        int(sol.status), f"stopped: {str(sol.message).replace('`', '')}")
