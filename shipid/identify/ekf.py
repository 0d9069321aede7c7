# Why one file: the numpy EKF (problem, filter pass, RTS and Bryson-Frazier smoothers) is one algorithm whose steps share its arrays; the compiled copy is split by job in shipid/_kernel/.
"""Augmented-state extended Kalman filter kernel and its RTS smoother.

The augmented state is ``z = [x, theta_s]``: the model's states followed by the
*scaled* estimated parameters ``theta_s = theta / scale`` (random walks).  The
transition is the model's RK4 map (:func:`shipid.integrate.rk4_step_tangent`),
whose exact Jacobian is the transition matrix; measurements pick states
(``y = H z + e`` with ``H`` a selection matrix), so the update is linear.

The kernel runs a batch of ``B`` independent problems in lock-step (several
logs, or several noise-tuning candidates) with numpy broadcasting over the
leading axis.  Logs of a joint fit are concatenated into one sequence with
*reset* samples where the ship state is re-initialised and the parameter
states carry over; this is an exact linear-Gaussian model, so the RTS smoother
runs straight across log boundaries.

Steps follow the seed's Appendix A: predict state, predict covariance, gain,
update state, update covariance (Joseph form, so ``P`` stays symmetric
positive semi-definite), loop.
"""
from __future__ import annotations

import math
import sys
import threading
from dataclasses import dataclass

import numpy as np
from scipy.linalg.lapack import dpotrf as _potrf
from scipy.linalg.lapack import dpotrs as _potrs

from ..integrate import STEP_TANGENTS, hold_steps, interval_steps
from ..models.base import Model
from .. import _jit, _kernel
from . import _memory

__all__ = ["EKFProblem", "EKFOutput", "run_ekf", "rts_smooth", "bf_smooth", "interval_steps", "INPUT_HOLDS",
           "gain_covariance"]

_LOG2PI = np.log(2.0 * np.pi)


@dataclass
class EKFProblem:
    """Arrays defining a batch of augmented-state EKF runs (all float64).

    Shapes: ``B`` batch members, ``N`` samples, ``nx`` model states, ``ne``
    estimated parameters (``nz = nx + ne``), ``nm`` measured channels,
    ``nu`` inputs.

    Attributes
    ----------
    model : Model
    est_idx : (ne,) int -- indices into ``model.param_names`` of the estimated parameters.
    p_base : (B, np) -- full parameter vectors; estimated entries are overwritten.
    scale : (ne,) -- ``theta = scale * theta_s``.
    t : (B, N) -- sample times [s]; at a reset sample the step from the previous
        sample is not integrated.
    U : (B, N, nu) -- inputs at the sample times (between samples: see ``input_hold``).
    Y : (B, N, nm) -- measurements, NaN where missing.
    meas_idx : (nm,) int -- state index measured by each channel.
    R : (B, nm) -- measurement noise variances.
    q : (B, nz) -- process-noise intensities (variance per second) of the augmented states.
    z0 : (B, nz), P0 : (B, nz, nz) -- initial mean and covariance.
    reset : (B, N) bool -- sample k starts a new log (never sample 0).
    x_reset : (B, N, nx) -- initial ship state used at reset samples.
    P_reset : (B, nx, nx) -- its covariance.
    substeps : int -- least number of RK4 steps per sample interval.
    method : a key of :data:`shipid.integrate.STEP_TANGENTS` ("rk4", "rk4-exact", "euler").
    input_hold : {"foh", "zoh"} -- inputs between samples: linear from ``U[k]`` to ``U[k+1]``
        (first-order hold, default) or held at ``U[k]`` (zero-order hold).
    h_max : float or None -- largest RK4 step [s]; an interval longer than ``substeps * h_max``
        (a logger dropout) is crossed in more steps.  None: always ``substeps`` steps.
    gate : float or None -- innovation gate in standard deviations (None: no gating).
    gate_run : int -- a channel rejected by the gate at ``gate_run`` consecutive measured samples
        has its next measurement accepted whatever its innovation (a filter that drifted away
        must not reject everything from then on).
    """

    model: Model
    est_idx: np.ndarray
    p_base: np.ndarray
    scale: np.ndarray
    t: np.ndarray
    U: np.ndarray
    Y: np.ndarray
    meas_idx: np.ndarray
    R: np.ndarray
    q: np.ndarray
    z0: np.ndarray
    P0: np.ndarray
    reset: np.ndarray
    x_reset: np.ndarray
    P_reset: np.ndarray
    substeps: int = 1
    method: str = "rk4"
    input_hold: str = "foh"
    h_max: float | None = None
    gate: float | None = None
    gate_run: int = 10

    @property
    def shape(self):
        B, N = self.t.shape
        return B, N, self.model.nx, len(self.est_idx), len(self.meas_idx)


#: Input holds understood by the kernel and the simulator.
INPUT_HOLDS = ("foh", "zoh")


@dataclass
class EKFOutput:
    """Filter output for a batch.

    ``z_post/P_post`` are the filtered (posterior) estimates at each sample,
    ``z_prior/P_prior`` the predictions at each sample (sample 0: the initial
    condition), ``F[k]`` the transition from k to k+1 (last entry the identity).
    ``innov`` (B, N, nm) are innovations ``y - H z_prior`` (NaN where no
    measurement; a gated channel keeps its innovation, marked in ``gated``),
    ``S_diag`` their predicted variances ``(H P_prior H^T + R)_jj``, ``nis`` (B, N)
    the normalised innovation squared of the accepted channels, ``loglik`` (B,)
    the innovation log-likelihood (``-inf`` for a diverged member),
    ``diverged`` (B,) bool and ``diverged_at`` (B,) sample index (-1 if not),
    ``message`` per member, ``gated`` (B, N, nm) bool the measurements rejected by
    the innovation gate and ``n_gated`` (B, nm) their count per channel.  ``compact``:
    ``P_prior`` holds only its rows at the measured states (B, N, nm, nz) and ``F``
    its ship-state rows (B, N, nx, nz) (``run_ekf(compact=True)``); ``"ship"``: in
    addition ``P_post`` holds only its ship-state rows (B, N, nx, nz)
    (``run_ekf(compact="ship")``).  ``gains``: with compact storage on the compiled path, the
    filter's ``(K^T (B, N, nm, nz), S^-1 e (B, N, nm), S^-1 (B, N, nm, nm))`` at the accepted channels
    (rows and columns in channel order; entries of other channels undefined), which
    :func:`bf_smooth` reads instead of solving for them again; else None.

    A member that diverged at sample ``kd`` was not computed further: its
    ``z_post/P_post/F`` from ``kd`` on and ``z_prior/P_prior/innov/S_diag/nis`` after
    ``kd`` are NaN; ``z_final/P_final`` are its last good posterior (sample ``kd - 1``,
    or the initial condition when ``kd = 0``).
    """

    z_post: np.ndarray | None
    P_post: np.ndarray | None
    z_prior: np.ndarray | None
    P_prior: np.ndarray | None
    F: np.ndarray | None
    z_final: np.ndarray
    P_final: np.ndarray
    innov: np.ndarray
    S_diag: np.ndarray
    loglik: np.ndarray
    nis: np.ndarray
    diverged: np.ndarray
    diverged_at: np.ndarray
    message: list
    gated: np.ndarray
    n_gated: np.ndarray
    compact: bool | str = False
    gains: tuple | None = None


