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
  service; ``u`` is floored at ``u_floor`` = 0.05 m/s to keep the terms finite);
* a propeller-induced side force and yaw moment ``b0 n^2``, ``c0 n^2``: a
  single-screw ship is not port/starboard symmetric (the rotating propeller
  and its slipstream load the hull and the rudder asymmetrically, so the
  rudder angle for a straight course is not zero and the turns to the two
  sides differ; e.g. the measured KVLCC2 tactical diameters of 3.07 L and
  3.33 L).  The force scales with the thrust, i.e. with ``n^2`` at a given
  advance ratio.  It is the response-model image of a rudder neutral angle
  ``delta_0`` (``c3 (delta - delta_0) = c3 delta - c3 delta_0``) scaled with
  the propeller loading; :class:`~shipid.models.mmg.MMGModel` carries the
  same effect as its parameter ``delta0``.  Zero in the default set (which
  was fitted before these two terms existed).

Equations (states ``x, y, psi, u, v, r``; inputs ``delta`` [rad], ``n`` [rps])::

    du/dt = a1 u + a2 v^2 + a3 r^2 + a4 delta^2 + a5 v r + a6 v delta + a7 r delta + a8 u n + a9 n^2
    dv/dt = b1 v + b2 r + b3 delta + b4 u r
            + b5 u v + b6 v|v| + b7 r|r| + b8 v^2 r/u + b9 v r^2/u + b0 n^2
    dr/dt = c1 v + c2 r + c3 delta
            + c4 u v + c5 u r + c6 v|v| + c7 r|r| + c8 v^2 r/u + c9 v r^2/u + c0 n^2

plus the kinematics of ``kcs-response``.  Linear in the 29 parameters, so
``jac_p`` is the regressor matrix and an equation-error fit is a linear least
squares problem (:func:`fit_to_model`); all Jacobians are analytic.

