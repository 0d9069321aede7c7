"""Routing problems as JSON (the ``shipid route PROBLEM.json`` input).

Two problem types; units SI (m, m/s, s) unless ``"units": "nautical"`` (Zermelo
only: nm, kn, h).  Positions are local east/north metres, or ``*_lonlat``
pairs in degrees for the PSO problem.

Zermelo::

    {"type": "zermelo", "speed": 1.0, "start": [x, y], "target": [x, y],
     "current": FIELD, "solver": "pmp" | "transcription" | "both",
     "units": "si" | "nautical", "n": 40}

PSO (seed 003)::

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
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd

from .fields import (AffineField, Field, GridField, PiecewiseTimeField, SumField, UniformField, VortexField,
                     linear_shear)

__all__ = ["field_from_spec", "load_problem_spec", "zermelo_from_spec", "usv_from_spec", "vessel_from_spec"]


def _need(spec: dict, key: str, where: str):
    if key not in spec:
        raise ValueError(f"{where}: missing key '{key}'")
    return spec[key]


def _vec(value, where: str, n: int = 2) -> np.ndarray:
    try:
        arr = np.asarray(value, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise ValueError(f"{where}: expected {n} numbers, got {value!r}") from None
    if arr.size != n or not np.all(np.isfinite(arr)):
        raise ValueError(f"{where}: expected {n} finite numbers, got {value!r}")
    return arr


def _num(value, where: str) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{where}: expected a number, got {value!r}") from None
    if not np.isfinite(v):
        raise ValueError(f"{where}: expected a finite number, got {value!r}")
    return v


def field_from_spec(spec, where: str = "field", base_dir: Path | None = None) -> Field:
    """Build a :class:`~shipid.routing.fields.Field` from its JSON description (module docstring)."""
    if spec is None:
        return UniformField()
    if not isinstance(spec, dict):
        raise ValueError(f"{where}: expected an object with a 'type', got {spec!r}")
    kind = _need(spec, "type", where)
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
        G = np.asarray(_need(spec, "G", where), dtype=float)
        if G.shape != (2, 2):
            raise ValueError(f"{where}.G: expected a 2x2 matrix, got {spec['G']!r}")
        return AffineField(G, _vec(spec.get("w0", [0, 0]), f"{where}.w0"), _vec(spec.get("origin", [0, 0]), f"{where}.origin"))
    if kind == "vortex":
        return VortexField(_num(_need(spec, "gamma", where), f"{where}.gamma"), _num(_need(spec, "rc", where), f"{where}.rc"),
                           _vec(spec.get("center", [0, 0]), f"{where}.center"))
    if kind == "grid_csv":
        path = Path(_need(spec, "path", where))
        if base_dir is not None and not path.is_absolute():
            path = base_dir / path
        if not path.exists():
            raise ValueError(f"{where}.path: file {path} does not exist")
        df = pd.read_csv(path)
        return GridField.from_dataframe(df, x=spec.get("x", "x"), y=spec.get("y", "y"), u=spec.get("u", "u"),
                                        v=spec.get("v", "v"), t=spec.get("t"), outside=spec.get("outside", "nearest"),
                                        name=str(path))
    if kind == "piecewise":
        fields = [field_from_spec(f, f"{where}.fields[{i}]", base_dir) for i, f in enumerate(_need(spec, "fields", where))]
        return PiecewiseTimeField(_need(spec, "times", where), fields)
    if kind == "sum":
        return SumField([field_from_spec(f, f"{where}.fields[{i}]", base_dir) for i, f in enumerate(_need(spec, "fields", where))])
    raise ValueError(f"{where}.type: unknown field type {kind!r}; use uniform, linear_shear, affine, vortex, grid_csv, piecewise or sum")


def load_problem_spec(path) -> tuple[dict, Path]:
    """Read and minimally validate a problem JSON; returns ``(spec, folder)``."""
    path = Path(path)
    if not path.exists():
        raise ValueError(f"{path}: no such problem file; use zermelo-paper, pso-paper or a JSON problem")
    try:
        spec = json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as exc:
        raise ValueError(f"{path}: not valid JSON ({exc.msg} at line {exc.lineno} column {exc.colno})") from None
    if not isinstance(spec, dict) or spec.get("type") not in ("zermelo", "pso"):
        raise ValueError(f"{path}: top-level 'type' must be 'zermelo' or 'pso'")
    return spec, path.parent


def zermelo_from_spec(spec: dict, where: str = "problem", base_dir: Path | None = None):
    """Build a :class:`~shipid.routing.zermelo.ZermeloProblem` from a ``"type": "zermelo"`` spec."""
    from .zermelo import ZermeloProblem

    units = spec.get("units", "si")
    if units not in ("si", "nautical"):
        raise ValueError(f"{where}.units: expected 'si' or 'nautical', got {units!r}")
    return ZermeloProblem(_num(_need(spec, "speed", where), f"{where}.speed"),
                          field_from_spec(spec.get("current"), f"{where}.current", base_dir),
                          _vec(_need(spec, "start", where), f"{where}.start"),
                          _vec(_need(spec, "target", where), f"{where}.target"),
                          _num(spec.get("t0", 0.0), f"{where}.t0"))


def vessel_from_spec(spec, where: str = "vessel", base_dir: Path | None = None):
    """Speed-power model from ``{"type": "paper"}`` or ``{"type": "model", ...}`` (module docstring)."""
    from .energy import ModelSpeedPower, PaperUSVModel

    if spec is None or spec.get("type", "paper") == "paper":
        return PaperUSVModel()
    if spec.get("type") != "model":
        raise ValueError(f"{where}.type: expected 'paper' or 'model', got {spec.get('type')!r}")
    from ..identify.result import model_from
    from ..models import get_model

    if "result" in spec:
        rpath = Path(spec["result"])
        if base_dir is not None and not rpath.is_absolute():
            rpath = base_dir / rpath
        if not rpath.exists():
            raise ValueError(f"{where}.result: file {rpath} does not exist")
        model, _ = model_from(rpath)
    elif spec.get("model") is not None:
        model = get_model(spec["model"], spec.get("params"))
    else:
        raise ValueError(f"{where}: give 'model' (a registered model name) or 'result' (a shipid fit JSON)")
    n = _num(_need(spec, "n", where), f"{where}.n")
    cp = _num(_need(spec, "power_coefficient", where), f"{where}.power_coefficient")
    return ModelSpeedPower(model, n, cp)


def usv_from_spec(spec: dict, where: str = "problem", base_dir: Path | None = None):
    """Build a :class:`~shipid.routing.pso.USVProblem` from a ``"type": "pso"`` spec."""
    from .pso import Obstacle, USVProblem, lonlat_to_local

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
    for i, o in enumerate(_need(spec, "obstacles", where)):
        w = f"{where}.obstacles[{i}]"
        if not isinstance(o, dict):
            raise ValueError(f"{w}: expected an object with x, y (or lon, lat) and radius")
        if "lon" in o:
            if origin is None:
                raise ValueError(f"{w}: lon/lat obstacles need start_lonlat")
            c = lonlat_to_local(_num(o["lon"], f"{w}.lon"), _num(_need(o, "lat", w), f"{w}.lat"), *origin)
        else:
            c = np.array([_num(_need(o, "x", w), f"{w}.x"), _num(_need(o, "y", w), f"{w}.y")])
        obstacles.append(Obstacle(float(c[0]), float(c[1]), _num(_need(o, "radius", w), f"{w}.radius")))
    return USVProblem(start, goal, obstacles,
                      current=field_from_spec(spec.get("current"), f"{where}.current", base_dir),
                      wind=field_from_spec(spec.get("wind"), f"{where}.wind", base_dir),
                      vessel=vessel_from_spec(spec.get("vessel"), f"{where}.vessel", base_dir),
                      r_min=_num(spec.get("r_min", 15.0), f"{where}.r_min"),
                      kinematics=spec.get("kinematics", "paper"),
                      n_sub=int(spec.get("n_sub", 1)), origin=origin)