def _divergence_message(k: int, tk: float, d2: float) -> str:
    """The message of a member that diverged at sample ``k`` (time ``tk``) with normalised innovation ``d2``."""
    if np.isfinite(d2):
        return f"filter diverged at sample {k} (t = {tk:.4g} s): normalised innovation {d2:.3g}"
    return f"filter diverged at sample {k} (t = {tk:.4g} s): non-finite state or covariance"


def _output(stored, z_final, P_final, innov, S_diag, nis, logdet, gated, diverged, diverged_at, message,
            compact=False, gains=None) -> EKFOutput:
    """The :class:`EKFOutput` of a run (both paths): ``stored`` is ``(z_post, P_post, z_prior, P_prior, F)``
    or None (``store=False``); the innovation log-likelihood is summed over the samples with accepted
    measurements from the per-sample ``nis`` and ``logdet`` (``log det S``), ``-inf`` for a diverged member."""
    cnt = (np.isfinite(innov) & ~gated).sum(axis=2)
    loglik = -0.5 * np.where(cnt > 0, nis + logdet + cnt * _LOG2PI, 0.0).sum(axis=1)
    loglik = np.where(diverged, -np.inf, loglik)
    z_post, P_post, z_prior, P_prior, F = (None,) * 5 if stored is None else stored
    return EKFOutput(z_post=z_post, P_post=P_post, z_prior=z_prior, P_prior=P_prior, F=F, z_final=z_final,
                     P_final=P_final, innov=innov, S_diag=S_diag, loglik=loglik, nis=nis, diverged=diverged,
                     diverged_at=diverged_at, message=message, gated=gated, n_gated=gated.sum(axis=1),
                     compact=compact if (compact and stored is not None) else False,
                     gains=gains if (compact and stored is not None) else None)


def _index_or_slice(idx, n: int):
    """``idx`` as a basic slice when it is a contiguous run of ``range(n)`` (indexing then gives a view)."""
    idx = np.asarray(idx, dtype=np.intp)
    if idx.size and idx[0] >= 0 and np.array_equal(idx, np.arange(idx[0], idx[0] + idx.size)) and idx[-1] < n:
        return slice(int(idx[0]), int(idx[0]) + idx.size)
    return idx


def _spd_solve(S: np.ndarray, rhs: np.ndarray):
    """Solve ``S X = rhs`` for a batch of symmetric positive-definite ``S`` and return ``log det S``.

    ``S (B, m, m)``, ``rhs (B, m, c)`` -> ``(X (B, m, c), log det S (B,) or float)``.
    A single member is solved by LAPACK's Cholesky routines directly
    (``dpotrf``/``dpotrs``: numpy's stacked wrappers cost more than the
    arithmetic for a 6x6 matrix); a batch uses numpy's stacked ``slogdet`` and
    ``solve``.  Where ``S`` is not positive definite (or not finite) ``X`` is
    NaN, which the caller's divergence check catches.
    """
    if S.shape[0] == 1:
        c, info = _potrf(S[0], lower=1, clean=0)  # LAPACK flags NaN pivots as not positive definite
        if info != 0:
            return np.full(rhs.shape, np.nan), np.nan
        X, info = _potrs(c, rhs[0], lower=1)
        return X[None], 2.0 * sum(map(math.log, c.diagonal().tolist()))
    sign, logdet = np.linalg.slogdet(S)
    ok = sign > 0
    if ok.all():
        try:
            return np.linalg.solve(S, rhs), logdet
        except np.linalg.LinAlgError:
            pass
    X = np.full(rhs.shape, np.nan)
    for b in np.flatnonzero(ok):
        try:
            X[b] = np.linalg.solve(S[b], rhs[b])
        except np.linalg.LinAlgError:
            pass
    return X, logdet


def _cross_interval(step, model, t0, x, u0, u1, p, h, n, scale, est, all_est):
    """Cross one sample interval in ``n`` RK4 steps of length ``h`` from ``(t0, x)``.

    Step ``i`` starts at ``t0 + i h`` with the end inputs of :func:`shipid.integrate.hold_steps`
    (first-order hold when ``u1`` is given, else ``u0`` held).
    Returns ``x(t0 + n h)``, ``dx/dx0 (B, nx, nx)`` and ``dx/dtheta_s (B, nx, ne)``.
    """
    Fx = Fp = None
    for i, (ua, ub) in enumerate(hold_steps(u0, u1, n)):
        x, Ax, Ap = step(model, t0 + i * h if i else t0, x, ua, p, h, ub)
        Ap = Ap * scale if all_est else Ap[..., est] * scale
        if Fx is None:
            Fx, Fp = Ax, Ap
        else:
            Fp = Ax @ Fp + Ap
            Fx = Ax @ Fx
    return x, Fx, Fp


