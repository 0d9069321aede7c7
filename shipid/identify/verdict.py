# Why one file: the graded verdict, the checks behind each grade and the exit status derived from it share one set of thresholds and reasons.
"""The graded verdict of a fit: is the data sound, and how wrong is the model on these runs?

Every fit result carries a :class:`Verdict` with one of four grades:

``consistent``
    The innovations of the filter lie in their chi-square band and are white, and the replayed model
    stays within a few noise standard deviations of the logs: the model explains the logs to their noise.
``model_error``
    No data or set-up defect was found, but the model misses the logs by more than their noise.  On
    thousands of samples of real data the chi-square band and the Ljung-Box test reject every model that
    is not the truth (Ljung & Box 1978: the test's power grows with the sample size), and every ship
    model has model-form error, so this grade is the normal outcome of a good fit on measured data.  It
    says *how much* the model misses: the replay RMSE of u, v, r and of the track (in metres and ship
    lengths), the fraction of each channel's variance the replay leaves unexplained, and the runs that
    contribute most.
``defect``
    A data or set-up defect is likely.  Only findings that model-form error cannot produce count:

    * a channel-consistency error of a log (:func:`shipid.logs.check_consistency`: a yaw rate that does
      not integrate to the heading, velocities in the wrong frame or units, time in the wrong unit, a
      rudder whose yaw response has the wrong sign over the whole log, a propeller turning astern while
      the ship moves ahead): these compare measured channels with each other through kinematics, with no
      model at all;
    * a well-determined coefficient (more than 3 standard deviations from zero, posterior standard
      deviation below half the prior's) of an *input* with the sign physics fixes under shipid's conventions
      (``Model.physics_signs``: a stern rudder's yaw moment positive and its sway force negative for positive
      rudder, rudder lift and thrust positive), or whose non-dimensional value lies outside
      ``Model.physics_ranges`` (the span of the published ship sets widened by :data:`RANGE_FACTOR`, chosen so
      that a degree/radian confusion, a factor 57.3, always leaves it): a linear-in-the-input term absorbs a
      sign or scale error of its input exactly, with white innovations, so only physics can see it.  (The
      rudder's sway term alone with the other sign, its yaw term right, is model error: a response model
      fitted to logs of the MMG model gets it; a defect only when the channel checks doubt u, v);
    * a log step longer than half the start model's fastest time constant at the logs' speed (fewer than two
      samples per time constant: the sampling theorem's limit for the fastest motion the model has; a log
      decimated or time in the wrong unit);

A fitted model that is not physical in its *own* motion -- a damping coefficient with the wrong sign
(``physics_signs`` of a state: own sway and yaw damping negative, resistance positive) or an own sway or yaw
damping that is positive along the logged motions (:func:`~shipid.identify.diagnostics.damping_check`) -- is
``model_error``, said first: model-form error alone produces it (a model without the wind that acts on the
logs, or linear derivatives carried beyond their drift range), so it names no data defect, but the model is
not to be used for prediction.

``diverged``
    The filter diverged and no data defect explains it: there is no estimate.  (When a channel-consistency
    error of the logs explains it, the grade is ``defect`` and names the fix.)

Innovations *smaller* than the noise model predicts are no grade of their own: on measured logs the noise
levels are declared conservatively or estimated from second differences that include the motion, and the
MARIN KVLCC2 and Esso Osaka fits show mean normalised innovations of 0.06-0.44 in their dynamic channels.

:func:`exit_status` maps a result (or its verdict) to the exit status of ``shipid fit``: 0 for
``consistent`` and ``model_error``, 3 for ``defect``, 4 for ``diverged`` (:data:`EXIT_STATUS`).  Other
commands (campaigns, cross-validation folds) import it so that every command grades a fit the same way.
"""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field

import numpy as np

from ..logs.consistency import check_consistency
from ..simulate import replay
from .plausibility import RANGE_FACTOR, logs_speed, physics_findings, prime_value, time_constant_at

__all__ = ["CONSISTENCY_RULES", "Verdict", "GRADES", "EXIT_STATUS", "exit_status", "verdict_of", "assess", "physics_findings",
           "RANGE_FACTOR", "warning_line", "clip", "time_constant_at", "verdict_from_identifier", "verdict_from_recipe", "plain_message"]

