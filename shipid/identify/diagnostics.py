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
from scipy.special import chdtrc, gammaincinv

from .data import prepare_logs

__all__ = ["identifiability", "consistency", "ljung_box", "CONSISTENCY_RULES"]


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


# --------------------------------------------------------------------------- consistency of a fit
from .verdict import CONSISTENCY_RULES  # noqa: E402 (the rules live with the verdict, on the results floor)


def ljung_box(x_segments, lags: int):
    """Ljung-Box portmanteau statistic of a zero-mean sequence given as segments (gaps between them).

    ``Q = n (n + 2) sum_{l=1}^{L} rho_l^2 / (n - l)`` (Ljung & Box 1978, "On a measure of lack of fit in
    time series models", Biometrika 65:297-303, eq. (2.1) with the sample autocorrelations taken about
    zero: the innovations of a consistent filter have zero mean, so a bias counts as lack of fit).
    ``rho_l = sum x_k x_{k+l} / sum x_k^2`` pools the lag products over the segments (NaN entries, e.g.
    missing or rejected samples, are left out of both sums).

    Returns ``(Q, p_value, rho (L,), n)``; ``p`` from the chi-square distribution with ``L`` degrees of
    freedom (no fitted ARMA terms are subtracted: the innovations are tested as they are).
    """
    num = np.zeros(lags)
    den = 0.0
    n = 0
    for x in x_segments:
        x = np.asarray(x, dtype=float)
        ok = np.isfinite(x)
        xz = np.where(ok, x, 0.0)
        den += float(np.sum(xz * xz))
        n += int(ok.sum())
        for l in range(1, min(lags, x.size - 1) + 1):
            num[l - 1] += float(np.dot(xz[:-l], xz[l:]))
    if n <= lags + 1 or not den > 0:
        return float("nan"), float("nan"), np.full(lags, np.nan), n
    rho = num / den
    Q = float(n * (n + 2) * np.sum(rho**2 / (n - np.arange(1, lags + 1))))
    return Q, float(chdtrc(lags, Q)), rho, n  # chi2.sf(Q, lags), without scipy.stats' per-call overhead


def _finite_or_none(v):
    v = float(v)
    return v if np.isfinite(v) else None


#: Largest fraction of the logged states at which a fitted model's own sway or yaw damping may be positive
#: before :func:`damping_check` calls the model unphysical (a few samples at a transient are tolerated).
DAMPING_FRACTION = 0.01


def damping_states(model, logs, max_points: int = 2000):
    """The logged states and inputs at which :func:`damping_check` evaluates the own damping.

    Up to ``max_points`` samples per log, evenly spaced, aligned as every fit aligns them
    (:func:`shipid.identify.data.prepare_logs`: inputs required, states by name; a state a log lacks counts
    as 0); rows with a non-finite value are left out.  Returns ``(X (N, nx), U (N, nu))``.
    """
    arrays, meas = prepare_logs(model, logs)
    cols = [model.state_index(s) for s in meas]
    X, U = [], []
    for a in arrays:
        n = a.t.size
        idx = np.unique(np.linspace(0, n - 1, min(n, max_points)).astype(int))
        x = np.zeros((idx.size, model.nx))
        x[:, cols] = a.Y[idx]
        x[:, [cols[j] for j in range(len(meas)) if not np.isfinite(a.Y[:, j]).any()]] = 0.0  # not in this log
        ok = np.isfinite(x).all(axis=1) & np.isfinite(a.U[idx]).all(axis=1)
        X.append(x[ok])
        U.append(a.U[idx][ok])
    return np.concatenate(X), np.concatenate(U)


def rest_state(model, logs):
    """The ship at rest, ``(X (1, nx), U (1, nu))``: every state 0, the rudder amidships (every input 0) but the
    propeller rate ``n`` at its median over the logs (the propeller keeps turning when a manoeuvre slows the
    ship down).  Scaling a logged motion's ``u, v, r`` together by ``s`` (the same drift angle and turning
    radius at a lower speed) takes it to this state at ``s = 0``; for a model whose own damping is linear in
    ``s`` (``response-nl``, ``kcs-response``) it is negative along every such slower motion exactly when it is
    at ``s = 1`` (the logged states) and at ``s = 0`` (here).
    """
    X = np.zeros((1, model.nx))
    U = np.zeros((1, model.nu))
    if "n" in model.input_names:
        n = np.concatenate([np.asarray(lg["n"], dtype=float) for lg in logs if "n" in lg.channels] or [np.zeros(0)])
        n = n[np.isfinite(n)]
        U[0, model.input_index("n")] = float(np.median(n)) if n.size else 0.0
    return X, U


