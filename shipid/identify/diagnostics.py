"""Identifiability diagnostics attached to every fit.

Three views of the same question -- which coefficients (or combinations) do
the logs actually determine?

* the posterior **correlation matrix** and pairs with |rho| > 0.95;
* the **information the data added** beyond the prior, ``I = P_post^-1 -
  P_prior^-1`` in scaled coordinates: its eigen-directions with little
  information relative to the prior are combinations the data do not
  determine; the condition number of the scaled posterior covariance;
* **model-specific checks** (``model.identifiability_notes(logs)``), e.g. the
  KCS response model at constant propeller rpm, where the regressors u, u*n
  and n^2 are collinear.
"""
from __future__ import annotations

import numpy as np
import pandas as pd

__all__ = ["identifiability"]


def _combo(vec: np.ndarray, names: list[str], tol: float = 0.25) -> str:
    idx = np.argsort(-np.abs(vec))
    terms = [f"{vec[i]:+.2f}*{names[i]}" for i in idx if abs(vec[i]) >= tol]
    return " ".join(terms) if terms else f"{vec[idx[0]]:+.2f}*{names[idx[0]]}"


def identifiability(
    names: list[str],
    cov_s: np.ndarray,
    prior_cov_s: np.ndarray,
    notes: list[str] | None = None,
    corr_limit: float = 0.95,
    info_ratio_limit: float = 1.0,
) -> dict:
    """Diagnostics from scaled posterior and prior covariances.

    Parameters
    ----------
    names : estimated parameter names
    cov_s, prior_cov_s : (ne, ne) posterior and prior covariance of the scaled parameters
    notes : model-specific warnings to include
    corr_limit : |correlation| above which a pair is reported
    info_ratio_limit : an eigen-direction whose data information is below
        ``info_ratio_limit`` times the prior information along it is reported
        as not determined by the data (the posterior variance along it is at
        least half the prior's).

    Returns
    -------
    dict with ``correlation`` (DataFrame), ``condition_number``,
    ``poorly_determined`` (list of names), ``unidentified_combinations``
    (list of dict with ``combination``, ``variance_ratio``), ``warnings`` (list of str).
    """
    ne = len(names)
    warnings: list[str] = list(notes or [])
    sd = np.sqrt(np.clip(np.diag(cov_s), 1e-300, None))
    corr = cov_s / np.outer(sd, sd)
    corr = np.clip(0.5 * (corr + corr.T), -1.0, 1.0)
    np.fill_diagonal(corr, 1.0)
    ev = np.linalg.eigvalsh(cov_s)
    cond = float(ev.max() / max(ev.min(), 1e-300))

    pairs = []
    for i in range(ne):
        for j in range(i + 1, ne):
            if abs(corr[i, j]) > corr_limit:
                pairs.append((names[i], names[j], float(corr[i, j])))
    for a, b, r in pairs:
        warnings.append(
            f"{a} and {b} are strongly correlated (rho = {r:+.3f}): the logs determine a combination of them "
            "better than each one; add manoeuvres that excite them differently"
        )

    # information added by the data, relative to the prior, in prior-whitened coordinates
    combos = []
    try:
        Lp = np.linalg.cholesky(prior_cov_s)
        Winv = np.linalg.inv(Lp)
        # posterior in whitened coordinates: W^-1 P W^-T ; eigenvalues near 1 = no information
        Pw = Winv @ cov_s @ Winv.T
        w, V = np.linalg.eigh(0.5 * (Pw + Pw.T))
        for k in range(ne):
            ratio = float(w[k])  # posterior/prior variance along this direction
            if ratio > 1.0 / (1.0 + info_ratio_limit):
                # express the direction in parameter (scaled) coordinates
                vec = Lp @ V[:, k]
                vec = vec / np.linalg.norm(vec)
                combos.append({"combination": _combo(vec, names), "variance_ratio": ratio})
    except np.linalg.LinAlgError:
        pass
    for c in combos:
        warnings.append(
            f"the data do not determine the combination {c['combination']} (scaled coefficients): its posterior "
            f"variance is {100 * c['variance_ratio']:.0f} % of the prior's, so the result along it is the prior"
        )
    prior_sd = np.sqrt(np.diag(prior_cov_s))
    poor = [n for n, s, p in zip(names, sd, prior_sd) if s > 0.5 * p]
    if poor:
        warnings.append(
            "poorly determined (posterior std above half the prior std): " + ", ".join(poor)
        )
    return {
        "correlation": pd.DataFrame(corr, index=names, columns=names),
        "condition_number": cond,
        "correlated_pairs": pairs,
        "poorly_determined": poor,
        "unidentified_combinations": combos,
        "warnings": warnings,
    }