#: Rules of the consistency verdict (fixed from clean synthetic logs before any wrong-physics case was
#: run; see docs/identification.md "Does the fit say when it is wrong?").
CONSISTENCY_RULES = {
    "alpha": 1e-3,          # two-sided level of the statistical tests (per channel and test)
    "nis_factor": 2.0,      # ... and the mean normalised innovation must be outside [1/f, f] to count
    "lb_lags": 20,          # Ljung-Box lags (at most a tenth of the samples)
    "rho_limit": 0.3,       # ... and some |autocorrelation| of the normalised innovations above this
    "replay_factor": 3.0,   # replay RMS of a dynamic channel above this many noise std
    "gated_fraction": 0.05, # more than this fraction of a channel's measurements rejected by the gate
}

#: The grades, best first.
GRADES = ("consistent", "model_error", "defect", "diverged")

#: Exit status of ``shipid fit`` for each grade.
EXIT_STATUS = {"consistent": 0, "model_error": 0, "defect": 3, "diverged": 4}

#: What the user should do, per grade (one sentence each; the report's banner and the CLI use them).
ADVICE = {
    "consistent": "The model explains the logs to their noise: use the coefficients.",
    "model_error": "No data defect found; the model misses the logs by more than their noise (numbers below): "
                   "judge it by its predictions of runs it has not seen (shipid validate).",
    "defect": "A data or set-up defect is likely: fix it as the reasons say and fit again before using the "
              "coefficients.",
    "diverged": "The filter diverged and there is no estimate: check the logs' units and signs and the start "
                "values, then fit again.",
}


#: Unit in which each channel's replay error is shown, with its factor from SI.
_USER_UNITS = {"x": ("m", 1.0), "y": ("m", 1.0), "psi": ("deg", 180.0 / math.pi), "u": ("m/s", 1.0),
               "v": ("m/s", 1.0), "r": ("deg/s", 180.0 / math.pi), "p": ("deg/s", 180.0 / math.pi),
               "phi": ("deg", 180.0 / math.pi)}


@dataclass
class Verdict:
    """The graded verdict of a fit.

    Attributes
    ----------
    grade : {"consistent", "model_error", "defect", "diverged"}
    reasons : list of str
        One line per kind of finding (channels listed), at most ~300 characters each.
    findings : list of dict
        The findings behind the reasons: ``kind``, ``grade`` (the grade it implies), ``channels``,
        ``option`` (what fixes it, or ""), ``message``.
    channels : dict
        Per channel: ``rmse`` and ``unit`` (replay error in user units), ``noise`` (the fit's noise std in
        the same unit), ``unexplained`` (fraction of the channel's variance the replay leaves unexplained).
    track : dict
        ``rmse_m`` and ``rmse_L`` (track error of the replay in metres and ship lengths), when known.
    runs : list of dict
        Per run, worst first: ``name``, ``track_rmse_m``, ``r_rmse`` [deg/s], ``share`` (its share of the
        squared yaw-rate replay error).
    """

    grade: str
    reasons: list = field(default_factory=list)
    findings: list = field(default_factory=list)
    channels: dict = field(default_factory=dict)
    track: dict = field(default_factory=dict)
    runs: list = field(default_factory=list)

    def __post_init__(self):
        if self.grade not in GRADES:
            raise ValueError(f"verdict grade '{self.grade}': expected one of {', '.join(GRADES)}")

    @property
    def exit_status(self) -> int:
        return EXIT_STATUS[self.grade]

    @property
    def advice(self) -> str:
        return ADVICE[self.grade]

    def to_dict(self) -> dict:
        return {"grade": self.grade, "reasons": list(self.reasons), "advice": self.advice,
                "findings": [dict(f) for f in self.findings], "channels": dict(self.channels),
                "track": dict(self.track), "runs": list(self.runs)}

    @classmethod
    def from_dict(cls, doc: dict, source: str = "result") -> "Verdict":
        if not isinstance(doc, dict) or doc.get("grade") not in GRADES:
            raise ValueError(f"{source}: verdict.grade must be one of {', '.join(GRADES)}")
        reasons = doc.get("reasons") or []
        if not isinstance(reasons, list) or not all(isinstance(r, str) for r in reasons):
            raise ValueError(f"{source}: verdict.reasons must be a list of strings")
        out = {}
        for key, kind in (("findings", list), ("channels", dict), ("track", dict), ("runs", list)):
            val = doc.get(key) or kind()
            if not isinstance(val, kind):
                raise ValueError(f"{source}: verdict.{key} must be a {'list' if kind is list else 'mapping'}")
            out[key] = val
        return cls(grade=doc["grade"], reasons=list(reasons), **out)

    def headline(self) -> str:
        """One line: the grade and its first reason (or the replay numbers of a model error)."""
        if self.grade == "consistent":
            return "verdict: consistent -- the model explains the logs to their noise"
        first = self.reasons[0] if self.reasons else ""
        return f"verdict: {self.grade.replace('_', ' ')} -- {first}" if first else f"verdict: {self.grade}"

    def __str__(self) -> str:
        return "\n".join([self.headline(), *(f"  {r}" for r in self.reasons[1:])])


