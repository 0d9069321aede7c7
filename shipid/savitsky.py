"""Calm-water resistance of a prismatic planing hull by Savitsky's method.

Implemented here from the published formulas:

* D. Savitsky (1964), "Hydrodynamic design of planing hulls", Marine
  Technology 1(1):71-95 -- lift of a planing surface with deadrise (eqs. for
  ``C_L0`` and ``C_Lbeta``), centre of pressure, mean bottom velocity,
  frictional drag on the wetted bottom and the trim (moment) equilibrium with
  thrust line and friction line offsets ("general case").
* D. Savitsky and P. W. Brown (1976), "Procedures for hydrodynamic evaluation
  of planing hulls in smooth and rough water", Marine Technology 13(4):381-400
  -- the same equations organised as a design procedure, the ITTC-1957
  friction line with a roughness allowance ``dCf = 0.0004``, and the ranges of
  validity restated below.

Notation (SI inside; the empirical formulas take the trim ``tau`` and deadrise
``beta`` in **degrees**, as published)::

    Cv       = V / sqrt(g b)                                speed coefficient
    C_Lbeta  = Delta / (0.5 rho V^2 b^2)                    lift coefficient
    C_Lbeta  = C_L0 - 0.0065 beta C_L0^0.6                  deadrise correction
    C_L0     = tau^1.1 (0.0120 lam^0.5 + 0.0055 lam^2.5 / Cv^2)
    lp / (lam b) = 0.75 - 1 / (5.21 Cv^2 / lam^2 + 2.39)    centre of pressure from transom
    V1       = V sqrt(1 - 0.0120 tau^1.1 / (lam^0.5 cos tau))  mean bottom velocity
    Df       = 0.5 rho V1^2 lam b^2 (Cf + dCf) / cos beta   friction on the wetted bottom
    Cf       = 0.075 / (log10(V1 lam b / nu) - 2)^2          ITTC 1957
    c = LCG - lp,  a = VCG - b tan(beta) / 4                 lever arms
    0 = Delta [(1 - sin tau sin(tau + eps)) c / cos tau - f sin tau] + Df (a - f)   trim equilibrium
    R_T = Delta tan tau + Df / cos tau                       total resistance (horizontal)

``lam`` is the mean wetted length-beam ratio, ``eps`` the inclination of the
thrust line to the keel [deg] and ``f`` the normal distance of the thrust line
below the centre of gravity [m].

Validity (Savitsky 1964; Savitsky and Brown 1976): ``0.60 <= Cv <= 13``,
``2 deg <= tau <= 15 deg``, ``lam <= 4``, deadrise ``beta <= 30 deg``,
prismatic hull, calm water, chines wetted.  :func:`savitsky_equilibrium`
reports which limits an operating point violates.

Below the planing range (the "hump" and displacement speeds) Savitsky's
equations do not apply.  The pre-planing regression of Savitsky and Brown
(1976, after Mercier and Savitsky 1973) needs the Series-62 coefficient table,
which is not reproduced here.  :func:`resistance_curve` therefore uses a
documented bridge below the lowest valid planing speed ``V_p``: ITTC-1957
friction on the static wetted area plus a residuary part
``R_R(V) = R_R(V_p) (V / V_p)^k`` whose exponent ``k`` makes the curve
continuous in value and slope at ``V_p`` (clipped to ``2 <= k <= 6``).  This
is an engineering assumption of shipid, not a prediction; when a towing-tank
or Maxsurf curve exists, pass it instead (``PlaningHull.resistance_table``).
"""
from __future__ import annotations

import bisect
from dataclasses import dataclass, field

import numpy as np
from scipy.interpolate import PchipInterpolator
from scipy.optimize import brentq

__all__ = [
    "PlaningHull", "SavitskyPoint", "savitsky_equilibrium", "resistance_curve",
    "ittc57_cf", "ResistanceCurve",
]

G = 9.80665


def ittc57_cf(re):
    """ITTC-1957 model-ship correlation line ``0.075 / (log10 Re - 2)^2``."""
    re = np.asarray(re, dtype=float)
    return 0.075 / (np.log10(np.maximum(re, 1e3)) - 2.0) ** 2


