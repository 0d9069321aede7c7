"""Other facilities' conventions through the CLI: a bundled zigzag (data/kcs_zz_m10.csv) rewritten the way
other loggers write it, one change at a time, then read by ``shipid log`` with the options a user would reach
for.  A convention shipid accepts must give back the original log (compared sample by sample); one it cannot
resolve must stop with exit 2 and one line naming the file and the option to use; the input file is never
changed.
"""
from __future__ import annotations

import hashlib
import io
import math
import re
import warnings

import numpy as np
import pandas as pd
import pytest

from shipid.cli import main
from shipid.datasets import bundled_data_dir
from shipid.logs import read_log

SRC = bundled_data_dir() / "kcs_zz_m10.csv"
CH = ("x", "y", "psi", "u", "v", "r", "delta", "n")
KN = 1852.0 / 3600.0


@pytest.fixture(scope="module")
def ref():
    return read_log(SRC)


@pytest.fixture(scope="module")
def table():
    d = pd.read_csv(SRC, comment="#")
    d.columns = [c.split(" [")[0] for c in d.columns]
    return d


def _csv(d: pd.DataFrame, sep: str = ",") -> str:
    return d.to_csv(sep=sep, index=False, float_format="%.17g", lineterminator="\n")


def _clock(t, fmt: str, start: str = "2024-05-01T10:00:00") -> pd.Series:
    return (pd.Timestamp(start) + pd.to_timedelta(np.asarray(t), unit="s")).strftime(fmt)


def _units_row(d):
    """Header of plain names, a units row under it (degrees, rpm), data in those units."""
    d = d.copy()
    d["psi"], d["r"], d["delta"], d["n"] = np.degrees(d.psi), np.degrees(d.r), np.degrees(d.delta), d.n * 60
    head, body = _csv(d).split("\n", 1)
    return head + "\ns,m,m,deg,m/s,m/s,[deg/s],(deg),rpm\n" + body


def _header_units(d):
    """Units other spellings of which loggers write in the header: km/h, r/min, deg/sec."""
    d = d.copy()
    d["u"], d["v"], d["n"], d["r"] = d.u * 3.6, d.v * 3.6, d.n * 60, np.degrees(d.r)
    return _csv(d.rename(columns={"u": "u [km/h]", "v": "v [kph]", "n": "n [r/min]", "r": "r [deg/sec]"}))


def _rate_of_turn(d, unit="deg/min"):
    d = d.copy()
    d["r"] = np.degrees(d.r) * 60   # a marine rate of turn: deg/min
    return _csv(d.rename(columns={"r": f"r [{unit}]"}))


def _speeds_kn(text):
    """A units row (a clock format for the time, knots for u, v) under the header of ``text``, u, v in knots."""
    d = pd.read_csv(io.StringIO(text), dtype={"time": str})
    d["u"], d["v"] = d.u / KN, d.v / KN
    head, body = _csv(d).split("\n", 1)
    return head + "\nhh:mm:ss.ffffff,m,m,rad,kn,m/s,rad/s,rad,1/s\n".replace("m/s,rad/s", "kn,rad/s") + body


def _clock_time(d, fmt="%H:%M:%S.%f", start="2024-05-01T10:00:00"):
    d = d.copy()
    d["time"] = _clock(d.time, fmt, start)
    return _csv(d)


def _repeated_rows(d):
    return _csv(pd.concat([d.iloc[:300], d.iloc[299:301], d.iloc[300:]]))


def _unwrapped_after_turns(d):
    d = d.copy()
    d["psi"] = d.psi + 4 * math.pi   # the log starts after two full turns, heading unwrapped
    return _csv(d)


def _extra_columns(d):
    d = d.copy()
    d["battery [V]"], d["throttle [%]"], d["Remark"] = 12.1, 50.0, "ok"
    return _csv(d)