def verdict_of(result) -> Verdict:
    """The :class:`Verdict` of a fit result (a ``FitResult``, a result dict, or a verdict itself).

    A result written before verdicts existed is graded from what it holds: a failed filter is
    ``diverged``, an inconsistent one ``model_error``.
    """
    if isinstance(result, Verdict):
        return result
    v = getattr(result, "verdict", None)
    if isinstance(v, Verdict):
        return v
    doc = result if isinstance(result, dict) else None
    if doc is not None and isinstance(doc.get("verdict"), dict):
        return Verdict.from_dict(doc["verdict"])
    if doc is None and isinstance(v, dict):
        return Verdict.from_dict(v)
    diag = (doc.get("diagnostics") if doc is not None else getattr(result, "diagnostics", None)) or {}
    success = doc.get("success", True) if doc is not None else getattr(result, "success", True)
    cons = diag.get("consistency") or {}
    message = (doc.get("message") if doc is not None else getattr(result, "message", "")) or ""
    if not success and "diverged" in message:
        return Verdict("diverged", [f"the filter diverged: {message}"[:300]])
    if cons and not cons.get("consistent", True):
        return Verdict("model_error", ["the fit is not consistent with its noise model (graded before verdicts "
                                       "existed: fit again for the full verdict)"])
    return Verdict("consistent")


def exit_status(result) -> int:
    """Exit status of ``shipid fit`` for a fit result or verdict: 0 consistent or model error, 3 defect,
    4 diverged (:data:`EXIT_STATUS`)."""
    return EXIT_STATUS[verdict_of(result).grade]


def warning_line(result) -> str | None:
    """The one line ``shipid fit`` prints for a verdict other than ``consistent`` (None when consistent)."""
    v = verdict_of(result)
    if v.grade == "consistent":
        return None
    if v.grade == "model_error":
        bad = [f for f in v.findings if f.get("kind") == "unphysical"]
        if bad:
            return clip(f"warning: model error -- no data defect found, but {bad[0]['message']}")
        nums = _numbers_line(v)
        return clip(f"warning: model error -- no data defect found; {nums or 'the model misses the logs by more than their noise'}"
                     " (result JSON: verdict)")
    first = v.reasons[0] if v.reasons else ""
    more = f" (+{len(v.reasons) - 1} more in the result JSON: verdict)" if len(v.reasons) > 1 else ""
    return clip(f"{'error' if v.grade == 'diverged' else 'warning'}: {v.grade} -- {first}{more}")


def clip(text: str, limit: int = 300) -> str:
    """``text`` cut at a word to at most ``limit`` characters (ending in ' ...' when cut)."""
    if len(text) <= limit:
        return text
    cut = text[: limit - 4].rsplit(" ", 1)[0]
    return cut + " ..."


def _fmt(v: float) -> str:
    return f"{v:.2g}" if abs(v) < 1 else f"{v:.3g}"


def _numbers_line(v: Verdict) -> str:
    """``replay RMSE u 0.05 m/s, v ..., r ...; track 12 m (0.04 L); unexplained r 8 %; worst run X``."""
    parts = [f"{ch} {_fmt(c['rmse'])} {c['unit']}" for ch, c in v.channels.items()
             if ch in ("u", "v", "r") and c.get("rmse") is not None]
    out = ("replay RMSE " + ", ".join(parts)) if parts else ""
    if v.track.get("rmse_m") is not None:
        out += f"{'; ' if out else ''}track {_fmt(v.track['rmse_m'])} m ({_fmt(v.track['rmse_L'])} L)" \
            if v.track.get("rmse_L") is not None else f"{'; ' if out else ''}track {_fmt(v.track['rmse_m'])} m"
    fvu = v.channels.get("r", {}).get("unexplained")
    if fvu is not None:
        out += f"; {100 * fvu:.0f} % of the yaw rate's variance unexplained"
    if v.runs:
        out += f"; worst run {v.runs[0]['name']}"
    return out