@dataclass(frozen=True)
class PlaningHull:
    """Particulars of a prismatic planing hull.

    Parameters
    ----------
    mass : float
        Displacement mass [kg].
    beam : float
        Chine beam ``b`` [m].
    lcg : float
        Longitudinal centre of gravity from the transom [m].
    vcg : float
        Vertical centre of gravity above the keel [m].
    deadrise : float
        Deadrise angle ``beta`` [deg].
    length : float
        Overall length [m] (for the static wetted area of the pre-planing bridge
        and the validity check ``lam b <= length``).
    epsilon : float
        Thrust-line inclination to the keel [deg].
    f : float
        Distance of the thrust line below the CG, normal to the thrust [m].
    rho, nu : float
        Water density [kg/m^3] and kinematic viscosity [m^2/s].
    dcf : float
        Roughness allowance added to the ITTC-1957 ``Cf`` (Savitsky and Brown 1976: 0.0004).
    static_wetted_area : float or None
        Wetted area at rest [m^2] for the pre-planing bridge; None estimates it
        as ``0.8 * length * beam / cos(beta)`` (a V-bottom wetted to the chines
        over 80 % of the length -- a shipid assumption).
    """

    mass: float
    beam: float
    lcg: float
    vcg: float
    deadrise: float
    length: float
    epsilon: float = 0.0
    f: float = 0.0
    rho: float = 1025.0
    nu: float = 1.19e-6
    dcf: float = 0.0004
    static_wetted_area: float | None = None

    def __post_init__(self):
        for name in ("mass", "beam", "lcg", "length", "rho", "nu"):
            val = getattr(self, name)
            if not np.isfinite(val) or val <= 0:
                raise ValueError(f"PlaningHull.{name} must be a positive number, got {val!r}")
        if not 0.0 <= self.deadrise < 45.0:
            raise ValueError(f"PlaningHull.deadrise must be in [0, 45) deg, got {self.deadrise!r}")

    @property
    def weight(self) -> float:
        """Weight ``Delta`` [N]."""
        return self.mass * G

    @property
    def wetted_area_static(self) -> float:
        """Wetted area at rest [m^2] used by the pre-planing bridge."""
        if self.static_wetted_area is not None:
            return float(self.static_wetted_area)
        return 0.8 * self.length * self.beam / np.cos(np.radians(self.deadrise))


@dataclass
class SavitskyPoint:
    """Equilibrium running attitude at one speed (Savitsky 1964, general case).

    Attributes
    ----------
    speed : float [m/s]
    trim : float [deg]
    lam : float
        Mean wetted length-beam ratio.
    cv : float
        Speed coefficient.
    lift_coefficient : float
        ``C_Lbeta``.
    friction : float
        ``Df`` [N].
    resistance : float
        ``R_T = Delta tan(tau) + Df / cos(tau)`` [N].
    lp : float
        Centre of pressure from the transom [m].
    valid : bool
        All validity limits satisfied.
    violations : list of str
        Human-readable list of the violated limits.
    success : bool
        False when no trim satisfies the moment equation in 0.5..25 deg.
    message : str
    """

    speed: float
    trim: float = np.nan
    lam: float = np.nan
    cv: float = np.nan
    lift_coefficient: float = np.nan
    friction: float = np.nan
    resistance: float = np.nan
    lp: float = np.nan
    valid: bool = False
    violations: list = field(default_factory=list)
    success: bool = False
    message: str = ""


def _cl0_from_clbeta(clb: float, beta: float) -> float:
    """Invert ``C_Lbeta = C_L0 - 0.0065 beta C_L0^0.6`` for ``C_L0``."""
    if beta == 0:
        return clb
    fun = lambda c: c - 0.0065 * beta * c**0.6 - clb  # noqa: E731
    hi = max(1.0, 10 * clb)
    # the function is increasing for C_L0 above its minimum; bracket there
    cmin = (0.0065 * beta * 0.6) ** (1 / 0.4)
    return brentq(fun, cmin, hi + cmin, xtol=1e-14)