The default parameter set ``"mmg-kcs-fit"`` was obtained with
:func:`fit_to_model` from the ``mmg`` model's KCS set (recipe and achieved
accuracy in the parameter file and docs/validation.md).
"""
from __future__ import annotations

import numpy as np

from .._jit import rebind
from . import _response_equations as _req
from .base import Model, batch_shape
from .response import _rows

__all__ = ["ResponseNLModel", "RESPONSE_NL_REGRESSORS", "PRIME_EXPONENTS", "fit_to_model", "ASYM_NAMES"]

G = 9.80665  # m/s^2, standard gravity (Froude non-dimensionalisation)

SEED_NAMES = ("a1", "a2", "a3", "a4", "a5", "a6", "a7", "a8", "a9", "b1", "b2", "b3", "b4", "c1", "c2", "c3")
EXTRA_NAMES = ("b5", "b6", "b7", "b8", "b9", "c4", "c5", "c6", "c7", "c8", "c9")
#: Propeller-induced port/starboard asymmetry (regressor n^2), appended after the symmetric terms.
ASYM_NAMES = ("b0", "c0")

#: Regressor of each coefficient (for tables and identifiability messages).
RESPONSE_NL_REGRESSORS = {
    "a1": "u", "a2": "v^2", "a3": "r^2", "a4": "delta^2", "a5": "v*r", "a6": "v*delta", "a7": "r*delta",
    "a8": "u*n", "a9": "n^2",
    "b1": "v", "b2": "r", "b3": "delta", "b4": "u*r", "b5": "u*v", "b6": "v|v|", "b7": "r|r|",
    "b8": "v^2 r/u", "b9": "v r^2/u",
    "c1": "v", "c2": "r", "c3": "delta", "c4": "u*v", "c5": "u*r", "c6": "v|v|", "c7": "r|r|",
    "c8": "v^2 r/u", "c9": "v r^2/u", "b0": "n^2", "c0": "n^2",
}
#: SI dimension of each coefficient as exponents (metre, second); rps counts as 1/s.  The prime
#: (Froude non-dimensional) value is ``c' = c / (L^a (L/g)^(b/2))`` for ``c`` in m^a s^b, so under
#: Froude scaling to ``lam`` times the length a coefficient scales by ``lam^(a + b/2)``.
PRIME_EXPONENTS = {
    "a1": (0, -1), "a2": (-1, 0), "a3": (1, 0), "a4": (1, -2), "a5": (0, 0), "a6": (0, -1), "a7": (1, -1),
    "a8": (0, 0), "a9": (1, 0),
    "b1": (0, -1), "b2": (1, -1), "b3": (1, -2), "b4": (0, 0), "b5": (-1, 0), "b6": (-1, 0), "b7": (1, 0),
    "b8": (0, 0), "b9": (1, 0), "b0": (1, 0),
    "c1": (-1, -1), "c2": (0, -1), "c3": (0, -2), "c4": (-2, 0), "c5": (-1, 0), "c6": (-2, 0), "c7": (0, 0),
    "c8": (-1, 0), "c9": (0, 0), "c0": (0, 0),
}
# parameter index -> (equation row 3/4/5, regressor position in that row)
_U_IDX = [0, 1, 2, 3, 4, 5, 6, 7, 8]
_V_IDX = [9, 10, 11, 12, 16, 17, 18, 19, 20, 27]      # b1 b2 b3 b4 b5 b6 b7 b8 b9 b0
_R_IDX = [13, 14, 15, 21, 22, 23, 24, 25, 26, 28]     # c1 c2 c3 c4 c5 c6 c7 c8 c9 c0

#: The equations (one copy, :mod:`._response_equations`) on numpy arrays.
_EQ = rebind(_req.FUNCTIONS, _req.NUMPY)
_POS = {"x": _req.NL_JX_POS, "p": _req.NL_JP_POS, "u": _req.NL_JU_POS}


class ResponseNLModel(Model):
    """Seed-002 response model with speed-dependent non-linear sway/yaw damping (29 coefficients).

    The coefficients are dimensional (SI, as ``kcs-response``) and belong to a
    ship of length ``lpp``; :meth:`to_prime`/:meth:`from_prime` convert them
    to and from the Froude-non-dimensional (prime) system, and
    :meth:`scaled` gives the geometrically similar ship of another length
    (times x sqrt(lam), positions x lam for ``lam = L_new/L``; see
    :mod:`shipid.scaling`).

    Parameters
    ----------
    params : mapping, array, str or None
        As for every model; default set ``"mmg-kcs-fit"``.  With the thirteen
        new coefficients zero the model equals ``kcs-response``.
    lpp : float, optional
        Length [m] of the ship the model describes.  A named parameter set
        (or the default) is Froude-scaled from its own length (its
        ``operating_point``) to ``lpp``; coefficients given as a mapping or
        array are taken as they are (they already belong to that ship).

    Attributes
    ----------
    lpp, design_speed, rudder_rate : float or None
        Ship length [m], approach speed [m/s], steering rate [rad/s] (those of
        a named set, Froude-scaled; None when unknown).
    u_floor : float
        Lower bound [m/s] of ``u`` in the ``1/u`` factors (default 0.05).
    """

    name = "response-nl"
    state_names = ("x", "y", "psi", "u", "v", "r")
    input_names = ("delta", "n")
    param_names = SEED_NAMES + EXTRA_NAMES + ASYM_NAMES
    units = {"x": "m", "y": "m", "psi": "rad", "u": "m/s", "v": "m/s", "r": "rad/s", "delta": "rad", "n": "rps",
             "a1": "1/s", "a2": "1/m", "a3": "m", "a4": "m/s^2", "a5": "1", "a6": "1/s", "a7": "m/s", "a8": "1",
             "a9": "m", "b1": "1/s", "b2": "m/s", "b3": "m/s^2", "b4": "1", "c1": "1/(m s)", "c2": "1/s",
             "c3": "1/s^2", "b5": "1/m", "b6": "1/m", "b7": "m", "b8": "1", "b9": "m", "c4": "1/m^2",
             "c5": "1/m", "c6": "1/m^2", "c7": "1", "c8": "1/m", "c9": "1", "b0": "m", "c0": "1"}
    default_parameter_set = "mmg-kcs-fit"
    u_floor = 0.05

    def __init__(self, params=None, *, lpp: float | None = None):
        super().__init__(params)
        self.lpp = self.design_speed = self.rudder_rate = None
        if params is None or isinstance(params, str):
            op = self.parameter_set(params or self.default_parameter_set).extra.get("operating_point", {})
            if "lpp_m" in op:
                self.lpp = float(op["lpp_m"])
                self.design_speed = float(op["u0_m_s"]) if "u0_m_s" in op else None
                self.rudder_rate = float(np.radians(op["rudder_rate_deg_s"])) if "rudder_rate_deg_s" in op else None
                if lpp is not None:
                    scaled = self.scaled(lpp)
                    self.params, self.lpp = scaled.params, scaled.lpp
                    self.design_speed, self.rudder_rate = scaled.design_speed, scaled.rudder_rate
                return
        if lpp is not None:
            if not float(lpp) > 0:
                raise ValueError(f"response-nl: lpp must be a positive length in metres, got {lpp}")
            self.lpp = float(lpp)

    def options(self) -> dict:
        """The ship length travels with fit results (``get_model("response-nl", coef, lpp=...)``)."""
        return {} if self.lpp is None else {"lpp": self.lpp}

    # ------------------------------------------------------- prime system
    def _length(self, lpp):
        L = self.lpp if lpp is None else float(lpp)
        if L is None or not L > 0:
            raise ValueError("response-nl: the ship length is unknown; pass lpp= (metres) to the model or here")
        return L

    def to_prime(self, lpp: float | None = None) -> dict:
        """Froude-non-dimensional coefficients ``c / (L^a (L/g)^(b/2))`` (:data:`PRIME_EXPONENTS`)."""
        L = self._length(lpp)
        return {k: float(v / (L ** PRIME_EXPONENTS[k][0] * (L / G) ** (PRIME_EXPONENTS[k][1] / 2)))
                for k, v in zip(self.param_names, self.params)}

    @classmethod
    def from_prime(cls, prime, lpp: float) -> "ResponseNLModel":
        """The model of a ship of length ``lpp`` [m] from prime coefficients (missing ones are 0)."""
        unknown = sorted(set(prime) - set(cls.param_names))
        if unknown:
            raise ValueError(f"response-nl: unknown prime coefficient(s) {unknown}")
        L = float(lpp)
        if not L > 0:
            raise ValueError(f"response-nl: lpp must be a positive length in metres, got {lpp}")
        vals = np.array([float(prime.get(k, 0.0)) * L ** PRIME_EXPONENTS[k][0]
                         * (L / G) ** (PRIME_EXPONENTS[k][1] / 2) for k in cls.param_names])
        return cls(vals, lpp=L)

    def scaled(self, lpp_new: float) -> "ResponseNLModel":
        """The Froude-similar model of the geometrically similar ship of length ``lpp_new`` [m]."""
        new = self.from_prime(self.to_prime(), lpp_new)
        lam = new.lpp / self._length(None)
        new.design_speed = None if self.design_speed is None else self.design_speed * np.sqrt(lam)
        new.rudder_rate = None if self.rudder_rate is None else self.rudder_rate / np.sqrt(lam)
        return new

    # ----------------------------------------------------------- regressors
    def regressors(self, x, u):
        """Regressor arrays of the u, v and r equations, shapes (..., 9), (..., 10), (..., 10)
        (order of ``_U/_V/_R_IDX``)."""
        x, u = np.asarray(x, dtype=float), np.asarray(u, dtype=float)
        g = np.stack(np.broadcast_arrays(*_EQ["nl_regressors"](x[..., 3], x[..., 4], x[..., 5], u[..., 0], u[..., 1],
                                                                self.u_floor)), axis=-1)
        return g[..., :9], g[..., 9:19], g[..., 19:]

    def _rhs(self, t, x, u, p):
        out = _EQ["nl_rates"](x[..., 2], x[..., 3], x[..., 4], x[..., 5], u[..., 0], u[..., 1], _rows(p),
                              self.u_floor)
        return np.stack(np.broadcast_arrays(*out), axis=-1)

    # ------------------------------------------------------------- Jacobians
    def _jacobian(self, x, u, p, which: str, ncol: int):
        """Jacobian ``which`` ("x", "p", "u") from the entries of ``_response_equations.nl_jac_*``."""
        vals = _EQ["nl_jac_" + which](x[..., 2], x[..., 3], x[..., 4], x[..., 5], u[..., 0], u[..., 1], _rows(p),
                                      self.u_floor)
        return _req.fill_numpy(batch_shape(x, u, p) + (6, ncol), _POS[which], vals)

    def _jac_x(self, t, x, u, p):
        return self._jacobian(x, u, p, "x", 6)

    def _jac_p(self, t, x, u, p):
        return self._jacobian(x, u, p, "p", self.np)

    def _jac_u(self, t, x, u, p):
        return self._jacobian(x, u, p, "u", 2)

    # the compiled EKF kernel (shipid.identify._kernel) uses the same equations
    _equations = _req.KERNEL_NL

    def _kernel_constants(self) -> np.ndarray:
        return np.array([self.u_floor])

    _pi = {k: i for i, k in enumerate(SEED_NAMES + EXTRA_NAMES + ASYM_NAMES)}


def fit_to_model(truth: Model, *, speeds=(1.4, 1.7, 2.0), turning_rudders=(10.0, 20.0, 35.0),
                 zigzags=(10.0, 20.0), free=None, output_error: bool = True, max_nfev: int = 40,
                 heading_change_deg: float = 400.0, decimate: int = 2, p0=None):
    """Fit ``response-nl`` to manoeuvres simulated with another model (e.g. ``mmg``).

    Recipe: (1) simulate with ``truth`` as one batch each: turning circles at ``turning_rudders`` to both
    sides and zigzags ``z/z`` for ``z`` in ``zigzags``, both sides first, at every approach speed in
    ``speeds`` (steady rps of the truth at each speed); (2) equation-error fit
    (:func:`shipid.identify.initial.equation_error_fit` given the truth's exact accelerations
    ``du/dt, dv/dt, dr/dt`` along those trajectories, no regularisation: a least-squares fit on this
    model's regressors); (3) if ``output_error``, refine all free coefficients with the identifier's
    :class:`~shipid.identify.batch.OutputErrorRefiner` on the simulation error of ``u, v, r, psi``
    (every manoeuvre replayed from its exact initial state with the truth's recorded inputs; runs on
    one time grid as one batch; exact RK4 tangent sensitivities; residuals scaled by U0, U0, U0/L and
    1 rad, ``U0 = max(speeds)``).

    Parameters
    ----------
    truth : Model  with states x, y, psi, u, v, r and inputs delta, n (and ``lpp``, ``rudder_rate``)
    free : sequence of str, optional  coefficients to fit (others are fixed at 0); default all 29.
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
    from ..identify.batch import OutputErrorRefiner
    from ..identify.data import prepare_logs
    from ..identify.initial import equation_error_fit
    from ..logs import TrialLog
    from ..manoeuvres import ship_info, turning_circle, zigzag

    model = ResponseNLModel(np.zeros(len(SEED_NAMES + EXTRA_NAMES + ASYM_NAMES)))
    names = list(model.param_names)
    free = list(names if free is None else free)
    unknown = sorted(set(free) - set(names))
    if unknown:
        raise ValueError(f"fit_to_model: unknown coefficient(s) {unknown}; response-nl has {names}")
    free = [k for k in names if k in free]
    fidx = np.array([names.index(k) for k in free])
    runs = [turning_circle(truth, list(turning_rudders), speed=list(speeds), side="both",
                           heading_change_deg=heading_change_deg)]
    for z in zigzags:
        runs.append(zigzag(truth, float(z), speed=list(speeds), first="both"))
    # the truth runs as logs (all six states measured exactly), their exact derivatives and initial states;
    # the inputs are sampled every `decimate` steps and held over each interval (the identifier's input
    # model), and the truth is re-run with exactly those inputs, so a perfect fit reproduces the logs
    from ..simulate import simulate

    logs, derivs, x0s = [], [], []
    for j, run in enumerate(runs):
        sim = run.simulation
        t, Ub = sim.t[::decimate], sim.u[:, ::decimate]
        Xb = simulate(truth, sim.x[:, 0], t, Ub).x
        for b in range(sim.x.shape[0]):
            X, U = Xb[b], Ub[b]
            logs.append(TrialLog.from_arrays(t, name=f"run{j}_{b}", **dict(zip(model.state_names, X.T)),
                                             **dict(zip(model.input_names, U.T))))
            derivs.append(truth.rhs(t, X, U))
            x0s.append(X[0])
    arrays, meas = prepare_logs(model, logs)
    n_samples = int(sum(a.t.size for a in arrays))
    p = np.zeros(model.np)
    theta, _, _, _ = equation_error_fit(model, arrays, meas, fidx, p, np.ones(fidx.size), derivatives=derivs,
                                        regularisation=0.0, max_points=max(n_samples, 1), max_nfev=100)
    p[fidx] = theta
    if p0 is not None:
        p = ResponseNLModel(p0).params.copy()
    info = {"equation_error_params": dict(zip(names, p.tolist())), "n_samples": n_samples,
            "settings": {"speeds": list(speeds), "turning_rudders": list(turning_rudders), "zigzags": list(zigzags),
                         "heading_change_deg": heading_change_deg, "decimate": decimate, "free": free,
                         "truth": f"{truth.name}" + (f" lpp={getattr(truth, 'lpp', None)}" if hasattr(truth, "lpp") else "")},
            "success": True, "message": "equation-error fit only", "nfev": 0}
    if output_error:
        L = ship_info(truth)["lpp"]
        U0 = float(np.max(speeds))
        ref = OutputErrorRefiner(model.with_params(p), estimate=free, channels=["u", "v", "r", "psi"],
                                 meas_std={"u": U0, "v": U0, "r": U0 / L, "psi": 1.0}, max_nfev=max_nfev,
                                 jacobian="tangent")
        ref.fit(logs, x0=x0s)
        p = ref.coef_.to_numpy()
        info.update(cost=(ref.cost_start_, ref.cost_), nfev=ref.nfev_, success=ref.success_, message=ref.message_)
    return ResponseNLModel(p), info
