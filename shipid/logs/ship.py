"""Ship particulars that travel with a log, and ship files (JSON/YAML)."""
from __future__ import annotations

import dataclasses
import json
import math
import os
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from ._text import load_mapping_file

# --------------------------------------------------------------------------------------
# ship particulars
# --------------------------------------------------------------------------------------


@dataclass
class ShipParticulars:
    """Main particulars that travel with a log (SI units).

    Ship files and ``from_dict`` accept the field names below and the usual
    symbols for them (case-sensitive): ``Lpp``/``L`` (lpp), ``B`` (beam),
    ``T``/``d`` (draught), ``Cb`` (block_coefficient), ``m`` (mass),
    ``xG``/``x_G`` (x_g), ``D_p``/``Dp`` (propeller_diameter), ``A_R``
    (rudder_area), ``A_T`` (transverse_area), ``A_L`` (lateral_area),
    ``U0``/``V`` (design_speed), ``nabla`` (displacement).

    Parameters
    ----------
    lpp : float
        Length between perpendiculars [m]; required, finite and > 0.
    beam, draught : float, optional
        Breadth and draught [m].
    displacement : float, optional
        Displacement volume [m^3].
    design_speed : float, optional
        Design (approach) speed [m/s].
    rudder_rate : float, optional
        Maximum rudder rate [rad/s].
    rudder_max : float, optional
        Maximum rudder angle [rad].
    name : str, optional
        Ship name, e.g. ``"KVLCC2"``.
    scale : float, optional
        Model scale factor (1 for full scale).
    block_coefficient : float, optional
        Block coefficient C_b = displacement / (lpp B T) [-], in (0, 1].
    mass : float, optional
        Mass [kg].
    x_g : float, optional
        Longitudinal centre of gravity from midship, forward positive [m] (may be negative).
    propeller_diameter : float, optional
        Propeller diameter D_p [m].
    rudder_area : float, optional
        Rudder area A_R [m^2].
    transverse_area, lateral_area : float, optional
        Transverse (frontal) and lateral projected areas above water A_T, A_L
        [m^2] (wind loads).
    extra : dict, optional
        Anything else (free-form, JSON-serialisable), e.g. ``{"source": ...}``.
    """

    lpp: float
    beam: float | None = None
    draught: float | None = None
    displacement: float | None = None
    design_speed: float | None = None
    rudder_rate: float | None = None
    rudder_max: float | None = None
    name: str | None = None
    scale: float | None = None
    block_coefficient: float | None = None
    mass: float | None = None
    x_g: float | None = None
    propeller_diameter: float | None = None
    rudder_area: float | None = None
    transverse_area: float | None = None
    lateral_area: float | None = None
    extra: dict = field(default_factory=dict)

    _POSITIVE = ("lpp", "beam", "draught", "displacement", "design_speed", "rudder_rate", "rudder_max", "scale",
                 "block_coefficient", "mass", "propeller_diameter", "rudder_area", "transverse_area", "lateral_area")
    _SIGNED = ("x_g",)
    #: usual symbols accepted in ship files -> field name
    ALIASES = {"Lpp": "lpp", "L": "lpp", "LPP": "lpp", "B": "beam", "T": "draught", "d": "draught",
               "draft": "draught", "Cb": "block_coefficient", "CB": "block_coefficient", "cb": "block_coefficient",
               "m": "mass", "xG": "x_g", "x_G": "x_g", "xg": "x_g", "D_p": "propeller_diameter",
               "Dp": "propeller_diameter", "A_R": "rudder_area", "AR": "rudder_area", "A_T": "transverse_area",
               "AT": "transverse_area", "A_L": "lateral_area", "AL": "lateral_area", "U0": "design_speed",
               "V": "design_speed", "nabla": "displacement"}

    def __post_init__(self):
        for f in self._POSITIVE + self._SIGNED:
            val = getattr(self, f)
            if val is None and f != "lpp":
                continue
            if isinstance(val, (bool, np.bool_)) or not isinstance(val, (int, float, np.integer, np.floating, str)):
                raise ValueError(f"ship particulars: {f} = {val!r} is not a number; give {f} in SI units")
            try:
                fv = float(val)
            except (TypeError, ValueError):
                raise ValueError(f"ship particulars: {f} = {val!r} is not a number; give {f} in SI units") from None
            if not math.isfinite(fv) or (fv <= 0 and f not in self._SIGNED):
                raise ValueError(f"ship particulars: {f} = {val!r} must be finite" +
                                 ("" if f in self._SIGNED else " and > 0"))
            setattr(self, f, fv)
        if self.rudder_max is not None and self.rudder_max > math.pi / 2:
            raise ValueError(f"ship particulars: rudder_max = {self.rudder_max} rad is beyond 90 deg; "
                             "give it in radians (35 deg = 0.6109 rad)")
        if self.rudder_rate is not None and self.rudder_rate > 3.0:
            raise ValueError(f"ship particulars: rudder_rate = {self.rudder_rate} rad/s looks like deg/s; "
                             "give it in rad/s (2.32 deg/s = 0.0405 rad/s)")
        if self.block_coefficient is not None and self.block_coefficient > 1.0:
            raise ValueError(f"ship particulars: block_coefficient = {self.block_coefficient:g} must lie in (0, 1]")
        if self.extra is None:
            self.extra = {}
        if not isinstance(self.extra, dict):
            raise ValueError(f"ship particulars: extra must be a dict, got {type(self.extra).__name__}")
        if self.name is not None:
            self.name = str(self.name)

    def to_dict(self) -> dict:
        """Plain dict (JSON-serialisable); fields that are None are left out."""
        d = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        return {k: v for k, v in d.items() if v is not None and not (k == "extra" and not v)}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any], *, source: str = "ship particulars") -> "ShipParticulars":
        """Build from a mapping; unknown keys are an error (typos must not pass silently)."""
        if not isinstance(d, Mapping):
            raise ValueError(f"{source}: expected a mapping of particulars, got {type(d).__name__}")
        known = [f.name for f in dataclasses.fields(cls)]
        unknown = sorted(str(k) for k in d if k not in known and k not in cls.ALIASES)
        if unknown:
            raise ValueError(f"{source}: unknown field(s) {unknown}; known fields are {known} and the symbols "
                             f"{sorted(cls.ALIASES)} (put anything else under 'extra')")
        given: dict[str, str] = {}
        out: dict[str, Any] = {}
        for k, v in d.items():
            f = cls.ALIASES.get(k, k)
            if f in given:
                raise ValueError(f"{source}: '{given[f]}' and '{k}' both give {f}; keep one")
            given[f] = k
            out[f] = v
        d = out
        if "lpp" not in d:
            raise ValueError(f"{source}: 'lpp' (length between perpendiculars, m) is required")
        try:
            return cls(**dict(d))
        except ValueError as exc:
            raise ValueError(f"{source}: {exc}".replace("ship particulars: ", "")) from None

    def __str__(self) -> str:
        s = f"{self.name or 'ship'} Lpp {self.lpp:g} m"
        if self.beam:
            s += f", B {self.beam:g} m"
        if self.draught:
            s += f", T {self.draught:g} m"
        if self.scale and self.scale != 1:
            s += f", scale 1:{self.scale:g}"
        return s


def read_ship(path: str | os.PathLike) -> ShipParticulars:
    """Read ship particulars from a JSON (or YAML, with PyYAML installed) file.

    The file holds one mapping with the fields of :class:`ShipParticulars`
    (SI units; ``lpp`` required), e.g. ``{"name": "KVLCC2", "lpp": 320}``.
    """
    p = Path(path)
    d = load_mapping_file(p, "ship file")
    return ShipParticulars.from_dict(d, source=f"`{p.name}`")


def _bundled_ship(name: str) -> ShipParticulars:
    text = resources.files("shipid").joinpath("data_ships", f"{name}.json").read_text("utf-8")
    return ShipParticulars.from_dict(json.loads(text), source=f"bundled ship {name}")


def _as_ship(ship, lpp) -> ShipParticulars | None:
    if ship is not None and not isinstance(ship, ShipParticulars):
        if isinstance(ship, Mapping):
            ship = ShipParticulars.from_dict(ship)
        else:
            ship = read_ship(ship)
    if lpp is not None:
        if ship is None:
            ship = ShipParticulars(lpp=lpp)
        else:
            ship = dataclasses.replace(ship, lpp=lpp)
    return ship
