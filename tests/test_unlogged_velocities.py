"""Logs of the track and heading without some velocities (sea trials with GNSS and a gyro, no sway log): the
reader accepts them and says so, the filter starts the missing velocities from the track and the fit recovers
the coefficients (synthetic truth)."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from shipid.cli import main
from shipid.datasets import bundled_kcs_logs
from shipid.logs import read_log
from shipid.models import get_model


def _without(tmp_path, drop, name):
    src = [p for p in bundled_kcs_logs() if p.stem == "kcs_zz_m10"][0]
    df = pd.read_csv(src, comment="#")
    out = tmp_path / f"{name}.csv"
    df.drop(columns=drop).to_csv(out, index=False)
    return out


@pytest.mark.parametrize("drop", [["v [m/s]"], ["v [m/s]", "r [rad/s]"]], ids=["no v", "no v, r"])
def test_fit_without_logged_velocities_recovers_the_truth(tmp_path, capsys, drop):
    """The bundled 10/10 zigzag (synthetic truth) without its v (and r) column: read with a note, fitted with the
    CLI's defaults (exit 0), and the sway and yaw coefficients lie within 3 sigma of the truth.  Before, the reader
    refused the file ('required column v') and, allowed to read it, the equation-error start used the surge
    equation with v = r = 0 and the filter diverged (exit 4)."""
    p = _without(tmp_path, drop, "zz")
    lg = read_log(p, lpp=4.36)
    missing = [c.split()[0] for c in drop]
    assert all(c not in lg.data.columns for c in missing)
    assert all(any(f"'{c}' not logged" in n for n in lg.notes) for c in missing)
    out = tmp_path / "fit.json"
    assert main(["fit", str(p), "--model", "kcs-response", "--lpp", "4.36", "--no-progress", "-o", str(out)]) == 0
    import json

    res = json.loads(out.read_text())
    coef, std = res["coef"], res["coef_std"]
    truth = get_model("kcs-response", "synthetic-truth").params_series()
    for k in ("b1", "b3", "c1", "c2", "c3"):
        assert abs(coef[k] - truth[k]) < 3 * std[k], (k, coef[k], std[k], truth[k])
    assert std["c3"] < 0.05 * abs(truth["c3"])  # the rudder's yaw moment stays well determined


def test_a_log_without_velocities_or_track_is_still_refused(tmp_path):
    """Without the track the velocities are required as before (the filter could not infer them)."""
    p = _without(tmp_path, ["v [m/s]", "x [m]", "y [m]"], "notrack")
    with pytest.raises(ValueError, match="required column 'v' not found"):
        read_log(p, lpp=4.36)


def test_track_start_of_unlogged_velocities():
    """The filter's start of the velocities a log lacks: the straight lines through the first 20 samples of the
    track and heading, rotated into body axes (exact on a straight run at constant speed, drift and heading)."""
    from shipid.identify import EKFIdentifier
    from shipid.logs import TrialLog

    U, beta, psi0 = 1.5, np.radians(4.0), np.radians(30.0)
    t = np.arange(0.0, 20.0, 0.1)
    u, v = U * np.cos(beta), -U * np.sin(beta)
    xd, yd = u * np.cos(psi0) - v * np.sin(psi0), u * np.sin(psi0) + v * np.cos(psi0)
    df = pd.DataFrame({"time": t, "x": xd * t, "y": yd * t, "psi": psi0 + 0 * t, "delta": 0.0, "n": 10.0})
    lg = TrialLog(df, name="straight")
    ident = EKFIdentifier(get_model("kcs-response"), n_passes=1, init="model", estimate=["c3"],
                          meas_std={"x": 0.01, "y": 0.01, "psi": 0.001})
    ident.fit([lg])
    a = ident._setup["arrays"][0]
    st = ident._track_start(a)
    assert set(st) == {"u", "v", "r"}
    assert st["u"][0] == pytest.approx(u, rel=1e-9) and st["v"][0] == pytest.approx(v, rel=1e-9)
    assert st["r"][0] == pytest.approx(0.0, abs=1e-12) and all(var > 0 for _, var in st.values())


def test_a_speed_column_named_U_beside_a_track_is_read_and_the_mapping_is_said(tmp_path):
    """'U' (shipid's speed over ground) is never taken for 'u' unasked; beside a logged track the log reads with
    u not logged, and the note says how to map 'U' if it was meant as 'u'."""
    src = [p for p in bundled_kcs_logs() if p.stem == "kcs_zz_m10"][0]
    df = pd.read_csv(src, comment="#").rename(columns={"u [m/s]": "U [m/s]"})
    p = tmp_path / "U.csv"
    df.to_csv(p, index=False)
    lg = read_log(p, lpp=4.36)
    assert "u" not in lg.data.columns
    assert any("the file's 'U' is read as channel 'U'; if it is 'u': --columns u=U" in n for n in lg.notes)
    assert any("'u' not logged" in n for n in lg.notes)
