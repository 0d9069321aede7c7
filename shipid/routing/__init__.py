"""Routing in currents: fields, Zermelo time-optimal routes, PSO energy-optimal USV planning."""
from __future__ import annotations

from .fields import (HOUR, KNOT, NM, AffineField, Field, FunctionField, GridField, PiecewiseTimeField,
                     SumField, UniformField, VortexField, as_field, course_from_math, linear_shear,
                     math_from_course)
from .zermelo import ZermeloProblem, ZermeloResult, extremal, paper_problem, solve_pmp, solve_transcription

__all__ = [
    "HOUR", "KNOT", "NM", "AffineField", "Field", "FunctionField", "GridField", "PiecewiseTimeField",
    "SumField", "UniformField", "VortexField", "as_field", "course_from_math", "linear_shear", "math_from_course",
    "ZermeloProblem", "ZermeloResult", "extremal", "paper_problem", "solve_pmp", "solve_transcription",
]
