"""Ship particulars that travel with a log, and ship files (JSON/YAML)."""
from __future__ import annotations

import dataclasses
import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

# --------------------------------------------------------------------------------------
# ship particulars
# --------------------------------------------------------------------------------------


@dataclass
class ShipParticulars:
    """Main particulars that travel with a log (SI units).

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
    extra: dict = field(default_factory=dict)

    _POSITIVE = ("lpp", "beam", "draught", "displacement", "design_speed", "rudder_rate", "rudder_max", "scale")

    def __post_init__(self):
        for f in self._POSITIVE:
            val = getattr(self, f)
            if val is None and f != "lpp":
                continue
            try:
                fv = float(val)
            except (TypeError, ValueError):
                raise ValueError(f"ship particulars: {f} = {val!r} is not a number; give {f} in SI units") from None
            if not math.isfinite(fv) or fv <= 0:
                raise ValueError(f"ship particulars: {f} = {val!r} must be finite and > 0")
            setattr(self, f, fv)
        if self.rudder_max is not None and self.rudder_max > math.pi / 2:
            raise ValueError(f"ship particulars: rudder_max = {self.rudder_max} rad is beyond 90 deg; "
                             "give it in radians (35 deg = 0.6109 rad)")
        if self.rudder_rate is not None and self.rudder_rate > 3.0:
            raise ValueError(f"ship particulars: rudder_rate = {self.rudder_rate} rad/s looks like deg/s; "
                             "give it in rad/s (2.32 deg/s = 0.0405 rad/s)")
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
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(d) - known)
        if unknown:
            raise ValueError(f"{source}: unknown field(s) {unknown}; known fields are {sorted(known)} "
                             "(put anything else under 'extra')")
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
    from ._text import _check_path

    p = Path(path)
    _check_path(p, what="ship file")
    text = p.read_bytes()
    try:
        s = text.decode("utf-8-sig")
    except UnicodeDecodeError:
        raise ValueError(f"`{p.name}`: ship file is not UTF-8 text; write it as JSON") from None
    if p.suffix.lower() in (".yaml", ".yml"):
        try:
            import yaml  # type: ignore
        except ImportError:
            raise ValueError(f"`{p.name}`: reading YAML needs PyYAML (pip install pyyaml); "
                             "or write the ship file as JSON") from None
        try:
            d = yaml.safe_load(s)
        except yaml.YAMLError as exc:
            raise ValueError(f"`{p.name}`: not valid YAML ({' '.join(str(exc).split())})") from None
    else:
        try:
            d = json.loads(s)
        except json.JSONDecodeError as exc:
            raise ValueError(f"`{p.name}` line {exc.lineno}: not valid JSON ({exc.msg}); "
                             "write e.g. {\"name\": \"KVLCC2\", \"lpp\": 320}") from None
    return ShipParticulars.from_dict(d, source=f"`{p.name}`")


def _bundled_ship(name: str) -> ShipParticulars:
    from importlib import resources

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