def run_ekf(prob: EKFProblem, store: bool = True, nis_limit: float = 1e6, store_dtype: str = "auto",
            compact: bool | str = False) -> EKFOutput:
    """Run the augmented-state EKF over a batch.

    Parameters
    ----------
    prob : EKFProblem
    store : bool
        Keep per-sample means, covariances and transitions (needed by the
        smoother; memory ``B * N * nz^2 * 24`` bytes).
    nis_limit : float
        A normalised innovation squared above this (or a non-finite or
        non-positive covariance) marks the member as diverged at that sample;
        it is then stopped (see below) and reported, never silently NaN.
    store_dtype : {"auto", "float64", "float32"}
        Type of the stored covariances and transitions (``P_post``, ``P_prior``, ``F``; the means stay
        float64, the filter computes in float64 either way).  float32 needs 20 instead of 32 bytes per
        ``nz^2`` and sample (with the smoother's output) at the price of rounding what the smoother
        reads (:mod:`shipid.identify._memory`).  ``"auto"``: float64, or float32 with a warning when
        float64 would exceed the memory limit.
    compact : bool
        With ``store``, keep of the predictions and transitions only what the adjoint-form smoother
        (:func:`bf_smooth`) reads: ``P_prior`` as its rows at the measured states ``(B, N, nm, nz)``
        and ``F`` as its ship-state rows ``(B, N, nx, nz)`` (the parameter rows are the identity);
        half the memory traffic of the full storage.  Float64 only: where the storage would be
        float32 the full storage is kept (``EKFOutput.compact`` says which one ran).
        ``"ship"``: in addition ``P_post`` as its ship-state rows ``(B, N, nx, nz)``, all that
        :func:`bf_smooth` reads of it for the ship states' smoothed means and variances (it then
        does not compute the parameters' smoothed means nor the covariance at sample 0: what the
        identifier takes from the filter's last sample when the parameters do not walk).

    Returns
    -------
    EKFOutput

    Notes
    -----
    The semantics, per member and sample ``k`` (a contract: the compiled kernel
    reproduces them):

    1. **Update** with the measurements of sample ``k``.  The innovation of channel
       ``j`` is ``e_j = y_j - z_prior[meas_idx_j]`` with prior variance
       ``S_jj = P_prior[meas_idx_j, meas_idx_j] + R_j``.  With ``gate`` set, a
       measured channel with ``|e_j| > gate * sqrt(S_jj)`` is *rejected* (treated as
       missing at this sample, flagged in ``gated``) unless it was rejected at its
       last ``gate_run`` measured samples in a row (then it is accepted and its
       count restarts); the run counters restart at reset samples.  The accepted
       channels update the state jointly (Joseph form); ``nis`` and the
       log-likelihood use the accepted channels only.
    2. **Divergence**: ``nis > nis_limit``, or a posterior covariance with a
       non-finite or non-positive trace, or a non-finite state, marks the member
       diverged at ``k``.  It stops there: its posterior at ``k`` and everything
       after is not computed (NaN in the stored arrays) and ``z_final/P_final``
       keep its last good posterior; the other members continue.  The loop ends
       when every member has diverged.
    3. **Predict** to ``k + 1`` unless ``k + 1`` is a reset sample (then the ship
       state restarts at ``x_reset`` with covariance ``P_reset``, nothing is
       integrated, and the parameter states carry over).  The interval
       ``dt_k = t[k+1] - t[k]`` is crossed in ``n_k = max(substeps,
       ceil(dt_k / h_max - 1e-9))`` equal RK4 steps ``h = dt_k / n_k``
       (:func:`interval_steps`), step ``i`` starting at ``t[k] + i h``.  Under
       ``input_hold="foh"`` the input is linear from ``U[k]`` to ``U[k+1]``: step
       ``i`` runs from ``u_a = (1-w_i) U[k] + w_i U[k+1]`` to ``u_b`` at
       ``w_{i+1}`` (``w_i = i / n_k``; the last ``u_b`` is ``U[k+1]`` itself), its
       RK4 stages see ``u_a``, ``(u_a + u_b) / 2``, ``(u_a + u_b) / 2``, ``u_b``, and
       the tangent is taken with the same stage inputs (the "rk4" Taylor tangent
       at ``(t, x, u_a)``); ``"zoh"`` holds ``U[k]``.  The transition is the
       product of the steps' tangents; ``P_prior = F P F^T`` (symmetrised) plus
       ``Q_k = diag(q) dt_k``.

    The loop is written for few numpy calls per sample (their fixed cost,
    not the arithmetic, dominates at ~20 states): ``H`` selects states, so
    ``P H^T`` and ``H P H^T`` are column/row picks of ``P`` (views when the
    measured states are contiguous), and the Joseph update
    ``(I - K H) P (I - K H)^T + K R K^T`` is evaluated as
    ``A - (A H^T - K R) K^T`` with ``A = P - K H P`` -- the same product,
    associated differently, without forming ``I - K H``.
    """
    # refuse what cannot fit (or store in float32 where only that fits)
    sdt = _memory.check(*prob.shape[:2], prob.shape[2] + prob.shape[3], prob.shape[4], store, store_dtype)
    if compact not in (False, True, "ship"):
        raise ValueError(f"compact must be False, True or 'ship', got {compact!r}")
    compact = (compact if store and sdt is np.float64 else False) or False
    fast = _run_compiled(prob, store, nis_limit, sdt, compact)  # the compiled kernel (same semantics), when available
    if fast is not None:
        return fast
    model = prob.model
    B, N, nx, ne, nm = prob.shape
    nz = nx + ne
    n_par = len(prob.p_base[0])
    mi = _index_or_slice(prob.meas_idx, nz)
    est = _index_or_slice(prob.est_idx, n_par)
    all_est = isinstance(est, slice) and est == slice(0, n_par)
    scale = np.asarray(prob.scale, dtype=float)
    step = STEP_TANGENTS[prob.method]
    if prob.input_hold not in INPUT_HOLDS:
        raise ValueError(f"input_hold must be one of {INPUT_HOLDS}, got {prob.input_hold!r}")
    foh = prob.input_hold == "foh"
    gate = None if prob.gate is None else float(prob.gate)
    if gate is not None and not gate > 0:
        raise ValueError(f"gate must be positive or None, got {prob.gate}")
    gate_run = int(prob.gate_run)
    eye = np.eye(nz)

    # per-sample quantities computed once, outside the loop
    t_all = prob.t
    dt = np.diff(t_all, axis=1)  # (B, N-1)
    n_all = interval_steps(t_all, int(prob.substeps), prob.h_max)
    h_all = dt / n_all
    Qd = prob.q[:, None, :] * dt[:, :, None]  # (B, N-1, nz) process-noise variances per interval
    # with one sampling interval throughout, Q is one matrix (added in one call); "one interval" to
    # rounding, since time stamps like k*0.1 give differences that vary in the last bits
    uniform = N > 1 and bool(np.all(np.abs(dt - dt[:, :1]) <= 1e-9 * np.abs(dt[:, :1])))
    Q_const = prob.q[:, :, None] * dt[:, :1, None] * np.eye(nz) if uniform else None
    # where every member shares the sample times, pass plain floats to the model (cheaper than (B,) arrays)
    shared_t = (t_all == t_all[:1]).all(axis=0).tolist()
    t_first = t_all[0].tolist()
    h_first = h_all[0].tolist()
    n_first = n_all[0].tolist()
    Y = prob.Y
    fin = np.isfinite(Y)
    all_k = fin.all(axis=(0, 2)).tolist()
    any_k = fin.any(axis=(0, 2)).tolist()
    reset_k = prob.reset.any(axis=0).tolist()
    reset_all = prob.reset.all(axis=0).tolist()
    R = prob.R
    Rrow = R[:, None, :]
    Rfull = R[:, :, None] * np.eye(nm)
    logR = np.log(R)
    logdet_k = np.full((B, N), np.nan)  # log det S per sample (masked channels removed)
    if gate is not None:
        mi_arr = np.asarray(prob.meas_idx, dtype=np.intp)
        run = np.zeros((B, nm), dtype=np.int64)  # consecutive rejections per channel
        gate2 = gate * gate

    z = prob.z0.copy()
    P = prob.P0.copy()
    z_good, P_good = z, P  # last good posterior (before any update: the initial condition)
    p = prob.p_base.copy()
    if store:
        z_post = np.empty((B, N, nz))
        nr = nx if compact == "ship" else nz  # the rows of P_post kept
        P_post = np.empty((B, N, nr, nz), dtype=sdt)
        z_prior = np.empty((B, N, nz))
        P_prior = np.empty((B, N, nm, nz) if compact else (B, N, nz, nz), dtype=sdt)
        Fs = np.zeros((B, N, nx, nz) if compact else (B, N, nz, nz), dtype=sdt)
        if not compact:
            Fs[:, :, nx:, nx:] = np.eye(ne)
        z_prior[:, 0], P_prior[:, 0] = z, P[:, mi] if compact else P
    F_in_store = store and sdt is np.float64 and not compact
    if not F_in_store:  # the transition is computed in float64 (then stored rounded, or its ship rows)
        Fbuf = np.zeros((B, nz, nz))
        Fbuf[:, nx:, nx:] = np.eye(ne)
    innov = np.full((B, N, nm), np.nan)
    S_diag = np.full((B, N, nm), np.nan)
    nis = np.full((B, N), np.nan)
    gated = np.zeros((B, N, nm), dtype=bool)
    diverged = np.zeros(B, dtype=bool)
    any_div = False
    diverged_at = np.full(B, -1)
    message = ["ok"] * B
    k_end = N  # samples computed (the loop stops when every member has diverged)
    for k in range(N):
        # ---- update with the measurements of sample k
        if gate is not None and reset_k[k]:
            run[prob.reset[:, k]] = 0
        if any_k[k]:
            e = Y[:, k] - z[:, mi]
            PHt = P[:, :, mi]  # (B, nz, nm)
            m = None
            if gate is not None:
                Sjj = P[:, mi_arr, mi_arr] + R
                mk = fin[:, k] & ~diverged[:, None] if any_div else fin[:, k]
                rej = mk & (e * e > gate2 * Sjj) & (run < gate_run)
                if rej.any():
                    run = np.where(rej, run + 1, np.where(mk, 0, run))
                    gated[:, k] = rej
                    m = mk & ~rej
                    e_raw, S_raw = e, Sjj
                else:
                    run[mk] = 0
            full = m is None and all_k[k] and not any_div
            if full:
                S = PHt[:, mi, :] + Rfull
            else:
                if m is None:
                    m = fin[:, k] & ~diverged[:, None]
                e = np.where(m, e, 0.0)
                PHt = PHt * m[:, None, :]
                S = PHt[:, mi, :] * m[:, :, None] + Rfull
            # one solve for the gain and the normalised innovation: S [K^T, a] = [H P, e]
            HP = PHt.transpose(0, 2, 1)
            X, logdet = _spd_solve(S, np.concatenate((HP, e[:, :, None]), axis=2))
            Kt = X[:, :, :nz]
            K = Kt.transpose(0, 2, 1)  # (B, nz, nm)
            z = z + (K @ e[:, :, None])[:, :, 0]
            A = P - K @ HP
            P = A - (A[:, :, mi] - K * Rrow) @ Kt
            d2 = np.add.reduce(e * X[:, :, nz], axis=1)
            if full:
                logdet_k[:, k] = logdet
                nis[:, k] = d2
                innov[:, k] = e
                S_diag[:, k] = S.reshape(B, nm * nm)[:, :: nm + 1]
            else:
                # remove the masked channels' R from det(S) (they carry no information)
                cnt = m.sum(axis=1)
                logdet = logdet - np.where(m, 0.0, logR).sum(axis=1)
                has = cnt > 0
                logdet_k[:, k] = logdet
                nis[:, k] = np.where(has, d2, np.nan)
                innov[:, k] = np.where(m, e, np.nan)
                S_diag[:, k] = np.where(m, np.diagonal(S, axis1=1, axis2=2), np.nan)
                if gated[:, k].any():  # a rejected channel keeps its innovation and prior variance
                    g = gated[:, k]
                    innov[:, k] = np.where(g, e_raw, innov[:, k])
                    S_diag[:, k] = np.where(g, S_raw, S_diag[:, k])
            # ---- divergence checks (NaN fails every comparison)
            # trace of P, poisoned (NaN) by a non-finite z; S not positive definite gave a NaN gain
            tr = np.add.reduce(P.reshape(B, nz * nz)[:, :: nz + 1] + 0.0 * z, axis=1)
            # margin > 0 iff d2 <= nis_limit and 0 < tr < inf; NaN anywhere fails
            margin = np.minimum(np.minimum(nis_limit - d2, tr), np.inf - tr)
            if not np.minimum.reduce(margin) > 0:
                bad = ~(margin > 0) & ~diverged
                if bad.any():
                    any_div = True
                    for b in np.flatnonzero(bad):
                        diverged[b] = True
                        diverged_at[b] = k
                        message[b] = _divergence_message(k, t_all[b, k], d2[b])
                    # the member stops: keep its last good posterior
                    z[bad] = z_good[bad]
                    P[bad] = P_good[bad]
        if store:
            z_post[:, k], P_post[:, k] = z, P[:, :nr]
            if any_div:
                z_post[diverged, k] = np.nan
                P_post[diverged, k] = np.nan
        z_good, P_good = z, P
        if k == N - 1:
            break
        if any_div and diverged.all():
            k_end = k + 1
            break
        # ---- predict to sample k+1 (RK4 map of the model, its tangent as the transition)
        F = Fs[:, k] if F_in_store else Fbuf
        zn = z.copy()
        Qk = Qd[:, k]
        rs = prob.reset[:, k + 1] if reset_k[k + 1] else None
        if not reset_all[k + 1]:  # nothing is integrated into a reset sample
            x = z[:, :nx]
            if all_est:
                p = z[:, nx:] * scale
            else:
                p[:, est] = z[:, nx:] * scale
            u0 = prob.U[:, k]
            u1 = prob.U[:, k + 1] if foh else None
            if B == 1:  # one member: the model on its unbatched arrays (numpy scalars: cheaper than (1,) arrays)
                x, Fx, Fp = _cross_interval(step, model, t_first[k], x[0], u0[0], None if u1 is None else u1[0],
                                            p[0], h_first[k], n_first[k], scale, est, all_est)
                x, Fx, Fp = x[None], Fx[None], Fp[None]
            elif shared_t[k] and shared_t[k + 1]:
                x, Fx, Fp = _cross_interval(step, model, t_first[k], x, u0, u1, p, h_first[k], n_first[k],
                                            scale, est, all_est)
            else:
                nk = n_all[:, k]
                if (nk == nk[0]).all():
                    x, Fx, Fp = _cross_interval(step, model, t_all[:, k], x, u0, u1, p, h_all[:, k], int(nk[0]),
                                                scale, est, all_est)
                else:  # members whose intervals need different step counts: one group per count
                    xg, Fx, Fp = np.empty_like(x), np.empty((B, nx, nx)), np.empty((B, nx, ne))
                    for nv in np.unique(nk):
                        g = np.flatnonzero(nk == nv)
                        xg[g], Fx[g], Fp[g] = _cross_interval(
                            step, model, t_all[g, k], x[g], u0[g], None if u1 is None else u1[g], p[g],
                            h_all[g, k], int(nv), scale, est, all_est)
                    x = xg
            F[:, :nx, :nx] = Fx
            F[:, :nx, nx:] = Fp
            zn[:, :nx] = x
        if rs is not None:
            F[rs, :nx, :] = 0.0
            zn[rs, :nx] = prob.x_reset[rs, k + 1]
            Qk = Qk.copy()
            Qk[rs, :nx] = 0.0
        Pn = F @ P @ F.transpose(0, 2, 1)
        Pn = 0.5 * (Pn + Pn.transpose(0, 2, 1))  # exactly symmetric
        if Q_const is not None and rs is None:
            Pn += Q_const
        else:
            Pn.reshape(B, nz * nz)[:, :: nz + 1] += Qk
            if rs is not None:
                Pn[rs, :nx, :nx] += prob.P_reset[rs]
        if any_div:
            zn[diverged], Pn[diverged] = z[diverged], P[diverged]
            if store:
                F[diverged] = np.nan
        if store and not F_in_store:
            Fs[:, k] = F[:, :nx] if compact else F
        z, P = zn, Pn
        if store:
            z_prior[:, k + 1], P_prior[:, k + 1] = z, P[:, mi] if compact else P
            if any_div:
                z_prior[diverged, k + 1] = np.nan
                P_prior[diverged, k + 1] = np.nan
    if store:
        Fs[:, N - 1] = eye[:nx] if compact else eye
        if k_end < N:  # every member diverged: nothing after was computed
            for a in (z_post, P_post, z_prior, P_prior, Fs):
                a[:, k_end:] = np.nan
            Fs[:, k_end - 1] = np.nan
        if any_div:
            for b in np.flatnonzero(diverged):
                Fs[b, diverged_at[b]:] = np.nan
    return _output((z_post, P_post, z_prior, P_prior, Fs) if store else None, z_good, P_good, innov, S_diag, nis,
                   logdet_k, gated, diverged, diverged_at, message, compact)


