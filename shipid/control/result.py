"""Common result object of the optimal-control solvers."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from ..results import ResultMixin, axes_column, plot_series
from .problem import Problem, evaluate

__all__ = ["ControlResult", "switch_time"]


def switch_time(U: np.ndarray, lo: float, hi: float, tf: float, tol: float = 0.02, max_between: int = 2) -> float | None:
    """Time of the single switch of a bang-bang control between its bounds.

    ``U`` holds the piecewise-constant values on equal intervals of ``[0, tf]``.
    Up to ``max_between`` consecutive intervals may hold intermediate values
    (a discretised switch); their fractions of the range count as time at the
    first level (the impulse-equivalent switch time).  Returns None when the
    history is not one switch between the bounds.
    """
    U = np.asarray(U, float)
    N = len(U)
    dt = tf / N
    z = (U - lo) / (hi - lo)
    top, bot = z >= 1 - tol, z <= tol
    for first, second, frac in ((top, bot, z), (bot, top, 1 - z)):
        if not first[0] or not second[-1]:
            continue
        j = int(np.argmin(first))  # first interval not at the first level
        k = int(np.argmax(second[j:])) + j  # first interval at the second level
        if k - j > max_between or not second[k:].all():
            continue
        return (j + float(np.sum(frac[j:k]))) * dt
    return None


@dataclass
class ControlResult(ResultMixin):
    """Result of :func:`solve_indirect` / :func:`solve_direct`.

    Attributes
    ----------
    success : bool
        Optimiser converged and every constraint holds within ``tol``.
    status : int
        0 success, 1 optimiser did not converge, 2 constraints violated.
    message : str
    method : str
        ``"indirect-steepest"``, ``"indirect-bfgs"``, ``"direct-slsqp"``...
    final_time : float [s]
    controls : ndarray (n_intervals, nu)
        Piecewise-constant inputs.
    t, x, u : ndarrays
        Fine-grid evaluation (times (K+1,), states (K+1, nx), inputs (K+1, nu)).
    violations : dict
        Constraint label -> dimensionless violation (see :func:`evaluate`).
    max_constraint_violation : float
    nit, nfev : int
        Optimiser iterations (summed over penalty stages) and cost/gradient evaluations.
    cost : float
        Final value of the problem's cost (``t_f`` for minimum time).
    wall_time : float [s]
    switch_time : float or None
        Single bang-bang switch time of ``problem.switch_input`` [s].
    history : list of dict
        Per stage/iteration record (cost, violation, tf).
    """

    problem: Problem
    method: str
    controls: np.ndarray
    final_time: float
    nit: int
    nfev: int
    optimizer_success: bool
    optimizer_message: str
    wall_time: float
    tol: float = 1e-2
    history: list = field(default_factory=list)

    def __post_init__(self):
        traj = evaluate(self.problem, self.controls, self.final_time)
        self.t, self.x, self.u = traj.t, traj.x, traj.u
        self.violations = traj.violations
        self.max_constraint_violation = float(traj.max_violation)
        pr = self.problem
        cost = pr.time_weight * self.final_time
        if pr.mayer is not None:
            cost += float(pr.mayer(self.x[-1], self.final_time)[0])
        if pr.running is not None:
            h = np.diff(self.t)
            cost += float(np.sum(h * pr.running(self.x[:-1], self.u[:-1])[0]))
        self.cost = cost
        ok_c = self.max_constraint_violation <= self.tol
        self.success = bool(self.optimizer_success and ok_c)
        self.status = 0 if self.success else (2 if not ok_c else 1)
        msg = self.optimizer_message
        if not ok_c:
            worst = max(self.violations, key=self.violations.get)
            msg += f"; constraint '{worst}' violated by {self.violations[worst]:.3g} (scaled) > tol {self.tol:g}"
        self.message = msg
        self.switch_time = None
        if pr.switch_input is not None:
            j = pr.model.input_index(pr.switch_input)
            self.switch_time = switch_time(self.controls[:, j], pr.u_lo[j], pr.u_hi[j], self.final_time)

    @property
    def model(self):
        return self.problem.model

    def to_pandas(self) -> pd.DataFrame:
        """Fine-grid trajectory: time index, one column per state and input."""
        m = self.problem.model
        cols = {n: self.x[:, i] for i, n in enumerate(m.state_names)}
        cols.update({n: self.u[:, i] for i, n in enumerate(m.input_names)})
        return pd.DataFrame(cols, index=pd.Index(self.t, name="time"))

    def summary(self) -> pd.DataFrame:
        """Headline numbers, one row each (``value`` and ``unit``): final time, switch time, cost, largest
        constraint violation, iterations, evaluations, wall time."""
        rows = [("final_time", self.final_time, "s"), ("switch_time", self.switch_time, "s"),
                ("cost", self.cost, ""), ("max_constraint_violation", self.max_constraint_violation, "scaled"),
                ("n_intervals", self.problem.n_intervals, ""), ("nit", self.nit, ""), ("nfev", self.nfev, ""),
                ("wall_time", self.wall_time, "s")]
        return pd.DataFrame({"value": [np.nan if v is None else float(v) for _, v, _ in rows],
                             "unit": [u for _, _, u in rows]}, index=pd.Index([k for k, _, _ in rows], name="quantity"))

    def _html_title(self) -> str:
        return f"Optimal control: {self.problem.name} ({self.method})"

    def to_dict(self) -> dict:
        """JSON-ready record (what ``shipid plan`` writes)."""
        m = self.problem.model
        return {
            "problem": self.problem.name,
            "model": m.name,
            "method": self.method,
            "success": self.success,
            "status": self.status,
            "message": self.message,
            "final_time_s": self.final_time,
            "switch_time_s": self.switch_time,
            "cost": self.cost,
            "max_constraint_violation": self.max_constraint_violation,
            "constraint_violations": self.violations,
            "nit": self.nit,
            "nfev": self.nfev,
            "wall_time_s": self.wall_time,
            "n_intervals": self.problem.n_intervals,
            "controls": {n: self.controls[:, j].tolist() for j, n in enumerate(m.input_names)},
            "final_state": dict(zip(m.state_names, map(float, self.x[-1]))),
        }

    def plot(self, ax=None):
        """States and inputs against time (one axes each, angles in degrees); returns the axes."""
        m = self.problem.model
        names = list(m.state_names) + list(m.input_names)
        axs = axes_column(ax, len(names), height=1.3)
        df = self.to_pandas()
        plot_series(axs, df.index.to_numpy(), df, names, m.units)
        axs[-1].set_xlabel("time [s]")
        return axs
