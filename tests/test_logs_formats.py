"""Format options of the log readers: generic tables (skip_rows, no header, column numbers, whitespace),
velocity frame, rudder sign, schema files and presets, and the same options on the CLI.

Every defect is built from a bundled log (data/kcs_tc_p35.csv): the file is rewritten the way another
facility would log it, and reading it back with the right options must give the original log.
"""
from __future__ import annotations

import json
import math
import warnings
from pathlib import Path

import numpy as np
import pytest

from shipid.datasets import bundled_data_dir
from shipid.logs import LogError, read_log
from shipid.logs.schema import PRESETS, Schema, load_schema

SRC = bundled_data_dir() / "kcs_tc_p35.csv"


@pytest.fixture(scope="module")
def ref():
    return read_log(SRC)


def _foreign_table(ref, path: Path) -> Path:
    """The log as a second facility writes it: 4 preamble lines, no header, whitespace, columns
    time x y psi[deg] ue ve (earth-fixed) r[deg/s] delta[deg, positive to port] n[rpm], plus a
    column of junk flags in column 10."""
    psi = ref["psi"]
    ue = ref["u"] * np.cos(psi) - ref["v"] * np.sin(psi)
    ve = ref["u"] * np.sin(psi) + ref["v"] * np.cos(psi)
    cols = [ref.time, ref["x"], ref["y"], np.degrees(psi), ue, ve, np.degrees(ref["r"]), -np.degrees(ref["delta"]),
            ref["n"] * 60.0, np.arange(len(ref)) % 2]
    lines = ["Facility X free-running test", "model 4.36 m, run 17", "", "  t  x  y  psi  u  v  r  delta  rpm  flag"]
    lines[2] = "-------------------------------------------"
    lines += ["  ".join(repr(float(v)) for v in row) for row in zip(*cols)]
    path.write_text("\n".join(lines) + "\n")
    return path


TABLE_SCHEMA = {"columns": {"time": 1, "x": 2, "y": 3, "psi": 4, "u": 5, "v": 6, "r": 7, "delta": 8, "n": 9},
                "units": {"psi": "deg", "r": "deg/s", "delta": "deg", "n": "rpm"},
                "velocity_frame": "earth", "rudder_sign": -1, "skip_rows": 4, "header": False,
                "delimiter": "whitespace"}


def _same(log, ref):
    for c in ("x", "y", "psi", "u", "v", "r", "delta", "n"):
        np.testing.assert_allclose(log[c], ref[c], rtol=1e-12, atol=1e-12, err_msg=c)
    np.testing.assert_allclose(log.time, ref.time, rtol=0, atol=1e-12)


def test_generic_table_read_with_options(ref, tmp_path):
    p = _foreign_table(ref, tmp_path / "run17.txt")
    log = read_log(p, lpp=4.36, **{k: v for k, v in TABLE_SCHEMA.items()})
    _same(log, ref)
    assert "col10" in log.channels          # the unmapped numeric column travels as an extra channel
    assert log.rows[0] == 5                 # file line numbers count the skipped preamble
    assert any("earth-fixed" in n for n in log.notes) and any("multiplied by -1" in n for n in log.notes)
    # the same through a schema file, JSON and YAML
    sj = tmp_path / "facility_x.json"
    sj.write_text(json.dumps(TABLE_SCHEMA))
    _same(read_log(p, schema=sj, lpp=4.36), ref)
    yaml = pytest.importorskip("yaml", reason="PyYAML not installed: YAML schema files untested")
    sy = tmp_path / "facility_x.yaml"
    sy.write_text(yaml.safe_dump(TABLE_SCHEMA))
    _same(read_log(p, schema=sy, lpp=4.36), ref)


def test_generic_table_errors_say_what_to_do(ref, tmp_path):
    p = _foreign_table(ref, tmp_path / "run17.txt")
    with pytest.raises(LogError, match=r"`run17.txt`: skip_rows = 5000 but the file has only \d+ line\(s\)"):
        read_log(p, **{**TABLE_SCHEMA, "skip_rows": 5000})
    # no header but no numbers either: the channels cannot be found by name
    kw = {**TABLE_SCHEMA}
    kw.pop("columns")
    with pytest.raises(LogError, match=r"required column 'time' not found; header has 'col1', 'col2'"):
        read_log(p, **kw)
    # the numeric first line of a header-less file, read with a header: says --no-header
    q = tmp_path / "numbers.csv"
    q.write_text("\n".join(",".join(str(float(v)) for v in range(9)) for _ in range(30)) + "\n")
    with pytest.raises(LogError, match=r"the first line is numbers, not a header .*or pass header=False "
                                       r"\(CLI: --no-header\) and map the columns by number"):
        read_log(q)
    with pytest.raises(ValueError, match=r"velocity_frame = 'ship'; use 'body'"):
        read_log(p, velocity_frame="ship")
    with pytest.raises(ValueError, match=r"rudder_sign = 2; use \+1"):
        read_log(p, rudder_sign=2)