# --------------------------------------------------------------------------- the verdict
def _group(findings: list[dict]) -> list[str]:
    """One reason per kind of finding: the first finding's message, the channels of all."""
    by_kind: dict = {}
    for f in findings:
        by_kind.setdefault(f["kind"], []).append(f)
    out = []
    for kind, fs in by_kind.items():
        chans = sorted({c for f in fs for c in f.get("channels", [])})
        head = fs[0]["message"]
        if len(fs) > 1:
            head += f" (and {len(fs) - 1} more of this kind"
            head += f"; channels {', '.join(chans)})" if chans else ")"
        out.append(clip(head))
    return out


def _consistency_findings(cons: dict, rules: dict) -> list[dict]:
    """The EKF stage's statistics as findings: too-small innovations (defect), too-large or non-white
    innovations, gated measurements and replay misses (model error)."""
    f_nis = float(rules.get("nis_factor", 2.0))
    small, large, colour, gated, miss = [], [], [], [], []
    for ch, row in (cons.get("channels") or {}).items():
        m, band = row.get("nis_mean"), row.get("nis_band")
        if m is not None and band:
            if m < band[0] and m < 1.0 / f_nis:
                small.append((ch, m))
            elif m > band[1] and m > f_nis:
                large.append((ch, m))
        p, rho = row.get("ljung_box_p"), row.get("rho_max")
        if p is not None and rho is not None and p < rules.get("alpha", 1e-3) and rho > rules.get("rho_limit", 0.3):
            colour.append((ch, rho))
        if (row.get("gated_fraction") or 0) > rules.get("gated_fraction", 0.05):
            gated.append((ch, row["gated_fraction"]))
        rr = row.get("replay_ratio")
        if ch in (cons.get("dynamic_channels") or []) and rr is not None and rr > rules.get("replay_factor", 3.0):
            miss.append((ch, rr))
    out = []

    def add(kind, grade, found, message, option=""):
        if found:
            out.append({"kind": kind, "grade": grade, "channels": [c for c, _ in found], "option": option,
                        "message": message})

    def chans(found):
        return ", ".join(c for c, _ in found)

    def span(found):
        return f"{_fmt(min(v for _, v in found))}-{_fmt(max(v for _, v in found))}" if found else ""

    add("noise_overstated", "note", small,
        f"innovations of {chans(small)} are {span(small)} of the noise model's: the noise levels are "
        "conservative (declared, or estimated from samples that include the motion)", option="--meas-std")
    add("innovations_large", "model_error", large,
        f"innovations of {chans(large)} are {span(large)} times the noise model's variance")
    add("innovations_coloured", "model_error", colour,
        f"innovations of {chans(colour)} are not white (largest autocorrelation "
        f"{max((r for _, r in colour), default=0.0):.2f}): the model leaves a systematic part of the motion")
    add("gated", "model_error", gated,
        f"{100 * max((g for _, g in gated), default=0.0):.0f} % of the measurements of {chans(gated)} "
        "were rejected by the innovation gate (outliers or a model far from the data)")
    add("replay_miss", "model_error", miss,
        f"the replayed model misses {chans(miss)} by up to {max((r for _, r in miss), default=0.0):.3g} noise "
        "standard deviations (RMS)")
    return out


def log_findings(logs) -> list[dict]:
    """Channel-consistency errors of the logs (:func:`shipid.logs.check_consistency`, the result the reader
    kept, else run here) as verdict findings, one per check kind."""
    out = []
    for lg in logs or []:
        res = getattr(lg, "consistency", None)
        if res is None:
            try:
                res = check_consistency(lg)
            except Exception:  # noqa: BLE001 -- a check that cannot run on this log has no finding
                continue
        for f in res.findings:
            if f.level == "warning" and f.check == "velocity_frame":   # supporting evidence only (a note)
                out.append({"kind": "log_velocity_frame_doubt", "grade": "note", "channels": list(f.channels),
                            "option": "", "message": f.message})
            if f.level != "error":
                continue
            out.append({"kind": f"log_{f.check}", "grade": "defect", "channels": list(f.channels),
                        "option": _option_in(f.message), "message": f.message})
    return out


