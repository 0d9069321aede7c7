"""Sensor faults a log can carry while its channels still look plausible, found when the log is read.

Each check returns :class:`shipid.logs.consistency.Finding` objects (the structure of the channel-consistency
checks, so that they are shown, counted and judged the same way) whose message names the file, the column and
what to check:

``yaw_rate_scale``
    A yaw-rate gyro with a scale error of a few percent.  The heading increments over non-overlapping
    windows are regressed on the increments of the integral of r (``dpsi = k * int r dt + b * dt``); the
    scale ``k`` has a standard error from the residuals (inflated for their lag-1 correlation), and a
    scale is reported when it differs from 1 by more than :data:`SCALE_SIGMAS` standard errors and by more
    than :data:`SCALE_FLOOR` -- a threshold set by the log's own information (a long turning log resolves
    a 2 % error, a short straight run none), not a fixed 10 %.  A gyro 5 % high biases the identified
    yaw coefficients by about as much (the KCS zigzag: c3 7 % high, 4 sigma from the truth).
``propeller_dead`` / ``propeller_constant``
    A propeller channel that reads zero while the ship makes way (a dead or unmapped channel: the fit
    would then have no propeller thrust to balance the resistance), and one that is exactly constant
    (a set-point logged instead of a measurement, or a frozen channel; information only, as a trial at a
    constant commanded rate is common).
``truncated_row`` / ``header_lookalike``
    Found by the CSV reader (a last row cut short, without its line end: a file copied while it was being
    written; header characters that look like Latin letters but are not, or invisible ones) and turned
    into findings here.
"""
from __future__ import annotations

import math
import unicodedata

import numpy as np

from .consistency import Finding

__all__ = ["SensorWarning", "check_sensors", "yaw_rate_scale", "SCALE_SIGMAS", "SCALE_FLOOR", "plain_header", "LOOKALIKES"]

#: Standard errors by which the gyro scale must differ from 1 to be reported (4: a false alarm on a log
#: whose residuals are Gaussian has probability 6e-5).
SCALE_SIGMAS = 4.0
#: Smallest scale error reported [fraction]: below 1 % the coefficients' bias is within their own uncertainty
#: on the bundled logs, and a gyro's calibration is rarely better specified.
SCALE_FLOOR = 0.01
#: Increments the regression uses (non-overlapping windows over the log): few and long, as the heading's
#: noise enters each increment once while the turn grows with its length (the standard error falls as
#: 1/sqrt(window length); on the bundled KCS logs 0.5-0.8 % with 25 windows, 1.4 % with 200).
_N_WINDOWS = 25

#: Letters of other scripts that look like Latin ones in a header (Cyrillic, Greek); NFKC folds the
#: full-width and other compatibility forms, and format characters (zero-width space, joiners, BOM) are
#: dropped.
LOOKALIKES = {"\u0430": "a", "\u0435": "e", "\u043e": "o", "\u0440": "p", "\u0441": "c", "\u0443": "y",
              "\u0445": "x", "\u0455": "s", "\u0456": "i", "\u0458": "j", "\u0410": "A", "\u0412": "B",
              "\u0415": "E", "\u041a": "K", "\u041c": "M", "\u041d": "H", "\u041e": "O", "\u0420": "P",
              "\u0421": "C", "\u0422": "T", "\u0425": "X", "\u03b1": "a", "\u03bf": "o", "\u03bd": "v",
              "\u03c1": "p", "\u0391": "A", "\u0392": "B", "\u0395": "E", "\u0397": "H", "\u0399": "I",
              "\u039a": "K", "\u039c": "M", "\u039d": "N", "\u039f": "O", "\u03a1": "P", "\u03a4": "T",
              "\u03a7": "X", "\u03a5": "Y", "\u0396": "Z"}


class SensorWarning(UserWarning):
    """A reader's finding (cut last row, look-alike header) said when the channel checks are turned off."""


def plain_header(cell: str) -> tuple[str, list[str]]:
    """``(cell with look-alike and invisible characters replaced, ["U+0440 CYRILLIC SMALL LETTER ER", ...])``."""
    found: list[str] = []
    out = []
    for ch in cell:
        if ch in LOOKALIKES:
            found.append(_describe(ch))
            out.append(LOOKALIKES[ch])
        elif unicodedata.category(ch) == "Cf":  # zero-width space/joiners, BOM, direction marks
            found.append(_describe(ch))
        elif ord(ch) > 127 and unicodedata.normalize("NFKC", ch) != ch and unicodedata.normalize("NFKC", ch).isascii():
            found.append(_describe(ch))
            out.append(unicodedata.normalize("NFKC", ch))
        else:
            out.append(ch)
    return "".join(out), found


def _describe(ch: str) -> str:
    return f"U+{ord(ch):04X} {unicodedata.name(ch, 'unnamed')}"


