"""Tests for shipid.logs: reading, validating and writing trial logs."""
from __future__ import annotations

import hashlib
import math
import re
import sys
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from shipid import LogError, ShipParticulars, TrialLog, read_log, read_ship
from shipid._io import OutputExistsError

MARIN = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "kvlcc2_marin"
MARIN_FILES = ["tc_35", "tc_-35", "zz_10", "zz_-10", "zz_20", "zz_-20"]

HEADER = "time [s],x [m],y [m],psi [rad],u [m/s],v [m/s],r [rad/s],delta [rad],n [rps]"


# ------------------------------------------------------------------------------------
# helpers
# ------------------------------------------------------------------------------------


def frame(n: int = 60, dt: float = 0.5, seed: int = 0) -> pd.DataFrame:
    """A plausible turning manoeuvre in the default schema (SI, radians)."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * dt
    r = 0.02 * np.tanh(t / 5.0)
    psi = np.concatenate([[0.0], np.cumsum(0.5 * (r[1:] + r[:-1]) * dt)])
    u = 1.5 - 0.002 * t
    v = -0.05 * np.tanh(t / 5.0)
    x = np.concatenate([[0.0], np.cumsum((u * np.cos(psi) - v * np.sin(psi))[:-1] * dt)])
    y = np.concatenate([[0.0], np.cumsum((u * np.sin(psi) + v * np.cos(psi))[:-1] * dt)])
    delta = np.where(t > 2, 0.35, 0.0)
    nn = 10.0 + 0.01 * rng.standard_normal(n)
    return pd.DataFrame({"time": t, "x": x, "y": y, "psi": psi, "u": u, "v": v, "r": r, "delta": delta, "n": nn})


def csv_text(df: pd.DataFrame, header: str = HEADER, cells: dict | None = None, sep: str = ",") -> str:
    """CSV text; ``cells`` maps (file line, column name) -> raw string placed in that cell."""
    lines = [header.replace(",", sep)]
    for i, row in enumerate(df.itertuples(index=False)):
        vals = [repr(float(v)) for v in row]
        line_no = i + 2
        for (ln, col), raw in (cells or {}).items():
            if ln == line_no:
                vals[list(df.columns).index(col)] = raw
        lines.append(sep.join(vals))
    return "\n".join(lines) + "\n"


def write(tmp_path: Path, name: str, content) -> Path:
    p = tmp_path / name
    if isinstance(content, str):
        p.write_text(content, encoding="utf-8")
    else:
        p.write_bytes(content)
    return p


def raises_unchanged(path: Path, match: str, **kw) -> LogError:
    """read_log(path) raises LogError matching ``match``; the file's bytes are unchanged."""
    before = hashlib.sha256(path.read_bytes()).hexdigest() if path.is_file() else None
    mtime = path.stat().st_mtime_ns if path.is_file() else None
    with pytest.raises(LogError, match=match) as ei:
        read_log(path, **kw)
    if before is not None:
        assert hashlib.sha256(path.read_bytes()).hexdigest() == before
        assert path.stat().st_mtime_ns == mtime
    msg = str(ei.value)
    assert "\n" not in msg, "messages must be one line for the CLI"
    return ei.value


# ------------------------------------------------------------------------------------
# reading the default schema
# ------------------------------------------------------------------------------------


def test_read_default_schema(tmp_path):
    df = frame()
    p = write(tmp_path, "trial.csv", csv_text(df))
    log = read_log(p, lpp=4.36)
    assert len(log) == 60
    assert log.channels == ["x", "y", "psi", "u", "v", "r", "delta", "n"]
    np.testing.assert_allclose(log.time, df.time)
    for c in log.channels:
        np.testing.assert_allclose(log[c], df[c], rtol=0, atol=1e-15)
    assert log.rows.tolist() == list(range(2, 62))
    assert log.ship.lpp == 4.36
    assert log.sha256 == hashlib.sha256(p.read_bytes()).hexdigest()
    assert log.path == p and log.name == "trial"
    assert log.dt == pytest.approx(0.5)
    assert log.missing == {} and log.dropouts == []
    assert log.has("u") and not log.has("phi") and "u" in log
    assert isinstance(log.data, pd.DataFrame) and list(log.data.columns)[0] == "time"
    tp = log.to_pandas()
    assert tp.index.name == "time" and "u" in tp


def test_header_without_units_is_si_and_extra_columns_kept(tmp_path):
    df = frame()
    df["U_wind"] = 3.0
    text = csv_text(df, header="time,x,y,psi,u,v,r,delta,n,U_wind")
    log = read_log(write(tmp_path, "t.csv", text))
    assert "U_wind" in log.channels
    np.testing.assert_allclose(log["U_wind"], 3.0)


def test_unit_conversions_from_header(tmp_path):
    df = frame()
    conv = df.copy()
    conv["psi"] = np.degrees(df.psi)
    conv["r"] = np.degrees(df.r)
    conv["delta"] = np.degrees(df.delta)
    conv["n"] = df.n * 60
    conv["u"] = df.u * 3600 / 1852
    conv["v"] = df.v * 3600 / 1852
    hdr = "time [s],x [m],y [m],psi [deg],u [knots],v [kn],r [deg/s],delta [deg],n [rpm]"
    log = read_log(write(tmp_path, "t.csv", csv_text(conv, header=hdr)))
    for c in ["psi", "r", "delta", "n", "u", "v"]:
        np.testing.assert_allclose(log[c], df[c], rtol=1e-12, atol=1e-15, err_msg=c)
    assert log.units_in["psi"] == "deg" and log.units_in["n"] == "rpm"


def test_unit_conversions_from_argument_and_column_map(tmp_path):
    df = frame()
    conv = df.copy()
    conv["psi"] = np.degrees(df.psi)
    conv["r"] = np.degrees(df.r)
    conv["n"] = df.n * 60
    conv.columns = ["t", "east", "north", "heading", "surge", "sway", "yawrate", "rudder", "rpm"]
    text = csv_text(conv, header=",".join(conv.columns))
    p = write(tmp_path, "t.csv", text)
    log = read_log(p, columns={"time": "t", "x": "east", "y": "north", "psi": "heading", "u": "surge",
                               "v": "sway", "r": "yawrate", "delta": "rudder", "n": "rpm"},
                   units={"psi": "deg", "r": "deg/s", "n": "rpm"})
    for c in ["psi", "r", "n", "u"]:
        np.testing.assert_allclose(log[c], df[c], rtol=1e-12, atol=1e-15)
    # Hz is revolutions per second
    df2 = frame()
    log2 = read_log(write(tmp_path, "hz.csv", csv_text(df2, header=HEADER.replace("[rps]", "[Hz]"))))
    np.testing.assert_allclose(log2["n"], df2.n)


def test_unknown_unit_and_wrong_dimension(tmp_path):
    p = write(tmp_path, "t.csv", csv_text(frame()))
    raises_unchanged(p, r"`t.csv` column 'u': unknown unit 'furlongs'; use one of", units={"u": "furlongs"})
    raises_unchanged(p, r"`t.csv` column 'psi': unit 'm/s' is a speed unit but 'psi' is a angle", units={"psi": "m/s"})
    raises_unchanged(p, r"units given for \['zeta'\] but the log has no such channel", units={"zeta": "deg"})


