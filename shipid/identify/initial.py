"""Equation-error start values for the identifier.

Differentiates the measured states with a Savitzky-Golay filter and fits the
model's state equations to the derivatives by (regularised) least squares on
the parameters: one linear solve when the model is linear in its parameters
(the response models), else iterated with the model's analytic or compiled
Jacobians.  Cheap, needs no start value of its own, and puts
the EKF close enough to the answer that its linearisation holds.  Only
equations whose right-hand side depends solely on measured states are used.
"""
from __future__ import annotations

import numpy as np
from scipy.optimize import least_squares
from scipy.signal import savgol_filter

from ..models.base import Model
from .data import LogArrays

__all__ = ["equation_error_fit"]


def _smooth_and_derivative(t: np.ndarray, y: np.ndarray, window_s: float):
    dt = float(np.median(np.diff(t)))
    w = max(5, int(round(window_s / dt)) | 1)
    w = min(w, (y.size - 1) | 1 if y.size % 2 == 0 else y.size)
    if w < 5:
        return y, np.gradient(y, t)
    ys = savgol_filter(y, w, 3, mode="interp")
    dy = savgol_filter(y, w, 3, deriv=1, delta=dt, mode="interp")
    return ys, dy


def equation_error_fit(
    model: Model,
    logs: list[LogArrays],
    meas_names: list[str],
    est_idx: np.ndarray,
    p0: np.ndarray,
    prior_std: np.ndarray,
    window_s: float | None = None,
    max_points: int = 20000,
    derivatives: list[np.ndarray] | None = None,
    regularisation: float = 1e-3,
    max_nfev: int = 50,
    linear="auto",
):
    """Least-squares fit of the estimated parameters to numerical derivatives.

    Parameters
    ----------
    derivatives : list of arrays (N_i, nx), optional
        Known state derivatives of each log (e.g. the exact right-hand side of
        a simulator that produced the log; NaN where unknown).  When given, the
        measured states are used as they are (not smoothed) and these replace
        the Savitzky-Golay derivatives.
    regularisation : float
        Weight of the pull to the start values, relative to ``sqrt(n_points)``
        residuals of unit size (0 turns it off: a plain least-squares fit).
    max_nfev : int
        Iteration limit of the least-squares solver.
    linear : "auto", True or False
        Residuals linear in the parameters (models linear in their parameters, like the response
        models, whose parameter Jacobian is the regressor matrix): solve the regularised linear
        least-squares problem in one step instead of iterating.  ``"auto"`` checks linearity
        numerically (a random step of two prior widths must change the residuals by exactly
        ``J step``, to 1e-9); False always iterates (trust-region reflective, ``max_nfev``).

    Returns
    -------
    theta : (ne,) estimate (``p0[est_idx]`` where the data do not inform it)
    se : (ne,) its standard errors (white-residual approximation; optimistic
        because numerical derivatives are correlated in time)
    used_equations : list of state names whose equations were used
    natural : (ne,) natural scale of each coefficient (NaN when no used equation holds it)
    """
    nx = model.nx
    meas_pos = {s: j for j, s in enumerate(meas_names)}
    if derivatives is not None and len(derivatives) != len(logs):
        raise ValueError(f"derivatives: expected one array per log ({len(logs)}), got {len(derivatives)}")
    rows_t, rows_x, rows_u, rows_dx, rows_ok = [], [], [], [], []
    for k_log, lg in enumerate(logs):
        t = lg.t
        if window_s is None:
            dt = float(np.median(np.diff(t)))
            win = max(10 * dt, 1.0)
        else:
            win = window_s
        X = np.zeros((t.size, nx))
        dX = np.full((t.size, nx), np.nan)
        ok = np.zeros((t.size, nx), dtype=bool)
        for i, s in enumerate(model.state_names):
            if s not in meas_pos:
                continue
            y = lg.Y[:, meas_pos[s]]
            good = np.isfinite(y)
            if good.sum() < 10:
                continue
            yi = np.interp(t, t[good], y[good])
            if derivatives is not None:
                ys, dy = yi, np.asarray(derivatives[k_log], dtype=float)[:, i]
                if not np.all(np.isfinite(dy)):
                    continue
            else:
                ys, dy = _smooth_and_derivative(t, yi, win)
            X[:, i] = ys
            dX[:, i] = dy
            ok[:, i] = True
        rows_t.append(t)
        rows_x.append(X)
        rows_u.append(lg.U)
        rows_dx.append(dX)
        rows_ok.append(ok)
    T = np.concatenate(rows_t)
    X = np.concatenate(rows_x)
    U = np.concatenate(rows_u)
    dX = np.concatenate(rows_dx)
    OK = np.concatenate(rows_ok)
    # thin long data sets; keep it cheap
    if T.size > max_points:
        sel = np.linspace(0, T.size - 1, max_points).astype(int)
        T, X, U, dX, OK = T[sel], X[sel], U[sel], dX[sel], OK[sel]

    # which equations can be used: depend on parameters, and only on measured states
    measured_state = OK.all(axis=0)
    Jx = np.abs(model.jac_x(T[:50], X[:50], U[:50], p0)).max(axis=0)  # (nx, nx)
    # an equation depends on a state wherever its Jacobian entry is non-zero somewhere: the logged samples set an
    # unmeasured state to 0 and may all lie where a term vanishes (a straight approach: no rudder, no sway, no yaw),
    # so the entries are also taken at generic points (a log without v and r had used the surge equation with
    # v = r = 0 and started a1 at 1/200 of its value)
    rng = np.random.default_rng(0)
    Xg = X[:50] + rng.uniform(-1.0, 1.0, X[:50].shape) * (0.1 + np.abs(X[:50]))
    Ug = U[:50] + rng.uniform(-1.0, 1.0, U[:50].shape) * (0.1 + np.abs(U[:50]))
    try:
        with np.errstate(all="ignore"):
            Jg = np.nan_to_num(np.abs(model.jac_x(T[:50], Xg, Ug, p0)), nan=1.0, posinf=1.0).max(axis=0)
        Jx = np.maximum(Jx, Jg)
    except (ValueError, ArithmeticError):  # a model that refuses such a point: the logged samples decide alone
        pass
    Jp = np.abs(model.jac_p(T[:50], X[:50], U[:50], p0)).max(axis=0)  # (nx, np)
    use = [
        i for i in range(nx)
        if measured_state[i] and Jp[i, est_idx].max() > 0 and all(measured_state[j] or Jx[i, j] == 0 for j in range(nx))
    ]
    if not use:
        return p0[est_idx].copy(), np.full(est_idx.size, np.inf), [], np.full(est_idx.size, np.nan)
    w = np.array([1.0 / max(np.std(dX[:, i]), 1e-12) for i in use])
    # natural scale of each coefficient: the size that makes its term as large as the
    # derivative it explains, std(dx_i/dt) / rms(d f_i / d theta_j); used for coefficients
    # that start at zero, where a relative prior means nothing
    Jall = model.jac_p(T, X, U, p0, columns=est_idx)
    natural = np.full(est_idx.size, np.nan)
    for j in range(est_idx.size):
        cands = [np.std(dX[:, i]) / np.sqrt(np.mean(Jall[:, i, j] ** 2)) for i in use
                 if np.any(Jall[:, i, j] != 0)]
        if cands:
            natural[j] = min(cands)
    zero = p0[est_idx] == 0
    prior_std = np.where(zero & np.isfinite(natural), natural, prior_std)

    def resid(theta):
        p = p0.copy()
        p[est_idx] = theta
        f = model.rhs(T, X, U, p)[:, use]
        r = ((dX[:, use] - f) * w).ravel()
        # weak pull to the start values so that collinear directions stay put
        reg = (theta - p0[est_idx]) / prior_std * regularisation * np.sqrt(T.size)
        return np.concatenate([r, reg])

    def jac(theta, Jp_est=None):
        if Jp_est is None:
            p = p0.copy()
            p[est_idx] = theta
            Jp_est = model.jac_p(T, X, U, p, columns=est_idx)
        J = -(Jp_est[:, use] * w[None, :, None]).reshape(-1, est_idx.size)  # (n * nuse, ne)
        return np.vstack([J, np.diag(regularisation * np.sqrt(T.size) / prior_std)])

    th0 = p0[est_idx]
    r0 = resid(th0)
    cost0 = 0.5 * float(np.sum(r0**2))
    # the parameter Jacobian at the start values was computed above (Jall): not again (for mmg it is a
    # complex-step Jacobian over every point and parameter, the cost of this start)
    J0 = jac(th0, Jall)
    if linear is True or (linear == "auto" and _is_linear(resid, J0, th0, prior_std, r0)):
        # residuals linear in theta (e.g. the response models): one regularised linear least-squares
        # solve gives the minimum the iterative solver converges to
        step = np.linalg.lstsq(J0 * prior_std, -r0, rcond=None)[0] * prior_std
        x = th0 + step
        fun = resid(x)
        sol_x, sol_cost, sol_fun, J = x, 0.5 * float(np.sum(fun**2)), fun, J0
    else:
        jac0 = (lambda th: J0 if np.array_equal(th, th0) else jac(th))  # noqa: E731
        sol = least_squares(resid, th0, jac=jac0, x_scale=prior_std, method="trf", max_nfev=max_nfev)
        sol_x, sol_cost, sol_fun, J = sol.x, sol.cost, sol.fun, sol.jac
    if not (np.all(np.isfinite(sol_x)) and np.isfinite(sol_cost) and sol_cost <= cost0):
        # the start values explain the derivatives better: keep them
        return th0.copy(), np.full(est_idx.size, np.inf), [model.state_names[i] for i in use], natural
    dof = max(J.shape[0] - J.shape[1], 1)
    s2 = float(np.sum(sol_fun**2) / dof)
    try:
        se = np.sqrt(np.clip(np.diag(np.linalg.pinv(J.T @ J)) * s2, 0, None))
    except np.linalg.LinAlgError:
        se = np.full(est_idx.size, np.inf)
    return sol_x, se, [model.state_names[i] for i in use], natural


def _is_linear(resid, J, th0, prior_std, r0) -> bool:
    """The residuals are linear in theta: a step of two prior widths in a random direction changes
    them by exactly ``J step`` (to rounding)."""
    step = 2.0 * prior_std * np.random.default_rng(0).uniform(0.5, 1.0, th0.size)
    r1 = resid(th0 + step)
    err = np.max(np.abs(r1 - (r0 + J @ step)))
    return bool(np.isfinite(err) and err <= 1e-9 * max(np.max(np.abs(r1 - r0)), 1e-300))
