"""IMO MSC.137(76) manoeuvring criteria: the L/V-dependent limits and the pass checks."""
from __future__ import annotations

import numpy as np


def _le(value, limit):
    return None if not np.isfinite(value) else bool(value <= limit)


def imo_limits(lpp: float, speed: float) -> dict:
    """IMO MSC.137(76) limits for a ship of length ``lpp`` [m] at test speed ``speed`` [m/s].

    10/10 first overshoot: 10 deg if L/V < 10 s, 20 deg if L/V >= 30 s, 5 + L/V/2 between;
    10/10 second overshoot: 25 / 40 / 17.5 + 0.75 L/V; 20/20 first overshoot 25 deg;
    advance 4.5 L, tactical diameter 5 L, initial turning 2.5 L.
    """
    if not (lpp > 0 and speed > 0):
        raise ValueError(f"imo_limits: lpp and speed must be positive, got lpp={lpp}, speed={speed}")
    lv = lpp / speed
    if lv < 10:
        o1, o2 = 10.0, 25.0
    elif lv >= 30:
        o1, o2 = 20.0, 40.0
    else:
        o1, o2 = 5.0 + 0.5 * lv, 17.5 + 0.75 * lv
    return {"L_over_V_s": lv, "zz10_overshoot1_deg": o1, "zz10_overshoot2_deg": o2, "zz20_overshoot1_deg": 25.0,
            "advance_L": 4.5, "tactical_diameter_L": 5.0, "initial_turning_L": 2.5}