# name -> (file text, CLI options, expected change of the log against the original)
ACCEPTED = {
    "units row under the header": (_units_row, [], {}),
    "km/h, r/min, deg/sec in the header": (_header_units, [], {}),
    "rate of turn in deg/min": (_rate_of_turn, [], {}),
    "clock time under a units row": (lambda d: _speeds_kn(_clock_time(d)), [], {}),
    "clock time of day": (_clock_time, [], {}),
    "same date (day/month) before the clock": (lambda d: _clock_time(d, "%d/%m/%Y %H:%M:%S.%f"), [], {}),
    "clock passing midnight": (lambda d: _clock_time(d, start="2024-05-01T23:59:00"), [], {}),
    "semicolon, decimal comma, CRLF": (lambda d: d.to_csv(sep=";", decimal=",", index=False, float_format="%.17g",
                                                          lineterminator="\r\n"), ["--delimiter", ";"], {}),
    "exact repeated rows": (_repeated_rows, [], {}),
    "heading unwrapped beyond 2 pi": (_unwrapped_after_turns, [], {"psi": 4 * math.pi}),
    "extra columns in units shipid does not convert": (_extra_columns, [], {}),
}


def _run(capsys, args):
    capsys.readouterr()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rc = main(args)
    return rc, capsys.readouterr()


@pytest.mark.parametrize("name", list(ACCEPTED))
def test_accepted_conventions_give_the_original_log(name, ref, table, tmp_path, capsys):
    make, opts, offset = ACCEPTED[name]
    p = tmp_path / "run.csv"
    p.write_bytes(make(table).encode())
    before = hashlib.sha256(p.read_bytes()).hexdigest()
    out = tmp_path / "si.csv"
    rc, cap = _run(capsys, ["log", str(p), "--lpp", "4.36", *opts, "-o", str(out)])
    assert rc == 0, cap.err
    assert hashlib.sha256(p.read_bytes()).hexdigest() == before
    log = read_log(out)
    assert len(log) == len(ref)
    np.testing.assert_allclose(log.time - log.time[0], ref.time, rtol=0, atol=1e-6)
    for c in CH:
        np.testing.assert_allclose(log[c], ref[c] + offset.get(c, 0.0), rtol=1e-9, atol=1e-12, err_msg=c)


def test_what_was_done_is_noted(table, tmp_path):
    p = tmp_path / "u.csv"
    p.write_text(_units_row(table))
    log = read_log(p, lpp=4.36)
    assert any("row 2 under the header read as the columns' units" in n and "psi [deg]" in n for n in log.notes)
    p.write_text(_repeated_rows(table))
    log = read_log(p, lpp=4.36)
    assert any("2 row(s) repeating the row above exactly dropped (rows 302, 304)" in n for n in log.notes)
    p.write_text(_extra_columns(table))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        log = read_log(p, lpp=4.36)
    np.testing.assert_allclose(log["battery"], 12.1)   # kept, as written
    assert any("'battery [V]' kept as channel 'battery' in its own unit 'V'" in n for n in log.notes)


@pytest.mark.parametrize("token", ["-", "--", "#N/A", "NA", "nan", ""])
def test_missing_value_tokens_are_gaps(token, ref, table, tmp_path):
    d = table.astype(object)
    d.loc[104, "u"] = token
    p = tmp_path / "gap.csv"
    p.write_text(_csv(d))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        log = read_log(p, lpp=4.36)
    assert log.missing == {"u": [106]}   # file line 106 = data row 104 (header on line 1)
    u = ref["u"].copy()
    u[104] = np.nan
    np.testing.assert_array_equal(log["u"], u)


def _speeds(d, factor):
    d = d.copy()
    d["u"], d["v"] = d.u * factor, d.v * factor
    return _csv(d)


def _ms(d):
    d = d.copy()
    d["time"] = np.round(d.time * 1000)
    return _csv(d)


def _date_changes(d):
    d = d.copy()
    d["time"] = _clock(d.time, "%d/%m/%Y %H:%M:%S.%f", "2024-05-01T23:59:00")
    return _csv(d)


def _units_row_conflict(d):
    head, body = _csv(d.rename(columns={"psi": "psi [rad]"})).split("\n", 1)
    return head + "\ns,m,m,deg,m/s,m/s,rad/s,rad,rps\n" + body