def test_earth_frame_needs_heading(ref, tmp_path):
    text = SRC.read_text().replace("psi [rad]", "heading [rad]")
    p = tmp_path / "nopsi.csv"
    p.write_text(text)
    with pytest.raises(LogError, match=r"velocity_frame='earth' needs u, v and psi .* missing \['psi'\]"):
        read_log(p, velocity_frame="earth")


def test_schema_files_are_checked(tmp_path):
    bad = tmp_path / "s.json"
    bad.write_text(json.dumps({"columns": {"u": 5}, "frame": "earth"}))
    with pytest.raises(ValueError, match=r"`s.json`: unknown key\(s\) \['frame'\]; known keys are \['name', 'fmt', "):
        load_schema(bad)
    bad.write_text(json.dumps({"columns": {"u": "surge"}, "header": False}))
    with pytest.raises(ValueError, match=r"header = false but columns \['u'\] are given by name; give column numbers"):
        load_schema(bad)
    bad.write_text(json.dumps({"columns": {"u": [5]}}))
    with pytest.raises(ValueError, match=r"columns\['u'\] = \[5\]; give a column name or a 1-based number"):
        load_schema(bad)
    bad.write_text("[" * 100_000 + "]" * 100_000)
    with pytest.raises(ValueError, match=r"`s.json`: nested more than 64 levels deep; not a schema file"):
        load_schema(bad)
    with pytest.raises(ValueError, match=r"schema 'esso': not a preset \(shipid, marin, esso-frt\)"):
        load_schema("esso")
    assert load_schema("esso-frt") is PRESETS["esso-frt"]
    assert isinstance(load_schema({"columns": {"u": 5}}), Schema)


def test_schema_arguments_override_per_channel(ref, tmp_path):
    """columns=/units= given with a schema replace only the channels they name."""
    p = _foreign_table(ref, tmp_path / "run17.txt")
    sj = tmp_path / "x.json"
    sj.write_text(json.dumps({**TABLE_SCHEMA, "units": {**TABLE_SCHEMA["units"], "n": "rps"}}))
    with pytest.raises(LogError, match="looks like rpm"):
        read_log(p, schema=sj, lpp=4.36)
    _same(read_log(p, schema=sj, lpp=4.36, units={"n": "rpm"}), ref)


def _cli(argv):
    from shipid.cli import main

    return main(argv)


def test_cli_reads_the_table_with_the_same_options(ref, tmp_path, capsys):
    p = _foreign_table(ref, tmp_path / "run17.txt")
    out = tmp_path / "clean.csv"
    argv = ["log", str(p), "--skip-rows", "4", "--no-header", "--delimiter", "whitespace",
            "--columns", "time=1,x=2,y=3,psi=4,u=5,v=6,r=7,delta=8,n=9",
            "--units", "psi=deg,r=deg/s,delta=deg,n=rpm", "--velocity-frame", "earth", "--rudder-sign", "-1",
            "--lpp", "4.36", "-o", str(out)]
    assert _cli(argv) == 0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        _same(read_log(out), ref)
    sj = tmp_path / "facility_x.json"
    sj.write_text(json.dumps(TABLE_SCHEMA))
    assert _cli(["log", str(p), "--schema", str(sj), "--lpp", "4.36"]) == 0
    assert "rudder angle multiplied by -1" in capsys.readouterr().out
    # a unit given twice: error, exit 2, one line
    assert _cli(["log", str(SRC), "--units", "psi=deg,psi=rad"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "--units: 'psi' is given twice (psi=deg and psi=rad); give it once" in err


@pytest.mark.parametrize("command", ["fit", "metrics", "validate", "report"])
def test_every_log_reading_command_has_the_options(command, capsys):
    from shipid.cli import build_parser

    text = build_parser()._subparsers._group_actions[0].choices[command].format_help()
    for opt in ("--schema", "--skip-rows", "--no-header", "--velocity-frame", "--rudder-sign", "--units",
                "--columns", "--delimiter", "--lpp", "--ship"):
        assert opt in text, (command, opt)


def test_ship_file_usual_symbols(tmp_path):
    from shipid.logs import read_ship

    p = tmp_path / "ship.json"
    p.write_text(json.dumps({"name": "Esso Osaka", "Lpp": 3.0, "B": 0.489, "d": 0.201, "Cb": 0.83, "m": 244.6,
                             "xG": 0.094, "D_p": 0.084, "A_R": 0.0106, "A_T": 0.135, "A_L": 0.52}))
    s = read_ship(p)
    assert (s.lpp, s.beam, s.draught, s.block_coefficient, s.mass, s.x_g, s.propeller_diameter, s.rudder_area,
            s.transverse_area, s.lateral_area) == (3.0, 0.489, 0.201, 0.83, 244.6, 0.094, 0.084, 0.0106, 0.135, 0.52)
    p.write_text(json.dumps({"lpp": 3.0, "x_G": -0.5}))
    assert read_ship(p).x_g == -0.5          # x_G may be negative (aft of midship)
    p.write_text(json.dumps({"lpp": 3.0, "keel": 1}))
    with pytest.raises(ValueError, match=r"`ship.json`: unknown field\(s\) \['keel'\]; known fields are \['lpp', "):
        read_ship(p)
    assert math.isclose(read_log(SRC).ship.lpp, 4.36)
