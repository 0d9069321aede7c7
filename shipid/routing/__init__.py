"""Routing in currents: fields, Zermelo time-optimal routes, PSO energy-optimal USV planning."""
from __future__ import annotations

from .fields import (HOUR, KNOT, NM, AffineField, Field, FunctionField, GridField, PiecewiseTimeField,
                     SumField, UniformField, VortexField, as_field, course_from_math, linear_shear,
                     math_from_course)
from .energy import ModelSpeedPower, PaperUSVModel, steady_surge_speed
from .pso import (Obstacle, USVProblem, compare_planners, paper_scenario, plan, plan_dopso, plan_eopso,
                  plan_ocpso, sail)
from .zermelo import ZermeloProblem, ZermeloResult, extremal, paper_problem, solve_pmp, solve_transcription

__all__ = [
    "HOUR", "KNOT", "NM", "AffineField", "Field", "FunctionField", "GridField", "PiecewiseTimeField",
    "SumField", "UniformField", "VortexField", "as_field", "course_from_math", "linear_shear", "math_from_course",
    "ZermeloProblem", "ZermeloResult", "extremal", "paper_problem", "solve_pmp", "solve_transcription",
    "ModelSpeedPower", "PaperUSVModel", "steady_surge_speed", "Obstacle", "USVProblem", "compare_planners",
    "paper_scenario", "plan", "plan_dopso", "plan_eopso", "plan_ocpso", "sail",
]
