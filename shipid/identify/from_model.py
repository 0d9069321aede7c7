"""Fit a model to another model's simulated standard manoeuvres (model-to-model identification).

:func:`fit_to_model` fits ``response-nl`` (:class:`~shipid.models.response_nl.ResponseNLModel`) to turning
circles and zigzags simulated with any protocol model (e.g. ``mmg``): an equation-error start on the truth's
exact accelerations, then the identifier's output-error refinement.  It made the default ``response-nl``
parameter set ``"mmg-kcs-fit"``.
"""
from __future__ import annotations

import numpy as np

from ..logs import TrialLog
from ..manoeuvres import ship_info, turning_circle, zigzag
from ..models.base import Model
from ..models.response_nl import ASYM_NAMES, EXTRA_NAMES, SEED_NAMES, ResponseNLModel
from ..simulate import simulate
from .batch import OutputErrorRefiner
from .data import prepare_logs
from .initial import equation_error_fit

__all__ = ["fit_to_model"]


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
    logs, derivs, x0s = [], [], []
    for j, run in enumerate(runs):
        sim = run.simulation
        t, Ub = sim.t[::decimate], sim.u[:, ::decimate]
        Xb = simulate(truth, sim.x[:, 0], t, Ub).x
        for b in range(sim.x.shape[0]):
            X, U = Xb[b], Ub[b]
            logs.append(TrialLog.from_arrays(t, name=f"run{j}_{b}", **dict(zip(model.state_names, X.T)),
                                             **dict(zip(model.input_names, U.T)), consistency_checks=False))
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
                                 jacobian="tangent", input_hold="zoh")
        # zoh: the truth's manoeuvres were simulated with the rudder law evaluated once per output step and
        # held over it, so a held-input replay reproduces them exactly (a real log would use foh)
        ref.fit(logs, x0=x0s)
        p = ref.coef_.to_numpy()
        info.update(cost=(ref.cost_start_, ref.cost_), nfev=ref.nfev_, success=ref.success_, message=ref.message_)
    return ResponseNLModel(p), info
