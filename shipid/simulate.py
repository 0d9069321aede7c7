"""Integrate a protocol model under an input schedule or a feedback law.

``shipid.simulate`` is this module, and calling it calls :func:`simulate`: ``shipid.simulate(model,
x0, t, U)`` and ``shipid.simulate.simulate(model, x0, t, U)`` are the same call, and
``shipid.simulate.replay`` is reachable as documented.  (The package exports the module rather than
the function so that the function's name does not hide the module's other tools.)

:func:`simulate` is the single forward simulator of the package, vectorised
over a leading batch axis, with inputs given as samples on the time grid
(held between samples, or linear between them with ``input_hold="foh"``, as
:func:`replay` does by default), as a callable ``controller(t, x) -> u``
for state feedback (held over each step), or as an :class:`InputLaw` (inputs
as a function of time with located events: the standard manoeuvres' rudder
laws).  Two integrators:

* ``method="rk4"`` (default): fixed-step RK4, the same map the EKF uses
  (:mod:`shipid.integrate`);
* ``method="dopri5"``: the embedded Dormand-Prince 5(4) pair with error
  control (:func:`shipid.integrate.dopri5`), one shared step for the batch,
  outputs on ``t`` from its dense output -- far fewer steps at equal accuracy.
"""
from __future__ import annotations

import sys
import types
import warnings
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
import pandas as pd

from ._kernel import replay_compiled
from .integrate import dopri5, hold_steps, interval_steps, rk4_map
from .models.base import Model
from .results import ResultMixin, axes_column, in_degrees, plot_series

__all__ = ["simulate", "SimulationResult", "InputLaw", "replay", "replay_errors", "METHODS", "INPUT_HOLDS"]

#: Integrators of :func:`simulate`.
METHODS = ("rk4", "dopri5")
#: Holds of sampled inputs between samples: first-order (linear) and zero-order (held).
INPUT_HOLDS = ("foh", "zoh")


class InputLaw:
    """Inputs as a function of time, with optional state events (base class).

    Subclasses implement :meth:`inputs`; laws that switch on the state (a zigzag's rudder reversal)
    also set ``has_events = True`` and implement :meth:`event` and :meth:`on_event`.  :func:`simulate`
    evaluates :meth:`inputs` at every stage (``dopri5``) or at the middle of each step (``rk4``, held
    over the step), steps onto :attr:`stops` exactly, and locates events within a step (the step is
    split at the event), so switching happens at the crossing, not at the next step start.

    :meth:`inputs` must give the value *at time t* for any ``t`` up to the current time (history is
    kept by the law), so that the recorded inputs of a result are the ones that acted.
    """

    #: Times [s] where the inputs have kinks (known in advance; the inputs must be continuous in time).
    stops: tuple = ()
    has_events: bool = False

    def inputs(self, t: float, x: np.ndarray) -> np.ndarray:
        """Inputs ``(..., nu)`` at time ``t`` [s] for states ``x (..., nx)``."""
        raise NotImplementedError

    def event(self, t, x: np.ndarray) -> np.ndarray:
        """Event functions ``(...)``: an event is a crossing from negative to >= 0.  While an event is
        located, ``t`` is an array of per-member times (shape ``(...)``)."""
        raise NotImplementedError

    def on_event(self, t: float, x: np.ndarray, mask: np.ndarray) -> None:
        """Called at an event with the members (``mask``) whose event function crossed zero."""
        raise NotImplementedError

    def input_history(self, t: np.ndarray, x: np.ndarray) -> np.ndarray:
        """Inputs ``(..., n_t, nu)`` that acted at the times ``t (n_t,)`` with states ``x (..., n_t, nx)``
        (after the run; subclasses vectorise this)."""
        return np.stack([self.inputs(tk, x[..., k, :]) for k, tk in enumerate(t)], axis=-2)

    def __call__(self, t, x):
        return self.inputs(t, x)