def _option_in(message: str) -> str:
    i = message.find("--")
    if i < 0:
        return ""
    return message[i:].split(")")[0].split(";")[0].strip()


def replay_numbers(model, logs, lpp=None, meas_std=None) -> tuple[dict, dict, list]:
    """Replay ``model`` on every log (its recorded inputs, from its first samples) and return
    ``(channels, track, runs)`` of :class:`Verdict`: RMSE per channel in user units, the fraction of the
    logged variance left unexplained, the track RMSE in m and ship lengths, the runs worst first."""
    sq: dict = {}
    var: dict = {}
    cnt: dict = {}
    track_sq, track_n = 0.0, 0
    runs = []
    for lg in logs or []:
        try:
            with np.errstate(all="ignore"), warnings.catch_warnings():
                warnings.simplefilter("ignore")
                sim = replay(model, lg)
        except Exception:  # noqa: BLE001 -- a model that cannot replay this log gives no numbers
            continue
        run = {"name": getattr(lg, "name", "log")}
        for i, ch in enumerate(model.state_names):
            if ch not in getattr(lg, "channels", ()) or ch not in _USER_UNITS:
                continue
            y = np.asarray(lg[ch], dtype=float)
            s = sim.x[:, i]
            if ch in ("psi", "phi"):
                e = np.angle(np.exp(1j * (s - y)))
            else:
                e = s - y
            ok = np.isfinite(y)
            e = np.where(np.isfinite(e), e, np.inf)[ok]
            if not e.size:
                continue
            sq[ch] = sq.get(ch, 0.0) + float(np.sum(e * e))
            cnt[ch] = cnt.get(ch, 0) + int(e.size)
            var[ch] = var.get(ch, 0.0) + float(np.sum((y[ok] - np.mean(y[ok])) ** 2))
            if ch == "r":
                run["r_sq"] = float(np.sum(e * e))
                run["r_rmse"] = float(np.sqrt(np.mean(e * e)) * _USER_UNITS["r"][1])
        if {"x", "y"} <= set(model.state_names) and {"x", "y"} <= set(getattr(lg, "channels", ())):
            d2 = (sim.state("x") - np.asarray(lg["x"], float)) ** 2 + (sim.state("y") - np.asarray(lg["y"], float)) ** 2
            ok = np.isfinite(np.asarray(lg["x"], float)) & np.isfinite(np.asarray(lg["y"], float))
            d2 = np.where(np.isfinite(d2), d2, np.inf)[ok]
            if d2.size:
                track_sq += float(np.sum(d2))
                track_n += int(d2.size)
                run["track_rmse_m"] = float(np.sqrt(np.mean(d2)))
        runs.append(run)
    channels = {}
    for ch in sq:
        unit, k = _USER_UNITS[ch]
        rmse = math.sqrt(sq[ch] / cnt[ch]) if cnt[ch] else float("nan")
        row = {"rmse": _finite(rmse * k), "unit": unit,
               "unexplained": _finite(sq[ch] / var[ch]) if var[ch] > 0 else None}
        if meas_std and ch in meas_std and meas_std[ch] is not None:
            row["noise"] = _finite(float(meas_std[ch]) * k)
        channels[ch] = row
    track = {}
    if track_n:
        t = math.sqrt(track_sq / track_n)
        track = {"rmse_m": _finite(t), "rmse_L": _finite(t / lpp) if lpp else None}
    tot = sum(r.get("r_sq", 0.0) for r in runs)
    for r in runs:
        r["share"] = _finite(r.pop("r_sq", 0.0) / tot) if tot > 0 and np.isfinite(tot) else None
        for k in ("r_rmse", "track_rmse_m"):
            if k in r:
                r[k] = _finite(r[k])
    runs.sort(key=lambda r: -(r.get("share") or 0.0))
    return channels, track, runs


def _finite(v):
    v = float(v)
    return v if math.isfinite(v) else None