def own_damping(model, X, U, params=None):
    """``(d(dv/dt)/dv, d(dr/dt)/dr)`` [1/s] of ``model`` at the states ``X`` (N, nx) and inputs ``U`` (N, nu).

    From the model's analytic state Jacobian.  ``params`` (B, np) evaluates B parameter vectors at once
    (then each array is (B, N)); default the model's own parameters ((N,) each).
    """
    iv, ir = model.state_index("v"), model.state_index("r")
    with np.errstate(all="ignore"):
        if params is None:
            J = model.jac_x(0.0, X, U)
        else:
            J = model.jac_x(0.0, X, U, params=np.asarray(params, dtype=float)[:, None, :])
    return J[..., iv, iv], J[..., ir, ir]


#: Margin of the own-damping constraint of the recipe's refinement, in units of the approach-speed time
#: scale U/L: the constraint asks ``d(dv/dt)/dv * L/U <= -margin`` (and the same for r).  A strict inequality
#: (no state undamped) written as a small fraction of a hull's own damping: the published KVLCC2 MMG set
#: (Yasukawa & Yoshimura 2015) has ``d(dv/dt)/dv * L/U`` of -0.43 to -1.38 and ``d(dr/dt)/dr * L/U`` of -1.59
#: to -3.10 along its own 35 deg turn and 10/10 and 20/20 zigzags (its Jacobian), so 0.02 is at most 5 % (sway)
#: and 1.3 % (yaw) of them.  Set from physics before any fit used it; no score chose it.
DAMPING_MARGIN = 0.02


#: Width of the softened hinge of :func:`damping_penalty`, in units of the margin: the residual is
#: ``w * s * log(1 + exp(z / s))`` for the violation ``z`` (in margins), i.e. ``max(0, z)`` within ``s * log 2``.
PENALTY_SOFTNESS = 0.1


def damping_penalty(model, logs, *, time_scale: float, margin: float = DAMPING_MARGIN, max_points: int = 500,
                    weight: float = 1.0):
    """Residuals that keep the own sway and yaw damping negative along the logged states and at rest.

    Returns ``f(params) -> (B, 2(N+1))`` for parameter vectors ``(B, np)`` (or ``(np,) -> (2(N+1),)``): at
    each of the N logged states of :func:`damping_states` (``max_points`` per log) and at the
    :func:`rest_state`, for v and for r, ``w * max(0, d * time_scale + margin) / margin`` (softened over
    :data:`PENALTY_SOFTNESS` margins); i.e. ~zero where the own damping ``d`` is below ``-margin / time_scale``
    and growing linearly with the violation.  A logged state has ``w = weight / sqrt(2N)`` (violating the
    margin at every one costs ``weight**2 / 2``), the rest state ``w = weight / sqrt(2)`` (as much as all of
    them).  An exterior penalty for
    :class:`shipid.identify.batch.OutputErrorRefiner`'s ``extra_residuals``; ``time_scale`` is L/U [s] of
    the approach speed.
    """
    if not (np.isfinite(time_scale) and time_scale > 0):
        raise ValueError(f"time_scale={time_scale!r}: give L/U in seconds (> 0)")
    if not (np.isfinite(margin) and margin > 0):
        raise ValueError(f"margin={margin!r}: give a positive margin (units of U/L)")
    X, U = damping_states(model, logs, max_points)
    if X.shape[0] == 0:
        raise ValueError("damping_penalty: no logged state with every channel finite")
    X0, U0 = rest_state(model, logs)
    X, U = np.concatenate([X, X0]), np.concatenate([U, U0])
    n = X.shape[0] - 1
    # each logged state weighs 1/(2N), the rest state as much as all of them together
    w = np.full(X.shape[0], float(weight) / np.sqrt(2.0 * n))
    w[-1] = float(weight) / np.sqrt(2.0)
    w = np.concatenate([w, w])

    def f(params):
        P = np.asarray(params, dtype=float)
        dv, dr = own_damping(model, X, U, np.atleast_2d(P))
        z = (np.concatenate([dv, dr], axis=1) * time_scale + margin) / margin
        # a softened hinge max(0, z): softplus of width PENALTY_SOFTNESS (a residual with a continuous
        # derivative, so that the solver's Gauss-Newton model holds across the constraint's edge)
        s = PENALTY_SOFTNESS
        out = w * s * np.logaddexp(0.0, z / s)
        out = np.where(np.isfinite(out), out, 1e6)
        return out if P.ndim == 2 else out[0]

    return f


