"""Steady turns of runs that are not standard manoeuvres (shipid.manoeuvres.run_metrics.steady_turn) and their
place in validation: a known circle, a hold too short, no hold; the Esso Osaka turning runs started from rest."""
from __future__ import annotations

import math
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from shipid.manoeuvres.run_metrics import steady_turn

ESSO = Path(__file__).parents[1] / ".." / "shared" / "data" / "esso_osaka_frt"


def _run(R=6.0, U=0.25, hold_deg=20.0, turns=3.0, dt=0.1, L=3.0):
    """Start from rest, accelerate on a straight line with the rudder moving (+-10 deg), hold ``hold_deg`` from
    t = 60 s along an exact circle of radius R at speed U for ``turns`` circles, then rudder amidships and the
    propeller stopped (10 s).  Returns the frame (shipid channels) and the hold's start and end times."""
    t1 = 60.0
    t_turn = turns * 2 * math.pi * R / U
    t = np.arange(0.0, t1 + t_turn + 10.0 + dt / 2, dt)
    n = len(t)
    x, y, psi = np.zeros(n), np.zeros(n), np.zeros(n)
    u = np.where(t < 50.0, U * t / 50.0, U)
    delta = np.where(t < t1, math.radians(10.0) * np.sign(np.sin(2 * math.pi * t / 20.0)), math.radians(hold_deg))
    nn = np.full(n, 10.0)
    a = t < t1
    x[a] = np.concatenate([[0.0], np.cumsum(0.5 * (u[a][1:] + u[a][:-1]) * dt)])
    x0 = x[a][-1]
    b = ~a
    ang = U * (t[b] - t1) / R  # turning to starboard: heading increases, centre at (x0, R)
    x[b], y[b], psi[b] = x0 + R * np.sin(ang), R * (1 - np.cos(ang)), ang
    end = t > t1 + t_turn
    delta[end] = 0.0
    nn[end] = 0.0
    r = np.where(b, U / R, 0.0)
    df = pd.DataFrame({"time": t, "x": x, "y": y, "psi": psi, "u": u, "v": 0.0, "r": r, "delta": delta, "n": nn})
    return df, t1, float(t[~end][-1])


def test_a_known_circle_after_a_start_from_rest():
    R, U, L = 6.0, 0.25, 3.0
    df, t1, t2 = _run(R, U, L=L)
    st = steady_turn(df, lpp=L, name="synthetic")
    assert st.success and st.message == "ok" and st.side == "starboard"
    assert st.hold_start == pytest.approx(t1, abs=1e-9) and st.hold_end == pytest.approx(t2, abs=1e-9)
    assert st.rudder_deg == pytest.approx(20.0) and st.n == 10.0
    assert st.heading_change_deg == pytest.approx(math.degrees(U * (t2 - t1) / R), rel=1e-9)  # ~3 circles
    assert st.steady_diameter_L == pytest.approx(2 * R / L, rel=1e-9)
    assert st.steady_speed == pytest.approx(U, rel=1e-12)
    assert st.time_360_s == pytest.approx(2 * math.pi * R / U, rel=1e-9)
    assert set(st.to_dict()) >= {"hold_start", "hold_end", "steady_diameter_L", "steady_speed", "time_360_s"}
    # port: the mirror image
    port = df.assign(y=-df.y, psi=-df.psi, r=-df.r, delta=-df.delta)
    sp = steady_turn(port, lpp=L)
    assert sp.side == "port" and sp.steady_diameter_L == pytest.approx(2 * R / L, rel=1e-9)


def test_a_short_hold_is_no_steady_turn_and_no_hold_is_an_error():
    df, t1, _ = _run(turns=0.9)
    st = steady_turn(df, lpp=3.0)
    assert not st.success and st.steady_diameter_L != st.steady_diameter_L  # NaN
    assert "a steady turn needs 360 deg" in st.message and st.to_dict()["steady_diameter_L"] is None
    calm = df.assign(delta=np.radians(2.0))
    with pytest.raises(ValueError, match="no rudder hold of at least 5 deg"):
        steady_turn(calm, lpp=3.0)
    with pytest.raises(ValueError, match=r"needs column\(s\) \['x', 'y'\]"):
        steady_turn(df.drop(columns=["x", "y"]), lpp=3.0)


