"""Wind forces on a ship's above-water hull: Fujiwara's regression, and apparent/true wind conversion.

Reference
---------
T. Fujiwara, M. Ueno, T. Nimura (1998), "Estimation of wind forces and moments acting on ships",
J. Soc. Naval Architects of Japan 183:77-90 (the regression of the Fourier components below, from
wind-tunnel tests of many ship types; extended in T. Fujiwara, M. Ueno, Y. Ikeda (2005), "A new
estimation method of wind forces and moments acting on ships on the basis of physical component
models", J. Japan Soc. Naval Architects and Ocean Engineers 2:243-255).

The coefficients are written as truncated Fourier series of the apparent wind angle ``gamma``
(the direction the wind comes *from*, relative to the bow, positive from starboard: 0 = head wind,
90 deg = wind on the starboard beam)::

    C_X = X0 + X1 cos g + X3 cos 3g + X5 cos 5g           X_A = q A_T C_X        (forward +)
    C_Y = -(Y1 sin g + Y3 sin 3g + Y5 sin 5g)              Y_A = q A_L C_Y        (starboard +)
    C_N = -(N1 sin g + N2 sin 2g + N3 sin 3g)              N_A = q A_L L C_N      (bow to starboard +)

with ``q = 1/2 rho_air V_A^2``.  Fujiwara measures his angle the other way round (positive from port);
the minus signs turn his coefficients into this package's axes (a starboard beam wind pushes the ship
to port: ``C_Y < 0``).  Each component is a linear regression on ratios of the above-water geometry:
``A_T`` (transverse) and ``A_L`` (lateral projected area), ``A_OD`` (lateral area of superstructures
on deck), ``C`` (distance of the centroid of ``A_L`` from midship, forward +), ``C_BR`` (same for the
superstructure), ``H_BR`` (height of the top of the superstructure), ``H_C`` (height of the centroid of
``A_L``), ``B`` and ``L``.

The regression coefficients are those of Fujiwara et al. (1998) as transcribed in the open code of the
Osaka University group for this very ship (NAOE-5thLab, used for Wakita et al. 2022); no table of the
paper was reachable here.  ``tests/test_environment.py`` checks that they and the ``esso_osaka_3m``
geometry reproduce the ten components that group published for the 3 m model (NAOE-5thLab/
mmg-1p1r-simulator, ``MMG_params_EssoOsaka3m.csv``) to rounding, besides the physical signs and
symmetries and the magnitudes against the ranges every wind-tunnel data set shows (head-wind ``C_X``
-0.5 ... -1.0, beam ``|C_Y|`` 0.7 ... 1.1).
"""
from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import ClassVar, Mapping

import numpy as np

from ._equations import coefficients_cs, wind_force_numpy

__all__ = ["WindForce", "fujiwara_components", "apparent_wind", "true_wind_from_apparent", "WIND_PARAM_NAMES",
           "RHO_AIR"]

#: Air density [kg/m^3] (15 deg C, sea level).
RHO_AIR = 1.225

#: Names of the ten Fourier components (the parameters an identifier can estimate).
WIND_PARAM_NAMES = ("wX0", "wX1", "wX3", "wX5", "wY1", "wY3", "wY5", "wN1", "wN2", "wN3")

# Fujiwara et al. (1998) regression: component -> (constant, [(coefficient, regressor name), ...]).
_REGRESSION = {
    "wX0": (-0.330, [(0.293, "B_HBR_AT"), (0.0193, "C_HC"), (0.6820, "AOD_L2")]),
    "wX1": (-1.353, [(1.700, "AL_LB"), (2.870, "LHC_AL"), (-0.463, "LHBR_AL"), (-0.570, "AOD_AL"),
                     (-6.640, "AT_LB"), (-0.0123, "L2_AT"), (0.0202, "L_HC")]),
    "wX3": (0.830, [(-0.413, "AL_LHBR"), (-0.0827, "AL_AT"), (-0.563, "LHC_AL"), (0.804, "AOD_AL"),
                    (-5.670, "AOD_L2"), (0.0401, "C_HC"), (-0.132, "CBR_L")]),
    "wX5": (0.0372, [(-0.0075, "AL_AOD"), (-0.103, "CBR_L"), (0.0921, "AL_LB")]),
    "wY1": (0.684, [(0.717, "CBR_L"), (-3.220, "C_L"), (0.0281, "AL_AOD"), (0.0661, "C_HC"), (0.298, "AT_BHBR")]),
    "wY3": (-0.400, [(0.282, "AL_LB"), (0.307, "LHC_AL"), (0.0519, "CBR_L"), (0.0526, "B_HBR"),
                     (-0.0814, "AOD_AL"), (0.0582, "AT_BHBR")]),
    "wY5": (0.122, [(-0.166, "AL_LB"), (-0.0054, "L_HBR"), (-0.0481, "CBR_L"), (-0.0136, "B2_AT"),
                    (0.0864, "C_L"), (-0.0297, "CHC_AL")]),
    "wN1": (0.299, [(1.710, "C_L"), (0.183, "LHC_AL"), (-1.090, "AT_AL"), (-0.0442, "C_HC"), (-0.289, "AL_LB"),
                    (4.240, "AT_L2"), (-0.0646, "B2_AT"), (0.0306, "CBR_L")]),
    "wN2": (0.117, [(0.123, "CBR_L"), (-0.323, "C_L"), (0.0041, "AL_AOD"), (-0.166, "AT_B2"), (-0.0109, "L_HBR"),
                    (0.174, "AT_BHBR"), (0.214, "AL_LB"), (-1.060, "AL_L2")]),
    "wN3": (0.0230, [(0.0385, "CBR_L"), (-0.0339, "AT_BHBR"), (0.0023, "AL_AT")]),
}