def yaw_rate_scale(t, psi, r) -> dict | None:
    """Scale ``k`` of the yaw rate against the heading (dpsi/dt = k r + b), its standard error and bias.

    ``{"scale", "scale_std", "bias_rad_s", "windows", "rho1"}``, or None when there are too few samples.
    """
    t, psi, r = (np.asarray(a, float) for a in (t, psi, r))
    ok = np.isfinite(t) & np.isfinite(psi) & np.isfinite(r)
    t, psi, r = t[ok], psi[ok], r[ok]
    if t.size < 40:
        return None
    ir = np.concatenate([[0.0], np.cumsum(0.5 * (r[1:] + r[:-1]) * np.diff(t))])
    lag = max(1, t.size // _N_WINDOWS)
    idx = np.arange(0, t.size, lag)
    dpsi, dir_, dt = np.diff(psi[idx]), np.diff(ir[idx]), np.diff(t[idx])
    if dpsi.size < 10 or not np.any(dir_):
        return None
    A = np.stack([dir_, dt], axis=1)
    coef, *_ = np.linalg.lstsq(A, dpsi, rcond=None)
    e = dpsi - A @ coef
    m = e.size
    s2 = float(e @ e) / max(m - 2, 1)
    try:
        cov = s2 * np.linalg.inv(A.T @ A)
    except np.linalg.LinAlgError:
        return None
    rho1 = float(np.corrcoef(e[:-1], e[1:])[0, 1]) if m > 3 and np.std(e) > 0 else 0.0
    inflate = math.sqrt((1 + rho1) / (1 - rho1)) if 0 < rho1 < 0.99 else (10.0 if rho1 >= 0.99 else 1.0)
    k = float(coef[0])
    return {"scale": k, "scale_std": float(math.sqrt(max(cov[0, 0], 0.0))) * inflate,
            "bias_rad_s": float(-coef[1] / k) if k else float("nan"), "windows": m, "rho1": rho1}


def _label(log) -> str:
    return f"`{log.path.name}`" if getattr(log, "path", None) is not None else f"log '{log.name}'"


def _col(log, c: str) -> str:
    src = (getattr(log, "sources", None) or {}).get(c)
    return f"'{c}' ({src})" if src else f"'{c}'"


def check_sensors(log, *, reader_notes: dict | None = None) -> list[Finding]:
    """The findings of the checks above for one :class:`~shipid.logs.TrialLog` (``reader_notes``: what the CSV
    reader found, ``{"truncated": {...}, "lookalike": [...]}``)."""
    out: list[Finding] = []
    label = _label(log)
    notes = reader_notes or {}
    tr = notes.get("truncated")
    if tr:
        out.append(Finding("warning", "truncated_row", (), f"{label} row {tr['row']}: the last row is cut short "
                           f"({tr['why']}, no line end): a file copied while it was being written? the row is "
                           "dropped; check that the file is complete", dict(tr)))
    for j, cell, fixed, chars in notes.get("lookalike", []):
        shown = ", ".join(chars[:2]) + (" ..." if len(chars) > 2 else "")
        out.append(Finding("warning", "header_lookalike", (), f"{label} column {j + 1}: header {cell!r} holds "
                           f"look-alike or invisible character(s) {shown}; read as {fixed!r}; retype the header "
                           "in plain letters", {"column": j + 1, "read_as": fixed}))
    data = log.data
    t = log.time
    if "psi" in data.columns and "r" in data.columns:
        est = yaw_rate_scale(t, data["psi"].to_numpy(), data["r"].to_numpy())
        if est is not None:
            k, sk = est["scale"], est["scale_std"]
            dev = abs(k - 1.0)
            if SCALE_FLOOR < dev <= 0.1 and dev > SCALE_SIGMAS * sk:
                out.append(Finding(
                    "warning", "yaw_rate_scale", ("r", "psi"),
                    f"{label}: yaw rate {_col(log, 'r')} reads {100 * (1 / k - 1):+.1f} % against dpsi/dt of the heading "
                    f"(scale {k:.3f} +/- {sk:.3f}, {dev / sk:.0f} standard errors from 1): check the gyro's "
                    "calibration (a fit's yaw coefficients scale with it)", est))
    if "n" in data.columns:
        n = data["n"].to_numpy(dtype=float)
        speed = _speed(log)
        if speed is not None:
            lpp = getattr(getattr(log, "ship", None), "lpp", None)
            way = 0.05 * math.sqrt(9.81 * lpp) if lpp else 0.2  # Froude number 0.05 (or 0.2 m/s)
            moving = np.isfinite(speed) & np.isfinite(n) & (speed > way)
            if moving.sum() >= 10:
                nm = n[moving]
                umax = float(np.max(speed[moving]))
                zero = float(np.mean(nm == 0.0))
                if zero >= 0.9:
                    out.append(Finding(
                        "warning", "propeller_dead", ("n",),
                        f"{label}: propeller {_col(log, 'n')} reads 0 in {100 * zero:.0f} % of the samples while the "
                        f"ship makes way (up to {umax:.3g} m/s): a dead or unmapped channel? check the sensor and "
                        "the column (a fit has no propeller thrust to balance the resistance without it)",
                        {"fraction_zero": zero, "speed_max": umax}))
                elif np.ptp(nm) == 0.0:
                    out.append(Finding(
                        "info", "propeller_constant", ("n",),
                        f"{label}: propeller {_col(log, 'n')} is exactly {nm[0]:.4g} throughout while the ship makes "
                        "way: a commanded rate, or a frozen channel? check that it is the measured rate",
                        {"value": float(nm[0])}))
    return out


def _speed(log):
    d = log.data
    if "u" in d.columns and np.isfinite(d["u"].to_numpy(dtype=float)).any():
        u = d["u"].to_numpy(dtype=float)
        v = d["v"].to_numpy(dtype=float) if "v" in d.columns else 0.0
        return np.hypot(u, np.nan_to_num(v) if np.ndim(v) else v)
    if "x" in d.columns and "y" in d.columns:
        t = log.time
        x, y = d["x"].to_numpy(dtype=float), d["y"].to_numpy(dtype=float)
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.hypot(np.gradient(x, t), np.gradient(y, t))
    return None
