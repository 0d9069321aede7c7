"""The ``esso-frt`` schema preset on the measured Esso Osaka 3 m model runs (../shared/data/esso_osaka_frt).

The conventions stated in the preset (shipid/logs/schema.py) are checked against the motion here:
yaw rate against d psi/dt, body-axis u, v against the track, the rudder sign against the direction
of turn, and the wind-direction convention against the relation relative = true - ship velocity.
"""
from __future__ import annotations

import math
import warnings
from pathlib import Path

import numpy as np
import pytest

from shipid.logs import read_log
from shipid.logs.schema import PRESETS

ESSO = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "esso_osaka_frt"
FILES = sorted(ESSO.glob("*/*.csv")) if ESSO.is_dir() else []
pytestmark = pytest.mark.skipif(not FILES, reason=f"Esso Osaka FRT data not found at {ESSO} "
                                                  "(../shared/data/esso_osaka_frt beside the repository)")
WIND = ("wind_speed_rel", "wind_dir_rel", "wind_speed_true", "wind_dir_true")


def _read(path):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        return read_log(path, schema="esso-frt")


@pytest.fixture(scope="module")
def logs():
    return {p.name: _read(p) for p in FILES}


def test_every_file_reads_with_wind_channels_and_ship(logs):
    assert len(logs) == 33
    for name, log in logs.items():
        assert log.channels[:8] == ["x", "y", "psi", "u", "v", "r", "delta", "n"], name
        assert all(c in log.channels for c in WIND), name
        assert log.units()["wind_dir_true"] == "rad" and log.units()["wind_speed_rel"] == "m/s"
        assert log.ship.lpp == 3.0 and log.ship.beam == 0.489 and log.ship.draught == 0.201
        assert log.ship.block_coefficient == 0.83 and log.ship.mass == 244.6 and log.ship.x_g == 0.094
        assert log.ship.propeller_diameter == 0.084 and log.ship.rudder_area == 0.0106
        assert log.ship.transverse_area == 0.135 and log.ship.lateral_area == 0.52
        assert log.dt == pytest.approx(0.1, abs=1e-9)
        # heading wrapped in the file, continuous here
        assert np.abs(np.diff(log["psi"])).max() < 1.0, name


def test_trailing_empty_rows_dropped_with_a_note(logs):
    log = logs["zigzag_31-Jul-2020_13_50_28.csv"]
    assert len(log) == 1701
    assert any(n.startswith("327 trailing row(s) of empty cells dropped (rows 1703, 1704, 1705, ...") for n in log.notes)
    assert not any("empty cells" in n for k, lg in logs.items() if k != "zigzag_31-Jul-2020_13_50_28.csv"
                   for n in lg.notes)


def test_sign_conventions_hold_against_the_motion(logs):
    """r = d psi/dt; u, v are body axes; positive delta turns to starboard (r > 0), as in shipid."""
    agree, total = 0, 0
    for name, log in logs.items():
        t, psi, r = log.time, log["psi"], log["r"]
        k = 10
        sm = np.convolve(np.gradient(psi, t), np.ones(k) / k, mode="same")[k:-k]
        slope = np.polyfit(r[k:-k], sm, 1)[0]
        assert 0.9 < slope < 1.05, (name, slope)
        c, s = np.cos(psi), np.sin(psi)
        xd = np.gradient(log["x"], t)
        yd = np.gradient(log["y"], t)
        ub = np.convolve(xd * c + yd * s, np.ones(k) / k, mode="same")[k:-k]
        assert np.corrcoef(ub, log["u"][k:-k])[0, 1] > 0.85, name
        if name.startswith("turn"):
            held = np.abs(log["delta"]) > math.radians(15)
            agree += int(np.sum(np.sign(log["delta"][held]) == np.sign(r[held])))
            total += int(held.sum())
    # turning runs: with the rudder hard over the ship turns the same way in > 90 % of the samples
    assert agree / total > 0.9, agree / total


def test_wind_directions_are_coming_from_clockwise(logs):
    """Relative wind = true wind - ship velocity, exactly, when both directions are 'coming from',
    clockwise (towards starboard), from the earth x axis (true) and from the bow (relative)."""
    for name, log in logs.items():
        psi, u, v = log["psi"], log["u"], log["v"]
        vt, tt = log["wind_speed_true"], log["wind_dir_true"]
        # air velocity (going to) in earth axes, minus the ship's velocity, in body axes
        ax = -vt * np.cos(tt) - (u * np.cos(psi) - v * np.sin(psi))
        ay = -vt * np.sin(tt) - (u * np.sin(psi) + v * np.cos(psi))
        bx, by = ax * np.cos(psi) + ay * np.sin(psi), -ax * np.sin(psi) + ay * np.cos(psi)
        rel_dir = np.arctan2(-by, -bx)
        err = (rel_dir - log["wind_dir_rel"] + math.pi) % (2 * math.pi) - math.pi
        assert np.sqrt(np.mean(err ** 2)) < 0.01, name
        assert np.sqrt(np.mean((np.hypot(bx, by) - log["wind_speed_rel"]) ** 2)) < 0.01, name
        # the other reading ('going to') misses the relative speed by ~0.3 m/s
        gx = vt * np.cos(tt) - (u * np.cos(psi) - v * np.sin(psi))
        gy = vt * np.sin(tt) - (u * np.sin(psi) + v * np.cos(psi))
        assert np.sqrt(np.mean((np.hypot(gx, gy) - log["wind_speed_rel"]) ** 2)) > 0.05, name
        for c in ("wind_dir_true", "wind_dir_rel"):   # as in the file: [0, 2 pi)
            assert 0.0 <= log[c].min() and log[c].max() < 2 * math.pi, (name, c)


def test_extra_channels_travel_through_window_and_resample(logs):
    log = logs["zigzag_31-Jul-2020_13_04_24.csv"]
    w = log.window(20.0, 40.0)
    assert w.channels == log.channels and w.time[0] == pytest.approx(20.0) and w.time[-1] == pytest.approx(40.0)
    np.testing.assert_array_equal(w["wind_dir_true"], log["wind_dir_true"][(log.time >= 20) & (log.time <= 40)])
    r = log.resample(0.5)
    assert r.channels == log.channels and r.dt == pytest.approx(0.5)
    # at the kept samples the values are the original ones; wrapped angles stay wrapped
    on = np.isin(np.round(log.time, 6), np.round(r.time, 6))
    np.testing.assert_allclose(r["wind_speed_true"], log["wind_speed_true"][on], atol=1e-12)
    assert 0.0 <= r["wind_dir_true"].min() and r["wind_dir_true"].max() < 2 * math.pi
    with pytest.raises(ValueError, match="holds 0 sample"):
        log.window(1e6, 2e6)


def test_preset_states_its_conventions():
    text = PRESETS["esso-frt"].conventions
    for phrase in ("body-axis", "positive delta_rudder turns to starboard", "comes FROM", "clockwise"):
        assert phrase in text