def test_heading_unwrapped(tmp_path):
    t = np.arange(400) * 0.5
    psi_true = 0.03 * t - 0.5        # 6 rad of turning: wraps twice
    r = np.full_like(t, 0.03)
    wrapped = np.mod(psi_true + np.pi, 2 * np.pi) - np.pi
    assert np.abs(np.diff(wrapped)).max() > 6  # really wrapped
    log = TrialLog.from_arrays(t, psi=wrapped, r=r, u=np.full_like(t, 1.0))
    np.testing.assert_allclose(log["psi"], psi_true, atol=1e-12)
    # degrees in [0, 360), declared: unwrapped into continuous radians
    deg = np.mod(np.degrees(psi_true), 360.0)
    df = pd.DataFrame({"time": t, "psi": deg, "r": r, "u": 1.0})
    p = write(tmp_path, "h.csv", csv_text(df, header="time [s],psi [deg],r [rad/s],u [m/s]"))
    log = read_log(p, required=("time", "psi"))
    np.testing.assert_allclose(log["psi"] - log["psi"][0], psi_true - psi_true[0], atol=1e-12)
    assert np.abs(np.diff(log["psi"])).max() < 0.1


# ------------------------------------------------------------------------------------
# bad input: one test per case; message names file/column/row and the value
# ------------------------------------------------------------------------------------


def test_missing_file_and_directory(tmp_path):
    with pytest.raises(LogError, match=r"nope.csv`: log file does not exist; check the path"):
        read_log(tmp_path / "nope.csv")
    raises_unchanged(tmp_path, r"is a directory, not a log file")


def test_missing_required_column(tmp_path):
    # (an input: always required; a velocity may be missing beside a logged track, tests/test_unlogged_velocities.py)
    df = frame().drop(columns="delta")
    hdr = HEADER.replace(",delta [rad]", "")
    p = write(tmp_path, "trial.csv", csv_text(df, header=hdr))
    e = raises_unchanged(p, r"`trial.csv` row 1: required column 'delta' not found; header has .*"
                            r"columns=\{'delta': 'your name'\}")
    assert e.column == "delta" and e.row == 1
    # columns= pointing at a column that does not exist
    raises_unchanged(p, r"columns maps 'delta' to 'rudder' but the header has no such column",
                     columns={"delta": "rudder"})
    # a velocity is required when the track is not logged
    df2 = frame().drop(columns=["r", "x"])
    p2 = write(tmp_path, "trial2.csv", csv_text(df2, header=HEADER.replace(",r [rad/s]", "").replace(",x [m]", "")))
    raises_unchanged(p2, r"`trial2.csv` row 1: required column 'r' not found")


def test_non_numeric_cell(tmp_path):
    p = write(tmp_path, "trial.csv", csv_text(frame(), cells={(14, "u"): "1.5 m/s"}))
    e = raises_unchanged(p, r"`trial.csv` column 'u' row 14: value '1.5 m/s' is not a number; fix the cell")
    assert (e.column, e.row, e.value) == ("u", 14, "1.5 m/s")
    p2 = write(tmp_path, "comma.csv", csv_text(frame(), cells={(9, "x"): '"1,5"'}))
    raises_unchanged(p2, r"`comma.csv` column 'x' row 9: value '1,5' is not a number \(decimal comma\?")


def test_time_repeated(tmp_path):
    df = frame()
    df.loc[30, "time"] = df.loc[29, "time"]   # file line 32 repeats line 31
    p = write(tmp_path, "trial.csv", csv_text(df))
    e = raises_unchanged(p, r"`trial.csv` column 'time' row 32: time 14.5 repeats 14.5 \(row 31\); "
                            r"time must increase strictly")
    assert e.row == 32 and e.value == 14.5


def test_time_decreasing(tmp_path):
    df = frame()
    df.loc[40, "time"] = 3.0
    p = write(tmp_path, "trial.csv", csv_text(df))
    raises_unchanged(p, r"`trial.csv` column 'time' row 42: time 3 goes back from 19.5 \(row 41\)")


def test_time_blank(tmp_path):
    p = write(tmp_path, "trial.csv", csv_text(frame(), cells={(7, "time"): ""}))
    raises_unchanged(p, r"`trial.csv` column 'time' row 7: time value blank/NaN is missing or not finite")


def test_empty_file(tmp_path):
    raises_unchanged(write(tmp_path, "empty.csv", b""), r"`empty.csv`: file is empty")
    raises_unchanged(write(tmp_path, "blank.csv", "\n  \n\n"), r"`blank.csv`: file is empty")


def test_header_only(tmp_path):
    raises_unchanged(write(tmp_path, "h.csv", HEADER + "\n\n"), r"`h.csv`: header only, no data rows")


def test_no_header(tmp_path):
    text = csv_text(frame()).split("\n", 1)[1]
    raises_unchanged(write(tmp_path, "nohdr.csv", text), r"`nohdr.csv` row 1: the first line is numbers, not a header")


def test_too_few_samples(tmp_path):
    p = write(tmp_path, "short.csv", csv_text(frame(n=12)))
    raises_unchanged(p, r"`short.csv`: only 12 sample\(s\); at least 20 are needed")
    assert len(read_log(p, min_samples=10)) == 12


def test_wrong_delimiter_semicolon(tmp_path):
    p = write(tmp_path, "semi.csv", csv_text(frame(), sep=";"))
    e = raises_unchanged(p, r"`semi.csv` row 1: the header has no commas but is semicolon-separated "
                            r".*pass delimiter=';' \(CLI: --delimiter ;\)")
    assert "time [s];x [m]" in str(e.value)
    log = read_log(p, delimiter=";")
    np.testing.assert_allclose(log["u"], frame().u)


def test_wrong_delimiter_tab_and_whitespace(tmp_path):
    p = write(tmp_path, "tab.csv", csv_text(frame(), sep="\t"))
    raises_unchanged(p, r"`tab.csv` row 1: the header has no commas but is tab-separated.*delimiter='\\t'")
    assert len(read_log(p, delimiter="\t")) == 60
    hdr = "time x y psi u v r delta n"
    p2 = write(tmp_path, "ws.txt", csv_text(frame(), header=hdr.replace(" ", ","), sep=" "))
    raises_unchanged(p2, r"`ws.txt` row 1: the header has no commas but is whitespace-separated")
    assert len(read_log(p2, delimiter="whitespace")) == 60


def test_single_column_header_with_semicolons_is_not_missing_column(tmp_path):
    # header is semicolon-separated, one data row uses commas: never a confusing "missing column"
    text = csv_text(frame(), sep=";")
    lines = text.splitlines()
    lines[5] = lines[5].replace(";", ",")
    p = write(tmp_path, "mixed.csv", "\n".join(lines) + "\n")
    e = raises_unchanged(p, r"`mixed.csv` row 1: the header has no commas but is semicolon-separated")
    assert "required column" not in str(e.value)
    # comma header, a data row with semicolons
    lines = csv_text(frame()).splitlines()
    lines[9] = lines[9].replace(",", ";")
    p2 = write(tmp_path, "mixed2.csv", "\n".join(lines) + "\n")
    raises_unchanged(p2, r"`mixed2.csv` row 10: 1 field\(s\) but the header has 9; the row contains semicolons: "
                         r"wrong delimiter\?")