@dataclass
class SimulationResult(ResultMixin):
    """Result of :func:`simulate` (and of :func:`replay`, which also keeps the measured log).

    Attributes
    ----------
    t : ndarray, shape (n_t,)
    x : ndarray, shape (n_t, nx) or (B, n_t, nx) for a batch
    u : ndarray, shape (n_t, nu) or (B, n_t, nu)
    model : Model
    success : bool
        False when the state became non-finite; ``x`` is NaN from there on.  In a batch the other
        members are integrated to the end (``rk4``: in the same run; open-loop ``dopri5``: a batch whose
        shared-step run fails is integrated member by member, ``meta["per_member"]``);
        ``meta["failed"]`` lists the failed members and ``meta["failed_at"]`` their failure times [s].
    message : str
    measured : DataFrame or None
        The log a :func:`replay` reproduces (``time`` and its channels); drawn under the simulation by
        :meth:`plot` and compared in :meth:`summary`.
    """

    t: np.ndarray
    x: np.ndarray
    u: np.ndarray
    model: Model
    params: np.ndarray
    success: bool = True
    message: str = "integration finished"
    meta: dict = field(default_factory=dict)
    measured: pd.DataFrame | None = field(default=None, repr=False)

    @property
    def batched(self) -> bool:
        return self.x.ndim == 3

    def state(self, name: str) -> np.ndarray:
        """Time history of one state, shape (n_t,) or (B, n_t)."""
        return self.x[..., self.model.state_index(name)]

    def input(self, name: str) -> np.ndarray:
        """Time history of one input."""
        return self.u[..., self.model.input_index(name)]

    def to_pandas(self, member: int | None = None) -> pd.DataFrame:
        """States and inputs as a frame indexed by time (one batch member)."""
        x, u = self.x, self.u
        if self.batched:
            if member is None:
                raise ValueError("batched result: pass member=i to choose one simulation")
            x, u = x[member], u[member]
        cols = {n: x[:, i] for i, n in enumerate(self.model.state_names)}
        cols.update({n: u[:, i] for i, n in enumerate(self.model.input_names)})
        return pd.DataFrame(cols, index=pd.Index(self.t, name="time"))

    def summary(self) -> pd.DataFrame:
        """Per state and input (angles in degrees): unit, start, end, min and max of the run (of every
        member of a batch, index ``(member, channel)``); a replay adds the ``rmse`` against the log
        (:func:`replay_errors`, in the same display units) and the track row."""
        units = self.model.units
        names = list(self.model.state_names) + list(self.model.input_names)
        data = np.concatenate([self.x, self.u], axis=-1)
        members = range(data.shape[0]) if self.batched else [None]
        rows, index = [], []
        for b in members:
            d = data[b] if b is not None else data
            for j, n in enumerate(names):
                col, unit = in_degrees(d[:, j], units.get(n, ""))
                fin = col[np.isfinite(col)]
                rows.append({"unit": unit, "start": col[0], "end": col[-1],
                             "min": fin.min() if fin.size else np.nan, "max": fin.max() if fin.size else np.nan})
                index.append(n if b is None else (b, n))
        out = pd.DataFrame(rows, index=pd.MultiIndex.from_tuples(index, names=["member", "channel"])
                           if self.batched else pd.Index(index, name="channel"))
        if self.measured is not None and not self.batched:
            err = replay_errors(self, self.measured)
            out["rmse"] = [float(in_degrees(err.loc[n, "rmse"], units.get(n, ""))[0]) if n in err.index else np.nan
                           for n in out.index]
            if "track" in err.index:
                out.loc["track", ["unit", "rmse"]] = ["m", float(err.loc["track", "rmse"])]
        return out

    def _key_numbers(self) -> dict:
        k = {"model": self.model.name, "duration [s]": float(self.t[-1] - self.t[0]) if self.t.size else 0.0,
             "samples": int(self.t.size)}
        if self.batched:
            k["members"] = int(self.x.shape[0])
        return k

    def _html_title(self) -> str:
        return "Replay" if self.measured is not None else "Simulation"

    def plot(self, ax=None, member: int | None = 0):
        """Plot states and inputs against time (one axes each, angles in degrees); a replay draws the
        measured log under the simulation.  ``member`` picks one run of a batch.  Returns the axes."""
        df = self.to_pandas(member if self.batched else None)
        names = list(self.model.state_names) + list(self.model.input_names)
        axs = axes_column(ax, len(names))
        if self.measured is not None:
            m = self.measured
            plot_series(axs, m["time"].to_numpy(), m, list(self.model.state_names), self.model.units,
                        color="0.55", lw=1.2, label="measured")
        plot_series(axs, df.index.to_numpy(), df, names, self.model.units, color="C0", lw=0.9,
                    label="simulated" if self.measured is not None else None)
        if self.measured is not None:
            axs[0].legend(loc="best", fontsize="small")
        axs[-1].set_xlabel("time [s]")
        return axs