def rts_smooth(out: EKFOutput, chunk: int = 256) -> tuple[np.ndarray, np.ndarray]:
    """Rauch-Tung-Striebel smoother for the EKF output (linearised about the filter).

    Uses the stored transitions ``F[k]`` (exact Jacobians of the RK4 map at
    the filtered estimate), so it is the extended RTS smoother; filterpy's
    ``rts_smoother`` assumes one linear ``F`` and cannot be used here.

    The gains ``G_k = Pf_k F_k^T Pp_{k+1}^-1`` depend on filter quantities
    only, so they are solved for ``chunk`` samples at a time in one stacked
    call; only the two-line backward recursion runs per sample.

    Returns
    -------
    z_s : (B, N, nz), P_s : (B, N, nz, nz)
    """
    if out.z_post is None or out.compact:
        raise ValueError("rts_smooth needs an EKF run with store=True (and not compact)")
    fast = _smooth_compiled(out)  # compiled backward recursion, when available
    if fast is not None:
        return fast
    zf, Pf, zp, Pp, F = out.z_post, out.P_post, out.z_prior, out.P_prior, out.F
    B, N, nz = zf.shape
    zs = np.empty_like(zf)
    Ps = np.empty(Pf.shape)
    zs[:, -1], Ps[:, -1] = zf[:, -1], Pf[:, -1]
    hi = N - 1  # samples lo..hi-1 are smoothed from hi..lo+1
    while hi > 0:
        lo = max(0, hi - chunk)
        # G^T = Pp^-1 F Pf  (Pp and Pf symmetric), for samples lo..hi-1 at once
        Pf_c = Pf[:, lo:hi + 1].astype(float, copy=False)  # float64 (a copy of a float32-stored chunk)
        Pp_c = Pp[:, lo:hi + 1].astype(float, copy=False)
        Gt_all = _psd_solve(Pp_c[:, 1:], F[:, lo:hi].astype(float, copy=False) @ Pf_c[:, :-1])
        G_all = Gt_all.swapaxes(-1, -2)
        for k in range(hi - 1, lo - 1, -1):
            G, Gt = G_all[:, k - lo], Gt_all[:, k - lo]
            zs[:, k] = zf[:, k] + (G @ (zs[:, k + 1] - zp[:, k + 1])[:, :, None])[:, :, 0]
            D = Pf_c[:, k - lo] + G @ (Ps[:, k + 1] - Pp_c[:, k + 1 - lo]) @ Gt
            Ps[:, k] = 0.5 * (D + D.transpose(0, 2, 1))
        hi = lo
    return zs, Ps