def test_ragged_row(tmp_path):
    lines = csv_text(frame()).splitlines()
    lines[20] += ",7"
    p = write(tmp_path, "ragged.csv", "\n".join(lines) + "\n")
    raises_unchanged(p, r"`ragged.csv` row 21: 10 field\(s\) but the header has 9")


def test_binary_garbage(tmp_path):
    rng = np.random.default_rng(1)
    blob = b"\x89PNG\r\n\x1a\n" + rng.integers(0, 256, 4000, dtype=np.uint8).tobytes()
    raises_unchanged(write(tmp_path, "image.csv", blob), r"`image.csv` row \d+: NUL byte at byte offset \d+; "
                                                        r"this is a binary file")
    # non-UTF-8 bytes without NUL and with control characters
    blob2 = bytes(range(1, 8)) * 10 + b"\xc3\x28" + b"\xfe\xff\x80" * 50
    raises_unchanged(write(tmp_path, "garbage.csv", blob2), r"`garbage.csv` row 1: byte 0x.. is not UTF-8 text")


def test_utf16_and_latin1_are_read(tmp_path):
    text = csv_text(frame())
    log = read_log(write(tmp_path, "u16.csv", text.encode("utf-16")))
    assert len(log) == 60
    text2 = "# logged by the pool, temperature 18 \xb0C\n" + text
    log2 = read_log(write(tmp_path, "latin1.csv", text2.encode("cp1252")))
    assert len(log2) == 60 and log2.rows[0] == 3


def test_absurd_speed(tmp_path):
    p = write(tmp_path, "trial.csv", csv_text(frame(), cells={(25, "u"): "1e308"}))
    e = raises_unchanged(p, r"`trial.csv` column 'u' row 25: value 1e\+308 m/s is absurd for 'u' "
                            r"\(\|value\| > 100 m/s\)")
    assert e.value == 1e308


def test_absurd_position_and_inf(tmp_path):
    p = write(tmp_path, "pos.csv", csv_text(frame(), cells={(5, "y"): "3e9"}))
    raises_unchanged(p, r"`pos.csv` column 'y' row 5: value 3e\+09 m is absurd")
    p2 = write(tmp_path, "inf.csv", csv_text(frame(), cells={(8, "v"): "inf"}))
    raises_unchanged(p2, r"`inf.csv` column 'v' row 8: value inf is not finite")
    p3 = write(tmp_path, "rate.csv", csv_text(frame(), cells={(8, "r"): "-4000"}))
    raises_unchanged(p3, r"`rate.csv` column 'r' row 8: value -4000 rad/s is absurd for 'r'")


def test_rudder_in_degrees_declared_radians(tmp_path):
    df = frame()
    df["delta"] = np.degrees(df.delta)
    p = write(tmp_path, "trial.csv", csv_text(df))
    e = raises_unchanged(p, r"`trial.csv` column 'delta' row 7: value 20.0535 looks like degrees .*"
                            r"pass units=\{'delta': 'deg'\} \(CLI: --units delta=deg\) or convert")
    assert e.row == 7
    log = read_log(p, units={"delta": "deg"})
    np.testing.assert_allclose(log["delta"], frame().delta)


def test_heading_in_degrees_with_wrap(tmp_path):
    # heading logged 0..360 degrees, wraps from 359 to 1: jump of -358 "rad"
    t = np.arange(100) * 0.5
    deg = np.mod(340.0 + 1.0 * t, 360.0)
    df = pd.DataFrame({"time": t, "psi": deg, "u": 1.0})
    p = write(tmp_path, "trial.csv", csv_text(df, header="time [s],psi [rad],u [m/s]"))
    raises_unchanged(p, r"`trial.csv` column 'psi' row 2: value 340 looks like degrees \(the first heading lies "
                        r"outside \+-2 pi rad\); pass units=\{'psi': 'deg'\}", required=("time",))
    # starting near zero (inside +-2 pi): the wrap-around jump from 0 to 359.5 gives it away
    deg2 = np.mod(5.0 - 0.5 * np.arange(100), 360.0)   # 5, 4.5, ..., 0, 359.5 (index 11, file line 13)
    df2 = pd.DataFrame({"time": t, "psi": deg2, "u": 1.0})
    p2 = write(tmp_path, "trial2.csv", csv_text(df2, header="time [s],psi [rad],u [m/s]"))
    raises_unchanged(p2, r"`trial2.csv` column 'psi' row 13: value 359.5 looks like degrees \(a jump of 359.5 from",
                     required=("time",))


def test_heading_in_degrees_without_wrap_detected_by_yaw_rate(tmp_path):
    # a 10/10 zigzag-like heading in degrees that never wraps; r in rad/s
    t = np.arange(400) * 0.25
    psi = 0.2 * np.sin(2 * np.pi * t / 40.0)
    r = np.gradient(psi, t)
    df = pd.DataFrame({"time": t, "psi": np.degrees(psi), "r": r, "u": 1.0})
    p = write(tmp_path, "zz.csv", csv_text(df, header="time [s],psi [rad],r [rad/s],u [m/s]"))
    e = raises_unchanged(p, r"`zz.csv` column 'psi' row \d+: value 11.459\d* looks like degrees \(heading changes "
                            r"57.\d x faster than the integral of r", required=("time",))
    assert e.column == "psi"
    # and the converse: r in deg/s, psi in rad (r below the 3 rad/s magnitude check)
    df2 = pd.DataFrame({"time": t, "psi": psi, "r": np.degrees(r), "u": 1.0})
    p2 = write(tmp_path, "zz2.csv", csv_text(df2, header="time [s],psi [rad],r [rad/s],u [m/s]"))
    raises_unchanged(p2, r"`zz2.csv` column 'r' row \d+: value 1.79\d* looks like deg/s", required=("time",))
    # the right declaration reads fine, and the heuristic can be switched off
    log = read_log(p, units={"psi": "deg"}, required=("time",))
    np.testing.assert_allclose(log["psi"], psi, atol=1e-12)
    # without the unit heuristics the consistency check (r against dpsi/dt) still finds it; both can be switched off
    with pytest.raises(LogError, match=r"dpsi/dt = 57.\d+ x yaw rate 'r' .*psi is in degrees: declare units"):
        read_log(p, unit_checks=False, required=("time",))
    assert read_log(p, unit_checks=False, consistency_checks=False, required=("time",))["psi"].max() > 11


def test_yaw_rate_in_degrees_by_magnitude(tmp_path):
    df = frame()
    df["r"] = np.degrees(df.r) * 5  # up to ~5.7 "rad/s"
    p = write(tmp_path, "trial.csv", csv_text(df))
    raises_unchanged(p, r"`trial.csv` column 'r' row \d+: value 3.\d+ looks like deg/s \(\|r\| > 3 rad/s")