def assess(*, consistency: dict | None, diverged: bool = False, message: str = "", physics: list | None = None,
           damping: dict | None = None, logs_found: list | None = None, channels: dict | None = None,
           track: dict | None = None, runs: list | None = None, rules: dict | None = None,
           refinement_failed: str | None = None, sampling: dict | None = None) -> Verdict:
    """Grade a fit from its parts (see the module docstring for the rules).

    Parameters
    ----------
    consistency : the EKF stage's ``diagnostics["consistency"]`` (channel statistics)
    diverged, message : the filter diverged, and its message
    physics : findings of :func:`physics_findings`
    damping : :func:`~shipid.identify.diagnostics.damping_check` of the final model
    logs_found : findings of :func:`log_findings`
    channels, track, runs : replay numbers (:func:`replay_numbers`)
    refinement_failed : the refinement's message when it did not succeed
    sampling : ``{"log_step": s, "time_constant": s}`` (the recipe's); see the module docstring
    """
    r = dict(CONSISTENCY_RULES)
    r.update(rules or {})
    channels, track, runs = dict(channels or {}), dict(track or {}), list(runs or [])
    findings = [dict(f, grade=f.get("grade", "defect")) for f in (logs_found or [])]
    step, tau = (sampling or {}).get("log_step"), (sampling or {}).get("time_constant")
    if step and tau and step > 0.5 * tau:
        findings.append({"kind": "sampling", "grade": "defect", "channels": [], "option": "",
                         "message": f"the logs sample every {step:.3g} s, more than half the ship's fastest time "
                                    f"constant ({tau:.3g} s at the logs' speed): a decimated log (or time in the wrong "
                                    "unit); fit the logger's full-rate file"})
    if diverged:
        div = {"kind": "diverged", "grade": "diverged", "channels": [], "option": "", "message": message}
        text = clip(f"the filter diverged: {message}" if message else "the filter diverged")
        if findings:   # a data defect found in the logs explains the divergence: name it and its fix
            return Verdict("defect", _group(findings) + [text], findings + [div], channels, track, runs)
        return Verdict("diverged", [text], [div], channels, track, runs)
    findings += [dict(f, grade=f.get("grade", "defect")) for f in (physics or [])]
    if any(f["kind"] == "log_velocity_frame_doubt" for f in findings):
        for f in findings:   # the sway term's sign and a doubt about u, v from the channels: v's sign
            if f["kind"] == "sway_sign":
                f["grade"] = "defect"
    if damping and damping.get("physical") is False:
        what = [s for s in ("v", "r") if (damping.get(s) or {}).get("fraction_positive") not in (None, 0.0)
                and damping[s]["fraction_positive"] > 0.01]
        findings.append({"kind": "unphysical", "grade": "model_error", "channels": what or ["v", "r"],
                         "option": "--sign-bounds",
                         "message": f"the fitted model is not physical: its own {' and '.join({'v': 'sway', 'r': 'yaw'}[s] for s in what) or 'sway or yaw'} "
                                    "damping is positive along the logged motions (self-excited); the model cannot "
                                    "represent these logs (missing wind or current, drift beyond its range?): do not "
                                    "predict with it; try --wind --current or --sign-bounds"})
    if refinement_failed:
        findings.append({"kind": "refinement", "grade": "defect", "channels": [], "option": "--refine none",
                         "message": clip(f"the refinement did not converge ({plain_message(refinement_failed)}): the EKF "
                                          "stage's coefficients stand; use them with --refine none or raise "
                                          "--max-nfev")})
    findings += _consistency_findings(consistency or {}, r)
    findings.sort(key=lambda f: f["kind"] != "unphysical")   # (stable) an unphysical model is said first
    defects = [f for f in findings if f["grade"] == "defect"]  # ("note" findings stay in the JSON only)
    errors = [f for f in findings if f["grade"] == "model_error"]
    if defects:
        grade = "defect"
        reasons = _group(defects) + _group(errors)
    elif errors:
        grade = "model_error"
        nums = _numbers_line(Verdict("model_error", [], [], channels, track, runs))
        reasons = ([clip(f"the model misses the logs by more than their noise: {nums}")] if nums else []) \
            + _group(errors)
    else:
        grade, reasons = "consistent", []
    return Verdict(grade, reasons, findings, channels, track, runs)


# --------------------------------------------------------------------------- from a fit
def _arrays_speed(ident) -> float:
    """Median speed [m/s] of the identifier's logged samples moving ahead."""
    s = getattr(ident, "_setup", None) or {}
    meas = list(s.get("meas", []))
    if "u" not in meas:
        return float("nan")
    iu = meas.index("u")
    iv = meas.index("v") if "v" in meas else None
    out = []
    for a in s.get("arrays", []):
        u = a.Y[:, iu]
        v = a.Y[:, iv] if iv is not None else np.zeros_like(u)
        sp = np.hypot(u, np.where(np.isfinite(v), v, 0.0))
        out.append(sp[np.isfinite(sp) & (u > 0)])
    sp = np.concatenate(out) if out else np.zeros(0)
    return float(np.median(sp)) if sp.size else float("nan")


