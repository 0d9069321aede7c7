"""``response-nl``: the seed-002 response model plus speed-dependent non-linear damping.

The seed's linear sway/yaw equations cannot represent turning circles and
zigzags at once (the yaw damping does not grow with drift and yaw rate, and
does not scale with speed, so a model fitted to zigzags turns far too
tightly or too widely).  This model keeps the 16 seed terms unchanged (same
names, same meaning as ``kcs-response``) and adds, in sway and yaw,

* speed-proportional linear damping ``u v`` (sway, yaw) and ``u r`` (yaw):
  hull forces are ``1/2 rho L d U^2 f(v', r')`` with ``v' = v/U``,
  ``r' = r L/U``, so the linear terms are ``U v`` and ``U r``; the seed has
  only ``b4 u r`` in sway;
* second-order modulus damping ``v|v|`` and ``r|r|`` (cross-flow drag; from
  ``U^2 v'|v'| = v|v|`` these need no speed factor);
* third-order cross terms ``v^2 r / u`` and ``v r^2 / u`` (from
  ``U^2 v'^2 r' = L v^2 r / U``, with U ~ u for the small drift of a ship in
  service; ``u`` is floored at ``u_floor`` = 0.05 m/s to keep the terms finite).

Equations (states ``x, y, psi, u, v, r``; inputs ``delta`` [rad], ``n`` [rps])::

    du/dt = a1 u + a2 v^2 + a3 r^2 + a4 delta^2 + a5 v r + a6 v delta + a7 r delta + a8 u n + a9 n^2
    dv/dt = b1 v + b2 r + b3 delta + b4 u r
            + b5 u v + b6 v|v| + b7 r|r| + b8 v^2 r/u + b9 v r^2/u
    dr/dt = c1 v + c2 r + c3 delta
            + c4 u v + c5 u r + c6 v|v| + c7 r|r| + c8 v^2 r/u + c9 v r^2/u

plus the kinematics of ``kcs-response``.  Linear in the 27 parameters, so
``jac_p`` is the regressor matrix and an equation-error fit is a linear least
squares problem (:func:`fit_to_model`); all Jacobians are analytic.

The default parameter set ``"mmg-kcs-fit"`` was obtained with
:func:`fit_to_model` from the ``mmg`` model's KCS set (recipe and achieved
accuracy in the parameter file and docs/validation.md).
"""
from __future__ import annotations

import numpy as np

from .base import Model
from .kinematics import planar_jacobian, planar_rates

__all__ = ["ResponseNLModel", "RESPONSE_NL_REGRESSORS", "fit_to_model"]

SEED_NAMES = ("a1", "a2", "a3", "a4", "a5", "a6", "a7", "a8", "a9", "b1", "b2", "b3", "b4", "c1", "c2", "c3")
EXTRA_NAMES = ("b5", "b6", "b7", "b8", "b9", "c4", "c5", "c6", "c7", "c8", "c9")

#: Regressor of each coefficient (for tables and identifiability messages).
RESPONSE_NL_REGRESSORS = {
    "a1": "u", "a2": "v^2", "a3": "r^2", "a4": "delta^2", "a5": "v*r", "a6": "v*delta", "a7": "r*delta",
    "a8": "u*n", "a9": "n^2",
    "b1": "v", "b2": "r", "b3": "delta", "b4": "u*r", "b5": "u*v", "b6": "v|v|", "b7": "r|r|",
    "b8": "v^2 r/u", "b9": "v r^2/u",
    "c1": "v", "c2": "r", "c3": "delta", "c4": "u*v", "c5": "u*r", "c6": "v|v|", "c7": "r|r|",
    "c8": "v^2 r/u", "c9": "v r^2/u",
}
# parameter index -> (equation row 3/4/5, regressor position in that row)
_U_IDX = [0, 1, 2, 3, 4, 5, 6, 7, 8]
_V_IDX = [9, 10, 11, 12, 16, 17, 18, 19, 20]          # b1 b2 b3 b4 b5 b6 b7 b8 b9
_R_IDX = [13, 14, 15, 21, 22, 23, 24, 25, 26]         # c1 c2 c3 c4 c5 c6 c7 c8 c9