def test_input_gap_is_error_unless_interpolated(tmp_path):
    p = write(tmp_path, "trial.csv", csv_text(frame(), cells={(20, "delta"): "", (21, "delta"): "NaN"}))
    e = raises_unchanged(p, r"`trial.csv` column 'delta' row 20: input value is blank/NaN \(2 such sample\(s\)\); "
                            r".*interpolate_inputs=True \(CLI: --interpolate-inputs\)")
    assert e.row == 20
    log = read_log(p, interpolate_inputs=True)
    np.testing.assert_allclose(log["delta"], frame().delta)  # constant 0.35 there: exact
    assert any("2 blank sample(s) filled by linear interpolation (rows 20, 21)" in n for n in log.notes)
    assert "delta" not in log.missing
    # a gap at the very start cannot be interpolated
    p2 = write(tmp_path, "start.csv", csv_text(frame(), cells={(2, "n"): ""}))
    raises_unchanged(p2, r"`start.csv` column 'n' row 2: input value is blank/NaN at the start",
                     interpolate_inputs=True)


def test_interpolation_is_linear_in_time(tmp_path):
    df = frame()
    df["n"] = 10 + 0.1 * df.time
    p = write(tmp_path, "trial.csv", csv_text(df, cells={(30, "n"): "", (31, "n"): ""}))
    log = read_log(p, interpolate_inputs=True)
    np.testing.assert_allclose(log["n"], df.n, rtol=1e-12)


def test_missing_measured_samples_are_nan_and_reported(tmp_path):
    p = write(tmp_path, "trial.csv", csv_text(frame(), cells={(10, "u"): "", (11, "u"): "nan", (40, "psi"): ""}))
    with pytest.warns(UserWarning, match=r"`trial.csv`: missing measured samples kept as NaN -- psi: 1 \(rows 40\); "
                                         r"u: 2 \(rows 10, 11\)"):
        log = read_log(p)
    assert log.missing == {"psi": [40], "u": [10, 11]} or log.missing == {"u": [10, 11], "psi": [40]}
    assert np.isnan(log["u"][[8, 9]]).all() and np.isfinite(log["u"]).sum() == 58
    assert np.isnan(log["psi"][38]) and np.isfinite(log["psi"][39])
    s = str(log)
    assert "missing samples: " in s and "u 2 (rows 10, 11)" in s


def test_time_dropout_reported(tmp_path):
    df = frame(n=80)
    df = df.drop(index=range(30, 40)).reset_index(drop=True)   # 10 samples lost: 5.5 s gap
    p = write(tmp_path, "trial.csv", csv_text(df))
    with pytest.warns(UserWarning, match=r"1 time dropout\(s\) longer than 3 x median dt \(first 14.5-20 s\)"):
        log = read_log(p)
    assert log.dropouts == [(14.5, 20.0)]
    assert "dropouts (> 3 dt): 1: 14.5-20 s" in str(log)


def test_blank_lines_and_comments_keep_file_line_numbers(tmp_path):
    text = csv_text(frame())
    lines = text.splitlines()
    lines.insert(0, "# trial 7, calm water")
    lines.insert(10, "")
    lines.insert(11, ",,,,,,,,")
    p = write(tmp_path, "trial.csv", "\n".join(lines) + "\n")
    log = read_log(p)
    assert len(log) == 60
    assert log.rows[0] == 3 and log.rows[-1] == 64
    p2 = write(tmp_path, "bad.csv", "\n".join(lines).replace("\n" + lines[30] + "\n", "\n" + lines[30].replace(
        lines[30].split(",")[4], "x", 1) + "\n") + "\n")
    raises_unchanged(p2, r"`bad.csv` column 'u' row 31: value 'x' is not a number")


def test_log_error_attributes(tmp_path):
    p = write(tmp_path, "trial.csv", csv_text(frame(), cells={(14, "v"): "abc"}))
    e = raises_unchanged(p, "abc")
    assert isinstance(e, ValueError)
    assert e.path == p and e.column == "v" and e.row == 14 and e.value == "abc"


# ------------------------------------------------------------------------------------
# from_arrays, to_csv round trip, summary, plot
# ------------------------------------------------------------------------------------


def test_from_arrays_generic_channels_allowed():
    t = np.linspace(0, 10, 101)
    log = TrialLog.from_arrays(t, name="glider", x=t, z=0.1 * t, theta=np.full_like(t, -0.5), u=np.ones_like(t),
                               w=0.1 + 0 * t, q=0 * t, fin=np.full_like(t, 0.1))
    assert log.channels == ["x", "z", "theta", "u", "w", "q", "fin"]
    assert log.name == "glider" and log.path is None and log.sha256 is None
    assert log.rows.tolist() == list(range(101))


def test_from_arrays_runs_the_same_validation():
    t = np.arange(50.0)
    with pytest.raises(LogError, match=r"log 'synthetic' column 'delta' index 0: value 35 looks like degrees"):
        TrialLog.from_arrays(t, delta=np.full(50, 35.0))
    with pytest.raises(LogError, match=r"log 'g' column 'fin' index 3: value 20 looks like degrees"):
        TrialLog.from_arrays(t, name="g", fin=np.r_[0, 0, 0, np.full(47, 20.0)])
    with pytest.raises(LogError, match=r"log 'synthetic' column 'time' index 5: time 4 repeats 4"):
        TrialLog.from_arrays(np.r_[t[:5], t[4:49]], u=np.ones(50))
    with pytest.raises(LogError, match=r"column 'u': has 49 samples but time has 50"):
        TrialLog.from_arrays(t, u=np.ones(49))
    with pytest.raises(LogError, match=r"column 'n' index 7: input value is blank/NaN"):
        TrialLog.from_arrays(t, n=np.where(t == 7, np.nan, 10.0))
    with pytest.raises(LogError, match=r"required channel\(s\) \['r'\] missing"):
        TrialLog.from_arrays(t, u=np.ones(50), required=("u", "r"))
    with pytest.raises(LogError, match=r"column 'foo': expected a 1-D array"):
        TrialLog.from_arrays(t, foo=np.ones((50, 2)))
    log = TrialLog.from_arrays(t, units={"delta": "deg"}, delta=np.full(50, 35.0))
    np.testing.assert_allclose(log["delta"], math.radians(35))


def test_to_csv_round_trip(tmp_path):
    df = frame(n=80, dt=0.1)
    ship = ShipParticulars(lpp=4.36, beam=0.61, name="KCS model", scale=52.67, extra={"source": "SPEC"})
    psi_wrapped = np.mod(df.psi + np.pi, 2 * np.pi) - np.pi
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        log = TrialLog.from_arrays(df.time, name="tc35 run 2", ship=ship, x=df.x, y=df.y, psi=psi_wrapped,
                                   u=np.where(df.index == 5, np.nan, df.u), v=df.v, r=df.r, delta=df.delta,
                                   n=df.n, phi=np.full(80, 0.01), wave=np.full(80, 0.3))
    out = tmp_path / "out.csv"
    log.to_csv(out)
    with pytest.warns(UserWarning, match="missing measured samples"):
        back = read_log(out)
    pd.testing.assert_frame_equal(back.data, log.data, check_exact=True)
    assert back.name == "tc35 run 2" and back.ship == ship
    assert back.missing == {"u": [out.read_text().splitlines().index(
        next(line for line in out.read_text().splitlines() if ",," in line)) + 1]}
    assert out.read_text().splitlines()[2].startswith("time [s],x [m],y [m],psi [rad],u [m/s],v [m/s],r [rad/s],"
                                                      "delta [rad],n [rps],phi [rad],wave")
    with pytest.raises(OutputExistsError, match="pass --force"):
        log.to_csv(out)
    before = out.read_bytes()
    log.to_csv(out, force=True)
    assert out.read_bytes() == before


