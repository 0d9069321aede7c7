"""The batch runner of the standard manoeuvres: ship facts of a model, the steady approach (rps holding a
speed), chunked batched integration until every member finished, and the result object."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pandas as pd

from ..models.base import Model
from ..results import ResultMixin
from ..simulate import METHODS, SimulationResult, simulate

_REQUIRED_STATES = ("x", "y", "psi", "u", "v", "r")
_REQUIRED_INPUTS = ("delta", "n")
#: Ship facts of models that do not carry them (the KCS model of Hajizadeh et al.).
_KNOWN_SHIPS = {"kcs-response": {"lpp": 4.36, "rudder_rate": math.radians(16.8), "design_speed": 1.7}}


def ship_info(model: Model) -> dict:
    """Ship facts a manoeuvre needs: ``lpp`` [m], ``rudder_rate`` [rad/s], ``design_speed`` [m/s].

    Taken from model attributes of those names, then from the default parameter set's
    ``operating_point`` (``lpp_m``, ``u0_m_s``, ``rudder_rate_deg_s``), then from the known
    ships of the bundled papers (only for a model of that ship's length); missing ones are absent from the dict.
    """
    info: dict[str, float] = {}
    for k in ("lpp", "rudder_rate", "design_speed"):
        val = getattr(model, k, None)
        if val is not None:
            info[k] = float(val)
    try:
        op = type(model).parameter_set(type(model).default_parameter_set).extra.get("operating_point", {}) \
            if getattr(type(model), "default_parameter_set", None) else {}
    except (ValueError, OSError):
        op = {}
    for key, name, conv in (("lpp_m", "lpp", 1.0), ("u0_m_s", "design_speed", 1.0), ("rudder_rate_deg_s", "rudder_rate", math.pi / 180)):
        if name not in info and key in op:
            info[name] = float(op[key]) * conv
    known = _KNOWN_SHIPS.get(model.name, {})
    if "lpp" not in info or abs(info["lpp"] / known.get("lpp", info["lpp"]) - 1.0) < 1e-9:  # only for that ship
        for k, val in known.items():
            info.setdefault(k, val)
    return info


def _check_model(model: Model):
    miss = [s for s in _REQUIRED_STATES if s not in model.state_names] + \
           [s for s in _REQUIRED_INPUTS if s not in model.input_names]
    if miss:
        raise ValueError(f"model '{model.name}' lacks {miss}; standard manoeuvres need states {_REQUIRED_STATES} "
                         f"and inputs {_REQUIRED_INPUTS}")


def _approach_state(model, speeds):
    B = speeds.shape[0]
    x0 = np.zeros((B, model.nx))
    x0[:, model.state_index("u")] = speeds
    return x0


def steady_rps(model: Model, speed, *, params=None, n_max: float = 1e3, xtol: float = 1e-10) -> np.ndarray:
    """Propeller rps holding ``speed`` [m/s] in a straight run (du/dt = 0, delta = 0, v = r = 0).

    Vectorised bisection over a batch of speeds through ``model.rhs``; works for any protocol model
    with states ``u`` and input ``n``.  ``params`` may be one parameter vector (np,) or one per speed
    (B, np).  Raises ValueError when no rps in (0, n_max] gives du/dt = 0.
    """
    _check_model(model)
    speeds = np.atleast_1d(np.asarray(speed, dtype=float))
    if np.any(speeds <= 0):
        raise ValueError(f"approach speed must be positive, got {speeds[speeds <= 0][0]}")
    p = model.params if params is None else np.asarray(params, dtype=float)
    iu, idl, inn = model.state_index("u"), model.input_index("delta"), model.input_index("n")
    x0 = _approach_state(model, speeds)

    def acc(n):
        uin = np.zeros((speeds.size, model.nu))
        uin[:, inn] = n
        return model.rhs(0.0, x0, uin, p)[:, iu]

    grid = np.concatenate([[0.0], np.geomspace(1e-3, n_max, 120)])
    G = grid.size
    ug = np.zeros((speeds.size, G, model.nu))
    ug[..., inn] = grid
    pg = p[:, None, :] if p.ndim == 2 else p  # per-speed parameters broadcast over the grid
    vals = model.rhs(0.0, np.repeat(x0[:, None, :], G, axis=1), ug, pg)[..., iu]  # (B, G), one batched call
    lo = np.full(speeds.size, np.nan)
    hi = np.full(speeds.size, np.nan)
    for b in range(speeds.size):
        k = np.nonzero((vals[b, :-1] < 0) & (vals[b, 1:] >= 0))[0]
        if k.size == 0:
            raise ValueError(f"model '{model.name}': no propeller rps in (0, {n_max}] holds {speeds[b]:.4g} m/s "
                             "(du/dt never changes sign); pass n= explicitly")
        lo[b], hi[b] = grid[k[0]], grid[k[0] + 1]
    del idl
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        a = acc(mid)
        lo = np.where(a < 0, mid, lo)
        hi = np.where(a < 0, hi, mid)
        if np.all(hi - lo < xtol * np.maximum(1.0, hi)):
            break
    return 0.5 * (lo + hi)


@dataclass
class ManoeuvreResult(ResultMixin):
    """A batch of simulated standard manoeuvres.

    Attributes
    ----------
    kind : "turning" or "zigzag"
    simulation : SimulationResult
        The batched run (``x`` shape (B, n_t, nx)).
    settings : DataFrame
        One row per member: rudder_deg, speed, n, side/first side, switch_deg (zigzag).
    metrics : list of TurningMetrics / ZigzagMetrics
    success : bool
    message : str
    """

    kind: str
    simulation: SimulationResult
    settings: pd.DataFrame
    metrics: list
    success: bool = True
    message: str = "ok"

    def to_pandas(self) -> pd.DataFrame:
        """Settings and metrics, one row per member (the flat keys of ``to_dict``)."""
        rows = []
        for i, m in enumerate(self.metrics):
            d = {k: v for k, v in m.to_dict().items() if not isinstance(v, dict)}
            rows.append({**self.settings.iloc[i].to_dict(), **d})
        return pd.DataFrame(rows)

    def member(self, i: int) -> pd.DataFrame:
        """Time series of member ``i`` (states and inputs)."""
        return self.simulation.to_pandas(member=i)

    #: Columns of :meth:`summary` (those a member's metrics have), after the settings.
    _SUMMARY_METRICS = ("advance_L", "transfer_L", "tactical_diameter_L", "steady_diameter_L", "speed_loss",
                        "overshoot1_deg", "overshoot2_deg", "initial_turning_L", "success")

    def summary(self) -> pd.DataFrame:
        """One row per member: its settings and the headline metrics (turning: advance, transfer, tactical
        and steady diameter in ship lengths, speed loss; zigzag: first and second overshoot [deg], initial
        turning [L]); every metric is in :meth:`to_pandas`."""
        df = self.to_pandas()
        keep = list(self.settings.columns) + [c for c in self._SUMMARY_METRICS if c in df.columns]
        return df[[c for c in dict.fromkeys(keep) if c in df.columns]]

    def _html_title(self) -> str:
        return f"{self.kind.capitalize()} manoeuvre" + (f"s ({len(self.metrics)} members)" if len(self.metrics) > 1 else "")

    def _key_numbers(self) -> dict:
        return {"model": self.simulation.model.name, "members": len(self.metrics)}

    def plot(self, ax=None):
        """Turning: the tracks in ship lengths (x/L up, y/L right, as a trial chart); zigzag: heading and rudder
        angle [deg] against time.  One line per member; returns the axes."""
        import matplotlib.pyplot as plt  # only when plotting: pyplot takes ~1 s to import

        sim, model = self.simulation, self.simulation.model
        if ax is None:
            _, ax = plt.subplots(figsize=(6, 5) if self.kind == "turning" else (8, 3.5))
        X = sim.x if sim.batched else sim.x[None]
        U = sim.u if sim.batched else sim.u[None]
        labels = [", ".join(f"{k} {v:g}" if isinstance(v, (int, float, np.floating)) else f"{v}" for k, v in row.items()
                            if k in ("rudder_deg", "switch_deg", "side", "first", "speed"))
                  for row in self.settings.to_dict("records")]
        if self.kind == "turning":
            L = self.metrics[0].lpp if self.metrics else 1.0
            ix, iy = model.state_index("x"), model.state_index("y")
            for b in range(X.shape[0]):
                ax.plot(X[b, :, iy] / L, X[b, :, ix] / L, lw=1.0, label=labels[b] if b < len(labels) else None)
            ax.set_xlabel("y / L (transfer)")
            ax.set_ylabel("x / L (advance)")
            ax.set_aspect("equal", adjustable="datalim")
        else:
            ipsi, idl = model.state_index("psi"), model.input_index("delta")
            for b in range(X.shape[0]):
                line, = ax.plot(sim.t, np.degrees(X[b, :, ipsi] - X[b, 0, ipsi]), lw=1.0,
                                label=f"heading, {labels[b]}" if b < len(labels) else None)
                ax.plot(sim.t, np.degrees(U[b, :, idl]), lw=0.8, ls="--", color=line.get_color())
            ax.set_xlabel("time [s]")
            ax.set_ylabel("heading change (solid), rudder (dashed) [deg]")
        if X.shape[0] <= 8:
            ax.legend(loc="best", fontsize="small")
        return ax


def _resolve(model, speed, n, rudder_rate, lpp, params):
    _check_model(model)
    info = ship_info(model)
    L = lpp if lpp is not None else info.get("lpp")
    if L is None:
        raise ValueError(f"model '{model.name}': ship length unknown; pass lpp=")
    rate = rudder_rate if rudder_rate is not None else info.get("rudder_rate")
    if rate is None:
        raise ValueError(f"model '{model.name}': rudder rate unknown; pass rudder_rate= [rad/s]")
    if speed is None and n is None:
        speed = info.get("design_speed")
        if speed is None:
            raise ValueError(f"model '{model.name}': approach speed unknown; pass speed= [m/s]")
    return float(L), float(rate), speed


def _run_batched(model, x0, t_step, controller_factory, done, params, t_max, chunk, method="rk4", rtol=1e-6):
    """Integrate in chunks until ``done(X_all, t_all)`` or ``t_max``; returns a SimulationResult.

    ``t_step`` is a step [s] or a callable ``(T, X) -> step`` choosing the step of the next chunk from
    the run so far (the time grid of ``simulate`` may be non-uniform).
    """
    ctrl = controller_factory()
    ts, Xs, Us, stats = [], [], [], []
    t0 = 0.0
    x = x0
    T = X = None  # the run so far (concatenated once per chunk)
    ok, msg = True, "integration finished"
    while True:
        h = t_step(T, X) if callable(t_step) else t_step
        n_steps = max(1, int(round(chunk / h)))
        t = t0 + h * np.arange(n_steps + 1)
        res = simulate(model, x, t, controller=ctrl, params=params, method=method, rtol=rtol,
                       first_step=stats[-1].get("h_last") if stats else None)
        stats.append(res.meta)
        ts.append(t if not ts else t[1:])
        Xs.append(res.x if not Xs else res.x[:, 1:])
        Us.append(res.u if not Us else res.u[:, 1:])
        if not res.success:
            ok, msg = False, res.message
            break
        x = res.x[:, -1]
        t0 = t[-1]
        T, X = np.concatenate(ts), np.concatenate(Xs, axis=1)
        finished = done(T, X)
        if finished or t0 >= t_max - 1e-9:
            if not finished:
                ok, msg = False, f"t_max = {t_max:g} s reached before every member finished the manoeuvre"
            break
    T, X, Uo = np.concatenate(ts), np.concatenate(Xs, axis=1), np.concatenate(Us, axis=1)
    # the last input sample of a chunk is re-evaluated by the next chunk: keep the later value
    p = model.params if params is None else np.asarray(params, dtype=float)
    meta = {"method": method}
    for k in ("n_steps", "n_rejected", "n_fev"):
        if any(k in m for m in stats):
            meta[k] = int(sum(m.get(k, 0) for m in stats))
    return SimulationResult(t=T, x=X, u=Uo, model=model, params=np.array(p), success=ok, message=msg, meta=meta)


def _time_step(L, speeds, dt):
    if dt is not None:
        return float(dt)
    return 0.05 * L / float(np.max(speeds))  # 20 RK4 steps per ship length travelled


def _check_method(method):
    if method not in METHODS:
        raise ValueError(f"method={method!r}: use one of {METHODS}")


def _speed_for_rps(model, n, params):
    lo, hi = np.full(n.shape, 1e-3), np.full(n.shape, 1e3)
    iu, inn = model.state_index("u"), model.input_index("n")
    p = model.params if params is None else params
    for _ in range(100):
        mid = np.sqrt(lo * hi)
        x0 = _approach_state(model, mid)
        uin = np.zeros((n.size, model.nu))
        uin[:, inn] = n
        a = model.rhs(0.0, x0, uin, p)[:, iu]
        lo, hi = np.where(a > 0, mid, lo), np.where(a > 0, hi, mid)
    return np.sqrt(lo * hi)