def simulate(
    model: Model,
    x0,
    t,
    inputs=None,
    *,
    controller: Callable | InputLaw | None = None,
    params=None,
    substeps: int = 1,
    method: str = "rk4",
    rtol: float = 1e-6,
    atol=None,
    first_step: float | None = None,
    input_hold: str = "zoh",
    h_max: float | None = None,
) -> SimulationResult:
    """Integrate ``model`` from ``x0`` over the time grid ``t``.

    Parameters
    ----------
    model : Model
    x0 : array, shape (nx,) or (B, nx)
        Initial state; a 2-D array runs a batch of B simulations at once.
    t : array, shape (n_t,)
        Strictly increasing output times [s]; steps may be non-uniform.
    inputs : array, shape (n_t, nu) or (B, n_t, nu), optional
        Inputs sampled on ``t``; between samples see ``input_hold``.
    controller : callable ``(t, x) -> u`` or InputLaw, optional
        A callable is state feedback evaluated at the start of each output interval and held over it
        (batch-aware: ``x`` has shape (B, nx) in a batch).  An :class:`InputLaw` is evaluated as a
        function of time (see there) with its events located within the steps.  Exactly one of
        ``inputs`` and ``controller`` must be given.
    params : array, shape (np,) or (B, np), optional
        Defaults to ``model.params``.
    substeps : int
        ``rk4``: (least) steps per output interval.
    h_max : float, optional
        ``rk4``: largest step [s]; a long interval (a logger dropout) is crossed in
        ``max(substeps, ceil(dt / h_max))`` steps (:func:`shipid.integrate.interval_steps`, as the EKF).
    method : {"rk4", "dopri5"}
        Fixed-step RK4 (the EKF's map) or adaptive Dormand-Prince 5(4) (see module docstring).
    rtol, atol : float
        ``dopri5`` error tolerances (per component |err| <= atol + rtol |x|); ``atol`` defaults to
        ``1e-3 rtol``.
    first_step : float, optional
        ``dopri5`` first step [s] (e.g. ``meta["h_last"]`` of a previous run being continued); default
        Hairer's starting-step heuristic.
    input_hold : {"zoh", "foh"}
        Sampled ``inputs`` between samples: held at the interval's first sample (zero-order hold,
        default here) or linear between the samples (first-order hold: every RK4 stage, or every
        ``dopri5`` stage, sees the input at its own time), as the EKF's ``input_hold``.

    Returns
    -------
    SimulationResult
        ``meta`` holds ``method`` and, for ``dopri5``, ``n_steps``, ``n_rejected``, ``n_fev``, ``h_last``.
    """
    _check_model(model, "model")
    t = np.asarray(t, dtype=float)
    if t.ndim != 1 or t.size < 2:
        raise ValueError(f"t must be a 1-D array of at least two times; got shape {t.shape}")
    if not np.all(np.isfinite(t)):
        i = int(np.flatnonzero(~np.isfinite(t))[0])
        raise ValueError(f"t must be finite; t[{i}] = {t[i]}")
    if np.any(np.diff(t) <= 0):
        i = int(np.flatnonzero(np.diff(t) <= 0)[0])
        raise ValueError(f"t must be strictly increasing; t[{i + 1}] = {t[i + 1]:g} follows t[{i}] = {t[i]:g}")
    if x0 is None:
        raise ValueError(f"x0 must be the initial state, shape ({model.nx},) for {list(model.state_names)}; got None")
    if (inputs is None) == (controller is None):
        raise ValueError("give exactly one of inputs= (sampled inputs) or controller= (feedback law)")
    if substeps < 1:
        raise ValueError(f"substeps must be >= 1, got {substeps}")
    if method not in METHODS:
        raise ValueError(f"method={method!r}: use one of {METHODS}")
    if input_hold not in INPUT_HOLDS:
        raise ValueError(f"input_hold={input_hold!r}: use one of {INPUT_HOLDS}")
    if method == "dopri5" and not (0 < rtol < 1):
        raise ValueError(f"rtol must be in (0, 1), got {rtol}")
    x0 = np.asarray(x0, dtype=float)
    if x0.ndim == 0 or x0.shape[-1] != model.nx or x0.ndim > 2:
        raise ValueError(f"x0 must have shape ({model.nx},) or (B, {model.nx}) for {model.state_names}; got {x0.shape}")
    if x0.ndim == 1 and not np.all(np.isfinite(x0)):
        i = int(np.flatnonzero(~np.isfinite(x0))[0])
        raise ValueError(f"x0 must be finite; x0[{i}] ('{model.state_names[i]}') = {x0[i]}")
    p = model.params if params is None else np.asarray(params, dtype=float)
    batch = x0.shape[:-1]
    n_t = t.size
    U = None
    if inputs is not None:
        U = np.asarray(inputs, dtype=float)
        if U.shape[-2:] != (n_t, model.nu):
            raise ValueError(f"inputs must have shape (..., {n_t}, {model.nu}) for {model.input_names}; got {U.shape}")
        U = np.broadcast_to(U, batch + (n_t, model.nu))
    law = controller if isinstance(controller, InputLaw) else None
    if method == "dopri5":
        atol = 1e-3 * rtol if atol is None else atol
        foh = input_hold == "foh" and U is not None
        start_ok = bool(np.all(np.isfinite(x0)))
        if start_ok or controller is not None:  # (a non-finite start would give a non-finite first step)
            res = _simulate_dopri5(model, x0, t, U, controller, law, p, rtol, atol, first_step, foh=foh)
            if res.success or not batch or controller is not None:
                return res
        elif not batch:
            return _dopri5_members(model, x0[None], t, None if U is None else U[None], p, rtol, atol, first_step,
                                   foh, single=True)
        # the batch shares one adaptive step, so one non-finite (or stiffly diverging) member stops it:
        # integrate the members one by one, finish those that can be finished and report the others
        return _dopri5_members(model, x0, t, U, p, rtol, atol, first_step, foh)
    foh = input_hold == "foh" and U is not None
    n_int = interval_steps(t, substeps, h_max).tolist()
    if (U is not None and controller is None and model.nu > 0 and p.dtype.kind == "f"
            and (p.ndim == 1 or p.shape[:-1] == batch)):
        # sampled inputs: the same RK4 map on the model's kernel equations: compiled, or run by the
        # interpreter on floats for one trajectory of a model that sets _python_replay
        Xc = replay_compiled(model, x0.reshape(-1, model.nx), t, U.reshape(-1, n_t, model.nu), p, n_int, foh)
        if Xc is not None:
            Xc = Xc.reshape(batch + (n_t, model.nx))
            bad = ~np.all(np.isfinite(Xc), axis=-1)  # (batch..., n_t): a member that became non-finite
            failed_at = np.where(bad.any(axis=-1), t[np.argmax(bad, axis=-1)], np.nan)
            ok = not bad.any()
            if not ok:  # NaN from the first non-finite sample on, and said (as the interpreted loop does)
                Xc = np.where((np.cumsum(bad, axis=-1) > 0)[..., None], np.nan, Xc)
                warnings.warn(_failure_message(t, failed_at), RuntimeWarning, stacklevel=2)
            meta = {"method": "rk4"}
            if batch:
                meta["failed"] = [int(i) for i in np.flatnonzero(np.isfinite(failed_at.ravel()))]
                meta["failed_at"] = [float(v) for v in failed_at.ravel()[meta["failed"]]]
            return SimulationResult(t=t, x=Xc, u=np.array(U), model=model, params=np.array(p), success=ok,
                                    message="integration finished" if ok else _failure_message(t, failed_at),
                                    meta=meta)
    X = np.full(batch + (n_t, model.nx), np.nan)
    Uout = np.full(batch + (n_t, model.nu), np.nan)
    x = x0.copy()
    X[..., 0, :] = x
    ok, msg = True, "integration finished"
    f = model._rhs_bound(p)
    failed_at = np.full(batch, np.nan)  # time at which each batch member became non-finite
    for k in range(n_t - 1):
        nk = n_int[k]
        h = (t[k + 1] - t[k]) / nk
        tk = t[k]
        if law is not None:
            Uout[..., k, :] = law.inputs(tk, x)
            for _ in range(nk):
                x = _rk4_law_step(f, law, tk, x, h)
                tk += h
        else:
            uk = controller(tk, x) if controller is not None else U[..., k, :]
            uk = np.broadcast_to(np.asarray(uk, dtype=float), batch + (model.nu,))
            Uout[..., k, :] = uk
            u1 = U[..., k + 1, :] if foh else None
            for i, (ua, ub) in enumerate(hold_steps(uk, u1, nk)):
                x = rk4_map(f, t[k] + i * h if i else tk, x, ua, h, ub)
        bad = ~np.all(np.isfinite(x), axis=-1)
        if np.any(bad):
            ok = False
            if not batch or np.all(bad | np.isfinite(failed_at)):
                X[..., k + 1, :] = np.where(np.isfinite(failed_at)[..., None], np.nan, x)
                failed_at = np.where(np.isfinite(failed_at), failed_at, t[k + 1])
                break
            # a batch finishes its other members: the failed ones restart from their last finite state
            # (so that nothing non-finite is integrated) and are recorded as NaN from here on
            failed_at = np.where(bad & ~np.isfinite(failed_at), t[k + 1], failed_at)
            x = np.where(bad[..., None], X[..., k, :], x)
            x = np.where(np.isfinite(x), x, 0.0)
        X[..., k + 1, :] = np.where(np.isfinite(failed_at)[..., None], np.nan, x)
    if not ok:
        msg = _failure_message(t, failed_at)
        warnings.warn(msg, RuntimeWarning, stacklevel=2)
    else:
        last = (law.inputs(t[-1], x) if law is not None else controller(t[-1], x)) if controller is not None else U[..., -1, :]
        Uout[..., -1, :] = np.broadcast_to(np.asarray(last, dtype=float), batch + (model.nu,))
    meta = {"method": "rk4"}
    if batch:
        meta["failed"] = [int(i) for i in np.flatnonzero(np.isfinite(failed_at.ravel()))]
        meta["failed_at"] = [float(v) for v in failed_at.ravel()[meta["failed"]]]
    return SimulationResult(t=t, x=X, u=Uout, model=model, params=np.array(p), success=ok, message=msg, meta=meta)