class ResponseNLModel(Model):
    """Seed-002 response model with speed-dependent non-linear sway/yaw damping (27 coefficients).

    Parameters
    ----------
    params : mapping, array, str or None
        As for every model; default set ``"mmg-kcs-fit"``.  With the eleven
        new coefficients zero the model equals ``kcs-response``.

    Attributes
    ----------
    u_floor : float
        Lower bound [m/s] of ``u`` in the ``1/u`` factors (default 0.05).
    """

    name = "response-nl"
    state_names = ("x", "y", "psi", "u", "v", "r")
    input_names = ("delta", "n")
    param_names = SEED_NAMES + EXTRA_NAMES
    units = {"x": "m", "y": "m", "psi": "rad", "u": "m/s", "v": "m/s", "r": "rad/s", "delta": "rad", "n": "rps",
             "a1": "1/s", "a2": "1/m", "a3": "m", "a4": "m/s^2", "a5": "1", "a6": "1/s", "a7": "m/s", "a8": "1",
             "a9": "m", "b1": "1/s", "b2": "m/s", "b3": "m/s^2", "b4": "1", "c1": "1/(m s)", "c2": "1/s",
             "c3": "1/s^2", "b5": "1/m", "b6": "1/m", "b7": "m", "b8": "1/m", "b9": "m", "c4": "1/m^2",
             "c5": "1/m", "c6": "1/m^2", "c7": "1", "c8": "1/m^2", "c9": "1"}
    default_parameter_set = "mmg-kcs-fit"
    u_floor = 0.05

    # ----------------------------------------------------------- regressors
    def _parts(self, x, u):
        psi, uu, v, r = x[..., 2], x[..., 3], x[..., 4], x[..., 5]
        d, n = u[..., 0], u[..., 1]
        q = 1.0 / np.maximum(uu, self.u_floor)
        return psi, uu, v, r, d, n, q

    def regressors(self, x, u):
        """Regressor arrays of the u, v and r equations, each shape (..., 9) (order of ``_U/_V/_R_IDX``)."""
        x, u = np.asarray(x, dtype=float), np.asarray(u, dtype=float)
        _, uu, v, r, d, n, q = self._parts(x, u)
        shape = np.broadcast_shapes(x.shape[:-1], u.shape[:-1])
        b = lambda a: np.broadcast_to(a, shape)  # noqa: E731
        ru = np.stack([b(a) for a in (uu, v * v, r * r, d * d, v * r, v * d, r * d, uu * n, n * n)], axis=-1)
        common = (v * np.abs(v), r * np.abs(r), v * v * r * q, v * r * r * q)
        rv = np.stack([b(a) for a in (v, r, d, uu * r, uu * v) + common], axis=-1)
        rr = np.stack([b(a) for a in (v, r, d, uu * v, uu * r) + common], axis=-1)
        return ru, rv, rr

    def _rhs(self, t, x, u, p):
        psi, uu, v = x[..., 2], x[..., 3], x[..., 4]
        r = x[..., 5]
        ru, rv, rr = self.regressors(x, u)
        du = np.einsum("...k,...k->...", ru, p[..., _U_IDX])
        dv = np.einsum("...k,...k->...", rv, p[..., _V_IDX])
        dr = np.einsum("...k,...k->...", rr, p[..., _R_IDX])
        out = [*planar_rates(psi, uu, v, r), du, dv, dr]
        shape = np.broadcast_shapes(*[np.shape(o) for o in out])
        return np.stack([np.broadcast_to(o, shape) for o in out], axis=-1)

    # ------------------------------------------------------------- Jacobians
    def _jac_x(self, t, x, u, p):
        psi, uu, v, r, d, n, q = self._parts(x, u)
        dq = np.where(uu > self.u_floor, -q * q, 0.0)
        shape = np.broadcast_shapes(x.shape[:-1], u.shape[:-1], p.shape[:-1])
        J = np.zeros(shape + (6, 6))
        P = lambda name: p[..., self._pi[name]]  # noqa: E731
        planar_jacobian(J, psi, uu, v)
        J[..., 3, 3] = P("a1") + P("a8") * n
        J[..., 3, 4] = 2 * P("a2") * v + P("a5") * r + P("a6") * d
        J[..., 3, 5] = 2 * P("a3") * r + P("a5") * v + P("a7") * d
        # row: (coef of v, r, u*r, u*v, v|v|, r|r|, v^2 r/u, v r^2/u)
        for row, (kv, kr, kur, kuv, kvv, krr, kvvr, kvrr) in (
                (4, ("b1", "b2", "b4", "b5", "b6", "b7", "b8", "b9")),
                (5, ("c1", "c2", "c5", "c4", "c6", "c7", "c8", "c9"))):
            J[..., row, 3] = P(kur) * r + P(kuv) * v + (P(kvvr) * v * v * r + P(kvrr) * v * r * r) * dq
            J[..., row, 4] = P(kv) + P(kuv) * uu + 2 * P(kvv) * np.abs(v) + (2 * P(kvvr) * v * r + P(kvrr) * r * r) * q
            J[..., row, 5] = P(kr) + P(kur) * uu + 2 * P(krr) * np.abs(r) + (P(kvvr) * v * v + 2 * P(kvrr) * v * r) * q
        return J

    def _jac_p(self, t, x, u, p):
        ru, rv, rr = self.regressors(x, u)
        shape = np.broadcast_shapes(x.shape[:-1], u.shape[:-1], p.shape[:-1])
        J = np.zeros(shape + (6, self.np))
        J[..., 3, _U_IDX] = ru
        J[..., 4, _V_IDX] = rv
        J[..., 5, _R_IDX] = rr
        return J

    def _jac_u(self, t, x, u, p):
        psi, uu, v, r, d, n, q = self._parts(x, u)
        shape = np.broadcast_shapes(x.shape[:-1], u.shape[:-1], p.shape[:-1])
        J = np.zeros(shape + (6, 2))
        P = lambda name: p[..., self._pi[name]]  # noqa: E731
        J[..., 3, 0] = 2 * P("a4") * d + P("a6") * v + P("a7") * r
        J[..., 3, 1] = P("a8") * uu + 2 * P("a9") * n
        J[..., 4, 0] = P("b3")
        J[..., 5, 0] = P("c3")
        return J

    _pi = {k: i for i, k in enumerate(SEED_NAMES + EXTRA_NAMES)}