# name -> (file text, message expected on stderr[, CLI options])
REFUSED = {
    "speeds in knots, undeclared": (lambda d: _speeds(d, 1 / KN),
                                    r"are 1\.94\d x the speed along the track of x, y: u, v look like knots: "
                                    r"declare .* \(CLI: --units u=kn,v=kn\)"),
    "speeds in km/h, undeclared": (lambda d: _speeds(d, 3.6), r"u, v look like km/h: .*--units u=km/h,v=km/h"),
    "time in ms, undeclared": (_ms, r"time looks like milliseconds: .*--units time=ms"),
    "a day/month date that changes": (_date_changes, r"column 'time' row \d+: the date changes from '01/05/2024' "
                                                     r"to '02/05/2024'; write the time as seconds or as ISO 8601"),
    "units row against the header": (_units_row_conflict, r"row 2: column 'psi \[rad\]' has the unit 'rad' in "
                                                          r"the header but 'deg' in the units row"),
    "deg/min declared as deg/s": (lambda d: _rate_of_turn(d, "deg/s"),
                                  r"column 'r' row \d+: value -?[\d.]+ rad/s, read as deg/s, is not plausible .*check "
                                  r"the unit declared for 'r' \(a marine rate of turn is in deg/min\)"),
    "comma delimiter given for a semicolon file": (lambda d: _csv(d, ";"),
                                                   r"row 1: the header is one column holding semicolons \('time;x;.*"
                                                   r"pass delimiter=';' \(CLI: --delimiter ;\)", ["--delimiter", ","]),
    "U for u": (lambda d: _csv(d.rename(columns={"u": "U"}).drop(columns=["x"])),
                r"required column 'u' not found; .*\('U' is read as channel 'U', not 'u'; if it is 'u': "
                r"--column u=U\)"),
}


@pytest.mark.parametrize("name", list(REFUSED))
def test_unresolvable_conventions_name_the_option(name, table, tmp_path, capsys):
    make, pattern, *opts = REFUSED[name]
    p = tmp_path / "run.csv"
    p.write_bytes(make(table).encode())
    before = p.read_bytes()
    rc, cap = _run(capsys, ["log", str(p), "--lpp", "4.36", *(opts[0] if opts else [])])
    assert rc == 2
    err = cap.err.strip()
    assert err.count("\n") == 0 and "Traceback" not in err and "`run.csv`" in err
    assert re.search(pattern, err), err
    assert p.read_bytes() == before


def test_consistency_checks_do_not_compare_across_a_dropout(table, tmp_path):
    """A 15 s hole in a zigzag: the heading changes across it while the yaw-rate integral bridges it by a
    straight line; comparing them made a false 'constant bias of -0.4 deg/s' warning."""
    p = tmp_path / "gap.csv"
    p.write_text(_csv(table[(table.time < 40) | (table.time > 55)]))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        log = read_log(p, lpp=4.36)
    assert log.dropouts == [(pytest.approx(39.9), pytest.approx(55.1))]
    assert log.consistency.status == "ok", str(log.consistency)
    yaw = next(f for f in log.consistency.findings if f.check == "yaw_rate")
    assert abs(yaw.values["bias_rad_s"]) < 1e-3 and abs(yaw.values["scale"] - 1) < 0.01
    frame = next(f for f in log.consistency.findings if f.check == "velocity_frame")
    assert frame.values["error_body"] < 0.05


ESSO = bundled_data_dir().resolve().parents[1] / "shared" / "data" / "esso_osaka_frt" / "zigzag" / \
    "zigzag_31-Jul-2020_13_04_24.csv"