def _check_model(model, name: str = "model") -> None:
    """TypeError naming the argument when ``model`` is not a model object (e.g. a model's name)."""
    if not all(hasattr(model, a) for a in ("nx", "state_names", "params")):
        hint = f"; build it with shipid.models.get_model({model!r})" if isinstance(model, str) else ""
        raise TypeError(f"{name} must be a model object (shipid.models), got {type(model).__name__}"
                        f" {str(model)[:40]!r}{hint}")


def _failure_message(t, failed_at) -> str:
    fa = np.atleast_1d(failed_at).ravel()
    idx = np.flatnonzero(np.isfinite(fa))
    if np.ndim(failed_at) == 0:
        return f"state became non-finite at t = {float(failed_at):.6g} s; the model or its parameters are unstable here"
    shown = ", ".join(f"{i} (t = {fa[i]:.6g} s)" for i in idx[:10]) + (" ..." if idx.size > 10 else "")
    return (f"state became non-finite in {idx.size} of {fa.size} batch member(s): {shown}; the others finished "
            "(meta['failed'] lists the failed members, NaN from their failure on)")


def _rk4_law_step(f, law, t, x, h):
    """RK4 over [t, t + h] under an InputLaw: input held at its mid-step value; stops inside the step
    and events located within it split the step (events by the Illinois method on the discrete map)."""
    t_end = t + h
    while t < t_end - 1e-12 * max(1.0, abs(t_end)):
        stop = next((s for s in law.stops if t + 1e-12 * max(1.0, abs(t)) < s < t_end), t_end)
        hs = stop - t
        xn = rk4_map(f, t, x, law.inputs(t + 0.5 * hs, x), hs)
        if law.has_events:
            g0, g1 = law.event(t, x), law.event(t + hs, xn)
            cross = (g0 < 0) & (g1 >= 0)
            if np.any(cross):
                lo, hi = np.zeros(g0.shape), np.ones(g0.shape)
                glo, ghi = np.where(cross, g0, -1.0), np.where(cross, g1, 1.0)
                for _ in range(50):  # Illinois on the fraction of the step, per crossing member
                    th = np.clip(np.where(cross, (lo * ghi - hi * glo) / (ghi - glo), 1.0), lo, hi)
                    ths = float(np.min(th[cross]))
                    xm = rk4_map(f, t, x, law.inputs(t + 0.5 * ths * hs, x), ths * hs)
                    gm = law.event(t + ths * hs, xm)
                    first = cross & (th == ths)
                    up = gm >= 0
                    hi, ghi = np.where(first & up, ths, hi), np.where(first & up, gm, np.where(first & ~up, ghi * 0.5, ghi))
                    lo, glo = np.where(first & ~up, ths, lo), np.where(first & ~up, gm, np.where(first & up, glo * 0.5, glo))
                    if np.all(hi[first] - lo[first] < 1e-12):
                        break
                    if np.all(np.abs(gm[first]) < 1e-13):
                        # located (g zero to rounding) at ths, also when gm is a hair below zero: the event is
                        # there, not at the bracket's upper end (which may still be the step end, and a member
                        # crossing just after another one's event then fired a whole step late)
                        hi = np.where(first, ths, hi)
                        break
                th_ev = float(np.min(hi[cross]))
                hs = th_ev * hs
                xn = rk4_map(f, t, x, law.inputs(t + 0.5 * hs, x), hs)
                # every member whose event function has reached zero by the event time fires there: a member
                # crossing within rounding of the located one (its own bracket not refined) would otherwise
                # start the next sub-step already past zero and never fire (batched zigzags of nearly equal
                # parameter sets -- a forward-difference Jacobian -- then missed a rudder reversal)
                mask = cross & ((hi <= th_ev + 1e-9) | (law.event(t + hs, xn) >= 0))
                law.on_event(t + hs, xn, mask)
        t, x = t + hs, xn
    return x


