"""The three scenarios of Ghorbani et al. as :class:`Problem` objects.

Common: the planing boat of Table 1 starts at rest at the origin; target
``x = 300 m, y = 0`` reached "stopped"; cost = final time (free).  Controls
``0 <= T <= 7.5 kN``, ``|phi_p| <= 45 deg``.  Scenarios 2 and 3 add the
constraints of eqs. (30)-(34): ``u <= 20 m/s``, ``|p| <= 10 deg/s``,
``|r| <= 15 deg/s``, ``|phi| <= 20 deg``.

"Stopped" means ``|u(t_f)| <= 0.5 m/s`` (and ``|v(t_f)| <= 0.5 m/s`` when
turning): the boat has no brake and its resistance vanishes like ``u^2`` at
rest, so reaching exactly zero speed takes infinite time (see
:mod:`shipid.control.analytic`).
"""
from __future__ import annotations

import numpy as np

from ..models import get_model
from .problem import Problem, check_problem_size

__all__ = ["paper_problem", "STOP_SPEED", "SCENARIOS"]

#: Terminal speed regarded as stopped [m/s].
STOP_SPEED = 0.5
SCENARIOS = ("paper-1", "paper-2", "paper-3")

_PATH = {"u": (None, 20.0), "p": (-np.radians(10), np.radians(10)), "r": (-np.radians(15), np.radians(15)),
         "phi": (-np.radians(20), np.radians(20))}


def paper_problem(which: str | int, *, model=None, n_intervals: int | None = None, substeps: int | None = None) -> Problem:
    """Problem of Ghorbani et al.'s scenario ``which`` (1, 2, 3 or "paper-1".."paper-3").

    Scenario 1 holds ``phi_p = 0`` (thrust is its only control, paper eqs. 23-24) and has no
    ``y`` condition (``y`` stays 0 by symmetry).

    Parameters
    ----------
    which : int or str
    model : Model, optional
        Default: ``get_model("planing-boat")`` (Table 1, Savitsky resistance).
    n_intervals, substeps : int, optional
        Control discretisation (defaults 40/4 for scenario 1, 30/6 otherwise).
    """
    key = str(which)
    key = key if key.startswith("paper-") else f"paper-{key}"
    if key not in SCENARIOS:
        raise ValueError(f"unknown scenario {which!r}; choose one of {', '.join(SCENARIOS)}")
    k = int(key[-1])
    m = get_model("planing-boat") if model is None else model
    bounds = {"T": (0.0, 7500.0), "phi_p": (-np.radians(45), np.radians(45))}
    N = n_intervals or (40 if k == 1 else 20)
    check_problem_size(m, N, substeps or (4 if k == 1 else 8), key)
    # initial guess: full thrust for the first half, then none (no knowledge of the switch)
    guess = np.zeros((N, 2))
    guess[: N // 2, 0] = 7500.0
    if k == 1:
        # the paper's scenario 1 has thrust as its only control (eqs. 23-24): phi_p is held at 0
        return Problem(model=m, x0=np.zeros(m.nx), input_bounds={"T": (0.0, 7500.0), "phi_p": (0.0, 0.0)}, tf_guess=60.0, tf_bounds=(10.0, 300.0),
                       terminal={"x": 300.0}, terminal_bounds={"u": (-STOP_SPEED, STOP_SPEED)},
                       u_guess=guess, n_intervals=N, substeps=substeps or 4,
                       name=key, switch_input="T", state_scale={"x": 10.0, "y": 10.0},
                       # single shooting: with phi_p fixed the lateral states are uncontrollable and
                       # their continuity rows make SLSQP's equality system rank deficient
                       shooting_segments=1)
    psi0 = np.radians(90.0 if k == 2 else 180.0)
    x0 = np.zeros(m.nx)
    x0[m.state_index("psi")] = psi0
    return Problem(model=m, x0=x0, input_bounds=bounds, tf_guess=70.0 if k == 2 else 80.0, tf_bounds=(10.0, 300.0),
                   state_bounds=_PATH, terminal={"x": 300.0, "y": 0.0},
                   terminal_bounds={"u": (-STOP_SPEED, STOP_SPEED), "v": (-STOP_SPEED, STOP_SPEED)},
                   u_guess=guess + [0.0, np.radians(5.0 if k == 2 else 10.0)], n_intervals=N,
                   substeps=substeps or 8,
                   name=key, switch_input="T", state_scale={"x": 10.0, "y": 10.0, "u": 10.0, "v": 1.0})