def test_measured_run_in_another_facilitys_units_via_a_schema_file(tmp_path, capsys):
    """An Esso Osaka zigzag as a full-scale-style logger writes it: own column names, compass heading 0-360
    deg, rate of turn in deg/min, rpm, rudder in degrees positive to port; a schema file maps it back."""
    if not ESSO.is_file():
        pytest.skip(f"measured data absent: {ESSO} (../shared/data/esso_osaka_frt)")
    import json

    e = pd.read_csv(ESSO)
    e.columns = [c.split(" [")[0] for c in e.columns]
    d = pd.DataFrame({"Time": e.t, "X": e.x_position_mid, "Y": e.y_position_mid,
                      "HDG": np.degrees(e.psi_hat) % 360, "Surge": e.u_velo, "Sway": e.vm_velo,
                      "ROT": np.degrees(e.r_angvelo) * 60, "RPM": e.n_prop * 60, "Rudder": -np.degrees(e.delta_rudder)})
    p = tmp_path / "run.csv"
    p.write_text(_csv(d))
    schema = {"columns": {"time": "Time", "x": "X", "y": "Y", "psi": "HDG", "u": "Surge", "v": "Sway", "r": "ROT",
                          "n": "RPM", "delta": "Rudder"},
              "units": {"psi": "deg", "r": "deg/min", "n": "rpm", "delta": "deg"}, "rudder_sign": -1,
              "ship": "esso_osaka_3m"}
    (tmp_path / "facility.json").write_text(json.dumps(schema))
    out = tmp_path / "si.csv"
    rc, cap = _run(capsys, ["log", str(p), "--schema", str(tmp_path / "facility.json"), "-o", str(out)])
    assert rc == 0, cap.err
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ref, log = read_log(ESSO, schema="esso-frt"), read_log(out)
    for c in CH:
        a, b = log[c], ref[c]
        if c == "psi":   # the compass heading starts at 359.1 deg, the file's wrapped one at -0.9 deg
            a = a - 2 * math.pi * np.round((a[0] - b[0]) / (2 * math.pi))
        np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-12, err_msg=c)


MARIN = bundled_data_dir().resolve().parents[1] / "shared" / "data" / "kvlcc2_marin" / "MARIN_FREE_KVLCC2_zz_10_m.dat"


@pytest.mark.parametrize("opts", [["--units", "psi=rad"], ["--columns", "u=5"]])
def test_table_options_on_a_marin_file_name_the_file_and_the_way_out(opts, capsys):
    if not MARIN.is_file():
        pytest.skip(f"measured data absent: {MARIN} (../shared/data/kvlcc2_marin)")
    rc, cap = _run(capsys, ["log", str(MARIN), *opts])
    assert rc == 2
    assert re.search(rf"^shipid log: error: `{MARIN.name}`: {opts[0].strip('-')}= \(CLI: {opts[0]}\) does not apply "
                     r"to a MARIN \.dat file .*pass fmt='csv' \(CLI: --format csv\)$", cap.err.strip()), cap.err


def test_velocity_frame_earth_given_for_body_axis_velocities(capsys):
    """--velocity-frame earth on a file whose u, v are body-axis rotated them wrongly and only warned
    ('agree with neither'); the file's own values fit as body axes, so the message says to drop the option."""
    tc = bundled_data_dir() / "kcs_tc_p35.csv"
    rc, cap = _run(capsys, ["log", str(tc), "--velocity-frame", "earth"])
    assert rc == 2
    assert re.search(r"`kcs_tc_p35.csv`: the file's 'u' \(column 5\), 'v' \(column 6\) are body-axis \(error \d+ %\), "
                     r"but were read as earth-fixed and rotated \(\d+ %\): drop velocity_frame='earth' "
                     r"\(CLI: --velocity-frame body\)", cap.err), cap.err
    rc, cap = _run(capsys, ["log", str(tc)])
    assert rc == 0, cap.err


def test_log_conversion_never_writes_over_its_input(table, tmp_path, capsys):
    p = tmp_path / "run.csv"
    p.write_text(_csv(table))
    before = p.read_bytes()
    (tmp_path / "link.csv").symlink_to(p)
    for out in (p, tmp_path / "link.csv"):
        rc, cap = _run(capsys, ["log", str(p), "--lpp", "4.36", "-o", str(out), "--force"])
        assert rc == 2 and "would replace the input file" in cap.err, cap.err
    assert p.read_bytes() == before