def _lam_from_cl0(cl0: float, tau: float, cv: float) -> float:
    """Invert Savitsky's ``C_L0(tau, lam, Cv)`` for ``lam`` (monotone in lam)."""
    target = cl0 / tau**1.1
    fun = lambda lam: 0.0120 * lam**0.5 + 0.0055 * lam**2.5 / cv**2 - target  # noqa: E731
    hi = 1.0
    while fun(hi) < 0:
        hi *= 2.0
        if hi > 1e4:
            return np.inf
    return brentq(fun, 1e-10, hi, xtol=1e-13)


def _state_at_trim(hull: PlaningHull, V: float, tau: float):
    b, beta = hull.beam, hull.deadrise
    cv = V / np.sqrt(G * b)
    clb = hull.weight / (0.5 * hull.rho * V**2 * b**2)
    cl0 = _cl0_from_clbeta(clb, beta)
    lam = _lam_from_cl0(cl0, tau, cv)
    tr = np.radians(tau)
    br = np.radians(beta)
    lp = lam * b * (0.75 - 1.0 / (5.21 * cv**2 / lam**2 + 2.39))
    arg = 1.0 - 0.0120 * tau**1.1 / (np.sqrt(lam) * np.cos(tr))
    V1 = V * np.sqrt(max(arg, 0.0))
    re = V1 * lam * b / hull.nu
    cf = float(ittc57_cf(re)) + hull.dcf
    df = 0.5 * hull.rho * V1**2 * lam * b**2 * cf / np.cos(br)
    c = hull.lcg - lp
    a = hull.vcg - b * np.tan(br) / 4.0
    er = np.radians(hull.epsilon)
    moment = hull.weight * ((1 - np.sin(tr) * np.sin(tr + er)) * c / np.cos(tr) - hull.f * np.sin(tr)) + df * (a - hull.f)
    res = hull.weight * np.tan(tr) + df / np.cos(tr)
    return dict(cv=cv, clb=clb, lam=lam, lp=lp, df=df, moment=moment, resistance=res)


def savitsky_equilibrium(hull: PlaningHull, speed: float) -> SavitskyPoint:
    """Trim, wetted length and resistance of ``hull`` planing at ``speed`` [m/s].

    Solves the trim-moment equation of Savitsky (1964) for the trim angle
    in 0.5..25 deg (Brent's method on a bracket found by scanning) and checks
    the validity limits.  Never raises for an out-of-range point: the result's
    ``valid``/``violations`` say what is wrong.
    """
    V = float(speed)
    if not np.isfinite(V) or V <= 0:
        raise ValueError(f"savitsky_equilibrium: speed must be a positive number [m/s], got {speed!r}")
    out = SavitskyPoint(speed=V)
    taus = np.linspace(0.5, 25.0, 50)
    m = np.array([_state_at_trim(hull, V, t)["moment"] for t in taus])
    ok = np.isfinite(m)
    sign_change = np.where(ok[:-1] & ok[1:] & (np.sign(m[:-1]) != np.sign(m[1:])))[0]
    if len(sign_change) == 0:
        out.message = f"no trim in 0.5..25 deg balances the trim moment at V = {V:.3f} m/s"
        return out
    i = sign_change[0]
    tau = brentq(lambda t: _state_at_trim(hull, V, t)["moment"], taus[i], taus[i + 1], xtol=1e-12)
    s = _state_at_trim(hull, V, tau)
    out.trim, out.lam, out.cv, out.lift_coefficient = tau, s["lam"], s["cv"], s["clb"]
    out.friction, out.resistance, out.lp = s["df"], s["resistance"], s["lp"]
    out.success = True
    v = []
    if not 0.60 <= s["cv"] <= 13.0:
        v.append(f"Cv = {s['cv']:.2f} outside 0.60..13")
    if not 2.0 <= tau <= 15.0:
        v.append(f"trim = {tau:.2f} deg outside 2..15 deg")
    if s["lam"] > 4.0:
        v.append(f"lambda = {s['lam']:.2f} > 4")
    if s["lam"] * hull.beam > hull.length:
        v.append(f"wetted length {s['lam'] * hull.beam:.2f} m > hull length {hull.length:.2f} m")
    if hull.deadrise > 30.0:
        v.append(f"deadrise {hull.deadrise} deg > 30 deg")
    out.violations, out.valid = v, not v
    out.message = "valid planing point" if not v else "; ".join(v)
    return out