def damping_check(model, logs, max_points: int = 2000) -> dict:
    """The fitted model's own damping along the logged motions: ``d(dv/dt)/dv`` and ``d(dr/dt)/dr``.

    For a conventional hull both are negative in every state the ship visits (sway and yaw motions are
    damped; a directionally unstable ship is unstable through the sway-yaw coupling, not through a
    positive own damping).  A model whose terms combine to a positive own damping over part of the
    logged states (e.g. a speed-independent term and a speed-proportional one of opposite signs, which
    cancel at the approach speed but not in the slow part of a turn) reproduces the logs with
    self-excited sway or yaw there: it is not a physical model of the ship, whatever its fit.

    Evaluated with the model's analytic Jacobian at the logged states and inputs (:func:`damping_states`,
    up to ``max_points`` samples per log, evenly spaced) and at rest (:func:`rest_state`).  Returns
    ``{"v": {...}, "r": {...}, "rest": {"v": d, "r": d}, "physical": bool, "reasons": [...]}`` with, per
    state, ``fraction_positive``, ``max`` and ``min`` [1/s] and ``n``; ``physical`` is False when a fraction
    exceeds :data:`DAMPING_FRACTION` or the damping at rest is positive.  Models without both v and r
    states return ``{"physical": None}``.
    """
    names = model.state_names
    if "v" not in names or "r" not in names:
        return {"physical": None, "reasons": [], "note": "the model has no v and r states"}
    X, U = damping_states(model, logs, max_points)
    out: dict = {"reasons": [], "threshold": DAMPING_FRACTION}
    if X.shape[0] == 0:
        return {**out, "physical": None, "note": "no logged state with every channel finite"}
    physical = True
    X0, U0 = rest_state(model, logs)
    out["rest"] = {}
    for s, what, d in zip(("v", "r"), ("sway", "yaw"), own_damping(model, X0, U0)):
        d0 = float(d[0])
        out["rest"][s] = _finite_or_none(d0)
        if np.isfinite(d0) and d0 > 0:
            physical = False
            out["reasons"].append(
                f"at rest (u = v = r = 0, rudder amidships, propeller turning) the fitted model's own {what} damping "
                f"d(d{s}/dt)/d{s} is positive ({d0:.3g} 1/s): it makes {what} self-excited when the ship slows down "
                f"(along every logged motion scaled down in speed, for a model whose damping is linear in that scale)")
    for s, what, d in zip(("v", "r"), ("sway", "yaw"), own_damping(model, X, U)):
        d = d[np.isfinite(d)]
        frac = float(np.mean(d > 0)) if d.size else float("nan")
        out[s] = {"fraction_positive": frac, "max": _finite_or_none(d.max()) if d.size else None,
                  "min": _finite_or_none(d.min()) if d.size else None, "n": int(d.size)}
        if d.size and frac > DAMPING_FRACTION:
            physical = False
            out["reasons"].append(
                f"the fitted model's own {what} damping d(d{s}/dt)/d{s} is positive (up to {d.max():.3g} 1/s) at "
                f"{100 * frac:.1f} % of the logged states: the model makes {what} self-excited there, which no "
                f"conventional hull does; its coefficients trade against each other (see the correlation "
                f"warnings) -- refine with the own-damping constraint (shipid fit's default, "
                f"physical_damping=True) or fix the offending terms")
    out["physical"] = physical
    return out