def fit_to_model(truth: Model, *, speeds=(1.4, 1.7, 2.0), turning_rudders=(10.0, 20.0, 35.0),
                 zigzags=(10.0, 20.0), free=None, output_error: bool = True, max_nfev: int = 40,
                 heading_change_deg: float = 400.0, decimate: int = 2, p0=None, verbose: int = 0):
    """Fit ``response-nl`` to manoeuvres simulated with another model (e.g. ``mmg``).

    Recipe: (1) simulate with ``truth`` as one batch each: turning circles at ``turning_rudders`` to both
    sides and zigzags ``z/z`` for ``z`` in ``zigzags``, both sides first, at every approach speed in
    ``speeds`` (steady rps of the truth at each speed); (2) equation-error fit: the truth's exact
    accelerations ``du/dt, dv/dt, dr/dt`` along those trajectories regressed on this model's regressors
    (linear least squares, one equation at a time); (3) if ``output_error``, refine all free coefficients
    with :func:`scipy.optimize.least_squares` on the simulation error of ``u, v, r, psi`` (every
    manoeuvre replayed with the truth's recorded inputs, as one batch; residuals scaled by U0, U0,
    U0/L and 1 rad).

    Parameters
    ----------
    truth : Model  with states x, y, psi, u, v, r and inputs delta, n (and ``lpp``, ``rudder_rate``)
    free : sequence of str, optional  coefficients to fit (others are fixed at 0); default all 27.
        ``free=SEED_NAMES`` fits the seed's 16-term ``kcs-response`` structure.
    decimate : int  use every ``decimate``-th sample of the truth runs
    p0 : mapping or array, optional  start the output-error fit here instead of at the equation-error fit
        (to continue an earlier fit)

    Returns
    -------
    model : ResponseNLModel  with the fitted coefficients
    info : dict  ``equation_error_params``, ``cost`` (initial, final), ``nfev``, ``success``, ``message``,
        ``settings`` (the recipe), ``n_samples``
    """
    from scipy.optimize import least_squares

    from ..manoeuvres import ship_info, turning_circle, zigzag
    from ..simulate import simulate

    model = ResponseNLModel(np.zeros(len(SEED_NAMES + EXTRA_NAMES)))
    names = list(model.param_names)
    free = list(names if free is None else free)
    unknown = sorted(set(free) - set(names))
    if unknown:
        raise ValueError(f"fit_to_model: unknown coefficient(s) {unknown}; response-nl has {names}")
    fidx = np.array([names.index(k) for k in free])
    runs = [turning_circle(truth, list(turning_rudders), speed=list(speeds), side="both",
                           heading_change_deg=heading_change_deg)]
    for z in zigzags:
        runs.append(zigzag(truth, float(z), speed=list(speeds), first="both"))
    # sample sets ----------------------------------------------------------------
    X_list, U_list, T_list = [], [], []
    for run in runs:
        sim = run.simulation
        for b in range(sim.x.shape[0]):
            X_list.append(sim.x[b, ::decimate])
            U_list.append(sim.u[b, ::decimate])
            T_list.append(sim.t[::decimate])
    Xs = np.concatenate(X_list)
    Us = np.concatenate(U_list)
    ok = np.all(np.isfinite(Xs), axis=1) & np.all(np.isfinite(Us), axis=1)
    Xs, Us = Xs[ok], Us[ok]
    acc = truth.rhs(0.0, Xs, Us)[:, 3:]
    ru, rv, rr = model.regressors(Xs, Us)
    p = np.zeros(model.np)
    for k, (R, idx) in enumerate(((ru, _U_IDX), (rv, _V_IDX), (rr, _R_IDX))):
        cols = [j for j, i in enumerate(idx) if i in set(fidx)]
        if not cols:
            continue
        A = R[:, cols]
        sc = np.linalg.norm(A, axis=0)
        sc[sc == 0] = 1.0
        sol = np.linalg.lstsq(A / sc, acc[:, k], rcond=None)[0] / sc
        for c, val in zip(cols, sol):
            p[idx[c]] = val
    if p0 is not None:
        p = ResponseNLModel(p0).params.copy()
    info = {"equation_error_params": dict(zip(names, p.tolist())), "n_samples": int(Xs.shape[0]),
            "settings": {"speeds": list(speeds), "turning_rudders": list(turning_rudders), "zigzags": list(zigzags),
                         "heading_change_deg": heading_change_deg, "decimate": decimate, "free": free,
                         "truth": f"{truth.name}" + (f" lpp={getattr(truth, 'lpp', None)}" if hasattr(truth, "lpp") else "")},
            "success": True, "message": "equation-error fit only", "nfev": 0}
    if output_error:
        L = ship_info(truth)["lpp"]
        U0 = float(np.max(speeds))
        # one batch: pad every run to the longest time grid (members past their end repeat their last input)
        n_t = max(len(t) for t in T_list)
        dt = T_list[0][1] - T_list[0][0]
        t = dt * np.arange(n_t)
        B = len(X_list)
        Xt = np.full((B, n_t, 6), np.nan)
        Ut = np.zeros((B, n_t, 2))
        for b, (Xb, Ub) in enumerate(zip(X_list, U_list)):
            Xt[b, :len(Xb)] = Xb
            Ut[b, :len(Ub)] = Ub
            Ut[b, len(Ub):] = Ub[-1]
        Ut = np.nan_to_num(Ut)
        mask = np.isfinite(Xt[..., 0])
        scale = np.array([U0, U0, U0 / L, 1.0])

        def resid(theta):
            q = p.copy()
            q[fidx] = theta
            with np.errstate(all="ignore"):
                sim = simulate(model, Xt[:, 0], t, Ut, params=q)
            err = (sim.x[..., [3, 4, 5, 2]] - Xt[..., [3, 4, 5, 2]]) / scale
            err = np.where(mask[..., None], err, 0.0)
            err = np.nan_to_num(err, nan=10.0, posinf=10.0, neginf=-10.0)
            return err.ravel() / np.sqrt(mask.sum())

        from ..integrate import rk4_step_tangent

        sel = np.array([3, 4, 5, 2])
        norm = 1.0 / np.sqrt(mask.sum())

        def jac(theta):
            # exact sensitivities of the RK4 map (shipid.integrate.rk4_step_tangent), one batched pass
            q = p.copy()
            q[fidx] = theta
            x = Xt[:, 0].copy()
            S = np.zeros((B, 6, model.np))
            J = np.zeros((B, n_t, 4, fidx.size))
            with np.errstate(all="ignore"):
                for k in range(n_t - 1):
                    x, Fx, Fp = rk4_step_tangent(model, t[k], x, Ut[:, k], q, t[k + 1] - t[k])
                    S = Fx @ S + Fp
                    J[:, k + 1] = S[:, sel][:, :, fidx]
            J = J / scale[None, None, :, None]
            J = np.where(mask[..., None, None], J, 0.0)
            J = np.nan_to_num(J, nan=0.0, posinf=0.0, neginf=0.0)
            return J.reshape(-1, fidx.size) * norm

        r0 = resid(p[fidx])
        sol = least_squares(resid, p[fidx], jac=jac, method="trf", x_scale="jac", max_nfev=max_nfev, verbose=verbose)
        p[fidx] = sol.x
        info.update(cost=(float(0.5 * r0 @ r0), float(sol.cost)), nfev=int(sol.nfev), success=bool(sol.success),
                    message=str(sol.message))
    return ResponseNLModel(p), info
