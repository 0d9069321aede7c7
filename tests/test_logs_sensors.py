"""Sensor faults found when a log is read (shipid.logs.sensors): each a warning naming the file and column and
saying what to check, in the structure of the consistency findings; and how often they fire on good logs."""
from __future__ import annotations

import io
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from shipid.cli import main
from shipid.logs import read_log
from shipid.logs.sensors import SCALE_FLOOR, SCALE_SIGMAS, check_sensors, plain_header, yaw_rate_scale

DATA = Path(__file__).resolve().parents[1] / "data"
SHARED = Path(__file__).resolve().parents[2] / "shared" / "data"
LOGS = sorted(DATA.glob("*.csv"))


def _edited(tmp_path, name, edit=None, rename=None, text_edit=None, src="kcs_zz_m10.csv") -> Path:
    lines = (DATA / src).read_text().splitlines()
    head = [ln for ln in lines if ln.startswith("#")]
    df = pd.read_csv(io.StringIO("\n".join(ln for ln in lines if not ln.startswith("#"))))
    if edit is not None:
        df = edit(df)
    if rename:
        df = df.rename(columns=rename)
    text = "\n".join(head) + "\n" + df.to_csv(index=False)
    p = tmp_path / name
    p.write_text(text_edit(text) if text_edit else text, encoding="utf-8")
    return p


def _read(p, **kw):
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        log = read_log(p, **kw)
    return log, [str(x.message) for x in w]


def _sensor_warnings(log):
    return [f for f in log.consistency.findings if f.level == "warning"
            and f.check in ("yaw_rate_scale", "propeller_dead", "truncated_row", "header_lookalike")]


@pytest.mark.parametrize("pct", [3, 5, -5])
def test_gyro_scale_error_of_a_few_percent(tmp_path, pct):
    p = _edited(tmp_path, "g.csv", edit=lambda d: d.assign(**{"r [rad/s]": d["r [rad/s]"] * (1 + pct / 100)}))
    log, _ = _read(p)
    f = [x for x in log.consistency.findings if x.check == "yaw_rate_scale"]
    assert len(f) == 1 and f[0].level == "warning", log.consistency
    import re

    sign = "+" if pct > 0 else "-"
    assert re.search(rf"yaw rate 'r' \(column 7 'r \[rad/s\]'\) reads \{sign}\d\.\d % against dpsi/dt of the heading "
                     r"\(scale \d\.\d{3} \+/- 0\.\d{3}, \d+ standard errors from 1\)", f[0].message), f[0].message
    assert "check the gyro's calibration" in f[0].message and f[0].message.startswith("`g.csv`: ")
    assert abs(1 / f[0].values["scale"] - 1 - pct / 100) < 3 * f[0].values["scale_std"]


def test_gyro_scale_threshold_is_the_logs_own_standard_error(tmp_path):
    """The same 3 % error is found on the long turning log and not on its first 30 s (too little turn)."""
    log, _ = _read(_edited(tmp_path, "full.csv", src="kcs_tc_p35.csv",
                           edit=lambda d: d.assign(**{"r [rad/s]": d["r [rad/s]"] * 1.03})))
    short, _ = _read(_edited(tmp_path, "short.csv", src="kcs_tc_p35.csv",
                             edit=lambda d: d.assign(**{"r [rad/s]": d["r [rad/s]"] * 1.03}).iloc[:300]))
    est_full = yaw_rate_scale(log.time, log.data["psi"], log.data["r"])
    est_short = yaw_rate_scale(short.time, short.data["psi"], short.data["r"])
    assert est_short["scale_std"] > 2 * est_full["scale_std"]
    assert any(f.check == "yaw_rate_scale" for f in log.consistency.findings)
    assert not any(f.check == "yaw_rate_scale" for f in short.consistency.findings)


def test_no_sensor_warning_on_the_bundled_logs():
    for p in LOGS:
        log, _ = _read(p)
        assert _sensor_warnings(log) == [], (p.name, [f.message for f in _sensor_warnings(log)])


