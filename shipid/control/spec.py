"""Problems from JSON (``shipid plan PROBLEM.json``) and time-optimal
manoeuvres for identified ship models.

PROBLEM.json (every key except ``model``/``fit_result`` and ``input_bounds``
is optional; SI units, angles in rad)::

    {
      "model": "kcs-response",            # registered model name ...
      "params": "synthetic-truth",        # ... with a parameter-set name or {name: value}
      "fit_result": "fit.json",           # ... or a result JSON of `shipid fit` (model + coef)
      "x0": {"u": 1.7},                   # initial state (unnamed states 0)
      "u_initial": {"delta": 0, "n": 10}, # input before t = 0 (start of rate limits)
      "input_bounds": {"delta": [-0.6109, 0.6109], "n": [5, 13]},
      "input_rate_bounds": {"delta": 0.2932},
      "state_bounds": {"r": [-0.1, 0.1]},
      "terminal": {"psi": 1.5708, "r": 0.0},
      "terminal_bounds": {},
      "final_time": null, "tf_guess": 30, "tf_bounds": [1, 600],
      "n_intervals": 20, "substeps": 4, "u_guess": {"delta": 0.3, "n": 10},
      "state_scale": {"psi": 0.1}, "switch_input": null, "name": "kcs-90"
    }
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .._io import (as_int, as_mapping, as_number, as_string, check_keys, read_json, short)
from ..identify.result import model_from
from ..models import get_model
from .problem import Problem, check_problem_size

__all__ = ["load_problem", "problem_from_dict", "kcs_turn_problem", "check_problem_size"]

_KEYS = {"model", "params", "fit_result", "x0", "u_initial", "input_bounds", "input_rate_bounds", "state_bounds",
         "terminal", "terminal_bounds", "final_time", "tf_guess", "tf_bounds", "n_intervals", "substeps", "u_guess",
         "state_scale", "switch_input", "name", "time_weight", "model_options"}


def _name_numbers(doc, key, where, *, positive=False):
    val = doc.get(key)
    if val is None:
        return {}
    out = {}
    for name, v in as_mapping(val, f"{where}: {key}", '{"psi": 1.57}').items():
        out[name] = as_number(v, f"{where}: {key}[{short(name, 20)}]", low=0.0 if positive else None,
                              low_open=positive)
    return out


def _vector(doc, key, where):
    """A state/input vector: ``{name: value}`` or a list of numbers (None when absent)."""
    val = doc.get(key)
    if val is None:
        return None
    if isinstance(val, list):
        return [as_number(v, f"{where}: {key}[{i}]") for i, v in enumerate(val)]
    return _name_numbers(doc, key, where)


def _pairs(doc, key, where):
    out = {}
    for name, val in as_mapping(doc.get(key) or {}, f"{where}: {key}", '{"delta": [-0.61, 0.61]}').items():
        w = f"{where}: {key}[{short(name, 20)}]"
        if not (isinstance(val, list) and len(val) == 2):
            raise ValueError(f"{w} must be [lo, hi], got {short(val, 40)}")
        lo, hi = (None if v is None else as_number(v, w) for v in val)
        if lo is not None and hi is not None and lo > hi:
            raise ValueError(f"{w}: lo {lo:g} > hi {hi:g}; give [lo, hi] with lo <= hi")
        out[name] = (lo, hi)
    return out


def problem_from_dict(doc: dict, *, where: str = "problem", base_dir: Path | None = None) -> Problem:
    """Build a :class:`Problem` from the JSON structure above (``where`` names the file in errors).

    Every key is type-checked (hand-written checks, one-line errors naming the
    key); unknown keys are refused; ``n_intervals`` and ``substeps`` are bounded
    so that the solvers' memory stays below :func:`memory_limit_bytes`
    (:func:`check_problem_size`).
    """
    if not isinstance(doc, dict):
        raise ValueError(f"{where}: expected a JSON object at the top level")
    check_keys(doc, _KEYS, where)
    if "fit_result" in doc:
        p = Path(as_string(doc["fit_result"], f"{where}: fit_result"))
        if base_dir is not None and not p.is_absolute():
            p = base_dir / p
        if not p.is_file():
            raise ValueError(f"{where}: fit_result file '{p}' not found; give a path relative to the problem file")
        model = model_from(p)[0]
    elif "model" in doc:
        name = as_string(doc["model"], f"{where}: model")
        params = doc.get("params")
        if params is not None and not isinstance(params, str):
            params = _name_numbers(doc, "params", where)
        opts = as_mapping(doc.get("model_options") or {}, f"{where}: model_options", '{"lpp": 320}')
        try:
            model = get_model(name, params, **opts)
        except TypeError as exc:
            raise ValueError(f"{where}: model_options {short(opts, 60)}: {exc}") from None
        except ValueError as exc:
            if opts and "could not convert" in str(exc):
                raise ValueError(f"{where}: model_options {short(opts, 60)}: every value must be a number ({exc})") from None
            raise ValueError(f"{where}: {exc}") from None
    else:
        raise ValueError(f"{where}: give 'model' (+ optional 'params') or 'fit_result'")
    if "input_bounds" not in doc:
        raise ValueError(f"{where}: 'input_bounds' is required, e.g. {{\"delta\": [-0.61, 0.61], \"n\": [5, 13]}}")
    lohi = _pairs(doc, "input_bounds", where)
    u_guess = doc.get("u_guess")
    if isinstance(u_guess, dict):
        g = _name_numbers(doc, "u_guess", where)
        u_guess = [g.get(n, (lohi[n][0] + lohi[n][1]) / 2 if n in lohi and None not in lohi[n] else 0.0)
                   for n in model.input_names]
    elif isinstance(u_guess, list):
        try:
            u_guess = np.asarray(u_guess, dtype=float)
        except (TypeError, ValueError):
            raise ValueError(f"{where}: u_guess must be {{name: value}}, a list of numbers or one list per interval") from None
    elif u_guess is not None:
        raise ValueError(f"{where}: u_guess must be {{name: value}} or a list, got {short(u_guess, 40)}")
    switch = doc.get("switch_input")
    kw = dict(
        model=model, x0=_vector(doc, "x0", where) or {}, input_bounds=lohi,
        final_time=as_number(doc.get("final_time"), f"{where}: final_time", low=0.0, low_open=True, allow_none=True),
        state_bounds=_pairs(doc, "state_bounds", where), terminal=_name_numbers(doc, "terminal", where),
        terminal_bounds=_pairs(doc, "terminal_bounds", where),
        input_rate_bounds=_name_numbers(doc, "input_rate_bounds", where, positive=True),
        u_initial=_vector(doc, "u_initial", where), u_guess=u_guess,
        state_scale=_name_numbers(doc, "state_scale", where, positive=True),
        name=as_string(doc.get("name", where), f"{where}: name"),
        switch_input=None if switch is None else as_string(switch, f"{where}: switch_input"),
    )
    if "tf_guess" in doc:
        kw["tf_guess"] = as_number(doc["tf_guess"], f"{where}: tf_guess", low=0.0, low_open=True)
    if "time_weight" in doc:
        kw["time_weight"] = as_number(doc["time_weight"], f"{where}: time_weight", low=0.0)
    if "tf_bounds" in doc:
        tb = doc["tf_bounds"]
        if not (isinstance(tb, list) and len(tb) == 2):
            raise ValueError(f"{where}: tf_bounds must be [lo, hi] in seconds, got {short(tb, 40)}")
        kw["tf_bounds"] = tuple(as_number(v, f"{where}: tf_bounds") for v in tb)
    kw["n_intervals"] = as_int(doc.get("n_intervals", 40), f"{where}: n_intervals", low=2)
    kw["substeps"] = as_int(doc.get("substeps", 4), f"{where}: substeps", low=1)
    check_problem_size(model, kw["n_intervals"], kw["substeps"], where)
    try:
        problem = Problem(**kw)
        problem.initial_controls()  # checks the shape of u_guess now, not in the solver
    except (ValueError, IndexError) as exc:
        raise ValueError(f"{where}: {exc}") from None
    return problem


def load_problem(path: str | Path) -> Problem:
    """Read a PROBLEM.json file (see the module docstring and docs/control.md)."""
    path = Path(path)
    if not path.exists():
        raise ValueError(f"problem file '{path}' not found; give paper-1, paper-2, paper-3 or a PROBLEM.json")
    doc = read_json(path, "PROBLEM.json file", advice="see docs/control.md for the format")
    return problem_from_dict(doc, where=f"{path}", base_dir=path.parent)


def kcs_turn_problem(model=None, *, heading_change_deg: float = 90.0, u0: float = 1.7, n0: float = 10.0,
                     max_rudder_deg: float = 35.0, max_rudder_rate_deg_s: float = 16.8, n_bounds: tuple = (5.0, 13.0),
                     n_intervals: int = 20, substeps: int = 4) -> Problem:
    """Minimum-time heading change of a KCS response model (identified or synthetic).

    Starts on a straight course at ``u0`` with ``n0`` and the rudder amidships;
    ends on the new heading with zero yaw rate.  Limits: rudder angle, rudder
    rate (16.8 deg/s for the 4.36 m model) on consecutive control values,
    propeller revolutions ``n_bounds`` [rps].
    """
    m = get_model("kcs-response") if model is None else model
    x0 = np.zeros(m.nx)
    x0[m.state_index("u")] = u0
    d = np.radians(max_rudder_deg)
    return Problem(
        model=m, x0=x0, input_bounds={"delta": (-d, d), "n": tuple(n_bounds)},
        input_rate_bounds={"delta": np.radians(max_rudder_rate_deg_s)}, u_initial={"delta": 0.0, "n": n0},
        terminal={"psi": np.radians(heading_change_deg), "r": 0.0}, tf_guess=30.0, tf_bounds=(1.0, 600.0),
        u_guess=[0.0, n0], n_intervals=n_intervals, substeps=substeps, state_scale={"psi": 0.1, "r": 0.01},
        name=f"kcs-{heading_change_deg:g}deg-turn",
    )