def _regressors(g: "WindForce") -> dict:
    L, B, AT, AL, AOD = g.lpp, g.breadth, g.A_T, g.A_L, g.A_OD
    C, CBR, HBR, HC = g.C, g.C_BR, g.H_BR, g.H_C
    return {
        "B_HBR_AT": B * HBR / AT, "C_HC": C / HC, "AOD_L2": AOD / L**2, "AL_LB": AL / (L * B), "LHC_AL": L * HC / AL,
        "LHBR_AL": L * HBR / AL, "AOD_AL": AOD / AL, "AT_LB": AT / (L * B), "L2_AT": L**2 / AT, "L_HC": L / HC,
        "AL_LHBR": AL / (L * HBR), "AL_AT": AL / AT, "CBR_L": CBR / L, "AL_AOD": AL / AOD, "C_L": C / L,
        "AT_BHBR": AT / (B * HBR), "B_HBR": B / HBR, "L_HBR": L / HBR, "B2_AT": B**2 / AT, "CHC_AL": C * HC / AL,
        "AT_AL": AT / AL, "AT_L2": AT / L**2, "AT_B2": AT / B**2, "AL_L2": AL / L**2,
    }


def fujiwara_components(geometry: "WindForce") -> dict:
    """The ten Fourier components ``wX0`` to ``wN3`` of Fujiwara et al. (1998) for a ship's geometry."""
    reg = _regressors(geometry)
    return {k: c0 + sum(a * reg[name] for a, name in terms) for k, (c0, terms) in _REGRESSION.items()}


