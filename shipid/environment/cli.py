"""What ``shipid fit --wind --current`` builds (kept here so the command stays a thin layer)."""
from __future__ import annotations

import sys
from pathlib import Path

from .._io import read_json
from .model import WIND_INPUTS, with_environment
from .wind import WindForce, true_wind_from_apparent

__all__ = ["environment_model", "wind_geometry", "add_true_wind", "true_wind_at_edge"]


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
    if not p.exists():
        raise ValueError(f"--wind {spec}: not 'esso-osaka-3m' and no such file")
    doc = read_json(p, "wind geometry", advice="give a JSON mapping with lpp, breadth, A_T, A_L, A_OD, C, "
                    "C_BR, H_BR, H_C")
    return WindForce.from_mapping(doc)


def environment_model(model, logs, *, wind=None, current=None):
    """``(model with environment, identifier keyword arguments)`` for the fit command."""
    geom = wind_geometry(wind, logs) if wind else None
    if geom is not None:
        true_wind_at_edge(logs, what="--wind", say=True)
    env = with_environment(model, wind=geom, current=current)
    return env, env.identifier_settings()


#: What :func:`add_true_wind` converts from: the apparent wind and the ship's heading and velocities.
APPARENT_WIND = ("wind_speed_rel", "wind_dir_rel", "psi", "u", "v")


def true_wind_at_edge(logs, *, what: str, say: bool = False) -> list:
    """Give every log (TrialLog or DataFrame) the true-wind channels ``wind_speed_true, wind_dir_true``
    a wind-aware model takes: a log that has only the apparent wind is converted in memory
    (:func:`add_true_wind`; its file is not touched), with one line on stderr per log when ``say``.
    Returns the logs converted.

    Raises
    ------
    ValueError
        ``what: `FILE` has no channel(s) [...]``: neither the true wind nor what the conversion
        needs, with the missing channels and how to map them.
    """
    converted = []
    for lg in logs:
        data = getattr(lg, "data", lg)
        cols = set(data.columns)
        miss = [c for c in WIND_INPUTS if c not in cols]
        if not miss:
            continue
        lack = [c for c in APPARENT_WIND if c not in cols]
        path = getattr(lg, "path", None)
        name = getattr(lg, "name", None) or data.attrs.get("name", "?")
        where = f"`{path.name}`" if path is not None else f"log '{name}'"
        if not lack:
            add_true_wind(data)
            converted.append(lg)
            if say:
                print(f"note: {where}: true wind converted from the apparent wind (wind_speed_rel, wind_dir_rel) "
                      "with the logged psi, u, v as the motion over ground (in memory; the file is unchanged)",
                      file=sys.stderr)
            continue
        raise ValueError(f"{what}: {where} has no channel(s) {miss}, nor {lack} to convert from; use "
                         "--schema esso-frt or --columns wind_speed_true=COL,wind_dir_true=COL (or the _rel pair)")
    return converted


def add_true_wind(frame) -> None:
    """Add ``wind_speed_true``, ``wind_dir_true`` to a log frame that has only the apparent wind
    (``wind_speed_rel``, ``wind_dir_rel``), using its ``psi, u, v`` as the ship's motion over ground
    (:func:`~shipid.environment.wind.true_wind_from_apparent`; right for GNSS-based velocities)."""
    V, d = true_wind_from_apparent(frame["wind_speed_rel"].to_numpy(float), frame["wind_dir_rel"].to_numpy(float),
                                   frame["psi"].to_numpy(float), frame["u"].to_numpy(float), frame["v"].to_numpy(float))
    frame["wind_speed_true"], frame["wind_dir_true"] = V, d
