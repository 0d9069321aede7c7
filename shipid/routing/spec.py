"""Routing problems as JSON (the ``shipid route PROBLEM.json`` input).

Two problem types; units SI (m, m/s, s) unless ``"units": "nautical"`` (Zermelo
only: nm, kn, h).  Positions are local east/north metres, or ``*_lonlat``
pairs in degrees for the PSO problem.

Zermelo::

    {"type": "zermelo", "speed": 1.0, "start": [x, y], "target": [x, y],
     "current": FIELD, "solver": "pmp" | "transcription" | "both",
     "units": "si" | "nautical", "n": 40}

PSO (Li et al.)::

    {"type": "pso", "start": [x, y] | "start_lonlat": [lon, lat],
     "goal": [x, y] | "goal_lonlat": [lon, lat],
     "obstacles": [{"x": .., "y": .., "radius": ..} | {"lon": .., "lat": .., "radius": ..}],
     "current": FIELD, "wind": FIELD, "r_min": 15, "kinematics": "paper" | "crab",
     "vessel": {"type": "paper"} |
               {"type": "model", "model": "kcs-response", "params": {..} | "result": "fit.json",
                "n": 10.0, "power_coefficient": 0.04},
     "replan_times": [..], "seed": 0, "n_particles": 40, "max_iter": 150}

FIELD::

    {"type": "uniform", "velocity": [wx, wy]}
    {"type": "uniform", "speed": 1.2, "direction_deg": 0, "convention": "towards" | "from"}
    {"type": "linear_shear", "k": -0.5}
    {"type": "affine", "G": [[..], [..]], "w0": [..]}
    {"type": "vortex", "gamma": .., "rc": .., "center": [x, y]}
    {"type": "grid_csv", "path": "currents.csv", "x": "x", "y": "y", "u": "u", "v": "v", "t": null}
    {"type": "piecewise", "times": [0, 480], "fields": [FIELD, FIELD]}
    {"type": "sum", "fields": [FIELD, ...]}

(``path`` is relative to the JSON file.)  Wind fields give the air's velocity
(towards); use ``"convention": "from"`` for a meteorological direction.

``replan_times`` [s] are the times at which OCPSO measures the environment and
replans (default: the breakpoints of piecewise current/wind fields).  Every
object is checked by hand-written checks: unknown keys are refused (a typo never
silently falls back to a default), numbers must be numbers (``true`` is not 1),
counts must be whole and in range, and ``n_particles`` x ``max_iter`` is bounded
by a memory estimate.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from .._io import as_int, as_mapping, as_number, as_string, check_keys, read_json, short
from ..identify.result import model_from
from ..models import get_model
from .energy import ModelSpeedPower, PaperUSVModel
from .fields import (AffineField, Field, GridField, PiecewiseTimeField, SumField, UniformField, VortexField,
                     linear_shear)
from .pso import Obstacle, USVProblem, check_pso_size, lonlat_to_local
from .zermelo import ZermeloProblem

__all__ = ["field_from_spec", "load_problem_spec", "zermelo_from_spec", "usv_from_spec", "vessel_from_spec",
           "check_pso_settings", "check_pso_size"]


def _need(spec: dict, key: str, where: str):
    if key not in spec:
        raise ValueError(f"{where}: missing key '{key}'")
    return spec[key]


def _vec(value, where: str, n: int = 2) -> np.ndarray:
    if not (isinstance(value, list) and len(value) == n):
        raise ValueError(f"{where}: expected a list of {n} numbers, got {short(value, 40)}")
    return np.array([_num(v, f"{where}[{i}]") for i, v in enumerate(value)])


def _num(value, where: str, *, low: float | None = None, low_open: bool = False) -> float:
    return as_number(value, where, low=low, low_open=low_open)


_FIELD_KEYS = {"uniform": {"type", "velocity", "speed", "direction_deg", "convention"},
               "linear_shear": {"type", "k"}, "affine": {"type", "G", "w0", "origin"},
               "vortex": {"type", "gamma", "rc", "center"},
               "grid_csv": {"type", "path", "x", "y", "u", "v", "t", "outside"},
               "piecewise": {"type", "times", "fields"}, "sum": {"type", "fields"}}
ZERMELO_KEYS = {"type", "speed", "start", "target", "current", "solver", "units", "n", "t0"}
PSO_KEYS = {"type", "start", "start_lonlat", "goal", "goal_lonlat", "obstacles", "current", "wind", "r_min",
            "kinematics", "vessel", "replan_times", "seed", "n_particles", "max_iter", "n_sub"}
_VESSEL_KEYS = {"paper": {"type"}, "model": {"type", "model", "params", "result", "n", "power_coefficient"}}


def _list(value, where: str, what: str) -> list:
    if not isinstance(value, list):
        raise ValueError(f"{where}: expected a list of {what}, got {type(value).__name__} {short(value, 40)}")
    return value


def field_from_spec(spec, where: str = "field", base_dir: Path | None = None) -> Field:
    """Build a :class:`~shipid.routing.fields.Field` from its JSON description (module docstring)."""
    if spec is None:
        return UniformField()
    if not isinstance(spec, dict):
        raise ValueError(f"{where}: expected an object with a 'type', got {short(spec, 40)}")
    kind = _need(spec, "type", where)
    if not isinstance(kind, str) or kind not in _FIELD_KEYS:
        raise ValueError(f"{where}.type: unknown field type {short(kind, 30)}; use {', '.join(_FIELD_KEYS)}")
    check_keys(spec, _FIELD_KEYS[kind], where)
    if kind == "uniform":
        if "velocity" in spec:
            return UniformField(*_vec(spec["velocity"], f"{where}.velocity"))
        conv = spec.get("convention", "towards")
        if conv not in ("towards", "from"):
            raise ValueError(f"{where}.convention: expected 'towards' or 'from', got {conv!r}")
        return UniformField.from_speed_direction(_num(_need(spec, "speed", where), f"{where}.speed"),
                                                 np.radians(_num(_need(spec, "direction_deg", where), f"{where}.direction_deg")),
                                                 convention=conv)
    if kind == "linear_shear":
        return linear_shear(_num(_need(spec, "k", where), f"{where}.k"))
    if kind == "affine":
        G = _list(_need(spec, "G", where), f"{where}.G", "two rows")
        if len(G) != 2:
            raise ValueError(f"{where}.G: expected a 2x2 matrix, got {short(G, 40)}")
        G = np.array([_vec(row, f"{where}.G[{i}]") for i, row in enumerate(G)])
        return AffineField(G, _vec(spec.get("w0", [0, 0]), f"{where}.w0"), _vec(spec.get("origin", [0, 0]), f"{where}.origin"))
    if kind == "vortex":
        return VortexField(_num(_need(spec, "gamma", where), f"{where}.gamma"), _num(_need(spec, "rc", where), f"{where}.rc"),
                           _vec(spec.get("center", [0, 0]), f"{where}.center"))
    if kind == "grid_csv":
        path = Path(as_string(_need(spec, "path", where), f"{where}.path"))
        if base_dir is not None and not path.is_absolute():
            path = base_dir / path
        if not path.is_file():
            raise ValueError(f"{where}.path: file {path} does not exist")
        cols = {k: spec.get(k, k) for k in ("x", "y", "u", "v")}
        for k, c in cols.items():
            as_string(c, f"{where}.{k}")
        t = None if spec.get("t") is None else as_string(spec["t"], f"{where}.t")
        try:
            df = pd.read_csv(path)
        except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as exc:
            raise ValueError(f"{path}: not a readable CSV of currents ({' '.join(str(exc).split())[:120]})") from None
        missing = [c for c in [*cols.values(), t] if c is not None and c not in df.columns]
        if missing:
            raise ValueError(f"{path}: no column(s) {short(missing, 60)}; the file has {short(list(df.columns), 80)}")
        try:
            return GridField.from_dataframe(df, **cols, t=t, outside=as_string(spec.get("outside", "nearest"),
                                            f"{where}.outside"), name=str(path))
        except (TypeError, ValueError) as exc:
            raise ValueError(f"{path}: {exc}") from None
    fields = [field_from_spec(f, f"{where}.fields[{i}]", base_dir)
              for i, f in enumerate(_list(_need(spec, "fields", where), f"{where}.fields", "fields"))]
    if kind == "piecewise":
        times = [_num(t, f"{where}.times[{i}]") for i, t in enumerate(_list(_need(spec, "times", where),
                                                                             f"{where}.times", "times [s]"))]
        try:
            return PiecewiseTimeField(times, fields)
        except ValueError as exc:
            raise ValueError(f"{where}: {exc}") from None
    return SumField(fields)


def load_problem_spec(path) -> tuple[dict, Path]:
    """Read and minimally validate a problem JSON; returns ``(spec, folder)``."""
    path = Path(path)
    if not path.exists():
        raise ValueError(f"{path}: no such problem file; use paper-zermelo, paper-pso or a JSON problem")
    spec = read_json(path, "routing problem file", advice="see shipid/routing/spec.py for the format")
    if not isinstance(spec, dict) or spec.get("type") not in ("zermelo", "pso"):
        raise ValueError(f"{path}: top-level 'type' must be 'zermelo' or 'pso'")
    check_keys(spec, ZERMELO_KEYS if spec["type"] == "zermelo" else PSO_KEYS, str(path))
    if spec["type"] == "zermelo":
        if "solver" in spec and spec["solver"] not in ("pmp", "transcription", "both"):
            raise ValueError(f"{path}: 'solver' must be pmp, transcription or both, got {short(spec['solver'], 30)}")
        if "n" in spec:
            as_int(spec["n"], f"{path}: n", low=2, high=100_000)
    else:
        check_pso_settings(spec, str(path))
    return spec, path.parent


def check_pso_settings(spec: dict, where: str) -> dict:
    """``seed``, ``n_particles``, ``max_iter``, ``n_sub`` and ``replan_times`` of a PSO spec, checked;
    returns them (absent keys omitted)."""
    out = {}
    if "seed" in spec:
        out["seed"] = as_int(spec["seed"], f"{where}: seed", low=0)
    if "n_particles" in spec:
        out["n_particles"] = as_int(spec["n_particles"], f"{where}: n_particles", low=2)
    if "max_iter" in spec:
        out["max_iter"] = as_int(spec["max_iter"], f"{where}: max_iter", low=1)
    if "n_sub" in spec:
        out["n_sub"] = as_int(spec["n_sub"], f"{where}: n_sub", low=1, high=10_000)
    if "replan_times" in spec:
        times = [_num(t, f"{where}: replan_times[{i}]", low=0.0)
                 for i, t in enumerate(_list(spec["replan_times"], f"{where}: replan_times", "times [s]"))]
        if any(b <= a for a, b in zip(times, times[1:])):
            raise ValueError(f"{where}: replan_times must increase, got {short(times, 60)}")
        out["replan_times"] = times
    n_obst = len(spec["obstacles"]) if isinstance(spec.get("obstacles"), list) else 3
    check_pso_size(out.get("n_particles", 25), out.get("max_iter", 120), n_obst, where)
    return out


def zermelo_from_spec(spec: dict, where: str = "problem", base_dir: Path | None = None):
    """Build a :class:`~shipid.routing.zermelo.ZermeloProblem` from a ``"type": "zermelo"`` spec."""
    units = spec.get("units", "si")
    if units not in ("si", "nautical"):
        raise ValueError(f"{where}.units: expected 'si' or 'nautical', got {short(units, 30)}")
    return ZermeloProblem(_num(_need(spec, "speed", where), f"{where}.speed", low=0.0, low_open=True),
                          field_from_spec(spec.get("current"), f"{where}.current", base_dir),
                          _vec(_need(spec, "start", where), f"{where}.start"),
                          _vec(_need(spec, "target", where), f"{where}.target"),
                          _num(spec.get("t0", 0.0), f"{where}.t0"))


def vessel_from_spec(spec, where: str = "vessel", base_dir: Path | None = None):
    """Speed-power model from ``{"type": "paper"}`` or ``{"type": "model", ...}`` (module docstring)."""
    if spec is None:
        return PaperUSVModel()
    as_mapping(spec, where, '{"type": "paper"}')
    kind = spec.get("type", "paper")
    if not isinstance(kind, str) or kind not in _VESSEL_KEYS:
        raise ValueError(f"{where}.type: expected 'paper' or 'model', got {short(kind, 30)}")
    check_keys(spec, _VESSEL_KEYS[kind], where)
    if kind == "paper":
        return PaperUSVModel()
    if "result" in spec:
        rpath = Path(as_string(spec["result"], f"{where}.result"))
        if base_dir is not None and not rpath.is_absolute():
            rpath = base_dir / rpath
        if not rpath.exists():
            raise ValueError(f"{where}.result: file {rpath} does not exist")
        model, _ = model_from(rpath)
    elif spec.get("model") is not None:
        params = spec.get("params")
        if params is not None and not isinstance(params, str):
            params = {k: _num(v, f"{where}.params.{short(k, 20)}") for k, v in
                      as_mapping(params, f"{where}.params", '{"a1": 0.1}').items()}
        model = get_model(as_string(spec["model"], f"{where}.model"), params)
    else:
        raise ValueError(f"{where}: give 'model' (a registered model name) or 'result' (a shipid fit JSON)")
    n = _num(_need(spec, "n", where), f"{where}.n", low=0.0, low_open=True)
    cp = _num(_need(spec, "power_coefficient", where), f"{where}.power_coefficient", low=0.0, low_open=True)
    return ModelSpeedPower(model, n, cp)


def usv_from_spec(spec: dict, where: str = "problem", base_dir: Path | None = None):
    """Build a :class:`~shipid.routing.pso.USVProblem` from a ``"type": "pso"`` spec."""
    origin = None
    if "start_lonlat" in spec:
        origin = tuple(_vec(spec["start_lonlat"], f"{where}.start_lonlat"))
        start = np.zeros(2)
    else:
        start = _vec(_need(spec, "start", where), f"{where}.start")

    def pos(key):
        if f"{key}_lonlat" in spec:
            if origin is None:
                raise ValueError(f"{where}.{key}_lonlat needs start_lonlat too")
            return lonlat_to_local(*_vec(spec[f"{key}_lonlat"], f"{where}.{key}_lonlat"), *origin)
        return _vec(_need(spec, key, where), f"{where}.{key}")

    goal = pos("goal")
    obstacles = []
    for i, o in enumerate(_list(_need(spec, "obstacles", where), f"{where}.obstacles",
                                '{"x": .., "y": .., "radius": ..} objects')):
        w = f"{where}.obstacles[{i}]"
        if not isinstance(o, dict):
            raise ValueError(f"{w}: expected an object with x, y (or lon, lat) and radius")
        check_keys(o, {"lon", "lat", "radius"} if "lon" in o else {"x", "y", "radius"}, w)
        if "lon" in o:
            if origin is None:
                raise ValueError(f"{w}: lon/lat obstacles need start_lonlat")
            c = lonlat_to_local(_num(o["lon"], f"{w}.lon"), _num(_need(o, "lat", w), f"{w}.lat"), *origin)
        else:
            c = np.array([_num(_need(o, "x", w), f"{w}.x"), _num(_need(o, "y", w), f"{w}.y")])
        obstacles.append(Obstacle(float(c[0]), float(c[1]), _num(_need(o, "radius", w), f"{w}.radius",
                                                                 low=0.0, low_open=True)))
    kin = spec.get("kinematics", "paper")
    if kin not in ("paper", "crab"):
        raise ValueError(f"{where}.kinematics: expected 'paper' or 'crab', got {short(kin, 30)}")
    settings = check_pso_settings(spec, where)
    try:
        return USVProblem(start, goal, obstacles,
                          current=field_from_spec(spec.get("current"), f"{where}.current", base_dir),
                          wind=field_from_spec(spec.get("wind"), f"{where}.wind", base_dir),
                          vessel=vessel_from_spec(spec.get("vessel"), f"{where}.vessel", base_dir),
                          r_min=_num(spec.get("r_min", 15.0), f"{where}.r_min", low=0.0),
                          kinematics=kin, n_sub=settings.get("n_sub", 1), origin=origin)
    except ValueError as exc:
        if str(exc).startswith(where):
            raise
        raise ValueError(f"{where}: {exc}") from None
