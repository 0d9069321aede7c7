"""Per-channel signs (``read_log(signs=)``, ``--sign r=-1,v=-1``) and the consistency checks of
``TrialLog.from_arrays``."""
from __future__ import annotations

import warnings

import numpy as np
import pytest

from shipid.cli import main
from shipid.datasets import bundled_kcs_logs
from shipid.logs import LogError, TrialLog, read_log


def _tc_path():
    return next(p for p in bundled_kcs_logs() if "tc_p35" in str(p))


@pytest.fixture
def flipped_csv(tmp_path):
    """The bundled turning log with r and v written port-positive (negated)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        log = read_log(_tc_path())
    df = log.data.copy()
    df["r"], df["v"] = -df["r"], -df["v"]
    p = tmp_path / "flipped.csv"
    df.to_csv(p, index=False)
    return p, log


def test_signs_negate_the_channels_back(flipped_csv):
    p, log = flipped_csv
    with pytest.raises(LogError, match=r"yaw rate 'r' \(column \d+\) has the opposite sign to dpsi/dt.*negate r \(CLI: --sign r=-1"):
        read_log(p)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        back = read_log(p, signs={"r": -1, "v": -1})
    np.testing.assert_array_equal(back["r"], log["r"])
    np.testing.assert_array_equal(back["v"], log["v"])
    assert "'r' multiplied by -1 (schema 'shipid' signs)" in back.notes


@pytest.mark.parametrize("signs, match", [
    ({"r": 2}, r"signs\['r'\] = 2; use \+1 \(file already in shipid's sign\) or -1 \(flip\)"),
    ({"delta": -1}, r"signs\['delta'\]: give the rudder's sign as rudder_sign=-1 \(CLI: --rudder-sign -1\)"),
    ({"time": -1}, r"signs\['time'\]: time cannot be negated"),
])
def test_bad_signs_are_named(flipped_csv, signs, match):
    with pytest.raises(ValueError, match=match):
        read_log(flipped_csv[0], signs=signs)


def test_sign_for_a_missing_channel_names_the_channels(flipped_csv):
    with pytest.raises(LogError, match=r"`flipped.csv`: signs for \['w'\], but the log has no such channel; its "
                                       r"channels are \[.*'r'.*\]"):
        read_log(flipped_csv[0], signs={"w": -1})


def test_cli_sign_option(flipped_csv, capsys):
    p, _ = flipped_csv
    assert main(["log", str(p), "--sign", "r=-1,v=-1"]) == 0
    capsys.readouterr()
    for arg, msg in [("r=2", "--sign r=2: give +1 or -1 (the channel is negated for -1), e.g. --sign r=-1,v=-1"),
                     ("r", "--sign entry 'r' must look like NAME=VALUE"),
                     ("delta=-1", "--sign delta: give the rudder's sign with --rudder-sign -1"),
                     ("r=-1,r=1", "--sign: 'r' is given twice")]:
        rc = main(["log", str(p), "--sign", arg])
        err = capsys.readouterr().err
        assert rc == 2 and msg in err and "Traceback" not in err, (arg, err)


def test_from_arrays_runs_the_consistency_checks():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        log = read_log(_tc_path())
    cols = {c: log.data[c].to_numpy() for c in log.channels if c != "time"}
    ok = TrialLog.from_arrays(log.time, name="ok", **cols)
    assert ok.consistency is not None and not ok.consistency.errors
    cols["r"] = -cols["r"]
    with pytest.raises(LogError, match=r"log 'bad': yaw rate 'r' has the opposite sign.*; pass consistency_checks=False$"):
        TrialLog.from_arrays(log.time, name="bad", **cols)
    skipped = TrialLog.from_arrays(log.time, name="bad", consistency_checks=False, **cols)
    assert skipped.consistency is None


def test_noisy_straight_heading_is_not_compared_with_r():
    """A noisy compass on a straight course (range of many degrees, no turn): no yaw-rate verdict."""
    from shipid.logs import check_consistency

    rng = np.random.default_rng(6)
    t = np.arange(2000) * 0.1
    log = TrialLog.from_arrays(t, psi=0.3 + rng.normal(0, 0.1, t.size), r=rng.normal(0, 0.002, t.size),
                               consistency_checks=False)
    res = check_consistency(log)
    assert not res.errors
    assert any("changes by less than 5 deg" in f.message for f in res.findings)