def bf_smooth(out: EKFOutput, R: np.ndarray, meas_idx, nx: int, chunk: int = 256):
    """The same smoother as :func:`rts_smooth` in Bryson-Frazier (adjoint) form, returning the smoothed
    means, the ship states' smoothed variances at every sample and the whole smoothed covariance at
    sample 0 -- what the identifier reports -- at a fraction of the cost: no inverse of the predicted
    covariance and no full covariance per sample.

    Backwards from ``lam = 0, Lam = 0`` at the last sample, with ``Pf``, ``Pp``, ``F`` the stored filter
    quantities (:class:`EKFOutput`) and the accepted channels of each sample (finite innovation, not
    gated)::

        zs_k = zf_k + Pf_k lam_k,          Ps_k = Pf_k - Pf_k Lam_k Pf_k
        lam~ = lam + H^T (S^-1 e - K^T lam),  Lam~ = (I - K H)^T Lam (I - K H) + H^T S^-1 H   (update at k)
        lam_{k-1} = F_{k-1}^T lam~,          Lam_{k-1} = F_{k-1}^T Lam~ F_{k-1}                (transition)

    with ``S = H Pp_k H^T + R`` and ``K = Pp_k H^T S^-1`` the filter's gain (Bierman 1977, the modified
    Bryson-Frazier smoother; equal to the RTS recursion in exact arithmetic for the filter's
    optimal-gain update).  Relies on the transition's parameter rows being the identity (the random
    walks of the augmented state), as :func:`run_ekf` stores them.

    Parameters
    ----------
    out : EKFOutput of a run with ``store=True`` (float64 storage, full or ``compact``; with
        ``compact="ship"`` only the ship rows of ``P_post`` are stored, and the parameters' smoothed
        means and ``Ps0`` are not computed: NaN)
    R : (B, nm) measurement noise variances of that run (``EKFProblem.R``)
    meas_idx : (nm,) state index of each channel
    nx : number of ship states (the first ``nx`` of the augmented state)

    Returns
    -------
    zs : (B, N, nz), var_x : (B, N, nx), Ps0 : (B, nz, nz) -- NaN for a member that diverged.
    """
    if out.z_post is None:
        raise ValueError("bf_smooth needs an EKF run with store=True")
    R = np.ascontiguousarray(R, dtype=float)
    acc = np.isfinite(out.innov) & ~out.gated
    fns = _jit.compiled(_kernel.SMOOTHER, fastmath=_kernel.FASTMATH, inline=_kernel.INLINE, error_model="numpy")
    B, N, nz = out.z_post.shape
    nm = R.shape[1]
    # the rows of the stored P_prior at the measured states (all of them, in channel order, when compact)
    pp_rows = np.arange(nm) if out.compact else np.ascontiguousarray(meas_idx, dtype=np.int64)
    if fns is not None:
        c = lambda a: np.ascontiguousarray(a, dtype=float)  # noqa: E731
        zs, var_x, Ps0 = np.empty((B, N, nz)), np.empty((B, N, nx)), np.empty((B, nz, nz))
        gains = out.gains is not None and out.compact
        Kst, ast, Sist = out.gains if gains else (np.empty((1, 1, 1, 1)), np.empty((1, 1, 1)), np.empty((1, 1, 1, 1)))
        fns["bf_batch"](c(out.z_post), c(out.P_post), c(out.P_prior), pp_rows, c(out.F), c(out.innov), acc, R,
                        np.ascontiguousarray(meas_idx, dtype=np.int64), int(nx), zs, var_x, Ps0, gains, c(Kst), c(ast),
                        c(Sist))
        return zs, var_x, Ps0
    zs, var_x, Ps0 = np.full((B, N, nz), np.nan), np.full((B, N, nx), np.nan), np.full((B, nz, nz), np.nan)
    good = np.flatnonzero(np.isfinite(out.z_post[:, -1]).all(axis=1))
    if good.size == 0:
        return zs, var_x, Ps0
    pick = (lambda a: a) if good.size == B else (lambda a: a[good])  # noqa: E731
    zf, Pf, Pp, F, innov, acc, R = (pick(a) for a in (out.z_post, out.P_post, out.P_prior, out.F, out.innov, acc, R))
    Bg = zf.shape[0]
    mi = _index_or_slice(meas_idx, nz)
    mi_rows = mi if isinstance(mi, slice) else mi[:, None]
    rows = slice(None) if out.compact else mi
    eye_m = np.eye(nm)
    F_full = np.zeros((Bg, nz, nz))  # the transition with its identity parameter rows (the ship rows stored)
    F_full[:, nx:, nx:] = np.eye(nz - nx)
    nr = Pf.shape[2]  # rows of P_post stored: all, or the ship rows (compact="ship")
    zs_g, var_g, Ps0_g = np.full((Bg, N, nz), np.nan), np.empty((Bg, N, nx)), np.full((Bg, nz, nz), np.nan)
    lam, Lam = np.zeros((Bg, nz)), np.zeros((Bg, nz, nz))
    hi = N
    while hi > 0:
        lo = max(0, hi - chunk)
        # gains, S^-1 e and S^-1 of samples lo..hi-1 in one stacked solve; a channel not accepted is a
        # decoupled unit row of S with zero right-hand sides (its K, S^-1 e and S^-1 entries are zero)
        m = acc[:, lo:hi]
        PH = Pp[:, lo:hi][:, :, rows, :] * m[..., None]
        S = PH[..., mi] * m[..., None, :] + np.where(m, R[:, None, :], 1.0)[..., None] * eye_m
        e = np.where(m, innov[:, lo:hi], 0.0)
        X = np.linalg.solve(S, np.concatenate((PH, e[..., None], eye_m * m[..., None]), axis=-1))
        for k in range(hi - 1, lo - 1, -1):
            Pfk = Pf[:, k]
            zs_g[:, k, :nr] = zf[:, k, :nr] + (Pfk @ lam[:, :, None])[:, :, 0]
            Pfx = Pfk[:, :nx]
            var_g[:, k] = np.diagonal(Pfx[:, :, :nx], axis1=1, axis2=2) - ((Pfx @ Lam) * Pfx).sum(axis=2)
            if k == 0:
                if nr == nz:
                    Ps0_g[:] = Pfk - Pfk @ Lam @ Pfk
                    Ps0_g[:] = 0.5 * (Ps0_g + Ps0_g.transpose(0, 2, 1))
                break
            Xk = X[:, k - lo]
            Kt, a, Si = Xk[:, :, :nz], Xk[:, :, nz], Xk[:, :, nz + 1:]
            LK = Lam @ Kt.transpose(0, 2, 1)  # (B, nz, nm)
            lam[:, mi] += a - (Kt @ lam[:, :, None])[:, :, 0]
            Lam[:, :, mi] -= LK
            Lam[:, mi, :] -= LK.transpose(0, 2, 1)
            Lam[:, mi_rows, mi] += Kt @ LK + Si
            F_full[:, :nx] = F[:, k - 1, :nx]
            Fk = F_full
            lam = (lam[:, None, :] @ Fk)[:, 0]
            Lam = Fk.transpose(0, 2, 1) @ Lam @ Fk
            Lam = 0.5 * (Lam + Lam.transpose(0, 2, 1))
        hi = lo
    zs[good], var_x[good], Ps0[good] = zs_g, var_g, Ps0_g
    return zs, var_x, Ps0


