"""Hostile and broken log files: each gives one clear line (exit 2 from the CLI, no traceback),
or is repaired with a note; the input is never modified."""
from __future__ import annotations

import hashlib
import json
import os
import warnings
from pathlib import Path

import pytest

from shipid.cli import main
from shipid.datasets import bundled_data_dir
from shipid.logs import LogError, read_log, read_ship

SRC = bundled_data_dir() / "kcs_tc_p35.csv"
MARIN = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "kvlcc2_marin"


def _lines():
    return SRC.read_text().splitlines()


def _write(tmp_path, name, lines) -> Path:
    p = tmp_path / name
    p.write_text("\n".join(lines) + "\n")
    return p


def _cli_one_line(argv, capsys, match: str):
    """The CLI exits 2 with exactly one stderr line containing ``match`` (no traceback)."""
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert "Traceback" not in err and err.count("\n") == 0, err[:500]
    assert match in err, err
    return err


def _unchanged(p: Path, before: str):
    assert hashlib.sha256(p.read_bytes()).hexdigest() == before


def test_two_extra_columns_of_the_same_name(tmp_path, capsys):
    lines = [ln if ln.startswith("#") else ln + (",wave,wave" if ln.startswith("time") else ",1,2") for ln in _lines()]
    p = _write(tmp_path, "dup.csv", lines)
    before = hashlib.sha256(p.read_bytes()).hexdigest()
    msg = ("`dup.csv` row 3: column 'wave' appears twice (columns 10 and 11 of the header); rename one, or pick "
           "one by number with columns={'wave': 10}")
    with pytest.raises(LogError) as ei:
        read_log(p)
    assert str(ei.value) == msg
    _cli_one_line(["log", str(p)], capsys, msg)
    _cli_one_line(["metrics", str(p)], capsys, msg)
    _unchanged(p, before)


def test_a_2mb_text_cell(tmp_path, capsys):
    lines = [ln if ln.startswith("#") else ln + (",remark" if ln.startswith("time") else ",ok") for ln in _lines()]
    lines[5] = lines[5][:-2] + '"' + "x" * 2_000_000 + '"'
    p = _write(tmp_path, "big.csv", lines)
    msg = (f"`big.csv` row 6: a cell of more than 131072 characters (the row has {len(lines[5])}); "
           "a log cell holds a number")
    with pytest.raises(LogError, match=msg.replace("(", r"\(").replace(")", r"\)")):
        read_log(p)
    _cli_one_line(["log", str(p)], capsys, msg)


def test_deeply_nested_metadata_line_and_ship_files(tmp_path, capsys):
    lines = _lines()
    lines[0] = "# shipid-log: " + "[" * 100_000 + "]" * 100_000
    p = _write(tmp_path, "deep.csv", lines)
    msg = ("`deep.csv` row 1: the '# shipid-log:' line is nested too deeply to be metadata; delete the line or give "
           "a flat JSON mapping")
    with pytest.raises(LogError) as ei:
        read_log(p)
    assert str(ei.value) == msg
    _cli_one_line(["log", str(p)], capsys, msg)
    sj = tmp_path / "ship.json"
    sj.write_text('{"lpp": ' + "[" * 100_000 + "]" * 100_000 + "}")
    with pytest.raises(ValueError, match=r"`ship.json`: nested more than 64 levels deep; not a ship file"):
        read_ship(sj)
    _cli_one_line(["log", str(SRC), "--ship", str(sj)], capsys, "`ship.json`: nested more than 64 levels deep")
    pytest.importorskip("yaml", reason="PyYAML not installed: YAML ship files untested")
    sy = tmp_path / "ship.yaml"
    sy.write_text("a: " + "[" * 100_000 + "]" * 100_000 + "\n")
    _cli_one_line(["log", str(SRC), "--ship", str(sy)], capsys, "`ship.yaml`: nested more than 64 levels deep")


