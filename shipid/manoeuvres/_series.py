"""Time-series helpers shared by the turning and zigzag metrics (execute detection, level crossings,
interpolation per batch row, the least-squares circle, JSON conversion)."""
from __future__ import annotations

import math

import numpy as np

EXECUTE_THRESHOLD_DEG = 0.5


def detect_execute(t, delta, threshold_deg: float = EXECUTE_THRESHOLD_DEG) -> tuple[int, float]:
    """Index and time of the rudder execute.

    The index ``i`` is the first sample with ``|delta - delta[0]| > threshold``; the time is when the
    rudder left its approach angle ``delta[0]``, with the rudder taken as linear between samples (as the
    identifier's default first-order hold): the line through samples ``i - 1`` and ``i`` crosses
    ``delta[0]`` at ``t[i - 1] + (t[i] - t[i - 1]) |delta[i-1] - delta[0]| / |delta[i] - delta[i-1]|``,
    so ``t[i - 1] <= time <= t[i]``.  (Taking ``t[i]`` itself put the execute up to one sample late on
    a log of a continuously moving rudder: 0.1 s, i.e. 0.04 L of advance, on the bundled 4.36 m logs.)

    ``delta`` in radians.  Raises ValueError when the rudder never moves.
    """
    delta = np.asarray(delta, dtype=float)
    t = np.asarray(t, dtype=float)
    moved = np.abs(delta - delta[0]) > math.radians(threshold_deg)
    if not moved.any():
        raise ValueError(f"no rudder execute found: |delta - delta[0]| never exceeds {threshold_deg} deg")
    i = int(np.argmax(moved))
    step = abs(delta[i] - delta[i - 1])
    frac = min(abs(delta[i - 1] - delta[0]) / step, 1.0)  # step > 0: sample i moved past the threshold, i - 1 did not
    return i, float(t[i - 1] + frac * (t[i] - t[i - 1]))


def _crossing_rows(t, h, level, start, valid):
    """Per row of ``h (B, n)``: the first sample at or after ``start (B,)`` (and inside ``valid (B, n)``)
    where ``h`` reaches ``level`` upwards, with the crossing linearly interpolated.

    Returns ``(found, k, f, time)``, arrays (B,): the index after the crossing, the fraction of the
    interval before it (1.0 when the level is reached at ``start`` itself) and the time.
    """
    col = np.arange(h.shape[1])
    mask = (h >= level) & (col >= start[:, None]) & valid
    found = mask.any(axis=1)
    k = np.argmax(mask, axis=1)
    rows = np.arange(h.shape[0])
    km = np.maximum(k - 1, 0)
    at_start = k == start
    with np.errstate(invalid="ignore", divide="ignore"):
        f = np.where(at_start, 1.0, (level - h[rows, km]) / (h[rows, k] - h[rows, km]))
        time = np.where(at_start, t[k], t[km] + f * (t[k] - t[km]))  # rows not found: unused
    return found, k, f, time


def _crossing(t, h, level, start):
    """:func:`_crossing_rows` for one series: ``(index_after, fraction, time)`` or None."""
    found, k, f, time = _crossing_rows(t, h[None], level, np.array([start]), np.ones((1, h.size), bool))
    return (int(k[0]), float(f[0]), float(time[0])) if found[0] else None


def _interp_rows(a, k, f):
    """``a`` at fraction ``f`` of the interval before index ``k``, per row (``a[k]`` when f >= 1 or k == 0)."""
    rows = np.arange(a.shape[0])
    km = np.maximum(k - 1, 0)
    with np.errstate(invalid="ignore"):  # f is not finite in rows without a crossing (unused)
        return np.where((f < 1.0) & (k > 0), a[rows, km] + f * (a[rows, k] - a[rows, km]), a[rows, k])


def _at_time_rows(t, a, te):
    """``np.interp(te[b], t, a[b])`` for each row ``b`` of ``a (B, n)`` (``te`` inside ``[t0, t_end]``)."""
    j = np.clip(np.searchsorted(t, te, side="right") - 1, 0, t.size - 2)
    w = (te - t[j]) / (t[j + 1] - t[j])
    rows = np.arange(a.shape[0])
    return np.where(w == 0.0, a[rows, j], a[rows, j] + w * (a[rows, j + 1] - a[rows, j]))


def _masked_sum(a, mask):
    """Row sums of ``a`` over ``mask`` (NaNs inside the mask propagate, outside are ignored)."""
    return np.where(mask, a, 0.0).sum(axis=1)


def _circle_fit_rows(x, y, mask):
    """Least-squares (Kasa) circle through the points of each row selected by ``mask``; (xc, yc, radius).

    Minimises sum (x^2 + y^2 + D x + E y + F)^2 in coordinates centred on the points' mean, where
    the normal equations separate: a 2x2 system for (D, E) and F = -mean(x^2 + y^2).
    """
    nw = mask.sum(axis=1)
    mx, my = _masked_sum(x, mask) / nw, _masked_sum(y, mask) / nw
    xc = np.where(mask, x - mx[:, None], 0.0)
    yc = np.where(mask, y - my[:, None], 0.0)
    z = xc * xc + yc * yc
    sxx, syy, sxy = (xc * xc).sum(1), (yc * yc).sum(1), (xc * yc).sum(1)
    sxz, syz = (xc * z).sum(1), (yc * z).sum(1)
    det = sxx * syy - sxy * sxy
    a = 0.5 * (sxz * syy - syz * sxy) / det
    b = 0.5 * (syz * sxx - sxz * sxy) / det
    F = -z.sum(1) / nw
    return mx + a, my + b, np.sqrt(np.maximum(a * a + b * b - F, 0.0))


def _unwrap(psi):
    """``np.unwrap(psi)`` (float array), skipping the work when no step exceeds pi (simulated headings;
    with NaNs it always unwraps, as before)."""
    psi = np.asarray(psi, dtype=float)
    return psi if psi.size < 2 or np.abs(np.diff(psi)).max() <= math.pi else np.unwrap(psi)


def _side(sign):
    return "starboard" if sign > 0 else "port"


def _execute(t, delta, execute_time):
    if execute_time is None:
        return detect_execute(t, delta)
    te = float(execute_time)
    if not (t[0] <= te <= t[-1]):
        raise ValueError(f"execute_time {te} s is outside the time range [{t[0]}, {t[-1]}] s")
    return int(np.searchsorted(t, te, side="left")), te


def _at_time(t, a, te):
    return float(np.interp(te, t, a))


def _jsonable(d):
    out = {}
    for k, v in d.items():
        if isinstance(v, dict):
            out[k] = _jsonable(v)
        elif isinstance(v, (np.floating, float)):
            out[k] = None if not np.isfinite(v) else float(v)
        elif isinstance(v, np.bool_):
            out[k] = bool(v)
        elif isinstance(v, np.integer):
            out[k] = int(v)
        else:
            out[k] = v
    return out