def consistency(names, innov, S_diag, gated, segments, replay_ratio=None, dynamic=(), rules=None,
                extra_reasons=()) -> dict:
    """Is the fit consistent with its own noise model?  Per channel and as one verdict.

    Parameters
    ----------
    names : list of str  measured channels
    innov, S_diag : (N, nm)  innovations and their predicted variances (one filter run, logs concatenated)
    gated : (N, nm) bool  measurements rejected by the innovation gate
    segments : list of slice  the samples of each log (autocorrelations do not cross logs)
    replay_ratio : dict channel -> float, optional  RMS of (replay - measurement) / meas_std over all logs
    dynamic : channels whose replay ratio enters the verdict (those with estimated parameters in their
        equations; positions and heading integrate and drift in an open-loop replay)
    rules : dict, optional  overrides of :data:`CONSISTENCY_RULES`
    extra_reasons : further findings that make the fit inconsistent

    Returns
    -------
    dict with ``channels`` (name -> statistics), ``consistent`` (bool), ``reasons`` (list of str),
    ``rules``.  Statistics per channel: ``n`` accepted samples, ``nis_mean`` (expected 1) and
    ``nis_band`` (its two-sided ``1 - alpha`` chi-square band for ``n_eff`` samples), ``n_eff``
    (``n / (1 + 2 sum rho_l^2)``: squares of correlated Gaussians are correlated by ``rho^2``),
    ``mean`` (normalised innovation, expected 0), ``ljung_box`` / ``ljung_box_p`` / ``rho_max``
    (largest |autocorrelation| over the lags), ``replay_ratio``, ``n_gated``, ``gated_fraction``.
    Non-finite values are None (the JSON stays strict).
    """
    # chi2.ppf(q, df) is 2 gammaincinv(df / 2, q) (scipy.stats' own formula; called directly, ~30x cheaper)
    chi2_ppf = lambda q, df: 2.0 * gammaincinv(df / 2.0, q)  # noqa: E731
    r = dict(CONSISTENCY_RULES)
    r.update(rules or {})
    alpha = r["alpha"]
    out_ch, reasons = {}, []
    for j, name in enumerate(names):
        acc = np.isfinite(innov[:, j]) & ~gated[:, j] & (S_diag[:, j] > 0)
        nu = np.where(acc, innov[:, j] / np.sqrt(np.where(acc, S_diag[:, j], 1.0)), np.nan)
        n = int(acc.sum())
        n_meas = int((np.isfinite(innov[:, j])).sum())
        n_g = int(gated[:, j].sum())
        row = {"n": n, "n_gated": n_g, "gated_fraction": n_g / n_meas if n_meas else 0.0}
        if n < 10:
            row.update(nis_mean=None, nis_band=None, n_eff=None, mean=None, ljung_box=None, ljung_box_p=None,
                       rho_max=None)
        else:
            lags = int(min(r["lb_lags"], max(1, n // 10)))
            Q, p, rho, _ = ljung_box([nu[s] for s in segments], lags)
            rho_f = np.where(np.isfinite(rho), rho, 0.0)
            n_eff = n / (1.0 + 2.0 * float(np.sum(rho_f**2)))
            m = float(np.nanmean(nu**2))
            band = (float(chi2_ppf(alpha / 2, n_eff) / n_eff), float(chi2_ppf(1 - alpha / 2, n_eff) / n_eff))
            row.update(nis_mean=m, nis_band=list(band), n_eff=n_eff, mean=float(np.nanmean(nu)), ljung_box=Q,
                       ljung_box_p=p, rho_max=float(np.max(np.abs(rho_f))), lags=lags)
            f = r["nis_factor"]
            if not band[0] <= m <= band[1] and not 1.0 / f <= m <= f:
                what = "larger" if m > 1 else "smaller"
                reasons.append(f"channel '{name}': innovations {what} than the noise model predicts "
                               f"(mean normalised innovation {m:.3g}, expected 1, band {band[0]:.2f}-{band[1]:.2f})")
            if p < alpha and row["rho_max"] > r["rho_limit"]:
                reasons.append(f"channel '{name}': innovations are not white (Ljung-Box Q = {Q:.4g} over {lags} lags, "
                               f"p = {p:.2g}, largest autocorrelation {row['rho_max']:.2f})")
        if n_meas and row["gated_fraction"] > r["gated_fraction"]:
            reasons.append(f"channel '{name}': {100 * row['gated_fraction']:.1f} % of its measurements were rejected "
                           "as outliers by the innovation gate")
        rr = None if replay_ratio is None else replay_ratio.get(name)
        row["replay_ratio"] = None if rr is None else _finite_or_none(rr)
        if name in dynamic and rr is not None:
            if not np.isfinite(rr):
                reasons.append(f"channel '{name}': the replay of the fitted model failed (non-finite)")
            elif rr > r["replay_factor"]:
                reasons.append(f"channel '{name}': the replayed model misses the measurements by {rr:.3g} noise "
                               f"std (RMS), more than {r['replay_factor']:g}")
        out_ch[name] = {k: (_finite_or_none(v) if isinstance(v, (float, np.floating)) else v) for k, v in row.items()}
    reasons += list(extra_reasons)
    return {"consistent": not reasons, "reasons": reasons, "channels": out_ch, "rules": r}
