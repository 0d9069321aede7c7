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

import json
from pathlib import Path

import numpy as np

from ..models import get_model
from .problem import Problem

__all__ = ["load_problem", "problem_from_dict", "kcs_turn_problem"]

_KEYS = {"model", "params", "fit_result", "x0", "u_initial", "input_bounds", "input_rate_bounds", "state_bounds",
         "terminal", "terminal_bounds", "final_time", "tf_guess", "tf_bounds", "n_intervals", "substeps", "u_guess",
         "state_scale", "switch_input", "name", "time_weight", "model_options"}


def problem_from_dict(doc: dict, *, where: str = "problem", base_dir: Path | None = None) -> Problem:
    """Build a :class:`Problem` from the JSON structure above (``where`` names the file in errors)."""
    if not isinstance(doc, dict):
        raise ValueError(f"{where}: expected a JSON object at the top level")
    unknown = sorted(set(doc) - _KEYS)
    if unknown:
        raise ValueError(f"{where}: unknown key(s) {unknown}; allowed keys are {sorted(_KEYS)}")
    if "fit_result" in doc:
        p = Path(doc["fit_result"])
        if base_dir is not None and not p.is_absolute():
            p = base_dir / p
        try:
            fit = json.loads(p.read_text(encoding="utf-8"))
        except FileNotFoundError:
            raise ValueError(f"{where}: fit_result file '{p}' not found; give a path relative to the problem file") from None
        except json.JSONDecodeError as exc:
            raise ValueError(f"{where}: fit_result '{p}' is not valid JSON ({exc})") from None
        if "model" not in fit or "coef" not in fit:
            raise ValueError(f"{where}: fit_result '{p}' needs keys 'model' and 'coef' (a `shipid fit` result)")
        from ..identify.result import FitResult

        # the result's model_options carry the ship it was fitted at (lpp, particulars)
        model = FitResult.from_dict(fit, source=str(p)).to_model()
    elif "model" in doc:
        model = get_model(doc["model"], doc.get("params"), **dict(doc.get("model_options", {})))
    else:
        raise ValueError(f"{where}: give 'model' (+ optional 'params') or 'fit_result'")
    if "input_bounds" not in doc:
        raise ValueError(f"{where}: 'input_bounds' is required, e.g. {{\"delta\": [-0.61, 0.61], \"n\": [5, 13]}}")

    def pairs(key):
        out = {}
        for name, val in dict(doc.get(key, {})).items():
            if not (isinstance(val, (list, tuple)) and len(val) == 2):
                raise ValueError(f"{where}: {key}['{name}'] must be [lo, hi], got {val!r}")
            out[name] = tuple(None if v is None else float(v) for v in val)
        return out

    u_guess = doc.get("u_guess")
    if isinstance(u_guess, dict):
        lohi = pairs("input_bounds")
        u_guess = [float(u_guess.get(n, (lohi[n][0] + lohi[n][1]) / 2 if n in lohi else 0.0)) for n in model.input_names]
    kw = dict(
        model=model, x0=doc.get("x0", {}), input_bounds=pairs("input_bounds"),
        final_time=doc.get("final_time"), state_bounds=pairs("state_bounds"),
        terminal={k: float(v) for k, v in dict(doc.get("terminal", {})).items()},
        terminal_bounds=pairs("terminal_bounds"),
        input_rate_bounds={k: float(v) for k, v in dict(doc.get("input_rate_bounds", {})).items()},
        u_initial=doc.get("u_initial"), u_guess=u_guess, state_scale=dict(doc.get("state_scale", {})),
        name=str(doc.get("name", where)), switch_input=doc.get("switch_input"),
    )
    for k in ("tf_guess", "time_weight"):
        if k in doc:
            kw[k] = float(doc[k])
    if "tf_bounds" in doc:
        kw["tf_bounds"] = tuple(float(v) for v in doc["tf_bounds"])
    for k in ("n_intervals", "substeps"):
        if k in doc:
            kw[k] = int(doc[k])
    try:
        return Problem(**kw)
    except ValueError as exc:
        raise ValueError(f"{where}: {exc}") from None


def load_problem(path: str | Path) -> Problem:
    """Read a PROBLEM.json file (see the module docstring)."""
    path = Path(path)
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ValueError(f"problem file '{path}' not found") from None
    except json.JSONDecodeError as exc:
        raise ValueError(f"'{path}' is not valid JSON: {exc}") from None
    return problem_from_dict(doc, where=f"'{path}'", base_dir=path.parent)


def kcs_turn_problem(model=None, *, heading_change_deg: float = 90.0, u0: float = 1.7, n0: float = 10.0,
                     max_rudder_deg: float = 35.0, max_rudder_rate_deg_s: float = 16.8, n_bounds: tuple = (5.0, 13.0),
                     n_intervals: int = 20, substeps: int = 4) -> Problem:
    """Minimum-time heading change of a KCS response model (identified or synthetic).

    Starts on a straight course at ``u0`` with ``n0`` and the rudder amidships;
    ends on the new heading with zero yaw rate.  Limits: rudder angle, rudder
    rate (SPEC: 16.8 deg/s for the 4.36 m model) on consecutive control values,
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
