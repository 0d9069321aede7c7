"""Optimal control of protocol models: problems, an indirect (costate,
steepest descent / BFGS, LEPF) and a direct (multiple shooting, SLSQP /
trust-constr, or IPOPT through the optional CasADi extra) solver with a common
result, Ghorbani et al.'s scenarios and time-optimal manoeuvres for identified ship
models."""
from .analytic import BangBang, bang_bang_straight
from .direct import solve_direct
from .indirect import lepf, solve_indirect
from .problem import Problem, evaluate, rk4_sensitivities
from .result import ControlResult, switch_time
from .scenarios import SCENARIOS, STOP_SPEED, paper_problem
from .spec import kcs_turn_problem, load_problem, problem_from_dict

__all__ = ["Problem", "ControlResult", "solve_indirect", "solve_direct", "bang_bang_straight", "BangBang", "lepf", "evaluate",
           "rk4_sensitivities", "switch_time", "paper_problem", "SCENARIOS", "STOP_SPEED", "kcs_turn_problem", "load_problem",
           "problem_from_dict"]