def _simulate_dopri5(model, x0, t, U, controller, law, p, rtol, atol, first_step=None, foh=False):
    batch = x0.shape[:-1]
    n_t = t.size
    f = model._rhs_bound(p)
    X = np.full(batch + (n_t, model.nx), np.nan)
    Uout = np.full(batch + (n_t, model.nu), np.nan)
    stats = {"method": "dopri5", "n_steps": 0, "n_rejected": 0, "n_fev": 0, "h_last": None}
    ok, msg = True, "integration finished"

    def add(r):
        for k in ("n_steps", "n_rejected", "n_fev"):
            stats[k] += getattr(r, k)
        stats["h_last"] = r.h_last

    if law is not None:
        r = dopri5(lambda tt, xx: f(tt, xx, law.inputs(tt, xx)), float(t[0]), x0, float(t[-1]), t, rtol=rtol,
                   atol=atol, h0=first_step, stops=law.stops, event=law.event if law.has_events else None,
                   on_event=law.on_event)
        add(r)
        X[...] = np.moveaxis(r.x, 0, -2)
        ok, msg = r.success, r.message
        Uout[...] = law.input_history(t, X)
    elif foh:
        # first-order-hold inputs: one run, inputs interpolated at every stage, stops where the slope changes
        dU = np.diff(U, axis=-2)
        slope = dU / np.diff(t)[:, None]
        kink = np.any(np.abs(np.diff(slope, axis=-2)) > 1e-12 * (1.0 + np.abs(slope[..., 1:, :])), axis=-1)
        stops = t[1:-1][np.any(kink.reshape(-1, n_t - 2), axis=0)] if n_t > 2 else ()

        def u_at(tt):
            k = min(max(int(np.searchsorted(t, tt, side="right")) - 1, 0), n_t - 2)
            w = (tt - t[k]) / (t[k + 1] - t[k])
            return (1.0 - w) * U[..., k, :] + w * U[..., k + 1, :]

        r = dopri5(lambda tt, xx: f(tt, xx, u_at(tt)), float(t[0]), x0, float(t[-1]), t, rtol=rtol, atol=atol,
                   h0=first_step, stops=stops)
        add(r)
        X[...] = np.moveaxis(r.x, 0, -2)
        ok, msg = r.success, r.message
        Uout[...] = U
    else:
        # zero-order-hold inputs: one adaptive run per interval of constant input
        X[..., 0, :] = x0
        x, h0 = x0, first_step
        k = 0
        if controller is None:  # sample indices where some input of some member changes
            diff = np.any(U[..., 1:, :] != U[..., :-1, :], axis=-1)
            changes = np.flatnonzero(np.any(diff.reshape(-1, n_t - 1), axis=0)) + 1
            ends = np.append(changes[changes < n_t - 1], n_t - 1)
        while k < n_t - 1:
            uk = controller(t[k], x) if controller is not None else U[..., k, :]
            uk = np.broadcast_to(np.asarray(uk, dtype=float), batch + (model.nu,))
            j = k + 1 if controller is not None else int(ends[np.searchsorted(ends, k, side="right")])
            r = dopri5(lambda tt, xx, uk=uk: f(tt, xx, uk), float(t[k]), x, float(t[j]), t[k + 1:j + 1],
                       rtol=rtol, atol=atol, h0=h0)
            add(r)
            Uout[..., k:j, :] = uk[..., None, :]
            X[..., k + 1:j + 1, :] = np.moveaxis(r.x, 0, -2)
            if not r.success:
                ok, msg = False, r.message
                break
            x, h0, k = r.x_final, r.h_last, j
        if ok:
            last = controller(t[-1], x) if controller is not None else U[..., -1, :]
            Uout[..., -1, :] = np.broadcast_to(np.asarray(last, dtype=float), batch + (model.nu,))
    return SimulationResult(t=t, x=X, u=Uout, model=model, params=np.array(p), success=ok, message=msg, meta=stats)


