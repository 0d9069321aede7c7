"""Diagnostic of the EKF posterior's over-coverage (docs/uncertainty.md sect. 3): the covariance the EKF reports
against the covariance of the same estimator's error under the noise the data actually have.

The EKF's coefficient covariance is the filter's P at the end of its last pass, computed under its assumed noise
model: sensor noise R plus process noise Q (default (0.1 sigma)^2 / dt on the measured states).  The replicate
data have sensor noise only.  For a filter whose gains K_k were computed under one noise model, the error
covariance under another follows the same linear recursion with the gains held (Gelb, *Applied Optimal
Estimation*, 1974, sect. 7.2, "sensitivity analysis" of a suboptimal filter):

    Pa+_k = (I - K_k H) Pa-_k (I - K_k H)^T + K_k R K_k^T,     Pa-_{k+1} = F_k Pa+_k F_k^T + Q_true,

with Pa-_0 = the filter's P0 and Q_true = 0 here (F_k, K_k: the last pass's own transitions and gains; log resets
as in the filter).  Nothing is tuned: it is the same estimate, only its covariance re-evaluated under the data's
noise model.  The script prints, per coefficient, the coverage and z spread of the reported intervals and of the
re-evaluated ones (same replicates as coverage_study(seed=2026): replicate i has the same logs).

    OPENBLAS_NUM_THREADS=1 nice python benchmarks/diag_ekf_actual_covariance.py [N_REPLICATES]
"""
import sys
import warnings

import numpy as np


def actual_covariance(prob, out):
    """Pa+ at the last sample of one EKF run (B = 1, stored with full float64 P_prior and F)."""
    nz = prob.z0.shape[1]
    mi = np.asarray(prob.meas_idx)
    R = np.diag(np.asarray(prob.R[0] if np.ndim(prob.R) > 1 else prob.R, dtype=float))
    Pa = prob.P0[0].copy()
    N = prob.t.shape[1]
    used = np.isfinite(out.innov[0]) & ~out.gated[0]
    for k in range(N):
        m = used[k]
        if m.any():
            Pp = out.P_prior[0, k]
            rows = mi[m]
            S = Pp[np.ix_(rows, rows)] + R[np.ix_(m, m)]
            K = np.linalg.solve(S, Pp[rows, :]).T  # (nz, nm_k)
            A = np.eye(nz)
            A[:, rows] -= K
            Pa = A @ Pa @ A.T + K @ R[np.ix_(m, m)] @ K.T
        if k == N - 1:
            break
        F = out.F[0, k]
        Pa = F @ Pa @ F.T
        if prob.reset[0, k + 1]:
            nx = prob.model.nx
            Pa[:nx, :nx] += prob.P_reset[0]
    return 0.5 * (Pa + Pa.T)


def main(n):
    from shipid.campaign import member_seeds
    from shipid.identify import EKFIdentifier
    from shipid.identify.coverage import COVERAGE_RECIPES
    from shipid.identify.ekf import run_ekf
    from shipid.models import get_model
    from shipid.synthetic import KCS_NOISE_STD, make_trial

    truth = get_model("kcs-response", "synthetic-truth")
    tv = truth.params
    Zr, Za, ratio = [], [], []
    for s in member_seeds(2026, n):  # as coverage_study's _replicate (same logs, same start)
        rng = np.random.default_rng(s)
        logs = [make_trial(truth, r, rng, dict(KCS_NOISE_STD))[0] for r in COVERAGE_RECIPES]
        start = truth.with_params(truth.params * (1 + 0.3 * rng.standard_normal(truth.np)))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            ident = EKFIdentifier(start, n_passes=2).fit(logs)
            prob = ident.problem_
            out = run_ekf(prob, store=True, compact=False, store_dtype="float64")
        res = ident.result()
        names = list(res.cov.index)
        idx = [truth.param_index(n) for n in names]
        scale = np.asarray(prob.scale, dtype=float)
        nx = truth.nx
        Pa = actual_covariance(prob, out)[nx:, nx:] * np.outer(scale, scale)
        Pf = out.P_post[0, -1][nx:, nx:] * np.outer(scale, scale)
        sd_rep = np.array([res.coef_std[n] for n in names])
        sd_act = np.sqrt(np.diag(Pa))
        err = np.array([res.coef[n] for n in names]) - tv[idx]
        Zr.append(err / sd_rep)
        Za.append(err / sd_act)
        ratio.append(sd_act / sd_rep)
        chk = np.sqrt(np.diag(Pf)) / sd_rep
    Zr, Za, ratio = map(np.array, (Zr, Za, ratio))
    print(f"{n} replicates, seed 2026; check: filtered end-of-pass sigma / reported sigma (last replicate) "
          f"{chk.min():.3f}-{chk.max():.3f}")
    print("coef   reported: cover  z mean  z std | actual (Q_true = 0): sigma ratio  cover  z mean  z std")
    for j, nme in enumerate(names):
        print(f"{nme:5s}  {np.mean(np.abs(Zr[:, j]) <= 1.96):13.2f} {Zr[:, j].mean():+7.2f} {Zr[:, j].std(ddof=1):6.2f} |"
              f" {np.median(ratio[:, j]):24.3f} {np.mean(np.abs(Za[:, j]) <= 1.96):6.2f} {Za[:, j].mean():+7.2f}"
              f" {Za[:, j].std(ddof=1):6.2f}")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 20)
