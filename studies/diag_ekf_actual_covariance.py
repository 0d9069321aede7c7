"""Diagnostic of the EKF posterior's over-coverage (docs/uncertainty.md sect. 3): the covariance the EKF reports
against the covariance of the same estimator's error under the noise the data actually have.

The EKF's coefficient covariance is the filter's P at the end of its last pass, computed under its assumed noise
model: sensor noise R plus process noise Q (default (0.1 sigma)^2 / dt on the measured states).  The replicate
data have sensor noise only.  For a filter whose gains K_k were computed under one noise model, the error
covariance under another follows the same linear recursion with the gains held (Gelb, *Applied Optimal
Estimation*, 1974, sect. 7.2, "sensitivity analysis" of a suboptimal filter):

    Pa+_k = (I - K_k H) Pa-_k (I - K_k H)^T + K_k R K_k^T,     Pa-_{k+1} = F_k Pa+_k F_k^T + Q_true,

with Pa-_0 = the filter's P0 and Q_true = 0 here (F_k, K_k: the last pass's own transitions and gains; log resets
as in the filter): :func:`shipid.identify.ekf.gain_covariance` via ``EKFIdentifier.sensor_noise_cov()``.  Nothing is tuned: it is the same estimate, only its covariance re-evaluated under the data's
noise model.  The script prints, per coefficient, the coverage and z spread of the reported intervals and of the
re-evaluated ones (same replicates as coverage_study(seed=2026): replicate i has the same logs).

    OPENBLAS_NUM_THREADS=1 nice python -m studies.diag_ekf_actual_covariance [N_REPLICATES]
"""
import sys
import warnings

import numpy as np


def main(n):
    from shipid.campaign import member_seeds
    from shipid.identify import EKFIdentifier
    from studies.coverage import COVERAGE_RECIPES
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
        res = ident.result()
        names = list(res.cov.index)
        idx = [truth.param_index(n) for n in names]
        Pa = ident.sensor_noise_cov().loc[names, names].to_numpy()  # shipid.identify.ekf.gain_covariance, q = 0
        sd_rep = np.array([res.coef_std[n] for n in names])
        sd_act = np.sqrt(np.diag(Pa))
        err = np.array([res.coef[n] for n in names]) - tv[idx]
        Zr.append(err / sd_rep)
        Za.append(err / sd_act)
        ratio.append(sd_act / sd_rep)
    Zr, Za, ratio = map(np.array, (Zr, Za, ratio))
    print(f"{n} replicates, seed 2026")
    print("coef   reported: cover  z mean  z std | actual (Q_true = 0): sigma ratio  cover  z mean  z std")
    for j, nme in enumerate(names):
        print(f"{nme:5s}  {np.mean(np.abs(Zr[:, j]) <= 1.96):13.2f} {Zr[:, j].mean():+7.2f} {Zr[:, j].std(ddof=1):6.2f} |"
              f" {np.median(ratio[:, j]):24.3f} {np.mean(np.abs(Za[:, j]) <= 1.96):6.2f} {Za[:, j].mean():+7.2f}"
              f" {Za[:, j].std(ddof=1):6.2f}")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 20)