def test_summary_and_plot(tmp_path):
    import matplotlib

    matplotlib.use("Agg")
    log = read_log(write(tmp_path, "trial.csv", csv_text(frame())), lpp=4.36)
    s = str(log)
    assert "TrialLog 'trial' (trial.csv, sha256 " in s and "60 samples, t = 0 .. 29.5 s, dt = 0.5 s" in s
    assert "ship: ship Lpp 4.36 m" in s and "missing samples: none" in s and "dropouts: none" in s
    axs = log.plot()
    assert len(axs) == 8 and axs[2].get_ylabel() == "psi [deg]"
    np.testing.assert_allclose(axs[2].lines[0].get_ydata(), np.degrees(log["psi"]))
    import matplotlib.pyplot as plt

    plt.close("all")


# ------------------------------------------------------------------------------------
# ship particulars
# ------------------------------------------------------------------------------------


def test_ship_particulars_validation_and_round_trip():
    s = ShipParticulars(lpp=320, beam=58, draught=20.8, name="KVLCC2", rudder_max=math.radians(35))
    assert ShipParticulars.from_dict(s.to_dict()) == s
    assert s.to_dict()["lpp"] == 320.0 and "displacement" not in s.to_dict()
    for bad, msg in [({"lpp": 0}, "lpp = 0 must be finite and > 0"), ({"lpp": float("nan")}, "finite"),
                     ({"lpp": "long"}, "is not a number"), ({"beam": 3}, "'lpp' .* is required"),
                     ({"lpp": 4, "rudder_max": 35}, "rudder_max = 35.0 rad is beyond 90 deg"),
                     # the usual symbols are accepted, but one field given twice is an error
                     ({"lpp": 4, "Lpp": 4}, r"'lpp' and 'Lpp' both give lpp; keep one"),
                     ({"lpp": 4, "bream": 0.6}, r"unknown field\(s\) \['bream'\]; known fields are "),
                     ({"lpp": True}, r"lpp = True is not a number"),
                     ({"lpp": 4, "Cb": 1.2}, r"block_coefficient = 1.2 must lie in \(0, 1\]")]:
        with pytest.raises(ValueError, match=msg):
            ShipParticulars.from_dict(bad)


def test_read_ship_json_yaml_and_errors(tmp_path, monkeypatch):
    p = write(tmp_path, "kcs.json", '{"name": "KCS", "lpp": 4.36, "beam": 0.61, "scale": 52.67}')
    s = read_ship(p)
    assert s.lpp == 4.36 and s.name == "KCS"
    with pytest.raises(ValueError, match=r"`bad.json`: not a ship \(not valid JSON: .* at line 1 column 14\); give a ship file"):
        read_ship(write(tmp_path, "bad.json", '{"lpp": 4.36,'))
    with pytest.raises(ValueError, match="ship file does not exist"):
        read_ship(tmp_path / "none.json")
    y = write(tmp_path, "kcs.yaml", "name: KCS\nlpp: 4.36\nbeam: 0.61\n")
    monkeypatch.setitem(sys.modules, "yaml", None)   # as if PyYAML were not installed
    with pytest.raises(ValueError, match=r"`kcs.yaml`: reading YAML needs PyYAML \(pip install pyyaml\); or write "
                                         r"the ship file as JSON"):
        read_ship(y)
    monkeypatch.delitem(sys.modules, "yaml")
    pytest.importorskip("yaml", reason="PyYAML not installed: YAML ship files untested")
    assert read_ship(y) == ShipParticulars(lpp=4.36, beam=0.61, name="KCS")


def test_ship_travels_with_log(tmp_path):
    p = write(tmp_path, "trial.csv", csv_text(frame()))
    sp = write(tmp_path, "kcs.json", '{"name": "KCS", "lpp": 4.36}')
    log = read_log(p, ship=sp)
    assert log.ship.name == "KCS" and log.ship.lpp == 4.36
    log2 = read_log(p, ship=sp, lpp=4.4)
    assert log2.ship.lpp == 4.4 and log2.ship.name == "KCS"
    with pytest.raises(ValueError, match="lpp = -1 must be finite and > 0"):
        read_log(p, lpp=-1)


# ------------------------------------------------------------------------------------
# MARIN SIMMAN .dat files (measured KVLCC2)
# ------------------------------------------------------------------------------------

needs_marin = pytest.mark.skipif(not MARIN.is_dir(), reason=f"MARIN KVLCC2 data not found at {MARIN} "
                                                            "(../shared/data/kvlcc2_marin beside the repository)")


def _marin(tag: str) -> Path:
    return MARIN / f"MARIN_FREE_KVLCC2_{tag}_m.dat"


def _raw_marin(tag: str) -> np.ndarray:
    rows = [line.split() for line in _marin(tag).read_text().splitlines()[3:]]
    return np.array([r for r in rows if r], dtype=float)


@needs_marin
@pytest.mark.parametrize("tag", MARIN_FILES)
def test_marin_reads_all_files(tag):
    p = _marin(tag)
    before = hashlib.sha256(p.read_bytes()).hexdigest()
    log = read_log(p)
    raw = _raw_marin(tag)
    assert log.fmt == "marin" and log.sha256 == before
    assert len(log) == raw.shape[0]             # no sample lost
    assert log.channels == ["x", "y", "psi", "u", "v", "r", "delta", "n", "phi", "p"]
    assert log.ship.lpp == 320.0 and log.ship.name == "KVLCC2"
    # time: strictly increasing, rounds to every printed stamp (3 significant digits)
    t = log.time
    assert np.all(np.diff(t) > 0)
    ulp = 10.0 ** (np.floor(np.log10(np.maximum(np.abs(raw[:, 0]), 0.1))) - 2)  # 0.00E+00: next stamp's
    assert np.max(np.abs(t - raw[:, 0]) / ulp) < 1.0
    assert log.dt == pytest.approx(0.13526, abs=2e-5)
    nrep = int(np.sum(np.diff(raw[:, 0]) == 0))
    assert nrep > 0 and any(f"{nrep} repeated stamps" in n for n in log.notes)
    # units: degrees -> radians, rpm -> rps; rudder flipped to shipid's starboard-positive convention
    np.testing.assert_allclose(log["delta"], -np.radians(raw[:, 9]))
    assert any("rudder angle multiplied by -1 (schema 'marin'" in n for n in log.notes)
    # turning circle, rudder hard over: the ship turns the way shipid's sign says, sign(delta) = sign(r)
    # (tc_35: the file's +35 deg reads -35 deg, r < 0, a turn to port)
    if tag.startswith("tc"):
        held = np.abs(log["delta"]) > np.radians(30)
        assert np.mean(np.sign(log["delta"][held]) == np.sign(log["r"][held])) > 0.95
    np.testing.assert_allclose(log["n"], raw[:, 10] / 60.0)
    np.testing.assert_allclose(log["phi"], np.radians(raw[:, 3]))
    # heading continuous
    assert np.abs(np.diff(log["psi"])).max() < 0.05
    # approach (before the rudder execute): surge ~ 8 m/s (15.5 kn), little sway
    first = np.arange(len(t)) < np.argmax(np.abs(raw[:, 9] - raw[0, 9]) > 0.5)
    assert first.sum() > 10
    assert np.mean(log["u"][first]) == pytest.approx(8.0, abs=0.15)
    assert np.abs(np.mean(log["v"][first])) < 0.1
    # file untouched
    assert hashlib.sha256(p.read_bytes()).hexdigest() == before