@pytest.mark.skipif(not (SHARED / "esso_osaka_frt").is_dir(), reason=f"Esso Osaka data not found under {SHARED}")
def test_esso_gyro_has_one_common_scale_that_the_long_runs_resolve():
    """The 33 Esso Osaka runs agree on one yaw-rate scale, dpsi/dt = 1.0136 +/- 0.0011 r (chi2/dof 1.1 about
    it): a real 1.3 % calibration offset of that gyro, not noise; the warning fires on the 4 runs long enough
    to resolve it at 4 standard errors, on no other."""
    ks, fired = [], []
    for p in sorted((SHARED / "esso_osaka_frt").glob("*/*.csv")):
        log, _ = _read(p, schema="esso-frt", consistency_checks=False)
        e = yaw_rate_scale(log.time, log.data["psi"], log.data["r"])
        ks.append((e["scale"], e["scale_std"]))
        fired += [f for f in check_sensors(log) if f.check == "yaw_rate_scale"]
    k = np.array(ks)
    w = 1 / k[:, 1] ** 2
    mean = float((k[:, 0] * w).sum() / w.sum())
    assert len(k) == 33 and 1.005 < mean < 1.02
    assert np.mean(((k[:, 0] - mean) / k[:, 1]) ** 2) < 2.0  # one scale explains every run
    assert 1 <= len(fired) <= 6 and all(1.005 < f.values["scale"] < 1.03 for f in fired)


def test_dead_propeller_while_making_way(tmp_path, capsys):
    p = _edited(tmp_path, "n0.csv", edit=lambda d: d.assign(**{"n [rps]": 0.0}))
    log, _ = _read(p)
    [f] = [x for x in log.consistency.findings if x.check == "propeller_dead"]
    assert f.level == "warning" and f.message == (
        "`n0.csv`: propeller 'n' (column 9 'n [rps]') reads 0 in 100 % of the samples while the ship makes way "
        "(up to 1.44 m/s): a dead or unmapped channel? check the sensor and the column (a fit has no propeller "
        "thrust to balance the resistance without it)")
    assert main(["log", str(p)]) == 0
    assert "reads 0 in 100 % of the samples" in capsys.readouterr().err


def test_constant_propeller_is_information(tmp_path):
    log, _ = _read(DATA / "kcs_zz_m10.csv")
    [f] = [x for x in log.consistency.findings if x.check == "propeller_constant"]
    assert f.level == "info" and "is exactly 9 throughout while the ship makes way" in f.message


@pytest.mark.parametrize("bad, good, code", [("\u0440si [rad]", "psi [rad]", "U+0440 CYRILLIC SMALL LETTER ER"),
                                             ("\uff55 [m/s]", "u [m/s]", "U+FF55 FULLWIDTH LATIN SMALL LETTER U"),
                                             ("r\u200b [rad/s]", "r [rad/s]", "U+200B ZERO WIDTH SPACE")])
def test_lookalike_header_characters_are_read_as_plain_and_named(tmp_path, bad, good, code):
    p = _edited(tmp_path, "h.csv", rename={good: bad})
    log, said = _read(p)
    ref, _ = _read(DATA / "kcs_zz_m10.csv")
    assert log.channels == ref.channels and np.array_equal(log.data.to_numpy(), ref.data.to_numpy())
    [f] = [x for x in log.consistency.findings if x.check == "header_lookalike"]
    assert f"header {bad!r} holds look-alike or invisible character(s) {code}; read as {good!r}" in f.message
    assert plain_header(bad) == (good, [code])


def test_a_cut_last_row_is_dropped_and_said(tmp_path, capsys):
    p = _edited(tmp_path, "t.csv", text_edit=lambda t: t.rstrip("\n")[:-3])
    before = p.read_bytes()
    log, said = _read(p)
    ref, _ = _read(DATA / "kcs_zz_m10.csv")
    assert len(log) == len(ref) - 1
    msg = ("`t.csv` row 1104: the last row is cut short (8 of 9 cells, no line end): a file copied while it was "
           "being written? the row is dropped; check that the file is complete")
    assert [f.message for f in log.consistency.findings if f.check == "truncated_row"] == [msg]
    assert main(["log", str(p), "--no-consistency-checks"]) == 0
    assert msg in capsys.readouterr().err and p.read_bytes() == before
    # a complete last row without its line end is read as it is
    q = _edited(tmp_path, "q.csv", text_edit=lambda t: t.rstrip("\n"))
    assert len(_read(q)[0]) == len(ref)


def test_schema_signs_and_noise_for_unknown_channels_are_refused(tmp_path, capsys):
    import json

    for key, val in (("signs", {"zz": -1}), ("meas_std", {"zz": 0.1})):
        s = tmp_path / f"{key}.json"
        s.write_text(json.dumps({key: val}))
        assert main(["log", str(DATA / "kcs_zz_m10.csv"), "--schema", str(s)]) == 2
        err = capsys.readouterr().err
        assert f"gives {key} for zz, but the log has no such channel" in err and err.count("\n") == 1


def test_symlink_loop_is_named(tmp_path, capsys):
    import os

    os.symlink("b.csv", tmp_path / "a.csv")
    os.symlink("a.csv", tmp_path / "b.csv")
    assert main(["log", str(tmp_path / "a.csv")]) == 2
    assert "a symbolic link to 'b.csv', which is missing or links back in a loop" in capsys.readouterr().err