def _dopri5_members(model, x0, t, U, p, rtol, atol, first_step, foh, single: bool = False):
    """``dopri5`` on each member of an open-loop batch ``x0 (B, nx)`` separately (after the shared-step run
    failed): the members that finish are kept, the others are NaN from their first non-finite sample on,
    listed in ``meta["failed"]`` with ``meta["failed_at"]`` [s], as the ``rk4`` batch does."""
    B = x0.shape[0]
    X = np.full((B, t.size, model.nx), np.nan)
    Uout = np.full((B, t.size, model.nu), np.nan)
    failed_at = np.full(B, np.nan)
    meta = {"method": "dopri5", "n_steps": 0, "n_rejected": 0, "n_fev": 0, "h_last": None, "per_member": True}
    for b in range(B):
        if not np.all(np.isfinite(x0[b])):  # nothing to integrate: failed at the start
            failed_at[b] = t[0]
            continue
        pb = p[b] if p.ndim == 2 else p
        r = _simulate_dopri5(model, x0[b], t, U[b], None, None, pb, rtol, atol, first_step, foh=foh)
        for k in ("n_steps", "n_rejected", "n_fev"):
            meta[k] += r.meta[k]
        X[b], Uout[b] = r.x, r.u
        bad = ~np.all(np.isfinite(r.x), axis=-1)
        if not r.success or bad.any():
            k = int(np.flatnonzero(bad)[0]) if bad.any() else t.size - 1
            failed_at[b] = t[k]
            X[b, k:] = np.nan
    meta["failed"] = [int(i) for i in np.flatnonzero(np.isfinite(failed_at))]
    meta["failed_at"] = [float(v) for v in failed_at[meta["failed"]]]
    ok = not meta["failed"]
    msg = "integration finished" if ok else _failure_message(t, failed_at[0] if single else failed_at)
    if not ok:
        warnings.warn(msg, RuntimeWarning, stacklevel=3)
    if single:
        X, Uout = X[0], Uout[0]
        meta = {k: v for k, v in meta.items() if k not in ("failed", "failed_at", "per_member")}
    return SimulationResult(t=t, x=X, u=Uout, model=model, params=np.array(p), success=ok, message=msg, meta=meta)


