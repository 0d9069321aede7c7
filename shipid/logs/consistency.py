# Why one file: the channel-consistency checks run as one set on one log, each a short function with its message.
"""Channel-consistency checks of a trial log, before any fit.

Aircraft system identification calls this *data compatibility analysis*: the
measured channels must agree with each other kinematically before a model is
fitted to them, and constant biases and scale factors are estimated where the
data allow (Klein & Morelli, *Aircraft System Identification*, AIAA 2006,
ch. 10).  For a ship in the horizontal plane the kinematics are

    dpsi/dt = r,   dx/dt = u cos psi - v sin psi,   dy/dt = u sin psi + v cos psi,

and the conventions say that a positive rudder angle turns the ship to
starboard (heading increasing) when it moves ahead, and that the propeller
turns ahead (n > 0) when it drives the ship ahead.

:func:`check_consistency` compares the channels by *increments over a lag*
(the heading change over L samples against the integral of r over the same
samples, the position change against the integrated velocities), which is
robust to the coarse printing of real files (MARIN prints 3 significant
digits: 1 deg of heading, 10 m of position) where finite differences are not.
Each finding is one plain sentence naming the file and columns and saying
what to do.  :func:`shipid.logs.read_log` runs the checks: errors raise
:class:`~shipid.logs.LogError`, warnings are issued as ``UserWarning``, and the
result is kept as ``log.consistency``.  docs/logs.md explains every message.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from ..results import ResultMixin
from .units import SHIP_CHANNELS, unit_key, UNITS

__all__ = ["Finding", "ConsistencyResult", "check_consistency", "CHECKS"]

#: the checks run by default, in order
CHECKS = ("yaw_rate", "velocity_frame", "rudder_sign", "propeller", "position_freeze", "glitches")

# thresholds (see docs/logs.md for how they were chosen: no error on the bundled logs, the six MARIN
# and the 33 Esso Osaka files; each injected defect of tests/test_logs_consistency.py found)
_FIT_GOOD = 0.3          # yaw rate vs dpsi/dt: rms of the unexplained heading increments / their rms, "agrees"
_FIT_BAD = 0.7           # above: does not agree (error); between: loosely (warning)
_FRAME_GOOD = 0.3        # relative error of the velocity integral against the track, "agrees"
_EXECUTE = math.radians(5.0)     # rudder execute: |delta - delta0| above this
_TURN_ERR = math.radians(10.0)   # heading change against the rudder over the first hold that is an error
_TURN_WARN = math.radians(3.0)   # ... and a warning
_SIGN_T_ERR = 5.0         # t statistic of the rudder's yaw response against shipid's sign that is an error
_SIGN_T_WARN = 3.0        # ... and a warning (a 1e-3 two-sided level for a normal statistic is 3.3)
_NU_WARN, _NU_ERR = 300.0, 3000.0  # median n*u [rps m/s] while moving ahead: looks like rpm
_FREEZE_WARN = 0.01      # fraction of frozen position samples that is warned about
_GLITCH_SIGMA = 12.0     # single-sample spike threshold in robust sigmas of the second difference


@dataclass
class Finding:
    """One consistency finding.

    Attributes
    ----------
    level : {"error", "warning", "info"}
    check : str
        Which check (one of :data:`CHECKS`).
    channels : tuple of str
        The channels concerned.
    message : str
        One sentence naming the file and the columns and saying what to do.
    values : dict
        The numbers behind the finding (correlations, scale, bias, counts, ...).
    """

    level: str
    check: str
    channels: tuple
    message: str
    values: dict = field(default_factory=dict)


@dataclass
class ConsistencyResult(ResultMixin):
    """Findings of :func:`check_consistency` for one log.

    ``success`` is False when there is an error; ``status`` is ``"ok"``,
    ``"warnings"`` or ``"errors"``; ``message`` says so in one line.
    """

    name: str
    findings: list
    checks: tuple = CHECKS

    @property
    def errors(self) -> list:
        return [f for f in self.findings if f.level == "error"]

    @property
    def warnings(self) -> list:
        return [f for f in self.findings if f.level == "warning"]

    @property
    def success(self) -> bool:
        return not self.errors

    @property
    def status(self) -> str:
        return "errors" if self.errors else ("warnings" if self.warnings else "ok")

    @property
    def message(self) -> str:
        ne, nw = len(self.errors), len(self.warnings)
        if not ne and not nw:
            return f"log '{self.name}': channels consistent ({', '.join(self.checks)} checked)"
        return f"log '{self.name}': {ne} consistency error(s), {nw} warning(s)"

    def to_pandas(self) -> pd.DataFrame:
        """One row per finding: level, check, channels, message."""
        return pd.DataFrame([{"level": f.level, "check": f.check, "channels": ", ".join(f.channels),
                              "message": f.message} for f in self.findings],
                            columns=["level", "check", "channels", "message"])

    def summary(self) -> pd.DataFrame:
        """One row per finding (level, check, channels, message); empty when the channels are consistent."""
        return self.to_pandas()

    def _html_title(self) -> str:
        return f"Channel consistency of '{self.name}'"

    def _key_numbers(self) -> dict:
        return {"checks": ", ".join(self.checks), "errors": len(self.errors), "warnings": len(self.warnings)}

    def plot(self, ax=None):
        """Findings per check, stacked by level (error, warning, info); returns the axes."""
        import matplotlib.pyplot as plt  # only when plotting: pyplot takes ~1 s to import

        if ax is None:
            _, ax = plt.subplots(figsize=(6, 2.5))
        checks = list(self.checks)
        bottom = np.zeros(len(checks))
        for level, colour in (("error", "C3"), ("warning", "C1"), ("info", "C0")):
            n = np.array([sum(f.level == level and f.check == c for f in self.findings) for c in checks], dtype=float)
            ax.bar(checks, n, bottom=bottom, color=colour, label=level)
            bottom += n
        ax.set_ylabel("findings")
        ax.tick_params(axis="x", labelrotation=30)
        ax.legend(loc="best", fontsize="small")
        return ax

    def to_dict(self) -> dict:
        return {"name": self.name, "success": self.success, "status": self.status, "message": self.message,
                "findings": [{"level": f.level, "check": f.check, "channels": list(f.channels),
                              "message": f.message, "values": f.values} for f in self.findings]}

    def __str__(self) -> str:
        return "\n".join([self.message] + [f"  {f.level}: {f.message}" for f in self.findings])


# --------------------------------------------------------------------------------------
# helpers
# --------------------------------------------------------------------------------------


class _Ctx:
    def __init__(self, log):
        self.log = log
        self.label = f"`{log.path.name}`" if log.path is not None else f"log '{log.name}'"
        self.t = log.time
        self.findings: list[Finding] = []
        self._sig: dict = {}
        self._arrays: dict = {}
        # kinematic checks on at most ~2048 samples (>= 1024) (increments over lags; integrals at the full rate)
        self.stride = max(1, self.t.size // 1024)

    def col(self, c: str) -> str:
        """``'r' (column 7)``, or ``'r' (column 7 'r_angvelo')`` when the file names it differently."""
        src = self.log.sources.get(c)
        if not src:
            return f"'{c}'"
        m = re.match(r"column (\d+) '(.*?)\s*(?:[\[(].*)?'$", src)
        if not m:
            return f"'{c}' ({src})"
        return f"'{c}' (column {m.group(1)})" if m.group(2) in ("", c) else f"'{c}' (column {m.group(1)} '{m.group(2)}')"

    def add(self, level, check, channels, text, **values):
        self.findings.append(Finding(level, check, tuple(channels), f"{self.label}: {text}", values))

    def get(self, c: str):
        """Channel ``c`` as an array, or None when absent or all NaN (arrays extracted once)."""
        if c not in self._arrays:
            a = self.log.data[c].to_numpy() if c in self.log.data.columns else None
            self._arrays[c] = a if a is not None and np.isfinite(a).any() else None
        return self._arrays[c]

    def _digits(self, c: str) -> tuple[int, float]:
        """(significant digits the file's values of ``c`` are printed with, factor file unit -> SI); judged on
        up to 256 values spread over the log.  16 = full precision."""
        if c not in self._sig:
            unit = unit_key(str(self.log.units_in.get(c, "")).split(" (")[0])
            factor = UNITS.get(unit, ("", 1.0))[1]
            a = self.get(c)
            f = a[np.isfinite(a) & (a != 0)]
            f = f[::max(1, f.size // 256)] / factor
            self._sig[c] = (_sig_digits(f), factor)
        return self._sig[c]

    def resolution(self, c: str, idx=slice(None)) -> np.ndarray:
        """Print resolution of channel ``c`` [SI] at samples ``idx``, from the digits of the file's values in
        the file's own unit (MARIN prints 3 significant digits: 0.1 deg at 35 deg, 10 m at 1000 m)."""
        s, factor = self._digits(c)
        a = np.abs(self.get(c)[idx]) / factor
        if s >= 16:
            return np.zeros_like(a)
        with np.errstate(divide="ignore", invalid="ignore"):
            ex = np.floor(np.log10(np.where(a > 0, a, 1.0)))
        return 10.0 ** (ex - (s - 1)) * factor

    def typical_resolution(self, c: str) -> float:
        """A channel's coarse print resolution: at its 90th-percentile magnitude."""
        s, factor = self._digits(c)
        a = np.abs(self.get(c))
        a = a[np.isfinite(a)][::max(1, a.size // 1024)]
        if s >= 16 or a.size == 0:
            return 0.0
        top = float(np.percentile(a, 90)) / factor
        return 10.0 ** (math.floor(math.log10(top)) - (s - 1)) * factor if top > 0 else 0.0


def _median(a: np.ndarray):
    """``np.median`` of a 1-D array, the same value to the last bit (the middle order statistics by
    ``np.partition``, NaN when any value is NaN), without ``np.median``'s general-axis overhead, which
    dominated these checks on their ~1-2k-sample grids."""
    a = np.asarray(a, dtype=float).ravel()
    n = a.size
    if n == 0:
        return np.median(a)  # NaN with numpy's warning
    k = n // 2
    p = np.partition(a, (k - 1, k, n - 1) if n % 2 == 0 else (k, n - 1))
    if np.isnan(p[-1]):
        return np.float64(np.nan)
    return p[k] if n % 2 else (p[k - 1] + p[k]) / 2.0


def _cumint(t: np.ndarray, a: np.ndarray) -> np.ndarray:
    """Cumulative trapezoidal integral of a(t), shape (n,), starting at 0 (NaN propagates)."""
    return np.concatenate([[0.0], np.cumsum(0.5 * (a[1:] + a[:-1]) * np.diff(t))])


def _quantum(a: np.ndarray) -> float:
    """Typical resolution of a channel: the median non-zero step between samples (0 if none)."""
    d = np.abs(np.diff(a[np.isfinite(a)]))
    d = d[d > 0]
    d = d[::max(1, d.size // 1024)]
    return float(_median(d)) if d.size else 0.0


def _lag(n: int, step: np.ndarray, resolution: float) -> int:
    """Samples per increment: the smallest power of 2 whose median |increment| is >= 10 resolutions."""
    lag = 1
    csum = np.concatenate([[0.0], np.cumsum(np.abs(np.nan_to_num(step)))])
    while lag * 8 < n:
        inc = csum[lag:] - csum[:-lag]
        if _median(inc) >= 10.0 * max(resolution, 1e-300):
            break
        lag *= 2
    return lag


def _incr(a: np.ndarray, lag: int) -> np.ndarray:
    return a[lag:] - a[:-lag]


def _segments(t: np.ndarray, dt_med: float) -> np.ndarray:
    """Segment number of each sample, shape (n,): it steps up after each time dropout (an interval longer than 3
    x the median ``dt_med``), so an increment over samples of one segment has ``_incr(seg, lag) == 0``.  An
    increment across a dropout compares the heading/position change with an integral that bridged the gap by a
    straight line: not a comparison of the channels."""
    return np.concatenate([[0], np.cumsum(np.diff(t) > 3.0 * dt_med)])


def _corr(a: np.ndarray, b: np.ndarray) -> float:
    ok = np.isfinite(a) & np.isfinite(b)
    if ok.sum() < 5:
        return float("nan")
    a, b = a[ok], b[ok]
    sa, sb = a.std(), b.std()
    if sa == 0 or sb == 0:
        return float("nan")
    return float(np.mean((a - a.mean()) * (b - b.mean())) / (sa * sb))


def _lags(lag0: int, n: int) -> list[int]:
    """lag0, 2 lag0, 4 lag0, ... while at least 16 increments fit."""
    out = [lag0]
    while out[-1] * 32 < n:
        out.append(out[-1] * 2)
    return out


def _yaw_fit(t, psi, int_r, lag, seg=None):
    """Heading increments over ``lag`` samples against those of the integral of r (``int_r``, same samples;
    increments across a dropout of ``seg`` (:func:`_segments`) left out):
    (unexplained fraction with r as logged, unexplained fraction with scale k and bias b fitted, k,
    b [rad/s], correlation)."""
    dpsi, dt_l, ir = _incr(psi, lag), _incr(t, lag), _incr(int_r, lag)
    if seg is not None:
        same = _incr(seg, lag) == 0
        dpsi, dt_l, ir = dpsi[same], dt_l[same], ir[same]
        if dpsi.size < 5:
            return float("inf"), float("inf"), float("nan"), float("nan"), float("nan")
    scale = float(np.sqrt(np.mean(dpsi ** 2)))
    if scale == 0:
        return float("inf"), float("inf"), float("nan"), float("nan"), float("nan")
    # dpsi/dt = k (r - b): dpsi = k ir - k b dt  (least squares in k and k b)
    A = np.stack([ir, dt_l], axis=1)
    if abs(_corr(ir, dt_l)) > 0.999 or np.std(dt_l) == 0 and np.std(ir) < 1e-3 * np.mean(np.abs(ir)):
        A = A[:, :1]   # r (nearly) constant: a scale and a bias cannot be told apart; fit the scale only
    coef, *_ = np.linalg.lstsq(A, dpsi, rcond=None)
    k = float(coef[0])
    bias = float(-coef[1] / k) if k != 0 and coef.size > 1 else float("nan")
    e_direct = float(np.sqrt(np.mean((dpsi - ir) ** 2)) / scale)
    e_fit = float(np.sqrt(np.mean((dpsi - A @ coef) ** 2)) / scale)
    return e_direct, e_fit, k, bias, _corr(dpsi, ir)


def _deg(x: float) -> str:
    return f"{math.degrees(x):+.3g} deg"


# --------------------------------------------------------------------------------------
# the checks
# --------------------------------------------------------------------------------------


def _other_yaw_column(c: _Ctx, ok, st, t_full, t, psi, seg, lags):
    """The column other than r whose integral explains the heading's increments as logged (no scale fitted),
    ``(name, unexplained fraction, correlation)``, when one does (unexplained fraction <= the "agrees" level);
    else None."""
    best, best_e, best_rho = None, float("inf"), float("nan")
    for other in c.log.channels:
        if other in ("psi", "r"):
            continue
        a = c.get(other)
        if a is None or not np.isfinite(a[ok]).all():
            continue
        io = _cumint(t_full, a[ok])[::st]
        eo, rho_o = min((_yaw_fit(t, psi, io, g, seg)[0], _yaw_fit(t, psi, io, g, seg)[4]) for g in lags)
        if eo < best_e:
            best, best_e, best_rho = other, eo, rho_o
    return (best, best_e, best_rho) if best is not None and best_e <= _FIT_GOOD else None


def _check_yaw_rate(c: _Ctx) -> None:
    psi, r = c.get("psi"), c.get("r")
    if psi is None or r is None:
        return
    t = c.t
    ok = np.isfinite(psi) & np.isfinite(r)
    if ok.sum() < 20:
        return
    st = c.stride   # on ~1024-2048 samples; the integrals at the full rate (r may be noisy)
    t_full = t[ok]
    ir_s = _cumint(t_full, r[ok])[::st]
    seg = _segments(t_full, float(_median(np.diff(c.t))))[::st]
    t, psi, r = t_full[::st], psi[ok][::st], r[ok]
    # the heading's change, not its noise: the range of its running mean over 1/50 of the samples (a noisy
    # compass on a straight course has a range of many degrees and no turn to compare r with)
    # (noise std from the sample-to-sample steps; the range of the mean of w noisy samples stays below 8 of
    # its std), so the heading must change by 5 deg and by more than its noise allows
    w = max(1, psi.size // 50)
    psi_s = np.convolve(psi, np.ones(w) / w, mode="valid")
    noise = 1.4826 * float(_median(np.abs(np.diff(psi)))) / math.sqrt(2.0)
    if np.ptp(psi_s) < max(math.radians(5.0), 8.0 * noise / math.sqrt(w)):
        c.add("info", "yaw_rate", ("r", "psi"), f"heading {c.col('psi')} changes by less than 5 deg: yaw rate "
              "not compared with dpsi/dt")
        return
    lag0 = _lag(psi.size, np.diff(psi), max(c.typical_resolution("psi"), _quantum(psi)))
    # the time scale at which r explains the heading best (short lags: noise; long: few increments)
    fits = {lag: _yaw_fit(t, psi, ir_s, lag, seg) for lag in _lags(lag0, psi.size)}
    lag = min(fits, key=lambda g: fits[g][1])
    e_direct, e_fit, k, bias, rho = fits[lag]
    vals = dict(rho=rho, scale=k, bias_rad_s=bias, error_direct=e_direct, error_fitted=e_fit, lag_samples=lag)
    who = f"yaw rate {c.col('r')}"
    shown = f"{rho:.3f}" if math.isfinite(rho) else "undefined"
    if e_fit <= _FIT_GOOD and k < -0.5 and abs(k + 1.0) >= 0.25:
        # r follows the heading with the other sign but not at its rate: another column (v, in a ship whose
        # drift opposes its turn) may sit in r's place; the search below decides
        e_fit = max(e_fit, _FIT_GOOD + 1e-9) if _other_yaw_column(c, ok, st, t_full, t, psi, seg, fits) else e_fit
    if e_fit <= _FIT_GOOD and k < -0.5:
        c.add("error", "yaw_rate", ("r", "psi"),
              f"{who} has the opposite sign to dpsi/dt of {c.col('psi')} (rho = {shown}, dpsi/dt = {k:.3g} r): "
              "negate r (CLI: --sign r=-1; schema \"signs\": {\"r\": -1}) or the heading", **vals)
        return
    if e_fit > _FIT_GOOD:
        # r does not explain the heading: which other column does?
        best, best_e, best_rho = _other_yaw_column(c, ok, st, t_full, t, psi, seg, fits) or (None, float("inf"),
                                                                                              float("nan"))
        if best is not None and best_e <= _FIT_GOOD:
            src = c.log.sources.get(best)
            target = src.split(" '")[0] if src else f"'{best}'"
            c.add("error", "yaw_rate", ("r", best),
                  f"{c.col(best)} agrees with dpsi/dt (rho = {best_rho:.3f}), {who} does not (rho = {shown}): "
                  f"columns swapped? map r to {target}", other=best, rho_other=best_rho, **vals)
        elif e_fit > _FIT_BAD:
            c.add("error", "yaw_rate", ("r", "psi"),
                  f"{who} does not agree with dpsi/dt of {c.col('psi')} (rho = {shown}; no other column does): "
                  "check the column, its unit and the heading", **vals)
        else:
            c.add("warning", "yaw_rate", ("r", "psi"),
                  f"{who} agrees only loosely with dpsi/dt of {c.col('psi')} (rho = {shown}, {100 * e_fit:.0f} % "
                  "unexplained): check the column, its filtering and time alignment", **vals)
        return
    if 40.0 < k < 80.0 or 1 / 80.0 < k < 1 / 40.0:
        fix = "psi is in degrees: declare units={'psi': 'deg'} (CLI: --units psi=deg)" if k > 1 else \
            "r is in deg/s: declare units={'r': 'deg/s'} (CLI: --units r=deg/s)"
        c.add("error", "yaw_rate", ("r", "psi"), f"dpsi/dt = {k:.4g} x {who} (57.3 = deg/rad): {fix}", **vals)
        return
    if abs(k - 1.0) > 0.1:
        c.add("warning", "yaw_rate", ("r", "psi"),
              f"dpsi/dt = {k:.3g} x {who} (rho = {shown}): a scale error of {100 * (k - 1):+.0f} %; check r's "
              "unit or calibration", **vals)
        return
    rmax = float(np.max(np.abs(r)))
    if abs(bias) > 0.05 * rmax:
        c.add("warning", "yaw_rate", ("r",),
              f"{who} carries a constant bias of {_deg(bias)}/s ({100 * abs(bias) / rmax:.0f} % of its largest "
              "value) against dpsi/dt: subtract it or fit a yaw-rate bias", **vals)
        return
    c.add("info", "yaw_rate", ("r", "psi"),
          f"{who} agrees with dpsi/dt (rho = {shown}, scale {k:.3f}, "
          + (f"bias {_deg(bias)}/s)" if math.isfinite(bias) else "bias not separable: r nearly constant)"), **vals)


def _check_velocity_frame(c: _Ctx) -> None:
    x, y, u, v, psi = (c.get(k) for k in ("x", "y", "u", "v", "psi"))
    if any(a is None for a in (x, y, u, v, psi)):
        return
    ok = np.isfinite(x) & np.isfinite(y) & np.isfinite(u) & np.isfinite(v) & np.isfinite(psi)
    if ok.sum() < 20:
        return
    st = c.stride   # on ~1024-2048 samples; the integrals at the full rate
    t, x, y, u, v, psi = (a[ok] for a in (c.t, x, y, u, v, psi))
    cs, sn = np.cos(psi), np.sin(psi)
    h = np.diff(t)[:, None] * 0.5
    integ: dict = {}

    def integrate(**cols):   # full-rate trapezoidal integrals, then the ~1-2k sample grid
        V = np.stack(list(cols.values()), axis=1)
        I = np.concatenate([np.zeros((1, V.shape[1])), np.cumsum((V[1:] + V[:-1]) * h, axis=0)])[::st]
        integ.update(zip(cols, I.T))

    integrate(ub=u * cs - v * sn, vb=u * sn + v * cs)
    seg = _segments(t, float(_median(np.diff(c.t))))[::st]
    t, x, y = t[::st], x[::st], y[::st]
    step = np.hypot(np.diff(x), np.diff(y))
    lag0 = _lag(x.size, step, max(c.typical_resolution("x"), c.typical_resolution("y"), _quantum(x), _quantum(y)))

    def incr(ke, kn, lag):   # track and velocity-integral increments, none across a dropout
        same = _incr(seg, lag) == 0
        return tuple(_incr(a, lag)[same] for a in (x, y, integ[ke], integ[kn]))

    def err(ke, kn, lag, k=1.0):
        dx, dy, px, py = incr(ke, kn, lag)
        scale = float(_median(np.hypot(dx, dy))) if dx.size >= 5 else 0.0
        if scale <= 0:
            return float("inf")
        return float(_median(np.hypot(dx - k * px, dy - k * py)) / scale)

    def speed_scale(ke, kn, lag):   # k of track = k x velocity integral (least squares)
        dx, dy, px, py = incr(ke, kn, lag)
        den = float(np.sum(px * px + py * py))
        return float(np.sum(dx * px + dy * py)) / den if den > 0 else float("nan")

    lags = _lags(lag0, x.size)
    body = {lag: err("ub", "vb", lag) for lag in lags}
    lag = min(body, key=body.get)
    uv = f"{c.col('u')}, {c.col('v')}"
    uf, vf = (a[ok] for a in (c.get("u"), c.get("v")))
    integrate(u=uf, v=vf, ubs=vf * cs - uf * sn, vbs=vf * sn + uf * cs, unx=u * cs + v * sn, uny=u * sn - v * cs)
    # v with the other sign (positive to port): the body-axis track with -v, against the one with v
    e_vneg = min(err("unx", "uny", g) for g in lags)
    if e_vneg <= _FRAME_GOOD and e_vneg < 0.5 * body[lag]:
        c.add("error", "velocity_frame", ("v",),
              f"{c.col('v')} has the other sign: with -v the body-axis velocities integrate to the track of x, y "
              f"(median error {100 * e_vneg:.0f} %), with v as logged worse ({100 * body[lag]:.0f} %): pass signs "
              "{'v': -1} (CLI: --sign v=-1)", error_body=body[lag], error_v_negated=e_vneg, lag_samples=lag)
        return
    if body[lag] <= _FRAME_GOOD:
        # both hypotheses: earth-fixed u, v that integrate to the track clearly better (half the error) are
        # earth-fixed, however small the body-axis error (on a course that turns little the two readings differ
        # little, and a body-axis error of 20 % passes)
        e_earth = min(err("u", "v", g) for g in lags)
        if e_earth < 0.5 * body[lag] and "(earth-fixed)" not in str(c.log.units_in.get("u", "")):
            c.add("error", "velocity_frame", ("u", "v"),
                  f"{uv} integrate to the track of x, y better as earth-fixed (median error {100 * e_earth:.0f} %) "
                  f"than as body-axis velocities ({100 * body[lag]:.0f} %): pass velocity_frame='earth' (CLI: "
                  "--velocity-frame earth)", error_body=body[lag], error_earth=e_earth, lag_samples=lag)
            return
        c.add("info", "velocity_frame", ("u", "v"),
              f"body-axis {uv} integrate to the track of x, y (median error {100 * body[lag]:.0f} %)",
              error_body=body[lag], error_earth=e_earth, lag_samples=lag)
        return
    # body axes do not fit: earth-fixed? swapped?
    errs = {g: (body[g], err("u", "v", g)) for g in lags}
    lag = min(errs, key=lambda g: min(errs[g]))
    e_body, e_earth = errs[lag]
    if not math.isfinite(min(e_body, e_earth)):
        return
    vals = dict(error_body=e_body, error_earth=e_earth, lag_samples=lag)
    if "(earth-fixed)" in str(c.log.units_in.get("u", "")):
        # the reader rotated u, v as earth-fixed: do the file's own values fit as body axes?
        fu, fv = uf * cs - vf * sn, uf * sn + vf * cs   # the file's values, un-rotated
        integrate(fbx=fu * cs - fv * sn, fby=fu * sn + fv * cs)
        e_file = err("fbx", "fby", lag)
        if e_file <= _FRAME_GOOD and e_file < 0.5 * e_body:
            c.add("error", "velocity_frame", ("u", "v"),
                  f"the file's {uv} are body-axis (error {100 * e_file:.0f} %), but were read as earth-fixed and "
                  f"rotated ({100 * e_body:.0f} %): drop velocity_frame='earth' (CLI: --velocity-frame body)",
                  error_file_body=e_file, **vals)
            return
    if e_earth <= _FRAME_GOOD and e_earth < 0.5 * e_body:
        c.add("error", "velocity_frame", ("u", "v"),
              f"{uv} agree with the earth-fixed dx/dt, dy/dt (error {100 * e_earth:.0f} %), not with body axes "
              f"({100 * e_body:.0f} %): pass velocity_frame='earth' (CLI: --velocity-frame earth)", **vals)
        return
    e_swap = err("ubs", "vbs", lag)
    if e_swap <= _FRAME_GOOD:
        c.add("error", "velocity_frame", ("u", "v"),
              f"{uv} look swapped: (v, u) fit the track (error {100 * e_swap:.0f} %), (u, v) do not "
              f"({100 * e_body:.0f} %): map u and v to each other's column", error_swapped=e_swap, **vals)
        return
    # u, v that fit the track up to a factor: a unit left undeclared (knots, km/h) or time not in seconds
    for frame, ke, kn in (("body", "ub", "vb"), ("earth", "u", "v")):
        k = speed_scale(ke, kn, lag)
        if not (math.isfinite(k) and k > 0 and err(ke, kn, lag, k) <= _FRAME_GOOD):
            continue
        vals.update(speed_scale=k, frame=frame)
        also = " (and they are earth-fixed: pass velocity_frame='earth', CLI: --velocity-frame earth)" \
            if frame == "earth" else ""
        for factor, fix in _SPEED_UNITS:
            if abs(k / factor - 1.0) < 0.05:
                c.add("error", "velocity_frame", ("u", "v"),
                      f"{uv} are {1 / k:.4g} x the speed along the track of x, y{also}: {fix}", **vals)
                return
        c.add("warning", "velocity_frame", ("u", "v", "x", "y"),
              f"{uv} are {1 / k:.4g} x the speed along the track of x, y{also}: check the units of u, v, x, y "
              "and time", **vals)
        return
    c.add("warning", "velocity_frame", ("u", "v", "x", "y"),
          f"{uv} agree with neither the body-axis ({100 * e_body:.0f} %) nor the earth-fixed ({100 * e_earth:.0f} %) "
          "reading of the track x, y: check the columns, their units and the heading", **vals)


#: (track speed / logged speed, what to do) for the units a file's speeds or time are commonly in unawares
_SPEED_UNITS = (
    (1852.0 / 3600.0, "u, v look like knots: declare units={'u': 'kn', 'v': 'kn'} (CLI: --units u=kn,v=kn)"),
    (1.0 / 3.6, "u, v look like km/h: declare units={'u': 'km/h', 'v': 'km/h'} (CLI: --units u=km/h,v=km/h)"),
    (1e-3, "time looks like milliseconds: declare units={'time': 'ms'} (CLI: --units time=ms)"),
    (60.0, "time looks like minutes: declare units={'time': 'min'} (CLI: --units time=min)"),
)


def _yaw_rate_series(c: _Ctx):
    """The yaw rate [rad/s] at every sample: the logged r when the yaw-rate check found nothing wrong with it,
    else the heading's central difference."""
    r = c.get("r")
    doubted = any(f.check == "yaw_rate" and f.level in ("error", "warning") for f in c.findings)
    if r is not None and np.isfinite(r).sum() > 20 and not doubted:
        return r
    psi = c.get("psi")
    if psi is None:
        return None
    with np.errstate(all="ignore"):
        return np.gradient(psi, c.t)


def _rudder_response(t, r, d, v, ahead, lag):
    """The yaw response to the rudder's *changes*, from pairs of adjacent windows of ``lag`` samples.

    The linear yaw equation ``dr/dt = c2 r + c1 v + c3 delta + c0`` in increments over a window,
    ``r(k + L) - r(k) = c2 int r + c1 int v + c3 int delta + c0 T``, differenced between a window and the
    one before it: the constant ``c0`` (a neutral rudder angle, a propeller's side force) cancels, and the
    rudder's movements, which are fast, dominate while ``r`` and ``v`` change smoothly.  Least squares of the
    differenced yaw-rate increments on the differenced integrals of ``r``, ``delta`` (and ``v`` when logged)
    over window pairs that do not overlap, where the ship moves ahead (``ahead``).  (``v`` is left out by the
    check: in a steady turn it is nearly collinear with ``r``.)  Returns ``(c3, its t
    statistic, pairs)``."""
    n = t.size
    mid = np.arange(lag, n - lag, 2 * lag)
    if mid.size < 8:
        return float("nan"), float("nan"), int(mid.size)
    cols = [d, r] + ([v] if v is not None else [])
    ints = [_cumint(t, np.nan_to_num(a)) for a in cols]
    lo, hi = mid - lag, mid + lag
    bad = np.concatenate([[0], np.cumsum(~ahead | ~np.isfinite(d) | ~np.isfinite(r))])
    ok = (bad[hi + 1] - bad[lo]) == 0
    if ok.sum() < 8:
        return float("nan"), float("nan"), int(ok.sum())

    def d2(a):
        return ((a[hi] - a[mid]) - (a[mid] - a[lo]))[ok]

    y = d2(r)
    X = np.column_stack([d2(I) for I in ints])
    if not np.any(X[:, 0]):
        return float("nan"), float("nan"), int(ok.sum())
    coef, *_ = np.linalg.lstsq(X, y, rcond=None)
    res = y - X @ coef
    dof = max(1, y.size - X.shape[1])
    s2 = float(res @ res) / dof
    try:
        cov = s2 * np.linalg.inv(X.T @ X)
    except np.linalg.LinAlgError:
        return float("nan"), float("nan"), int(ok.sum())
    se = math.sqrt(max(float(cov[0, 0]), 0.0))
    return float(coef[0]), (float(coef[0]) / se if se > 0 else float("nan")), int(ok.sum())


def _first_hold(c: _Ctx):
    """The heading change over the first rudder hold against its side: ``(level, text, values)`` when it
    turned the ship against shipid's convention by more than 10 deg (error) or 3 deg (warning), else None."""
    d, psi, u = c.get("delta"), c.get("psi"), c.get("u")
    if d is None or psi is None or u is None:
        return None
    n = c.get("n")
    t = c.t
    d0 = float(np.nanmedian(d[:max(5, d.size // 50)]))
    off = d - d0
    hit = np.flatnonzero(np.abs(off) > _EXECUTE)
    if hit.size == 0:
        return None
    i = int(hit[0])
    side = math.copysign(1.0, off[i])
    # the rudder hold: until it comes back within half the execute angle or changes side
    rest = np.flatnonzero((side * off[i:] < 0.5 * _EXECUTE))
    j = i + int(rest[0]) if rest.size else d.size - 1
    if j - i < 3:
        return None
    seg = slice(i, j + 1)
    umax = float(np.nanmax(u))
    ahead = umax > 0 and float(np.nanmin(u[seg])) > 0.3 * umax
    if n is not None:
        ahead = ahead and float(np.nanmin(n[seg])) >= 0
    turn = float(psi[j] - psi[i])
    if not ahead or not math.isfinite(turn):
        return None
    held = float(d[seg][int(np.nanargmax(np.abs(off[seg])))])
    vals = dict(execute_time=float(t[i]), delta_held=held, heading_change=turn)
    what = (f"the first rudder execute ({c.col('delta')} {math.degrees(held):+.1f} deg, t = {t[i]:.4g} s) turned the "
            f"ship to {'port' if turn < 0 else 'starboard'} (heading {math.degrees(turn):+.0f} deg)")
    if side * turn <= -_TURN_ERR:
        return "error", what, vals
    if side * turn <= -_TURN_WARN:
        return "warning", what, vals
    return None


def _check_rudder_sign(c: _Ctx) -> None:
    """The rudder's sign from the yaw response to every rudder movement of the log.

    Under shipid's convention a positive rudder turns the ship to starboard when it moves ahead: the yaw
    acceleration follows the rudder, ``dr/dt = c2 r + c3 delta + ...`` with ``c3 > 0`` for every ship with a
    stern rudder.  The fit of :func:`_rudder_response` gives the sign of ``c3`` with its t statistic from all
    rudder movements at once, so a zigzag with small check angles (heading changes of a few degrees between
    reversals) is judged as surely as a turning circle.  A clear heading change against the rudder over the
    first hold (:func:`_first_hold`) is an error too, and a weaker one an error when the whole log agrees."""
    d, u = c.get("delta"), c.get("u")
    r = _yaw_rate_series(c)
    if d is None or r is None:
        return
    t = c.t
    n_ = c.get("n")
    d0 = float(np.nanmedian(d[:max(5, d.size // 50)]))
    off = d - d0
    if not np.nanmax(np.abs(off)) > math.radians(1.0):
        return   # the rudder never moves: nothing to judge
    if u is not None and np.isfinite(u).any() and np.nanmax(u) > 0:
        ahead = np.nan_to_num(u, nan=-1.0) > 0.3 * float(np.nanmax(u))
    else:
        ahead = np.ones(t.size, dtype=bool)
    if n_ is not None:
        ahead &= ~(np.nan_to_num(n_) < 0)
    # windows of 4, 8, 16, ... samples (while 32 pairs fit): the rudder's movements take from a second (a model)
    # to tens of seconds (a full-scale ship); the sign is judged at the window where the response is clearest,
    # and not at all when windows disagree clearly (|t| >= the error level with both signs)
    fits = []
    lag = 4
    while lag * 64 <= t.size:
        k_, t_, m_ = _rudder_response(t, r, off, None, ahead, lag)
        if math.isfinite(t_):
            fits.append((k_, t_, m_, lag))
        lag *= 2
    if not fits:
        return
    k, tstat, m, lag = min(fits, key=lambda f: f[1])
    if max(f[1] for f in fits) >= _SIGN_T_ERR and tstat <= -_SIGN_T_ERR:
        tstat = float("nan")   # contradictory evidence: no judgement from the whole log
    first = _first_hold(c)
    vals = dict(yaw_per_rudder=k, t_statistic=tstat, windows=m, lag_samples=lag, neutral_rad=d0)
    if first is not None and (first[0] == "error" or not tstat > -_SIGN_T_ERR):
        # the first hold's turn (a turning circle's or a large zigzag's first heading change) is the plainer
        # evidence when it is clear; the whole log's response decides otherwise
        level, what, v1 = first
        if level == "error" or tstat <= -_SIGN_T_WARN:
            c.add("error", "rudder_sign", ("delta",),
                  f"{what}: rudder sign opposite to shipid's; pass rudder_sign=-1 (CLI: --rudder-sign -1)", **vals, **v1)
            return
    if not math.isfinite(tstat):
        return
    what = (f"over the whole log ({m} pairs of windows of {lag} samples) positive rudder {c.col('delta')} turns the ship "
            f"to port (yaw acceleration per rudder angle {k:.3g} 1/s^2, t = {tstat:.1f})")
    if tstat <= -_SIGN_T_ERR:
        c.add("error", "rudder_sign", ("delta",),
              f"{what}: rudder sign opposite to shipid's; pass rudder_sign=-1 (CLI: --rudder-sign -1)", **vals)
    elif tstat <= -_SIGN_T_WARN:
        c.add("warning", "rudder_sign", ("delta",),
              f"{what}, against shipid's convention (positive rudder to starboard); check the rudder sign "
              "(rudder_sign=-1 flips it)", **vals)


def _check_propeller(c: _Ctx) -> None:
    n, u = c.get("n"), c.get("u")
    if n is None or u is None:
        return
    umax = float(np.nanmax(u))
    if not umax > 0:
        return
    ahead = np.isfinite(u) & np.isfinite(n) & (u > 0.3 * umax)
    if ahead.sum() < 10:
        return
    neg = float(np.mean(n[ahead] < 0))
    if neg > 0.8:
        c.add("warning", "propeller", ("n",),
              f"{c.col('n')} is negative (astern) in {100 * neg:.0f} % of the samples while the ship moves ahead "
              f"(u up to {umax:.3g} m/s): propeller sign flipped? (shipid: n > 0 ahead); negate n",
              fraction_negative=neg)
        return
    # n u [rps m/s] ~ g Fn^2 / (J D/L): 1..150 for displacement ships and their models at any scale
    # (KVLCC2 full scale 12, KCS 4.36 m model 17, Esso Osaka 3 m model 4..8); rpm gives 60 x that
    score = float(np.median(np.abs(n[ahead]) * u[ahead]))
    vals = dict(n_times_u=score)
    if c.log.ship is not None and score > _NU_WARN:
        if np.nanmax(np.abs(n)) * math.sqrt(c.log.ship.lpp) <= 200.0:
            return   # the ship's length says rps (checked when reading)
    if score > _NU_ERR:
        c.add("error", "propeller", ("n",),
              f"{c.col('n')} looks like rpm: n x u = {score:.0f} rps m/s while moving ahead (ships and models: "
              "~1-150); declare units={'n': 'rpm'} (CLI: --units n=rpm)", **vals)
    elif score > _NU_WARN:
        c.add("warning", "propeller", ("n",),
              f"{c.col('n')} may be in rpm: n x u = {score:.0f} rps m/s while moving ahead (ships and models: "
              "~1-150; fast craft more); if so declare units={'n': 'rpm'}, or give lpp", **vals)


def _sig_digits(f: np.ndarray) -> int:
    """Fewest significant digits that reproduce every (non-zero, finite) value of ``f``; 16 if none do."""
    if f.size == 0:
        return 16
    ex = np.floor(np.log10(np.abs(f)))
    s = np.arange(1, 16)[:, None]
    q = 10.0 ** (ex[None, :] - (s - 1))   # (15, n): the print step of each value at 1..15 digits, all at once
    ok = np.all(np.abs(np.round(f / q) * q - f) <= 1e-9 * np.abs(f), axis=1)
    return int(np.argmax(ok)) + 1 if ok.any() else 16


def _check_position_freeze(c: _Ctx) -> None:
    x, y, u, v = (c.get(k) for k in ("x", "y", "u", "v"))
    if x is None or y is None or u is None or v is None:
        return
    t = c.t
    dx, dy = np.diff(x), np.diff(y)
    frozen = (dx == 0) & (dy == 0)
    cand = np.flatnonzero(frozen)
    if cand.size:
        expected = np.hypot(u[cand + 1], v[cand + 1]) * (t[cand + 1] - t[cand])
        res = np.maximum(c.resolution("x", cand + 1), c.resolution("y", cand + 1))
        frozen[cand] = (expected > 2.0 * res) & np.isfinite(expected)
    nf = int(frozen.sum())
    if nf == 0:
        return
    f = np.concatenate([[False], frozen, [False]]).astype(np.int8)
    starts, ends = np.flatnonzero(np.diff(f) == 1), np.flatnonzero(np.diff(f) == -1)   # runs [s, e)
    longest = float(max(t[e] - t[s] for s, e in zip(starts, ends)))
    jumps = [float(np.hypot(dx[e], dy[e])) for e in ends if e < dx.size]
    frac = nf / max(dx.size, 1)
    vals = dict(frozen_samples=nf, fraction=frac, stretches=int(starts.size), longest_s=longest,
                max_jump_m=max(jumps) if jumps else 0.0)
    level = "warning" if frac > _FREEZE_WARN else "info"
    c.add(level, "position_freeze", ("x", "y"),
          f"positions {c.col('x')}, {c.col('y')} freeze on {nf} samples while the ship moves ({100 * frac:.1f} %, "
          f"{starts.size} stretches, longest {longest:.3g} s), then jump (up to {vals['max_jump_m']:.3g} m): "
          "GNSS freezes; give x, y little weight", **vals)


def _check_glitches(c: _Ctx) -> None:
    counts, first = {}, {}
    units = c.log.units()
    names = [ch for ch in c.log.channels if c.get(ch) is not None]
    if len(c.t) < 10 or not names:
        return
    # first differences of all channels at once, (n-1, channels); wrapped angles (wind directions) wrapped
    A = np.column_stack([c.get(ch) for ch in names]).astype(float, copy=False)  # the cached column arrays
    D = A[1:] - A[:-1]
    for j, ch in enumerate(names):
        if units.get(ch) == "rad" and ch not in SHIP_CHANNELS:
            D[:, j] = (D[:, j] + math.pi) % (2 * math.pi) - math.pi
    step = max(1, D.shape[0] // 1024)
    sub, sub2 = D[::step], (D[1:] - D[:-1])[::step]   # first and second differences, a subset
    thr = np.zeros(len(names))
    for j in range(len(names)):
        d1, d2 = sub[:, j][np.isfinite(sub[:, j])], sub2[:, j][np.isfinite(sub2[:, j])]
        if d2.size < 10:
            continue
        sig = 1.4826 * float(_median(np.abs(d2 - _median(d2))))
        nz = np.abs(d1[d1 != 0])
        # beyond 12 robust sigmas and 10 typical steps (quantised sensors dither by one step: the Esso rudder
        # by 0.56 deg), and (below) 3 print resolutions at the sample (MARIN: 0.1 deg at 35 deg)
        thr[j] = max(_GLITCH_SIGMA * sig, 10.0 * (float(_median(nz)) if nz.size else 0.0))
    with np.errstate(invalid="ignore"):
        big = np.abs(D) > np.where(thr > 0, thr, np.inf)
    # a spike at sample i: a big step up to it and a big step back, the neighbours agreeing
    both = big[:-1] & big[1:]
    hit = np.flatnonzero(both.any(axis=1))
    sub_rows, cols = np.nonzero(both[hit])
    rows = hit[sub_rows]
    if rows.size:
        up, back = D[rows, cols], D[rows + 1, cols]
        ok = (np.sign(up) == -np.sign(back)) & (np.abs(up + back) < 0.25 * np.minimum(np.abs(up), np.abs(back)))
        rows, cols, up, back = rows[ok], cols[ok], up[ok], back[ok]
    for j in np.unique(cols):
        ch = names[j]
        i = rows[cols == j] + 1
        res = 3.0 * c.resolution(ch, i)
        keep = i[(np.abs(up[cols == j]) > res) & (np.abs(back[cols == j]) > res)]
        if keep.size:
            counts[ch] = int(keep.size)
            first[ch] = int(c.log.rows[int(keep[0])])
    if not counts:
        return
    total = sum(counts.values())
    parts = ", ".join(f"{c.col(ch)} {k} (first at row {first[ch]})" for ch, k in counts.items())
    level = "warning" if total > max(2, 0.001 * len(c.log)) else "info"
    c.add(level, "glitches", tuple(counts),
          f"single-sample spikes: {parts}; check the sensor or blank those cells", counts=counts, first_rows=first)


_RUN = {"yaw_rate": _check_yaw_rate, "velocity_frame": _check_velocity_frame, "rudder_sign": _check_rudder_sign,
        "propeller": _check_propeller, "position_freeze": _check_position_freeze, "glitches": _check_glitches}


def check_consistency(log, *, checks=CHECKS) -> ConsistencyResult:
    """Check that a log's channels agree with each other (kinematics and sign conventions).

    Parameters
    ----------
    log : TrialLog
    checks : sequence of str
        Which of :data:`CHECKS` to run (default all): ``yaw_rate`` (r against
        dpsi/dt: correlation, scale, bias; names another column that agrees
        when r does not), ``velocity_frame`` (u, v against the track: body or
        earth axes, or swapped), ``rudder_sign`` (the sign of the yaw response to every rudder movement),
        ``propeller`` (n x u separates rps from rpm without a length; n < 0
        while moving ahead), ``position_freeze`` (GNSS positions that freeze
        and jump, counted), ``glitches`` (single-sample spikes per channel).

    Returns
    -------
    ConsistencyResult
        ``findings`` (level, check, channels, message, values), ``success``
        (no error), ``status``, ``message``, ``to_pandas()``.
    """
    unknown = [k for k in checks if k not in _RUN]
    if unknown:
        raise ValueError(f"checks: unknown {unknown}; choose from {list(CHECKS)}")
    ctx = _Ctx(log)
    with np.errstate(invalid="ignore", divide="ignore"):
        for k in checks:
            _RUN[k](ctx)
    order = {"error": 0, "warning": 1, "info": 2}
    ctx.findings.sort(key=lambda f: order[f.level])
    return ConsistencyResult(name=log.name, findings=ctx.findings, checks=tuple(checks))