@dataclass
class ResistanceCurve:
    """Tabulated ``R_T(V)`` with a C1 interpolant.

    Attributes
    ----------
    speed : ndarray [m/s], increasing, starting at 0
    resistance : ndarray [N]
    planing_speed : float
        Lowest speed of the valid planing range (``nan`` for a user table).
    regime : ndarray of str
        ``"planing"``, ``"pre-planing bridge"`` or ``"table"`` per sample.
    source : str
    """

    speed: np.ndarray
    resistance: np.ndarray
    planing_speed: float = np.nan
    regime: np.ndarray | None = None
    source: str = ""

    def __post_init__(self):
        s, r = np.asarray(self.speed, float), np.asarray(self.resistance, float)
        if s.ndim != 1 or s.shape != r.shape or len(s) < 3:
            raise ValueError("ResistanceCurve: speed and resistance must be 1-D arrays of equal length >= 3")
        if np.any(np.diff(s) <= 0) or s[0] < 0:
            raise ValueError("ResistanceCurve: speeds must be increasing and non-negative [m/s]")
        if not np.all(np.isfinite(r)):
            raise ValueError("ResistanceCurve: resistance values must be finite [N]")
        if s[0] > 0:  # R(0) = 0 at rest
            s, r = np.r_[0.0, s], np.r_[0.0, r]
        self.speed, self.resistance = s, r
        pch = PchipInterpolator(s, r, extrapolate=True)
        # Hermite data for a fast evaluation (np.searchsorted instead of scipy's call overhead)
        self._y = r
        self._d = pch.derivative()(s)
        # the same cubic per segment in power form about its left knot: c0 + c1 t + c2 t^2 + c3 t^3, t = V - s_i
        h = np.diff(s)
        dy = np.diff(r) / h
        d0, d1 = self._d[:-1], self._d[1:]
        self._coef = np.array([r[:-1], d0, (3 * dy - 2 * d0 - d1) / h, (d0 + d1 - 2 * dy) / h**2])
        # uniform tables (Savitsky curves) index by division instead of a search
        self._inv_step = 1.0 / h[0] if np.allclose(h, h[0], rtol=1e-12, atol=0.0) else None

    def _hermite(self, a):
        s, n = self.speed, len(self.speed)
        if self._inv_step is not None:
            with np.errstate(invalid="ignore"):  # NaN (a diverged trajectory) -> any index; t stays NaN
                i = np.minimum(np.maximum(((a - s[0]) * self._inv_step).astype(np.intp), 0), n - 2)
        else:
            i = np.minimum(np.maximum(np.searchsorted(s, a, side="right") - 1, 0), n - 2)
        t = a - s[i]
        c0, c1, c2, c3 = self._coef[:, i]
        val = c0 + t * (c1 + t * (c2 + t * c3))
        der = c1 + t * (2 * c2 + 3 * t * c3)
        return val, der

    def _scalar(self, V: float):
        """Value and derivative at one speed with Python floats (fast path of the same Hermite cubic)."""
        a = abs(V)
        sgn = 1.0 if V > 0 else (-1.0 if V < 0 else 0.0)
        s = self.speed
        vmax = float(s[-1])
        if a > vmax:
            rmax = float(self._y[-1])
            if a > 1e100:  # a diverged trajectory: inf (as the array path gives), not OverflowError
                return sgn * np.inf, np.inf
            return sgn * rmax * (a / vmax) ** 2, 2 * rmax * a / vmax**2
        if not hasattr(self, "_lists"):
            self._lists = (s.tolist(), self._y.tolist(), self._d.tolist())
        sl, yl, dl = self._lists
        i = min(max(bisect.bisect_right(sl, a) - 1, 0), len(sl) - 2)
        h = sl[i + 1] - sl[i]
        t = (a - sl[i]) / h
        t2, t3 = t * t, t * t * t
        val = (2 * t3 - 3 * t2 + 1) * yl[i] + (t3 - 2 * t2 + t) * h * dl[i] + (-2 * t3 + 3 * t2) * yl[i + 1] + (t3 - t2) * h * dl[i + 1]
        der = ((6 * t2 - 6 * t) * yl[i] + (3 * t2 - 4 * t + 1) * h * dl[i] + (-6 * t2 + 6 * t) * yl[i + 1]
               + (3 * t2 - 2 * t) * h * dl[i + 1]) / h
        return sgn * val, der

    def __call__(self, V):
        """``R_T`` [N] at speed(s) ``V``; odd in V (resistance opposes motion), quadratic beyond the table."""
        if np.ndim(V) == 0:
            return self._scalar(float(V))[0]
        V = np.asarray(V, dtype=float)
        a = np.abs(V)
        vmax = self.speed[-1]
        inside = np.minimum(a, vmax)
        r = self._hermite(inside)[0]
        rmax = self.resistance[-1]
        r = np.where(a > vmax, rmax * (a / vmax) ** 2, r)
        return np.sign(V) * r

    def derivative(self, V):
        """``dR_T/dV`` [N s/m]."""
        if np.ndim(V) == 0:
            return self._scalar(float(V))[1]
        V = np.asarray(V, dtype=float)
        a = np.abs(V)
        vmax = self.speed[-1]
        d = self._hermite(np.minimum(a, vmax))[1]
        d = np.where(a > vmax, 2 * self.resistance[-1] * a / vmax**2, d)
        return d