def _series(d) -> dict:
    return {k: float(v) for k, v in (d.items() if hasattr(d, "items") else [])}


def verdict_from_identifier(ident) -> Verdict:
    """The verdict of a bare :class:`~shipid.identify.EKFIdentifier` fit: its consistency statistics, the
    physics of its coefficients, and its replay (RMS from the identifier's own replay of every stretch)."""
    cons = (getattr(ident, "diagnostics_", None) or {}).get("consistency") or {}
    model = ident.to_model()
    physics = physics_findings(model, _series(ident.coef_), _series(ident.coef_std_), _series(ident.prior_std_),
                               _arrays_speed(ident))
    sig = _series(getattr(ident, "meas_std_", {}))
    channels = {}
    for ch, row in (cons.get("channels") or {}).items():
        rr = row.get("replay_ratio")
        if ch in _USER_UNITS and rr is not None and ch in sig:
            unit, k = _USER_UNITS[ch]
            channels[ch] = {"rmse": _finite(rr * sig[ch] * k), "unit": unit, "noise": _finite(sig[ch] * k)}
    sampling = {}
    s = getattr(ident, "_setup", None) or {}
    steps = [np.diff(a.t) for a in s.get("arrays", []) if a.t.size > 1]
    speed = _arrays_speed(ident)
    if steps and np.isfinite(speed) and speed > 0:
        try:
            sampling = {"log_step": float(np.median(np.concatenate(steps))),
                        "time_constant": time_constant_at(ident.model, speed)}
        except (ValueError, np.linalg.LinAlgError, ZeroDivisionError):
            sampling = {}
    return assess(consistency=cons, diverged=not ident.success_, message=ident.message_, physics=physics,
                  logs_found=log_findings(getattr(ident, "_trial_logs", None)), channels=channels,
                  sampling=sampling)


def verdict_from_recipe(recipe, result) -> Verdict:
    """The verdict of a :class:`~shipid.identify.recipe.RecipeFit`: the EKF stage's consistency statistics,
    the physics of the final coefficients, the final model's own damping and replay on the fitted logs,
    and the logs' channel-consistency errors."""
    ekf = recipe.ekf
    cons = (getattr(ekf, "diagnostics_", None) or {}).get("consistency") or {}
    source = list(getattr(recipe, "source_logs", None) or recipe.logs or [])
    sampling = getattr(recipe, "sampling", None)
    if not ekf.success_:
        return assess(consistency=cons, diverged=True, message=ekf.message_, logs_found=log_findings(source),
                      sampling=sampling)
    final = recipe.final
    model = final.to_model()
    logs = list(recipe.logs or [])
    speed = logs_speed(logs) if logs else _arrays_speed(ekf)
    physics = physics_findings(model, dict(result.coef), dict(result.coef_std), _series(ekf.prior_std_), speed)
    lpp = recipe.lpp or (result.ship or {}).get("lpp")
    channels, track, runs = replay_numbers(model, logs, lpp=lpp, meas_std=_series(getattr(ekf, "meas_std_", {})))
    refine_msg = None
    if recipe.refiner is not None and not recipe.refiner.success_:
        refine_msg = str(recipe.refiner.message_)
    return assess(consistency=cons, physics=physics, damping=result.diagnostics.get("damping"),
                  logs_found=log_findings(source), channels=channels, track=track, runs=runs,
                  refinement_failed=refine_msg, sampling=sampling)


#: The optimiser's own stopping messages (scipy.optimize.least_squares) in the user's words.
_SOLVER_WORDS = (
    ("Both `ftol` and `xtol` termination conditions are satisfied.", "the cost and the coefficients stopped changing"),
    ("`ftol` termination condition is satisfied.", "the cost stopped decreasing"),
    ("`xtol` termination condition is satisfied.", "the coefficients stopped changing"),
    ("`gtol` termination condition is satisfied.", "the cost's gradient vanished"),
    ("The maximum number of function evaluations is exceeded.",
     "the evaluation limit was reached (raise --max-nfev)"),
)


def plain_message(message: str) -> str:
    """A fit's message with the optimiser's stopping strings in plain words."""
    text = str(message or "")
    for raw, plain in _SOLVER_WORDS:
        text = text.replace(raw, plain)
    return text