def _ulp3(a):
    """Resolution of numbers printed with 3 significant digits."""
    return 10.0 ** (np.floor(np.log10(np.maximum(np.abs(a), 1e-6))) - 2)


@needs_marin
@pytest.mark.parametrize("tag", MARIN_FILES)
def test_marin_body_axis_rotation(tag):
    """The file's u, v are earth-fixed (d(x0, y0)/dt); ours, rotated back by psi, integrate to the track.

    Positions are printed with 3 significant digits (10 m resolution beyond 1 km), so the check
    compares displacements over 200-sample windows (27 s, ~200 m) with the integrated velocities,
    allowing the print resolution of both ends plus 1 m.
    """
    log = read_log(_marin(tag))
    raw = _raw_marin(tag)
    t, x, y, psi, u, v = log.time, log["x"], log["y"], log["psi"], log["u"], log["v"]

    def integ(a):
        return np.concatenate([[0.0], np.cumsum(0.5 * (a[1:] + a[:-1]) * np.diff(t))])

    k = np.arange(0, len(t) - 200, 50)
    # print resolution of both ends + 1 m + 3 % of the displacement: in the turning circles the
    # integrated velocities fall short of the track by a systematic ~1.5 % (the positions belong to
    # the logged reference point, the velocities perhaps to another; see docs/logs.md)
    disp = np.hypot(x[k + 200] - x[k], y[k + 200] - y[k])
    tol_x = _ulp3(x[k]) / 2 + _ulp3(x[k + 200]) / 2 + 1.0 + 0.03 * disp
    tol_y = _ulp3(y[k]) / 2 + _ulp3(y[k + 200]) / 2 + 1.0 + 0.03 * disp

    def misfit(ve_x, ve_y):
        X, Y = integ(ve_x), integ(ve_y)
        ex = (X[k + 200] - X[k]) - (x[k + 200] - x[k])
        ey = (Y[k + 200] - Y[k]) - (y[k + 200] - y[k])
        return np.abs(ex) / tol_x, np.abs(ey) / tol_y

    # 1. the file's u, v are earth-fixed velocities
    ex, ey = misfit(raw[:, 5], raw[:, 6])
    assert np.quantile(ex, 0.95) < 1 and np.quantile(ey, 0.95) < 1
    # 2. our body-axis u, v rotated back by psi give the same track
    ex, ey = misfit(u * np.cos(psi) - v * np.sin(psi), u * np.sin(psi) + v * np.cos(psi))
    assert np.quantile(ex, 0.95) < 1 and np.quantile(ey, 0.95) < 1
    # 3. negative control: taking the file's u, v as body axes misses the track by far
    ue, ve = raw[:, 5], raw[:, 6]
    ex, ey = misfit(ue * np.cos(psi) - ve * np.sin(psi), ue * np.sin(psi) + ve * np.cos(psi))
    assert max(ex.max(), ey.max()) > 5
    # 4. body-axis surge ~ 8 m/s on approach, positive throughout; the earth-fixed x-velocity is not
    assert np.mean(u[t < 4]) == pytest.approx(8.0, abs=0.15) and u.min() > 1.0
    if tag.startswith("tc"):
        assert ue.min() < -2.0  # the turn reverses the earth-fixed x-velocity ...
        assert u.min() > 2.0    # ... but never the surge


@needs_marin
def test_marin_turning_circle_heading_passes_540_deg():
    for tag, sign in (("tc_35", 1), ("tc_-35", -1)):
        log = read_log(_marin(tag))
        heading_change = np.degrees(log["psi"] - log["psi"][0])
        assert sign * heading_change.max() > 540 or -sign * heading_change.min() > 540 or \
            np.abs(heading_change).max() > 540
        assert np.abs(heading_change).max() > 540
        # unwrapped and monotone in the steady turn: no 360-degree jumps
        assert np.abs(np.diff(np.degrees(log["psi"]))).max() < 3


@needs_marin
def test_marin_drop_repeated_stamps():
    raw = _raw_marin("zz_10")
    nrep = int(np.sum(np.diff(raw[:, 0]) == 0))
    with pytest.warns(UserWarning, match="time dropout"):
        log = read_log(_marin("zz_10"), marin_time="drop")
    assert len(log) == raw.shape[0] - nrep
    np.testing.assert_array_equal(log.time, np.unique(raw[:, 0]))
    assert any(f"{nrep} samples with a repeated time stamp dropped" in n for n in log.notes)


@needs_marin
def test_marin_auto_detect_and_ship_override(tmp_path):
    log = read_log(_marin("zz_20"), fmt="marin", lpp=3.2)
    assert log.ship.lpp == 3.2 and log.ship.name == "KVLCC2"
    # a copy under another extension is still recognised by its title line
    p = write(tmp_path, "copy.txt", _marin("zz_20").read_bytes())
    assert read_log(p).fmt == "marin"


def test_marin_format_errors(tmp_path):
    head = "MARIN(Maritime Research Institute Netherlands)\nZig-zag manoeuvring for KVLCC2 : 10 / -10\n\n"
    row = "\t".join(["1.00E+00"] * 11)
    rows = [("\t".join([f"{0.135 * i:.2E}"] + ["1.00E+00"] * 10)) for i in range(40)]
    p = write(tmp_path, "short_row.dat", head + "\n".join(rows[:10] + [row.rsplit("\t", 1)[0]] + rows[11:]) + "\n")
    raises_unchanged(p, r"`short_row.dat` row 14: 10 number\(s\), a MARIN row has 11")
    bad = rows[:5] + [rows[5].replace("1.00E+00", "abc", 1)] + rows[6:]
    p2 = write(tmp_path, "bad_cell.dat", head + "\n".join(bad) + "\n")
    raises_unchanged(p2, r"`bad_cell.dat` column 'x' row 9: value 'abc' is not a number")


