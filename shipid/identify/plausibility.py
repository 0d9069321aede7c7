"""Plausibility from physics: a fitted coefficient against the signs physics fixes and the non-dimensional
ranges of the published ship sets (``Model.physics_signs``, ``Model.physics_ranges``), at any scale.

Used by :mod:`shipid.identify.verdict`; nothing here compares a coefficient with another ship's parameter set.
"""
from __future__ import annotations

import numpy as np

from ..manoeuvres import steady_rps
from ..models.base import STERN_RUDDER_SIGNS

__all__ = ["RANGE_FACTOR", "time_constant_at", "logs_speed", "prime_value", "physics_findings"]

#: Factor by which a declared non-dimensional range (the span of the published sets) is widened on both
#: sides.  With the widest declared span (max/min 2.14, the rudder's yaw term across the four published
#: response-model images), a window of span 2.14 * 5**2 = 53.5 < 57.3: a value inside it multiplied or
#: divided by 57.3 (degrees taken as radians or back) always falls outside.
RANGE_FACTOR = 5.0


def time_constant_at(model, speed: float) -> float:
    """The fastest time constant [s] of ``model``'s surge, sway and yaw (its Jacobian's largest decay rate) in
    straight running at ``speed`` [m/s], with the propeller rate that holds that speed.  ValueError when it has
    no decaying mode."""
    n = float(steady_rps(model, speed)[0]) if "n" in model.input_names else 0.0
    x = np.zeros(model.nx)
    x[model.state_index("u")] = speed
    u = np.zeros(model.nu)
    if "n" in model.input_names:
        u[model.input_index("n")] = n
    J = np.asarray(model.jac_x(0.0, x, u), dtype=float)
    dyn = [model.state_index(s) for s in ("u", "v", "r") if s in model.state_names]
    rates = np.abs(np.linalg.eigvals(J[np.ix_(dyn, dyn)]).real)
    rates = rates[rates > 0]
    if not rates.size:
        raise ValueError("no decaying mode")
    return 1.0 / float(rates.max())



def logs_speed(arrays_or_logs) -> float:
    """Median speed through the water [m/s] of the logged samples moving ahead (``hypot(u, v)``), from
    TrialLogs or the identifier's arrays (``.Y`` with channel names ``.meas``); NaN when unknown."""
    speeds = []
    for a in arrays_or_logs:
        try:
            u = np.asarray(a["u"], dtype=float)
            v = np.asarray(a["v"], dtype=float) if "v" in getattr(a, "channels", ()) else np.zeros_like(u)
        except (KeyError, TypeError, ValueError):
            continue
        s = np.hypot(u, np.where(np.isfinite(v), v, 0.0))
        speeds.append(s[np.isfinite(s) & (u > 0)])
    s = np.concatenate(speeds) if speeds else np.zeros(0)
    return float(np.median(s)) if s.size else float("nan")


def prime_value(model, name: str, value: float, speed: float) -> float:
    """``value`` of coefficient ``name`` in the ITTC prime system (lengths by L, times by L/U).

    A model with dimensional coefficients (``prime_exponents``: SI dimension m^a s^b) divides by
    ``L^a (L/U)^b`` with ``L`` its length and ``U`` = ``speed`` (the logs' median speed); the speed, not
    the Froude prime's ``sqrt(L/g)``, because a force proportional to the speed squared then has one
    value at every speed.  A model whose coefficients are already non-dimensional returns ``value``."""
    exps = getattr(model, "prime_exponents", None) or {}
    if name not in exps:
        return float(value)
    L = getattr(model, "lpp", None)
    if not (L and np.isfinite(speed) and speed > 0):
        return float("nan")
    a, b = exps[name]
    return float(value) / (L ** a * (L / speed) ** b)


def physics_findings(model, coef: dict, coef_std: dict, prior_std: dict, speed: float) -> list[dict]:
    """Coefficients the data determine that contradict physics: the sign in ``model.physics_signs`` or the
    non-dimensional range in ``model.physics_ranges`` (widened by :data:`RANGE_FACTOR`).

    A coefficient counts when its posterior standard deviation is below half its prior standard deviation
    and it is more than 3 of them from zero.  Returns findings (dicts with ``kind``, ``channels``,
    ``option``, ``message``, ``coefficient``).
    """
    signs = getattr(model, "physics_signs", None) or {}
    ranges = getattr(model, "physics_ranges", None) or {}
    out = []
    for name in set(signs) | set(ranges):
        th, sd, ps = coef.get(name), coef_std.get(name), prior_std.get(name)
        if th is None or sd is None or not (np.isfinite(th) and np.isfinite(sd) and sd > 0):
            continue
        if ps is not None and np.isfinite(ps) and not sd < 0.5 * ps:
            continue
        if not abs(th) > 3 * sd:
            continue
        sign, why, chans, option = signs.get(name, (0, "", (), ""))
        if sign and th * sign < 0:
            own = not set(chans) & {"delta", "n"}   # a state's own damping or resistance: model-form error can do it
            out.append({"kind": "unphysical" if own else "physics_sign", "grade": "model_error" if own else "defect",
                        "coefficient": name, "channels": list(chans), "option": option,
                        "message": f"{name} = {th:.3g} +- {sd:.2g} is {'negative' if th < 0 else 'positive'} but "
                                   f"{why}{(': ' + option) if option else ''}"})
            continue
        if name in ranges:
            lo, hi, chans_r, option_r = ranges[name]
            pv = prime_value(model, name, th, speed)
            if not np.isfinite(pv) or pv == 0:
                continue
            a_lo, a_hi = sorted((abs(lo), abs(hi)))
            if abs(pv) > a_hi * RANGE_FACTOR or abs(pv) < a_lo / RANGE_FACTOR:
                out.append({"kind": "physics_range", "grade": "defect", "coefficient": name, "channels": list(chans_r),
                            "option": option_r,
                            "message": f"{name} = {th:.3g} ({name}' = {pv:.3g} non-dimensional) is "
                                       f"{'above' if abs(pv) > a_hi * RANGE_FACTOR else 'below'} the published "
                                       f"ships' {a_lo:.2g}-{a_hi:.2g} by more than {RANGE_FACTOR:g}x: "
                                       f"{option_r}"})
    # a stern rudder's sway term with the wrong sign while its yaw term has the right one: the rudder's sign is
    # fine (it would flip both), the sway velocity's is not
    sway = [n for n in signs if signs[n] is STERN_RUDDER_SIGNS["sway"]]
    yaw = [n for n in signs if signs[n] is STERN_RUDDER_SIGNS["yaw"]]
    wrong = {f["coefficient"] for f in out if f["kind"] == "physics_sign"}
    if yaw and not wrong & set(yaw) and yaw[0] in coef:
        for f in out:
            if f["coefficient"] in sway and f["kind"] == "physics_sign":
                # the sway equation's fit alone is wrong: model-form error does that (a response model fitted to
                # logs of another model form), so it is a defect only with a velocity-frame doubt about v's sign
                f.update(kind="sway_sign", grade="model_error", channels=["v"], option="--sign v=-1",
                         message=f["message"].split(": ")[0] + f" while {yaw[0]} has the rudder's sign: the sway "
                                 "equation misses the logs, or v is logged positive to port (--sign v=-1)")
    return sorted(out, key=lambda f: f["coefficient"])
