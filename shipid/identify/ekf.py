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

from dataclasses import dataclass

import numpy as np

from ..integrate import STEP_TANGENTS
from ..models.base import Model

__all__ = ["EKFProblem", "EKFOutput", "run_ekf", "rts_smooth"]

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
    U : (B, N, nu) -- inputs, held constant from sample k to k+1.
    Y : (B, N, nm) -- measurements, NaN where missing.
    meas_idx : (nm,) int -- state index measured by each channel.
    R : (B, nm) -- measurement noise variances.
    q : (B, nz) -- process-noise intensities (variance per second) of the augmented states.
    z0 : (B, nz), P0 : (B, nz, nz) -- initial mean and covariance.
    reset : (B, N) bool -- sample k starts a new log (never sample 0).
    x_reset : (B, N, nx) -- initial ship state used at reset samples.
    P_reset : (B, nx, nx) -- its covariance.
    substeps : int -- RK4 steps per sample interval.
    method : a key of :data:`shipid.integrate.STEP_TANGENTS` ("rk4", "rk4-exact", "euler").
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

    @property
    def shape(self):
        B, N = self.t.shape
        return B, N, self.model.nx, len(self.est_idx), len(self.meas_idx)


@dataclass
class EKFOutput:
    """Filter output for a batch.

    ``z_post/P_post`` are the filtered (posterior) estimates at each sample,
    ``z_prior/P_prior`` the predictions at each sample (sample 0: the initial
    condition), ``F[k]`` the transition from k to k+1 (last entry unused).
    ``innov`` (B, N, nm) are innovations (NaN where no measurement),
    ``S_diag`` their predicted variances, ``loglik`` (B,) the innovation
    log-likelihood, ``diverged`` (B,) bool and ``diverged_at`` (B,) sample
    index (-1 if not), ``message`` per member.
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


def _params(prob: EKFProblem, z: np.ndarray) -> np.ndarray:
    nx = prob.model.nx
    p = prob.p_base.copy()
    p[:, prob.est_idx] = z[:, nx:] * prob.scale
    return p


def _transition(prob: EKFProblem, k: int, z: np.ndarray):
    """Propagate the augmented mean from sample k to k+1; return (z_next, F)."""
    model = prob.model
    B, N, nx, ne, _ = prob.shape
    nz = nx + ne
    x = z[:, :nx]
    p = _params(prob, z)
    h = (prob.t[:, k + 1] - prob.t[:, k]) / prob.substeps
    step = STEP_TANGENTS[prob.method]
    uk = prob.U[:, k]
    tk = prob.t[:, k].copy()
    x, Fx, Fp = step(model, tk, x, uk, p, h)
    Fp = Fp[:, :, prob.est_idx] * prob.scale
    for _ in range(prob.substeps - 1):
        tk = tk + h
        x, Ax, Ap = step(model, tk, x, uk, p, h)
        Fp = Ax @ Fp + Ap[:, :, prob.est_idx] * prob.scale
        Fx = Ax @ Fx
    F = np.zeros((B, nz, nz))
    F[:, :nx, :nx] = Fx
    F[:, :nx, nx:] = Fp
    F[:, nx:, nx:] = np.eye(ne)
    zn = np.concatenate([x, z[:, nx:]], axis=1)
    dt = prob.t[:, k + 1] - prob.t[:, k]
    Q = prob.q * dt[:, None]
    rs = prob.reset[:, k + 1]
    if rs.any():
        F[rs, :nx, :] = 0.0
        zn[rs, :nx] = prob.x_reset[rs, k + 1]
        Q[rs, :nx] = 0.0
    return zn, F, Q, rs


def run_ekf(prob: EKFProblem, store: bool = True, nis_limit: float = 1e6) -> EKFOutput:
    """Run the augmented-state EKF over a batch.

    Parameters
    ----------
    prob : EKFProblem
    store : bool
        Keep per-sample means, covariances and transitions (needed by the
        smoother; memory ``B * N * nz^2 * 24`` bytes).
    nis_limit : float
        A normalised innovation squared above this (or a non-finite or
        non-positive covariance) marks the member as diverged; it is then
        frozen (no further updates) and reported, never silently NaN.

    Returns
    -------
    EKFOutput
    """
    B, N, nx, ne, nm = prob.shape
    nz = nx + ne
    mi = np.asarray(prob.meas_idx)
    eye = np.eye(nz)
    z = prob.z0.copy()
    P = prob.P0.copy()
    if store:
        z_post = np.empty((B, N, nz))
        P_post = np.empty((B, N, nz, nz))
        z_prior = np.empty((B, N, nz))
        P_prior = np.empty((B, N, nz, nz))
        Fs = np.empty((B, N, nz, nz))
        z_prior[:, 0], P_prior[:, 0] = z, P
    innov = np.full((B, N, nm), np.nan)
    S_diag = np.full((B, N, nm), np.nan)
    nis = np.full((B, N), np.nan)
    loglik = np.zeros(B)
    diverged = np.zeros(B, dtype=bool)
    diverged_at = np.full(B, -1)
    message = ["ok"] * B
    R = prob.R
    logR = np.log(R)
    Rfull = R[:, :, None] * np.eye(nm)
    for k in range(N):
        # ---- update with the measurements of sample k
        y = prob.Y[:, k]
        m = np.isfinite(y) & ~diverged[:, None]
        if m.any():
            full = bool(m.all())
            # H selects states, so P H^T and H P H^T are column/row picks of P
            PHt = P[:, :, mi]  # (B, nz, nm)
            if not full:
                PHt = PHt * m[:, None, :]
            S = PHt[:, mi, :] if full else PHt[:, mi, :] * m[:, :, None]
            S = S + Rfull
            e = y - z[:, mi]
            if not full:
                e = np.where(m, e, 0.0)
            # one solve for the gain and the normalised innovation: S [K^T, a] = [H P, e]
            sol = np.linalg.solve(S, np.concatenate([PHt.transpose(0, 2, 1), e[:, :, None]], axis=2))
            Kt, Sinv_e = sol[:, :, :nz], sol[:, :, nz]
            K = Kt.transpose(0, 2, 1)
            z = z + np.einsum("bij,bj->bi", K, e)
            KH = np.zeros((B, nz, nz))
            KH[:, :, mi] = K if full else K * m[:, None, :]
            IKH = eye - KH
            # Joseph form: symmetric by construction (exactly symmetrised after the prediction)
            P = IKH @ P @ IKH.transpose(0, 2, 1) + (K * R[:, None, :]) @ Kt
            d2 = np.einsum("bi,bi->b", e, Sinv_e)
            sign, logdet = np.linalg.slogdet(S)
            cnt = m.sum(axis=1)
            if not full:
                # remove the masked channels' R from det(S) (they carry no information)
                logdet = logdet - np.sum(np.where(m, 0.0, logR), axis=1)
            ll = -0.5 * (d2 + logdet + cnt * _LOG2PI)
            loglik += np.where(cnt > 0, ll, 0.0)
            nis[:, k] = np.where(cnt > 0, d2, np.nan)
            innov[:, k] = e if full else np.where(m, e, np.nan)
            Sd = np.diagonal(S, axis1=1, axis2=2)
            S_diag[:, k] = Sd if full else np.where(m, Sd, np.nan)
            # ---- divergence checks (NaN fails every comparison)
            tr = np.einsum("bii->b", P)
            bad = ~diverged & ~((d2 <= nis_limit) & (tr > 0) & (tr < np.inf) & (sign > 0)
                                & np.isfinite(z).all(axis=1))
            if bad.any():
                for b in np.flatnonzero(bad):
                    diverged[b] = True
                    diverged_at[b] = k
                    tk = prob.t[b, k]
                    message[b] = (
                        f"filter diverged at sample {k} (t = {tk:.4g} s): normalised innovation {d2[b]:.3g}"
                        if np.isfinite(d2[b]) else f"filter diverged at sample {k} (t = {tk:.4g} s): non-finite state or covariance"
                    )
                # freeze the member at its last good values
                if store and k > 0:
                    z[bad] = z_post[bad, k - 1]
                    P[bad] = P_post[bad, k - 1]
                else:
                    z[bad] = prob.z0[bad]
                    P[bad] = prob.P0[bad]
        if store:
            z_post[:, k], P_post[:, k] = z, P
        if k == N - 1:
            break
        # ---- predict to sample k+1
        zn, F, Q, rs = _transition(prob, k, z)
        Pn = F @ P @ F.transpose(0, 2, 1)
        Pn[:, np.arange(nz), np.arange(nz)] += Q
        if rs.any():
            Pn[rs, :nx, :nx] += prob.P_reset[rs]
        Pn = 0.5 * (Pn + Pn.transpose(0, 2, 1))
        if diverged.any():
            zn[diverged], Pn[diverged] = z[diverged], P[diverged]
            F[diverged] = eye
        z, P = zn, Pn
        if store:
            Fs[:, k] = F
            z_prior[:, k + 1], P_prior[:, k + 1] = z, P
    if store:
        Fs[:, N - 1] = eye
    return EKFOutput(
        z_post=z_post if store else None, P_post=P_post if store else None,
        z_prior=z_prior if store else None, P_prior=P_prior if store else None,
        F=Fs if store else None, z_final=z, P_final=P, innov=innov, S_diag=S_diag,
        loglik=loglik, nis=nis, diverged=diverged, diverged_at=diverged_at, message=message,
    )


def rts_smooth(out: EKFOutput) -> tuple[np.ndarray, np.ndarray]:
    """Rauch-Tung-Striebel smoother for the EKF output (linearised about the filter).

    Uses the stored transitions ``F[k]`` (exact Jacobians of the RK4 map at
    the filtered estimate), so it is the extended RTS smoother; filterpy's
    ``rts_smoother`` assumes one linear ``F`` and cannot be used here.

    Returns
    -------
    z_s : (B, N, nz), P_s : (B, N, nz, nz)
    """
    if out.z_post is None:
        raise ValueError("rts_smooth needs an EKF run with store=True")
    zf, Pf, zp, Pp, F = out.z_post, out.P_post, out.z_prior, out.P_prior, out.F
    B, N, nz = zf.shape
    zs = np.empty_like(zf)
    Ps = np.empty_like(Pf)
    zs[:, -1], Ps[:, -1] = zf[:, -1], Pf[:, -1]
    for k in range(N - 2, -1, -1):
        # G = Pf F^T Pp^-1  ->  solve Pp^T G^T = F Pf^T (Pp symmetric)
        FPf = F[:, k] @ Pf[:, k]
        Gt = _psd_solve(Pp[:, k + 1], FPf)
        G = Gt.transpose(0, 2, 1)
        zs[:, k] = zf[:, k] + (G @ (zs[:, k + 1] - zp[:, k + 1])[:, :, None])[:, :, 0]
        Ps[:, k] = Pf[:, k] + G @ (Ps[:, k + 1] - Pp[:, k + 1]) @ Gt
        Ps[:, k] = 0.5 * (Ps[:, k] + Ps[:, k].transpose(0, 2, 1))
    return zs, Ps


def _psd_solve(A: np.ndarray, Bm: np.ndarray) -> np.ndarray:
    """Solve ``A X = B`` for symmetric PSD ``A`` (batch), robust to singular blocks."""
    try:
        return np.linalg.solve(A, Bm)
    except np.linalg.LinAlgError:
        return np.linalg.pinv(A, hermitian=True) @ Bm