def _psd_solve(A: np.ndarray, Bm: np.ndarray) -> np.ndarray:
    """Solve ``A X = B`` for stacked symmetric PSD ``A (..., n, n)``, robust to singular blocks.

    One stacked LU solve; if any block is singular, the stack goes through the
    (Hermitian) pseudo-inverse instead.
    """
    try:
        return np.linalg.solve(A, Bm)
    except np.linalg.LinAlgError:
        return np.linalg.pinv(A, hermitian=True) @ Bm


def gain_covariance(prob: EKFProblem, out: EKFOutput, q=None) -> np.ndarray:
    """Error covariance of a filter run's last posterior with its own gains, under process noise ``q``.

    The filter's ``P`` is the error covariance only when the noise it assumed (``prob.R``, ``prob.q``) is the noise
    of the data.  With the gains ``K_k`` and transitions ``F_k`` of the run held, the error of the same estimate
    under other process noise follows the linear recursion (Gelb, *Applied Optimal Estimation*, 1974, sect. 7.2,
    sensitivity analysis of a suboptimal filter; the Joseph form of the update)::

        Pa+_k = (I - K_k H_k) Pa-_k (I - K_k H_k)^T + K_k R K_k^T,   Pa-_{k+1} = F_k Pa+_k F_k^T + q dt_k

    from ``Pa-_0 = P0``, with the measurements the filter used at each sample (gated or missing ones skipped) and
    the log resets of the run (``x_reset`` with ``P_reset``).  ``q`` (nz,) or (B, nz): process-noise intensities
    as ``prob.q``; None: no process noise (logs with sensor noise only).  With ``q = prob.q`` it reproduces the
    filter's own ``P_post[:, -1]`` (the gains are then the optimal ones).

    Parameters
    ----------
    prob : EKFProblem
    out : EKFOutput of ``run_ekf(prob, store=True, compact=False, store_dtype="float64")``

    Returns
    -------
    ndarray (B, nz, nz)
    """
    if out.P_prior is None or out.compact or out.F is None or out.P_prior.dtype != np.float64:
        raise ValueError("gain_covariance needs run_ekf(prob, store=True, compact=False, store_dtype='float64')")
    if np.any(out.diverged):
        raise ValueError("gain_covariance: the filter diverged; its gains do not define an estimate")
    B, N, nx, ne, nm = prob.shape
    nz = nx + ne
    mi = np.asarray(prob.meas_idx)
    qq = np.zeros((B, nz)) if q is None else np.broadcast_to(np.asarray(q, dtype=float), (B, nz))
    dt = np.diff(prob.t, axis=1)
    used = np.isfinite(out.innov) & ~out.gated
    res = np.empty((B, nz, nz))
    for b in range(B):
        Rb = np.asarray(prob.R[b], dtype=float)
        Pa = np.array(prob.P0[b], dtype=float)
        for k in range(N):
            m = used[b, k]
            if m.any():
                Pp = out.P_prior[b, k]
                rows = mi[m]
                Rm = np.diag(Rb[m])
                K = np.linalg.solve(Pp[np.ix_(rows, rows)] + Rm, Pp[rows, :]).T  # the filter's gain (nz, nm_k)
                A = np.eye(nz)
                A[:, rows] -= K
                Pa = A @ Pa @ A.T + K @ Rm @ K.T
            if k == N - 1:
                break
            F = out.F[b, k]
            Pa = F @ Pa @ F.T
            if prob.reset[b, k + 1]:
                Pa[:nx, :nx] += prob.P_reset[b]
                Pa[np.arange(nx, nz), np.arange(nx, nz)] += qq[b, nx:] * dt[b, k]
            else:
                Pa[np.arange(nz), np.arange(nz)] += qq[b] * dt[b, k]
            Pa = 0.5 * (Pa + Pa.T)
        res[b] = Pa
    return res


