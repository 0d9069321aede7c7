"""Hold-out validation on the measured MARIN KVLCC2 runs (SIMMAN 2008).

Fit a model on the turning circles (tc +-35) and the 10/10 zigzags, predict
the 20/20 zigzags it has not seen, and compare the closed-loop standard
manoeuvres of the fitted model with the measured ones (issue 3, point 5).
Used by ``notebooks/02_validate_kvlcc2.ipynb`` and ``tests/test_kvlcc2_study.py``.

The MARIN files use the opposite rudder sign to the shipped models (+35 deg
turns to port), so the rudder is flipped on reading (``RUDDER_SIGN``).
"""
from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pandas as pd

from .identify import EKFIdentifier
from .logs import TrialLog, read_log
from .models import get_model
from .validation import validate

__all__ = ["RUNS", "TRAIN", "TEST", "RUDDER_SIGN", "MEASURED_README", "load_runs", "fit_model", "evaluate", "neutral_rudder_angle",
           "DEFAULT_SETUPS"]

RUNS = ("tc_35", "tc_-35", "zz_10", "zz_-10", "zz_20", "zz_-20")
TRAIN = ("tc_35", "tc_-35", "zz_10", "zz_-10")
TEST = ("zz_20", "zz_-20")
RUDDER_SIGN = -1.0
#: Measured values stated in the data folder's README (logged reference point).
MEASURED_README = {
    "tc_35": {"advance_L": 3.02, "transfer_L": 1.20, "tactical_diameter_L": 3.07},
    "tc_-35": {"advance_L": 3.09, "transfer_L": 1.35, "tactical_diameter_L": 3.33},
    "zz_10": {"overshoot1_deg": 9.4}, "zz_-10": {"overshoot1_deg": 8.1},
    "zz_20": {"overshoot1_deg": 15.6}, "zz_-20": {"overshoot1_deg": 12.7},
}


def load_runs(folder, decimate: int = 1) -> dict[str, TrialLog]:
    """The six runs as TrialLogs (rudder sign flipped to the models' convention), every
    ``decimate``-th sample (full scale; 0.135 s native sampling)."""
    folder = Path(folder)
    out = {}
    for k in RUNS:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)
            lg = read_log(folder / f"MARIN_FREE_KVLCC2_{k}_m.dat")
        ch = {c: lg[c][::decimate] for c in lg.channels if c != "time"}
        ch["delta"] = RUDDER_SIGN * ch["delta"]
        out[k] = TrialLog.from_arrays(lg.time[::decimate], name=k, ship=lg.ship, **ch)
    return out


#: The three model set-ups compared (start model, identifier options).
DEFAULT_SETUPS = {
    # constant rpm in every run: a1, a8, a9 are collinear, so a8 is fixed (the identifier says why)
    "kcs-response": lambda: (get_model("kcs-response"), {"fixed": {"a8": 0.0}}),
    # started from a kcs-response fit (the seed terms) with the non-linear terms at zero: the
    # default set is for the 4.36 m KCS model and is no start for a 320 m tanker
    # b0, c0 (propeller asymmetry) stay 0: the EKF cannot identify them from these runs (see fit_model)
    "response-nl": lambda: (get_model("response-nl", lpp=320.0), {"fixed": {"a8": 0.0, "b0": 0.0, "c0": 0.0}}),
    # the published KVLCC2 MMG set at full scale; re-identify the linear and the main
    # non-linear hull derivatives and the resistance, keep the rudder/propeller interaction
    "mmg": lambda: (get_model("mmg", "kvlcc2", lpp=320.0),
                    {"estimate": ["Yv", "Yr", "Nv", "Nr", "Yvvr", "Nvvr", "Nrrr", "R0"]}),
}


def neutral_rudder_angle(runs: dict[str, TrialLog], names=TRAIN, departure_deg: float = 1.0) -> float:
    """Rudder angle [rad] that holds the ship on a straight course: the mean rudder of the approach
    phases (from the start of each run until the rudder first departs by more than
    ``departure_deg`` from its first value; at least 3 samples) of the runs ``names``, pooled
    sample by sample."""
    vals = []
    for k in names:
        d = runs[k]["delta"]
        moved = np.flatnonzero(np.abs(d - d[0]) > np.radians(departure_deg))
        if moved.size == 0 or moved[0] < 3:
            raise ValueError(f"run '{k}': no approach phase of at least 3 samples before the rudder moves")
        vals.append(d[:moved[0]])
    return float(np.mean(np.concatenate(vals)))


def fit_model(name: str, runs: dict[str, TrialLog], train=TRAIN, n_passes: int = 2, start=None,
              neutral: bool = True):
    """Fit the set-up ``name`` of :data:`DEFAULT_SETUPS` to the training runs.

    With ``neutral`` the ``mmg`` set-up takes its rudder neutral angle ``delta0`` from the approach
    phases of the training runs (the rudder that holds a straight course,
    :func:`neutral_rudder_angle`) instead of estimating it: estimated by the EKF it lands on the
    wrong side (-0.9 deg against the measured +0.9 deg) and the turns miss by +5.9 / -5.3 %.
    ``response-nl`` keeps its asymmetry terms ``b0, c0`` at 0 (symmetric): estimated, or fixed from
    the start model's ``b3, c3``, the EKF fit diverges in its second pass and the turns get worse
    (docs/validation.md).
    """
    model, opts = DEFAULT_SETUPS[name]()
    if neutral and name == "mmg":
        opts = {**opts, "fixed": {"delta0": neutral_rudder_angle(runs, train)}}
    if start is None and name == "response-nl":
        seed = fit_model("kcs-response", runs, train=train, n_passes=n_passes).coef_
        start = {k: float(seed.get(k, 0.0)) for k in model.param_names}
    if start is not None:
        model = model.with_params({k: v for k, v in start.items() if k in model.param_names})
    return EKFIdentifier(model, n_passes=n_passes, **opts).fit([runs[k] for k in train])


def evaluate(result_or_model, runs: dict[str, TrialLog], names=RUNS) -> pd.DataFrame:
    """Measured vs closed-loop predicted metrics of each run: one row per (run, metric)."""
    rows = []
    vals = validate(result_or_model, [runs[k] for k in names], lpp=320.0)
    for k, v in zip(names, vals):
        keys = (["advance_L", "transfer_L", "tactical_diameter_L"] if k.startswith("tc")
                else ["overshoot1_deg", "overshoot2_deg"])
        std = v.get("standard") or {}
        for c in keys:
            m, p = v["measured"].get(c), std.get(c)
            rows.append({"run": k, "set": "test" if k in TEST else "train", "metric": c, "measured": m,
                         "predicted": p, "error": None if (m is None or p is None) else p - m,
                         "rel_error_%": None if (m is None or p is None or c.endswith("deg")) else 100 * (p - m) / m})
    return pd.DataFrame(rows)