@pytest.mark.skipif(not ESSO.is_dir(), reason=f"Esso Osaka data set (FRT-DS-ESSO) not found at {ESSO}")
def test_validate_reports_the_steady_turn_of_a_turning_run_started_from_rest():
    """An Esso Osaka turning run starts from rest (no standard metrics); validation reports the steady turn of
    its 35 deg hold, measured and in the replay, with their difference.  Measured: the numbers of steady_turn on
    the log; the measured steady diameters of the turning runs lie within the 1.9-4.4 L the study reports."""
    from shipid.logs import read_log
    from shipid.models import get_model
    from shipid.validation import validate_one

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        lg = read_log(ESSO / "turning" / "turn_14-Oct-2020_15_21_57.csv", schema="esso-frt")
    v = validate_one(get_model("lowspeed"), lg, closed_loop=False)
    assert v.measured is None and any("start from rest" in n for n in v.notes)
    d = v.to_dict()["steady_turn"]
    direct = steady_turn(lg).to_dict()
    assert d["measured"] == direct and direct["success"] and direct["rudder_deg"] == pytest.approx(-35.3, abs=0.1)
    assert 1.9 <= direct["steady_diameter_L"] <= 4.4 and direct["hold_start"] == pytest.approx(110.0, abs=0.5)
    p = d["predicted"]
    assert p["hold_start"] == direct["hold_start"] and p["side"] == "port"
    assert d["difference"]["steady_diameter_L"] == pytest.approx(p["steady_diameter_L"] - direct["steady_diameter_L"])


def test_validation_leaves_out_brief_holds():
    """A run whose longest hold turns less than STEADY_REPORT_DEG (a random or zigzag run) gets no steady_turn entry;
    one that turns more but under 360 deg gets the entry with success False and the reason."""
    from shipid.logs import TrialLog
    from shipid.models import get_model
    from shipid.manoeuvres.run_metrics import STEADY_REPORT_DEG
    from shipid.validation import validate_one

    m = get_model("kcs-response")
    short = TrialLog(_run(turns=0.3)[0], name="short")  # 108 deg in the hold
    v = validate_one(m, short, lpp=3.0, closed_loop=False)
    assert v.to_dict()["steady_turn"] == {} and STEADY_REPORT_DEG == 180.0
    most = TrialLog(_run(turns=0.8)[0], name="most")  # 288 deg
    d = validate_one(m, most, lpp=3.0, closed_loop=False).to_dict()["steady_turn"]
    assert d["measured"]["success"] is False and "a steady turn needs 360 deg" in d["measured"]["message"]


def test_cli_metrics_gives_the_steady_turn_of_a_run_started_from_rest(tmp_path, capsys):
    """`shipid metrics` on runs that are not standard manoeuvres: one started from rest that turns three circles
    gets its steady turn (exit 0); one that turns too little gets no metrics, its reason, and exit 1 -- no longer
    exit 2 for the whole command, as a bad input would."""
    import json

    from shipid.cli import main

    L = 3.0
    good, short = tmp_path / "turn.csv", tmp_path / "short.csv"
    _run(L=L)[0].to_csv(good, index=False)
    _run(turns=0.3)[0].to_csv(short, index=False)
    out = tmp_path / "m.json"
    assert main(["metrics", str(good), "--lpp", str(L), "-o", str(out)]) == 0
    d = json.loads(out.read_text())[0]
    assert d["manoeuvre"] == "steady turn" and d["success"] and "start from rest" in d["note"]
    assert d["steady_diameter_L"] == pytest.approx(2 * 6.0 / L, rel=1e-9)
    capsys.readouterr()
    assert main(["metrics", str(good), str(short), "--lpp", str(L), "-o", str(out), "--force"]) == 1
    both = json.loads(out.read_text())
    assert [e["manoeuvre"] for e in both] == ["steady turn", None] and "start from rest" in both[1]["note"]
    err = capsys.readouterr().err
    assert "no standard-manoeuvre metrics or steady turn for short.csv" in err and "Traceback" not in err