def resistance_curve(hull: PlaningHull, vmax: float = 25.0, n: int = 101) -> ResistanceCurve:
    """Tabulate ``R_T(V)`` for ``0 <= V <= vmax`` [m/s].

    Planing range: Savitsky's equilibrium where every validity limit holds,
    from the lowest such speed ``V_p`` upward.  Below ``V_p``: the pre-planing
    bridge of the module docstring (ITTC-1957 friction on the static wetted
    area plus a residuary part ``~ V^k`` matched in value and slope at ``V_p``).

    Raises
    ------
    ValueError
        When no speed up to ``vmax`` gives a valid planing point.
    """
    V = np.linspace(0.0, float(vmax), int(n))
    pts = [savitsky_equilibrium(hull, v) if v > 0 else None for v in V]
    valid = np.array([p is not None and p.valid for p in pts])
    # first index from which the planing range is valid throughout
    idx = None
    for i in range(len(V)):
        if valid[i:].all():
            idx = i
            break
    if idx is None or idx >= len(V) - 2:
        raise ValueError(
            f"resistance_curve: Savitsky's planing equations are not valid for this hull at any speed up to {vmax} m/s; "
            "supply a measured resistance table instead"
        )
    R = np.array([p.resistance if p is not None else 0.0 for p in pts])
    Vp = V[idx]
    S = hull.wetted_area_static
    L = hull.length

    def r_fric(v):
        re = np.maximum(v, 1e-9) * L / hull.nu
        return 0.5 * hull.rho * S * v**2 * (ittc57_cf(re) + hull.dcf)

    # slope of the planing curve at V_p by a one-sided difference
    dRp = (R[idx + 1] - R[idx]) / (V[idx + 1] - V[idx])
    h = 1e-4 * Vp
    dRf = (r_fric(Vp + h) - r_fric(Vp - h)) / (2 * h)
    rr_p = R[idx] - r_fric(Vp)
    if rr_p <= 0:
        k = 2.0
        rr_p = max(rr_p, 0.0)
    else:
        k = float(np.clip(Vp * (dRp - dRf) / rr_p, 2.0, 6.0))
    low = V < Vp
    R[low] = r_fric(V[low]) + rr_p * (V[low] / Vp) ** k
    R[0] = 0.0
    regime = np.where(low, "pre-planing bridge", "planing")
    return ResistanceCurve(
        speed=V, resistance=R, planing_speed=float(Vp), regime=regime,
        source=f"Savitsky (1964) planing equilibrium for V >= {Vp:.2f} m/s; pre-planing bridge (k = {k:.2f}) below",
    )