def _log_frame(log) -> pd.DataFrame:
    data = log if isinstance(log, pd.DataFrame) else getattr(log, "data", None)
    if not isinstance(data, pd.DataFrame) or "time" not in data.columns:
        raise ValueError("replay needs a TrialLog or a DataFrame with a 'time' column")
    return data


def replay(model: Model, log, *, x0=None, substeps: int = 2, params=None, input_hold: str = "foh",
           h_max: float | None = None, initial: dict | None = None) -> SimulationResult:
    """Simulate ``model`` with the recorded inputs of ``log`` from its initial state.

    Parameters
    ----------
    model : Model
        Typically a fitted model (``FitResult.to_model()``).
    log : TrialLog or DataFrame
        Must contain ``time`` and every input of the model.
    x0 : array (nx,), optional
        Initial state; default: the mean of the first five finite samples of
        each logged state (0 for states not logged).
    substeps : int
        RK4 steps per sample interval.
    params : array (np,) or (B, np), optional
        Parameters (default the model's); B sets replay the log as one batch of B members.
    input_hold : {"foh", "zoh"}
        Inputs between samples: linear between the logged values (default; a real rudder moves
        between samples, and the EKF assumes the same by default) or held.
    h_max : float, optional
        Largest RK4 step [s] (default ``1.5 * median(dt) / substeps``): gaps in the log are crossed in
        as many steps as they need, as the EKF does.
    initial : dict, optional
        Start values of named states in place of the default ``x0``'s (e.g. the current ``cx``, ``cy`` of a
        model with current states, which no log carries); not with ``x0``.
    """
    if isinstance(substeps, bool) or not isinstance(substeps, (int, np.integer)) or substeps < 1:
        raise ValueError(f"substeps must be a whole number >= 1 (RK4 steps per log sample), got {substeps!r}")
    if initial and x0 is not None:
        raise ValueError("replay: give x0 or initial, not both")
    bad = [k for k in (initial or {}) if k not in model.state_names]
    if bad:
        raise ValueError(f"initial: {bad} are not states of model '{model.name}' (states: {list(model.state_names)})")
    df = _log_frame(log)
    t = df["time"].to_numpy(dtype=float)
    missing = [n for n in model.input_names if n not in df.columns]
    if missing:
        raise ValueError(f"log lacks input channel(s) {missing} needed to replay model '{model.name}'")
    U = np.column_stack([df[n].to_numpy(dtype=float) for n in model.input_names])
    if not np.all(np.isfinite(U)):
        k = int(np.flatnonzero(~np.all(np.isfinite(U), axis=1))[0])
        raise ValueError(f"log input missing at sample {k} (t = {t[k]:.6g} s); interpolate the inputs before replaying")
    if x0 is None:
        x0 = np.zeros(model.nx)
        for i, n in enumerate(model.state_names):
            if n in df.columns:
                col = df[n].to_numpy(dtype=float)
                fin = col[np.isfinite(col)][:5]
                if fin.size:
                    x0[i] = fin.mean()
        for k, v in (initial or {}).items():
            x0[model.state_index(k)] = float(v)
    if params is not None and np.ndim(params) == 2:
        x0 = np.broadcast_to(np.asarray(x0, dtype=float), (np.shape(params)[0], model.nx))
    if h_max is None:
        h_max = 1.5 * float(np.median(np.diff(t))) / substeps
    sim = simulate(model, x0, t, U, substeps=substeps, params=params, input_hold=input_hold, h_max=h_max)
    sim.measured = df
    return sim