def test_true_is_not_a_length(tmp_path, capsys):
    sj = tmp_path / "ship.json"
    sj.write_text(json.dumps({"lpp": True}))
    with pytest.raises(ValueError, match=r"`ship.json`: lpp = True is not a number; give lpp in SI units"):
        read_ship(sj)
    lines = _lines()
    lines[1] = '# shipid-ship: {"lpp": true}'
    p = _write(tmp_path, "t.csv", lines)
    _cli_one_line(["log", str(p)], capsys, "lpp = True is not a number")


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no FIFOs on this platform")
def test_a_fifo_is_refused_not_read(tmp_path, capsys):
    f = tmp_path / "pipe.csv"
    os.mkfifo(f)
    with pytest.raises(LogError, match=r"is not a regular file \(a pipe, socket or device\); give the log file itself"):
        read_log(f)
    _cli_one_line(["log", str(f)], capsys, "is not a regular file")


@pytest.mark.skipif(not MARIN.is_dir(), reason=f"MARIN KVLCC2 data not found at {MARIN}")
def test_marin_duplicated_row_repaired_or_refused(tmp_path, capsys):
    src = MARIN / "MARIN_FREE_KVLCC2_zz_10_m.dat"
    m = src.read_text().splitlines()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        ref = read_log(src)
    dup = m[:500] + [m[500]] + m[500:]
    p = _write(tmp_path, "zz_dup.dat", dup)
    with warnings.catch_warnings():
        warnings.simplefilter("error")          # no dropout warning: nothing else is lost
        log = read_log(p)
    assert len(log) == len(ref)                 # was 1160 of 3844 samples (70 % dropped)
    assert log.notes[0] == ("1 row(s) repeating the previous row exactly dropped (rows 502): a duplicated row breaks "
                            "the uniform time base")
    assert (log.time == ref.time).all()
    # a repeated row with a changed value cannot be repaired safely: refused, naming the row
    bad = m[500].split()
    bad[1] = str(float(bad[1]) + 1.0)
    p2 = _write(tmp_path, "zz_dup2.dat", m[:500] + [" ".join(bad)] + m[500:])
    msg = ("`zz_dup2.dat` column 'time' row 502: time stamps are not consistent with uniform sampling from this row "
           "on (printed 67.2 s)")
    with pytest.raises(LogError, match=msg.replace("(", r"\(").replace(")", r"\)")):
        read_log(p2)
    _cli_one_line(["log", str(p2)], capsys, msg)
    # ... unless asked to drop the repeated stamps
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        assert len(read_log(p2, marin_time="drop")) < len(ref)


def test_units_given_twice(tmp_path, capsys):
    _cli_one_line(["fit", str(SRC), "--units", "psi=deg,psi=rad", "--model", "kcs-response",
                   "-o", str(tmp_path / "r.json")], capsys,
                  "--units: 'psi' is given twice (psi=deg and psi=rad); give it once")


def test_a_log_too_large_for_memory_is_refused_before_it_is_read(tmp_path, monkeypatch, capsys):
    """Estimated from the file's size and its first rows (about 0.8 kB of memory a row while reading)."""
    p = tmp_path / "long.csv"
    lines = _lines()
    with open(p, "w") as fh:
        fh.write("\n".join(lines) + "\n")
        fh.truncate(200 * 2**20)  # the rest of a 200 MiB log (sparse)
    monkeypatch.setenv("SHIPID_MEMORY_LIMIT_GB", "1")
    err = _cli_one_line(["log", str(p)], capsys, "`long.csv`: reading about")
    assert "rows (200 MiB) needs about" in err and "(limit 1 GiB" in err and "split the log into shorter runs" in err


def test_heading_in_radians_under_a_deg_header_is_blamed_on_psi(tmp_path, capsys):
    lines = [ln.replace("psi [rad]", "psi [deg]") for ln in (bundled_data_dir() / "kcs_zz_m10.csv").read_text().splitlines()]
    p = _write(tmp_path, "h.csv", lines)
    err = _cli_one_line(["log", str(p)], capsys, "`h.csv` column 'psi'")
    assert "declared in deg looks like radians" in err and "--units psi=rad" in err


def test_reference_offset_must_lie_on_the_ship(capsys):
    err = _cli_one_line(["metrics", str(SRC), "--reference-offset", "1e308"], capsys, "--reference-offset 1e+308")
    assert "the logged point must lie on the ship (within +/-0.6 Lpp = +/-2.62 m of midship)" in err