#: Buffers of the compiled filter's stored arrays kept for reuse (:func:`_stored_empty`): at most
#: ``_POOL_BYTES`` in all, each at most ``_POOL_ARRAY_BYTES`` (larger storage is allocated and freed as usual).
_POOL_BYTES = 64 << 20
_POOL_ARRAY_BYTES = 16 << 20
_pool: list = []
_pool_lock = threading.Lock()  # (a buffer is taken under the lock: threads running fits never share one)


def _free_refs() -> int:
    """Reference count :func:`_stored_empty` sees for a pooled buffer that nothing else holds."""
    probe = [np.empty(1)]
    for buf in probe:
        return sys.getrefcount(buf)


def _stored_empty(shape, dtype=np.float64) -> np.ndarray:
    """``np.empty(shape, dtype)`` for the filter's stored arrays, from a small pool of buffers whose
    previous users have all let go (no array or view of it is alive).  Fresh memory costs a page fault
    and the zeroing of every page at its first write -- on this kind of machine ~0.7 us per sample of a
    22-state compact run, a sixth of the filter -- where a reused buffer is just written.  The kernel
    writes every entry, so a reused buffer's old contents are never seen."""
    dtype = np.dtype(dtype)
    n = int(np.prod(shape)) * dtype.itemsize
    if n > _POOL_ARRAY_BYTES or n == 0:
        return np.empty(shape, dtype)
    with _pool_lock:
        return _take(n).view(dtype).reshape(shape)