@dataclass(frozen=True)
class WindForce:
    """Above-water geometry of a ship and the wind force model built on it.

    Attributes
    ----------
    lpp, breadth : float
        Length between perpendiculars and breadth [m] (Fujiwara uses the length overall; Lpp is used
        here, as in the Osaka University code for the Esso Osaka).
    A_T, A_L : float
        Transverse and lateral projected areas above water [m^2].
    A_OD : float
        Lateral projected area of superstructures/deck structures [m^2].
    C, C_BR : float
        Centroid of ``A_L`` and of the superstructure from midship, forward positive [m].
    H_BR, H_C : float
        Height above the waterline of the top of the superstructure and of the centroid of ``A_L`` [m].
    rho_air : float
        Air density [kg/m^3].
    """

    lpp: float
    breadth: float
    A_T: float
    A_L: float
    A_OD: float
    C: float
    C_BR: float
    H_BR: float
    H_C: float
    rho_air: float = RHO_AIR
    #: Wind parameters the fit recipe estimates by default (``shipid fit --wind``): the leading Fourier components
    #: of Fujiwara's surge force, side force and yaw moment, as in the Esso Osaka study; the others stay at the
    #: regression's values from the above-water geometry.
    recipe_estimate: ClassVar[tuple[str, ...]] = ("wX1", "wY1", "wN1", "wN2")

    def __post_init__(self):
        for k in ("lpp", "breadth", "A_T", "A_L", "A_OD", "H_BR", "H_C", "rho_air"):
            v = getattr(self, k)
            if not (np.isfinite(v) and v > 0):
                raise ValueError(f"WindForce: {k} must be a positive number, got {v}")

    @classmethod
    def esso_osaka_3m(cls) -> "WindForce":
        """The 3 m Esso Osaka model of FRT-DS-ESSO: A_T 0.135 m^2, A_L 0.520 m^2 (data README; 0.13544
        and 0.52038 in the dataset authors' code), A_OD, C, C_BR, H_BR, H_C as in that code (NAOE-5thLab,
        Osaka University), whose published Fujiwara components this geometry reproduces.  ``C_BR`` =
        -0.062 m (near midship) is the owners' value; a
        transcription with -1.233 m (a VLCC bridge aft) was traced to a copied line (docs/environment.md)."""
        return cls(lpp=3.0, breadth=0.48925, A_T=0.13544, A_L=0.52038, A_OD=0.14230, C=-0.01299, C_BR=-0.06209,
                   H_BR=0.294, H_C=0.10359)

    @classmethod
    def from_mapping(cls, doc: Mapping) -> "WindForce":
        known = set(cls.__dataclass_fields__)
        unknown = sorted(set(doc) - known)
        if unknown:
            raise ValueError(f"WindForce: unknown field(s) {unknown}; known fields are {sorted(known)}")
        return cls(**{k: float(v) for k, v in doc.items()})

    def to_dict(self) -> dict:
        return asdict(self)

    def scaled(self, lpp_new: float) -> "WindForce":
        """Geometrically similar ship of length ``lpp_new`` (lengths x lambda, areas x lambda^2)."""
        lam = float(lpp_new) / self.lpp
        return WindForce(lpp=self.lpp * lam, breadth=self.breadth * lam, A_T=self.A_T * lam**2, A_L=self.A_L * lam**2,
                         A_OD=self.A_OD * lam**2, C=self.C * lam, C_BR=self.C_BR * lam, H_BR=self.H_BR * lam,
                         H_C=self.H_C * lam, rho_air=self.rho_air)

    def components(self) -> dict:
        """Fujiwara's Fourier components for this geometry (``WIND_PARAM_NAMES`` -> value)."""
        return fujiwara_components(self)

    def coefficients(self, gamma, components=None):
        """``(C_X, C_Y, C_N)`` at apparent wind angles ``gamma`` [rad] (arrays broadcast).

        ``components``: a mapping of the Fourier components (default: Fujiwara's regression)."""
        g = np.asarray(gamma, dtype=float)
        return coefficients_cs(np.cos(g), np.sin(g), self._comp(components))

    def force(self, speed, gamma, components=None):
        """``(X_A, Y_A, N_A)`` [N, N, N m] at midship for apparent wind ``speed`` [m/s] from ``gamma`` [rad]."""
        g = np.asarray(gamma, dtype=float)
        V = np.asarray(speed, dtype=float)
        return self.force_cs(V * np.cos(g), V * np.sin(g), self._comp(components))

    def force_cs(self, a_cos, a_sin, comp):
        """Forces from the apparent wind vector written as ``(V cos gamma, V sin gamma)`` (no angle, no
        square root: smooth at V = 0 and complex-step safe).  ``comp`` is a sequence of the ten components
        in :data:`WIND_PARAM_NAMES` order (floats or arrays)."""
        return wind_force_numpy()(a_cos, a_sin, *self.scales(), *comp)

    def scales(self) -> tuple:
        """``(1/2 rho_air A_T, 1/2 rho_air A_L, 1/2 rho_air A_L L)``: the force scales per V^2."""
        ra = 0.5 * self.rho_air
        return ra * self.A_T, ra * self.A_L, ra * self.A_L * self.lpp

    def _comp(self, components):
        base = self.components()
        if components is not None:
            unknown = sorted(set(components) - set(WIND_PARAM_NAMES))
            if unknown:
                raise ValueError(f"wind components: unknown name(s) {unknown}; use {list(WIND_PARAM_NAMES)}")
            base.update({k: float(v) for k, v in components.items()})
        return [base[k] for k in WIND_PARAM_NAMES]


def apparent_wind(speed_true, dir_true, psi, u_ground, v_ground):
    """Apparent wind ``(speed [m/s], angle [rad])`` from the true wind and the ship's motion over ground.

    ``dir_true`` is the earth-fixed direction the wind comes from, measured like the heading ``psi``;
    the apparent angle is relative to the bow, positive from starboard, in (-pi, pi] (the convention of
    the Esso Osaka logs: there the logged relative wind equals this conversion of the logged true wind
    to 0.02 m/s).
    """
    ax, ay = _air_body(speed_true, dir_true, psi, u_ground, v_ground)
    return np.hypot(ax, ay), np.arctan2(-ay, -ax)


def _air_body(speed_true, dir_true, psi, ug, vg):
    """Air velocity relative to the ship in body axes (the wind blows *towards* ``dir_true + pi``)."""
    wx, wy = -speed_true * np.cos(dir_true), -speed_true * np.sin(dir_true)
    c, s = np.cos(psi), np.sin(psi)
    return c * wx + s * wy - ug, -s * wx + c * wy - vg


def true_wind_from_apparent(speed_rel, dir_rel, psi, u_ground, v_ground):
    """True wind ``(speed, direction from [rad, earth-fixed, (-pi, pi]])`` from the apparent wind and the
    ship's body velocities over ground (the inverse of :func:`apparent_wind`)."""
    ax, ay = -speed_rel * np.cos(dir_rel) + u_ground, -speed_rel * np.sin(dir_rel) + v_ground
    c, s = np.cos(psi), np.sin(psi)
    wx, wy = c * ax - s * ay, s * ax + c * ay
    return np.hypot(wx, wy), np.arctan2(-wy, -wx)