def test_propeller_in_rpm_declared_rps_when_lpp_known(tmp_path):
    df = frame()
    df["n"] = df.n * 60   # 600 rpm of a 4.36 m model, declared rps
    p = write(tmp_path, "trial.csv", csv_text(df))
    raises_unchanged(p, r"`trial.csv` column 'n' row 2: value 600.\d+ looks like rpm "
                        r"\(n sqrt\(Lpp\) = 125\d rps m\^0.5 "
                        r"for Lpp 4.36 m.*pass units=\{'n': 'rpm'\}", lpp=4.36)
    np.testing.assert_allclose(read_log(p, lpp=4.36, units={"n": "rpm"})["n"], frame().n)
    # without Lpp the consistency check judges by n x u (scale-free): a warning, not an error (fast craft)
    with pytest.warns(UserWarning, match=r"`trial.csv`: 'n' \(column 9\) may be in rpm: n x u = 8\d\d rps m/s"):
        assert read_log(p)["n"][0] > 500


def test_case_insensitive_names_and_non_numeric_extra_column(tmp_path):
    df = frame()
    hdr = "Time [s],X [m],Y [m],PSI [rad],u [m/s],v [m/s],r [rad/s],Delta [rad],n [rps],U [m/s],remark"
    lines = csv_text(df.assign(U=1.5), header=hdr.rsplit(",", 1)[0]).splitlines()
    lines = [lines[0] + ",remark"] + [ln + (",ok" if i % 2 else ",rudder hard over") for i, ln in enumerate(lines[1:])]
    p = write(tmp_path, "caps.csv", "\n".join(lines) + "\n")
    with pytest.warns(UserWarning, match=r"column 'remark' is not numeric; ignored"):
        log = read_log(p)
    assert log.channels == ["x", "y", "psi", "u", "v", "r", "delta", "n", "U"]
    np.testing.assert_allclose(log["psi"], df.psi)
    # a mostly numeric extra column with one bad cell is an error, not silently dropped
    lines2 = csv_text(df.assign(wave=0.2), header=HEADER + ",wave [m]").splitlines()
    lines2[33] = lines2[33].rsplit(",", 1)[0] + ",0.2m"
    p2 = write(tmp_path, "wave.csv", "\n".join(lines2) + "\n")
    raises_unchanged(p2, r"`wave.csv` column 'wave' row 34: value '0.2m' is not a number")


def test_time_units(tmp_path):
    df = frame()
    conv = df.assign(time=df.time * 1000)
    log = read_log(write(tmp_path, "ms.csv", csv_text(conv, header=HEADER.replace("time [s]", "time [ms]"))))
    np.testing.assert_allclose(log.time, df.time)


def test_semicolon_with_decimal_comma(tmp_path):
    df = frame()
    text = csv_text(df, sep=";").replace(".", ",")
    text = text.replace("time [s]", "time [s]")
    p = write(tmp_path, "excel.csv", text)
    raises_unchanged(p, r"semicolon-separated")
    log = read_log(p, delimiter=";")
    for c in df.columns[1:]:
        np.testing.assert_allclose(log[c], df[c], rtol=1e-14, atol=1e-15)


def test_iso_time_stamps(tmp_path):
    df = frame()
    stamps = pd.Timestamp("2024-05-01T12:00:00") + pd.to_timedelta(df.time, unit="s")
    lines = csv_text(df).splitlines()
    out = [lines[0]] + [f"{s.isoformat()},{ln.split(',', 1)[1]}" for s, ln in zip(stamps, lines[1:])]
    p = write(tmp_path, "iso.csv", "\n".join(out) + "\n")
    log = read_log(p)
    np.testing.assert_allclose(log.time, df.time, atol=1e-9)
    assert "t = 0 s at 2024-05-01T12:00:00" in log.notes[0]
    out[20] = "yesterday," + out[20].split(",", 1)[1]
    p2 = write(tmp_path, "iso_bad.csv", "\n".join(out) + "\n")
    raises_unchanged(p2, r"`iso_bad.csv` column 'time' row 21: value 'yesterday' is not a date-time stamp")


def test_duplicate_column_trailing_delimiter_and_blank_required(tmp_path):
    df = frame()
    lines = csv_text(df).splitlines()
    # trailing commas (an empty unnamed column) are harmless
    p = write(tmp_path, "trail.csv", "\n".join(ln + "," for ln in lines) + "\n")
    assert read_log(p).channels == ["x", "y", "psi", "u", "v", "r", "delta", "n"]
    # two 'u' columns are ambiguous
    p2 = write(tmp_path, "dup.csv", "\n".join([lines[0] + ",u [m/s]"] + [ln + ",1.0" for ln in lines[1:]]) + "\n")
    raises_unchanged(p2, r"`dup.csv` row 1: column 'u' appears twice \(columns 5 and 10 of the header\)")
    # ... unless columns= says which one is meant
    log = read_log(p2, columns={"u": 5})
    np.testing.assert_allclose(log["u"], df.u)
    np.testing.assert_allclose(read_log(p2, columns={"u": 10})["u"], 1.0)
    assert any("ignored: columns= maps 'u'" in n for n in log.notes)
    # a required channel without a single value
    p3 = write(tmp_path, "blank_r.csv", csv_text(df, cells={(k, "r"): "" for k in range(2, 62)}))
    raises_unchanged(p3, r"`blank_r.csv` column 'r' row 2: required channel is entirely blank/NaN")


@needs_marin
def test_marin_file_read_as_csv_says_so():
    raises_unchanged(_marin("zz_10"), r"required column 'time' not found.*this looks like a MARIN .dat file: "
                                      r"pass fmt='marin'", fmt="csv")


# ------------------------------------------------------------------------------------
# `shipid log`: summary, conversion, one-line errors with exit code 2
# ------------------------------------------------------------------------------------


def test_cli_log_summary_and_convert(tmp_path, capsys):
    from shipid.cli import main

    df = frame()
    conv = df.assign(psi=np.degrees(df.psi), n=df.n * 60)
    p = write(tmp_path, "trial.csv", csv_text(conv, cells={(10, "u"): ""}))
    out = tmp_path / "clean.csv"
    code = main(["log", str(p), "--units", "psi=deg,n=rpm", "--lpp", "4.36", "-o", str(out)])
    text = capsys.readouterr().out
    assert code == 0
    assert "TrialLog 'trial' (trial.csv" in text and "missing samples: u 1 (rows 10)" in text
    assert "converted from: psi deg, n rpm" in text and f"wrote {out}" in text
    with pytest.warns(UserWarning):
        back = read_log(out)
    np.testing.assert_allclose(back["psi"], df.psi, rtol=1e-12, atol=1e-15)
    assert back.ship.lpp == 4.36
    assert main(["log", str(p), "--units", "psi=deg,n=rpm", "-o", str(out)]) == 2
    assert "output exists" in capsys.readouterr().err


@pytest.mark.parametrize("case", ["missing", "nonnumeric", "time", "empty", "header", "short", "semicolon",
                                  "binary", "absurd", "degrees", "inputgap", "dir"])