def _take(n: int) -> np.ndarray:
    for buf in _pool:
        if buf.nbytes == n and sys.getrefcount(buf) == _FREE:
            return buf
    buf = np.empty(n, dtype=np.uint8)
    _pool.append(buf)
    total = sum(b.nbytes for b in _pool)
    i = 0
    while total > _POOL_BYTES and i < len(_pool) - 1:  # drop the oldest free buffers beyond the budget
        if sys.getrefcount(_pool[i]) == _FREE - 1:  # (-1: no loop variable holds it here)
            total -= _pool.pop(i).nbytes
        else:
            i += 1
    return buf


_FREE = _free_refs()


def _run_compiled(prob, store: bool, nis_limit: float, store_dtype=np.float64, compact: bool | str = False):
    """:func:`run_ekf` on the compiled kernel (:mod:`shipid._kernel`), or ``None`` when it is not available
    (numba off, the model has no compiled equations, or a method the kernel does not implement)."""
    if prob.method not in _kernel.METHODS:
        return None
    if prob.input_hold not in INPUT_HOLDS:
        raise ValueError(f"input_hold must be one of {INPUT_HOLDS}, got {prob.input_hold!r}")
    if prob.gate is not None and not float(prob.gate) > 0:
        raise ValueError(f"gate must be positive or None, got {prob.gate}")
    fns = _kernel.filter_functions(prob.model)
    if fns is None:
        return None
    B, N, nx, ne, nm = prob.shape
    nz = nx + ne
    f64 = lambda a: np.ascontiguousarray(a, dtype=float)  # noqa: E731
    t = f64(prob.t)
    Y = f64(prob.Y)
    fin = np.isfinite(Y)
    reset = np.ascontiguousarray(prob.reset, dtype=np.bool_)
    dt = np.diff(t, axis=1)
    # the numpy path adds one Q (that of the first interval) when the sampling is uniform and no member
    # resets at k+1; the interval's own Q otherwise
    uniform = N > 1 and bool(np.all(np.abs(dt - dt[:, :1]) <= 1e-9 * np.abs(dt[:, :1])))
    dtq = dt.copy()
    if uniform:
        keep = ~reset[:, 1:].any(axis=0)
        dtq[:, keep] = dt[:, :1]
    nsteps = interval_steps(t, int(prob.substeps), prob.h_max)
    if N == 1:
        dtq, nsteps = np.zeros((B, 1)), np.ones((B, 1), dtype=np.int64)
    nan = lambda *shape: np.full(shape, np.nan)  # noqa: E731
    if store:  # every entry is written by the kernel (uninitialised buffers, reused where free: _stored_empty)
        z_post, z_prior = _stored_empty((B, N, nz)), _stored_empty((B, N, nz))
        P_post = _stored_empty((B, N, nx if compact == "ship" else nz, nz), store_dtype)
        P_prior = _stored_empty((B, N, nm, nz) if compact else (B, N, nz, nz), store_dtype)
        Fs = _stored_empty((B, N, nx, nz) if compact else (B, N, nz, nz), store_dtype)
    gains = bool(store and compact)  # the update's gains, for the smoother (EKFOutput.gains)
    if gains:
        Kst, ast, Sist = _stored_empty((B, N, nm, nz)), _stored_empty((B, N, nm)), _stored_empty((B, N, nm, nm))
    else:
        Kst, ast, Sist = np.empty((1, 1, 1, 1)), np.empty((1, 1, 1)), np.empty((1, 1, 1, 1))
    if not store:
        z_post = z_prior = np.empty((1, 1, nz))
        P_post = P_prior = Fs = np.empty((1, 1, nz, nz))
    z_fin, P_fin = np.empty((B, nz)), np.empty((B, nz, nz))
    innov, S_diag, nis, logdet = nan(B, N, nm), nan(B, N, nm), nan(B, N), nan(B, N)
    gated = np.zeros((B, N, nm), dtype=np.bool_)
    div = np.zeros(B, dtype=np.bool_)
    div_at = np.full(B, -1, dtype=np.int64)
    d2_at = np.full(B, np.nan)
    _kernel.call(
        prob.model, fns, "ekf_batch", t, f64(prob.U), Y, fin, fin.any(axis=(0, 2)), reset, f64(prob.x_reset), f64(prob.P_reset), f64(prob.q), dtq,
        nsteps, f64(prob.R), f64(prob.z0), f64(prob.P0), f64(prob.p_base),
        np.ascontiguousarray(prob.est_idx, dtype=np.int64), f64(prob.scale),
        np.ascontiguousarray(prob.meas_idx, dtype=np.int64), f64(prob.model._kernel_constants()), nx,
        _kernel.METHODS[prob.method], prob.input_hold == "foh", -1.0 if prob.gate is None else float(prob.gate),
        int(prob.gate_run), float(nis_limit), bool(store), bool(compact),
        z_post, P_post, z_prior, P_prior, Fs, z_fin, P_fin, innov, S_diag, nis, logdet, gated, div, div_at, d2_at,
        gains, Kst, ast, Sist)
    message = ["ok"] * B
    for b in np.flatnonzero(div):
        message[b] = _divergence_message(int(div_at[b]), t[b, div_at[b]], d2_at[b])
    return _output((z_post, P_post, z_prior, P_prior, Fs) if store else None, z_fin, P_fin, innov, S_diag, nis,
                   logdet, gated, div, div_at, message, compact, (Kst, ast, Sist) if gains else None)



def _smooth_compiled(out):
    """:func:`rts_smooth` compiled (:mod:`shipid._kernel`), or ``None`` when compilation is off."""
    fns = _jit.compiled(_kernel.SMOOTHER, fastmath=_kernel.FASTMATH, inline=_kernel.INLINE, error_model="numpy")
    if fns is None:
        return None
    c = lambda a: np.ascontiguousarray(a, dtype=float)  # noqa: E731
    cs = lambda a: np.ascontiguousarray(a, dtype=np.float32 if a.dtype == np.float32 else float)  # noqa: E731
    zs, Ps = np.empty(out.z_post.shape), np.empty(out.P_post.shape)
    _jit.compile_notice(fns["rts_batch"], "the smoother", seconds=10)
    fns["rts_batch"](c(out.z_post), cs(out.P_post), c(out.z_prior), cs(out.P_prior), cs(out.F), zs, Ps)
    return zs, Ps
