"""What ``shipid fit --wind --current`` builds (kept here so the command stays a thin layer)."""
from __future__ import annotations

import json
from pathlib import Path

from .model import with_environment
from .wind import WindForce, true_wind_from_apparent

__all__ = ["environment_model", "wind_geometry", "add_true_wind"]


def wind_geometry(spec: str, logs=()) -> WindForce:
    """A :class:`WindForce` from ``"esso-osaka-3m"``, a JSON file of its fields, or ``"auto"`` (the logs'
    ship: the Esso Osaka 3 m model is the only ship whose full above-water geometry is shipped)."""
    if spec == "auto":
        ship = getattr(logs[0], "ship", None) if logs else None
        name = str(getattr(ship, "name", "") or "").lower()
        if "esso" in name:
            return WindForce.esso_osaka_3m()
        raise ValueError("--wind: the logs' ship has no shipped above-water geometry; give --wind esso-osaka-3m or "
                         "--wind FILE.json with lpp, breadth, A_T, A_L, A_OD, C, C_BR, H_BR, H_C (m, m^2)")
    if spec == "esso-osaka-3m":
        return WindForce.esso_osaka_3m()
    p = Path(spec)
    if not p.is_file():
        raise ValueError(f"--wind {spec}: not 'esso-osaka-3m' and no such file")
    try:
        doc = json.loads(p.read_text(encoding="utf-8"))
    except json.JSONDecodeError as exc:
        raise ValueError(f"--wind {spec}: not valid JSON ({exc.msg} at line {exc.lineno})") from None
    return WindForce.from_mapping(doc)


def environment_model(model, logs, *, wind=None, current=None):
    """``(model with environment, identifier keyword arguments)`` for the fit command."""
    geom = wind_geometry(wind, logs) if wind else None
    if geom is not None:
        for lg in logs:
            data = getattr(lg, "data", lg)
            miss = [c for c in ("wind_speed_true", "wind_dir_true") if c not in data.columns]
            if miss and {"wind_speed_rel", "wind_dir_rel", "psi", "u", "v"} <= set(data.columns):
                add_true_wind(data)  # converted at the edge (in memory; the file is not touched)
                miss = []
            if miss:
                raise ValueError(f"--wind: log '{getattr(lg, 'name', '?')}' has no channel(s) {miss}; read it with a "
                                 "schema that maps the wind columns (e.g. --schema esso-frt) or --columns")
    env = with_environment(model, wind=geom, current=current)
    return env, env.identifier_settings()


def add_true_wind(frame) -> None:
    """Add ``wind_speed_true``, ``wind_dir_true`` to a log frame that has only the apparent wind
    (``wind_speed_rel``, ``wind_dir_rel``), using its ``psi, u, v`` as the ship's motion over ground
    (:func:`~shipid.environment.wind.true_wind_from_apparent`; right for GNSS-based velocities)."""
    V, d = true_wind_from_apparent(frame["wind_speed_rel"].to_numpy(float), frame["wind_dir_rel"].to_numpy(float),
                                   frame["psi"].to_numpy(float), frame["u"].to_numpy(float), frame["v"].to_numpy(float))
    frame["wind_speed_true"], frame["wind_dir_true"] = V, d