def test_cli_bad_input_exit_2_one_line_file_unchanged(tmp_path, capsys, case):
    from shipid.cli import main

    df = frame()
    files = {
        "missing": (csv_text(df.drop(columns="n"), header=HEADER.replace(",n [rps]", "")), r"column 'n' not found"),
        "nonnumeric": (csv_text(df, cells={(9, "r"): "n/a?"}), r"column 'r' row 9: value 'n/a\?' is not a number"),
        "time": (csv_text(df.assign(time=np.r_[df.time[:20], df.time[19:59]])), r"column 'time' row 22: time"),
        "empty": (b"", r"file is empty"),
        "header": (HEADER + "\n", r"header only"),
        "short": (csv_text(frame(n=5)), r"only 5 sample"),
        "semicolon": (csv_text(df, sep=";"), r"row 1: the header has no commas but is semicolon-separated"),
        "binary": (b"\x1f\x8b\x08\x00" + bytes(200), r"binary file"),
        "absurd": (csv_text(df, cells={(30, "u"): "1e308"}), r"column 'u' row 30: value 1e\+308 m/s is absurd"),
        "degrees": (csv_text(df.assign(delta=np.degrees(df.delta))), r"column 'delta' row 7: value 20.05\d+ looks "
                                                                      r"like degrees"),
        "inputgap": (csv_text(df, cells={(33, "n"): ""}), r"column 'n' row 33: input value is blank"),
    }
    if case == "dir":
        p, pattern = tmp_path, "is a directory"
    else:
        content, pattern = files[case]
        p = write(tmp_path, f"{case}.csv", content)
    before = p.read_bytes() if p.is_file() else None
    code = main(["log", str(p)])
    err = capsys.readouterr().err
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("shipid log: error: ")
    assert re.search(pattern, lines[0]), lines[0]
    if before is not None:
        assert p.read_bytes() == before
    assert "Traceback" not in err


def test_heading_heuristic_not_fooled_by_noise():
    """Noisy compass and gyro on a straight course: no 'looks like degrees' from noise alone."""
    rng = np.random.default_rng(3)
    t = np.arange(6000) * 0.1
    for s_psi, s_r in [(0.05, 0.002), (1e-4, 0.01), (0.02, 0.02)]:
        psi = 0.3 + rng.normal(0, s_psi, t.size)
        r = rng.normal(0, s_r, t.size)
        log = TrialLog.from_arrays(t, psi=psi, r=r)
        assert len(log) == 6000
    # a case where the raw slope alone (-22 +- 22) would have said "degrees": the standard error saves it
    rng6 = np.random.default_rng(6)
    t2 = np.arange(2000) * 0.1
    psi = 0.3 + rng6.normal(0, 0.1, t2.size)
    r = rng6.normal(0, 0.002, t2.size)
    rdt = 0.5 * (r[1:] + r[:-1]) * 0.1
    assert 20 < abs(np.diff(psi) @ rdt / (rdt @ rdt)) < 200 and np.abs(rdt).sum() > 0.2
    assert len(TrialLog.from_arrays(t2, psi=psi, r=r)) == 2000
    # while a real zigzag in degrees with the same noise is caught
    psi_true = 0.2 * np.sin(2 * np.pi * t / 60)
    with pytest.raises(LogError, match="looks like degrees"):
        TrialLog.from_arrays(t, psi=np.degrees(psi_true) + rng.normal(0, 0.05, t.size),
                             r=np.gradient(psi_true, t) + rng.normal(0, 0.002, t.size))


@needs_marin
def test_marin_standard_manoeuvre_values_match_data_readme():
    """Advance/transfer/tactical diameter and first overshoots from our logs vs ../shared/data/kvlcc2_marin/README.md.

    Same definitions as the README: rudder execute at the first |delta - delta0| > 0.5 deg, positions of
    the logged reference point, distances along/across the heading at execute.  The README prints 2-3
    digits; the heading in the file has 0.1 deg resolution between 10 and 100 deg.
    """
    lpp = 320.0
    readme_tc = {"tc_35": (3.02, 1.20, 3.07), "tc_-35": (3.09, 1.35, 3.33)}
    for tag, (adv, tra, tac) in readme_tc.items():
        log = read_log(_marin(tag))
        d = np.degrees(log["delta"])
        i0 = int(np.argmax(np.abs(d - d[0]) > 0.5))
        p0 = log["psi"][i0]
        dx, dy = log["x"] - log["x"][i0], log["y"] - log["y"][i0]
        along = dx * np.cos(p0) + dy * np.sin(p0)
        lat = -dx * np.sin(p0) + dy * np.cos(p0)
        change = np.abs(log["psi"] - p0)

        def at(deg, a):
            j = int(np.argmax(change >= np.radians(deg)))
            f = (np.radians(deg) - change[j - 1]) / (change[j] - change[j - 1])
            return a[j - 1] + f * (a[j] - a[j - 1])

        assert at(90, along) / lpp == pytest.approx(adv, abs=0.006), tag
        assert abs(at(90, lat)) / lpp == pytest.approx(tra, abs=0.006), tag
        assert abs(at(180, lat)) / lpp == pytest.approx(tac, abs=0.006), tag
    readme_zz = {"zz_10": 9.4, "zz_-10": 8.1, "zz_20": 15.6, "zz_-20": 12.7}
    for tag, overshoot in readme_zz.items():
        log = read_log(_marin(tag))
        d = np.degrees(log["delta"])
        i0 = int(np.argmax(np.abs(d - d[0]) > 0.5))
        amp = abs(float(tag.split("_")[1]))
        # read in the shipid convention (the MARIN reader flips the file's port-positive rudder):
        # a positive rudder angle turns the ship to starboard (heading increases)
        h = np.sign(d[i0] - d[0]) * np.degrees(log["psi"] - log["psi"][i0])
        j = i0 + int(np.argmax(h[i0:] >= amp))       # first rudder reversal: heading change reaches amp
        k = j + int(np.argmax(h[j:] < amp))          # heading back through amp
        assert h[j:k].max() - amp == pytest.approx(overshoot, abs=0.15), tag


def test_fast_and_careful_parsers_agree_bit_for_bit(tmp_path):
    """Large clean files go through pandas' C parser; the result equals Python's float() cell by cell."""
    rng = np.random.default_rng(5)
    n = 500
    df = frame(n=n, dt=0.1)
    df["u"] = df.u + rng.standard_normal(n) * 10.0 ** rng.integers(-12, 0, n)
    text = csv_text(df, cells={(40, "v"): "", (41, "v"): "NaN"})
    p = write(tmp_path, "big.csv", text)
    with pytest.warns(UserWarning, match="missing measured samples"):
        log = read_log(p)
    cells = [line.split(",") for line in text.splitlines()[1:]]
    u_ref = np.array([float(c[4]) for c in cells])
    np.testing.assert_array_equal(log["u"], u_ref)
    assert log.missing == {"v": [40, 41]}
    # one quoted cell sends the file down the careful path: same numbers
    assert "\n0.5," in text
    p2 = write(tmp_path, "quoted.csv", text.replace("\n0.5,", '\n"0.5",', 1))
    with pytest.warns(UserWarning, match="missing measured samples"):
        log2 = read_log(p2)
    pd.testing.assert_frame_equal(log2.data, log.data, check_exact=True)