def replay_errors(sim: SimulationResult, log) -> pd.DataFrame:
    """Per-channel RMSE and NRMSE (RMSE / range of the measurement) of a replay,
    plus the track error (RMS distance between simulated and logged x, y).

    Returns a DataFrame indexed by channel with columns ``rmse``, ``nrmse``,
    ``n_samples``; the row ``track`` holds the RMS position error [m].
    """
    df = _log_frame(log)
    rows = {}
    for i, n in enumerate(sim.model.state_names):
        if n not in df.columns:
            continue
        y = df[n].to_numpy(dtype=float)
        s = sim.x[:, i]
        ok = np.isfinite(y) & np.isfinite(s)
        if not ok.any():
            continue
        e = s[ok] - y[ok]
        rmse = float(np.sqrt(np.mean(e**2)))
        rng = float(np.ptp(y[ok]))
        rows[n] = {"rmse": rmse, "nrmse": rmse / rng if rng > 0 else np.nan, "n_samples": int(ok.sum())}
    if {"x", "y"} <= set(df.columns) and {"x", "y"} <= set(sim.model.state_names):
        dx = sim.state("x") - df["x"].to_numpy(dtype=float)
        dy = sim.state("y") - df["y"].to_numpy(dtype=float)
        d2 = dx**2 + dy**2
        ok = np.isfinite(d2)
        if ok.any():
            rows["track"] = {"rmse": float(np.sqrt(np.mean(d2[ok]))), "nrmse": np.nan, "n_samples": int(ok.sum())}
    return pd.DataFrame.from_dict(rows, orient="index")


class _CallableModule(types.ModuleType):
    """This module's type: calling the module calls :func:`simulate`."""

    def __call__(self, *args, **kwargs) -> SimulationResult:
        return simulate(*args, **kwargs)


sys.modules[__name__].__class__ = _CallableModule
