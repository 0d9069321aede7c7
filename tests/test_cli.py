"""The CLI: `shipid fit` on good and bad input, `shipid models`, `shipid demo`.

Every bad-input case must exit with code 2, print ONE line on stderr naming the
file (and the column and row where that applies) with the value, leave the
input bytes unchanged and write no output."""
from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from shipid.cli import main
from shipid.datasets import bundled_kcs_logs

SRC = {p.stem: p for p in bundled_kcs_logs()}


def _lines(path: Path) -> list[str]:
    return path.read_text().splitlines()


def _write(tmp_path, name, lines=None, data=None) -> Path:
    p = tmp_path / name
    if data is not None:
        p.write_bytes(data)
    else:
        p.write_text("\n".join(lines) + "\n")
    return p


def _base(tmp_path):
    """The bundled 10/10 zigzag: comment lines, header, data (header is line 3)."""
    lines = _lines(SRC["kcs_zz_m10"])
    assert lines[2].startswith("time [s]")
    return lines


def _case_missing_column(tmp_path):
    lines = [",".join(c for i, c in enumerate(l.split(",")) if i != 8) if not l.startswith("#") else l
             for l in _base(tmp_path)]
    return _write(tmp_path, "non.csv", lines), ["non.csv", "'n'", "row"]


def _case_non_numeric(tmp_path):
    lines = _base(tmp_path)
    f = lines[40].split(",")
    f[4] = "1.7O"  # letter O typed for zero
    lines[40] = ",".join(f)
    return _write(tmp_path, "typo.csv", lines), ["typo.csv", "column 'u", "row 41", "1.7O"]


def _case_time_not_increasing(tmp_path):
    lines = _base(tmp_path)
    lines[100], lines[101] = lines[101], lines[100]
    return _write(tmp_path, "swap.csv", lines), ["swap.csv", "column 'time'", "row 102"]


def _case_empty(tmp_path):
    return _write(tmp_path, "empty.csv", data=b""), ["empty.csv", "empty"]


def _case_header_only(tmp_path):
    return _write(tmp_path, "head.csv", _base(tmp_path)[:3]), ["head.csv", "no data rows"]


def _case_too_few_samples(tmp_path):
    return _write(tmp_path, "short.csv", _base(tmp_path)[:10]), ["short.csv", "7 sample", "at least"]


def _case_wrong_delimiter(tmp_path):
    lines = [l.replace(",", ";") if not l.startswith("#") else l for l in _base(tmp_path)]
    return _write(tmp_path, "semi.csv", lines), ["semi.csv", "row 3", "semicolon", "--delimiter"]


def _case_binary_garbage(tmp_path):
    rng = np.random.default_rng(0)
    return _write(tmp_path, "blob.csv", data=rng.integers(0, 256, 4096, dtype=np.uint8).tobytes()), ["blob.csv", "binary"]


def _case_absurd_value(tmp_path):
    lines = _base(tmp_path)
    f = lines[500].split(",")
    f[4] = "1e308"
    lines[500] = ",".join(f)
    return _write(tmp_path, "absurd.csv", lines), ["absurd.csv", "column 'u'", "row 501", "1e+308"]


def _case_degrees_declared_radians(tmp_path):
    lines = _base(tmp_path)
    out = lines[:3]
    for l in lines[3:]:
        f = l.split(",")
        f[3] = repr(float(f[3]) * 180 / np.pi + 90.0)  # a compass heading in degrees
        out.append(",".join(f))
    return _write(tmp_path, "deg.csv", out), ["deg.csv", "column 'psi'", "row 4", "degrees", "psi=deg"]


def _case_missing_file(tmp_path):
    return tmp_path / "nothere.csv", ["nothere.csv", "does not exist"]


def _case_input_gap(tmp_path):
    lines = _base(tmp_path)
    f = lines[200].split(",")
    f[7] = ""
    lines[200] = ",".join(f)
    return _write(tmp_path, "gap.csv", lines), ["gap.csv", "column 'delta'", "row 201", "--interpolate-inputs"]


BAD = [_case_missing_column, _case_non_numeric, _case_time_not_increasing, _case_empty, _case_header_only,
       _case_too_few_samples, _case_wrong_delimiter, _case_binary_garbage, _case_absurd_value,
       _case_degrees_declared_radians, _case_missing_file, _case_input_gap]


@pytest.mark.parametrize("case", BAD, ids=[c.__name__[6:] for c in BAD])
def test_bad_input_exit_2_one_line_named_and_input_untouched(case, tmp_path, capsys):
    path, needles = case(tmp_path)
    before = path.read_bytes() if path.exists() else None
    out = tmp_path / "result.json"
    rc = main(["fit", str(path), "-o", str(out), "--no-progress"])
    err = capsys.readouterr().err.strip()
    assert rc == 2
    assert len(err.splitlines()) == 1, err
    assert "Traceback" not in err
    for n in needles:
        assert n in err, f"{n!r} not in: {err}"
    assert not out.exists()
    if before is not None:
        assert path.read_bytes() == before


def test_fit_writes_result_and_refuses_to_overwrite(tmp_path, capsys):
    out = tmp_path / "r.json"
    args = ["fit", str(SRC["kcs_zz_m10"]), "--estimate", "c1,c2,c3", "--passes", "1", "-o", str(out), "--no-progress"]
    assert main(args) == 0
    doc = json.loads(out.read_text())
    assert doc["model"] == "kcs-response" and set(doc["cov"]["names"]) == {"c1", "c2", "c3"}
    assert doc["inputs"][0]["sha256"] and doc["inputs"][0]["path"].endswith("kcs_zz_m10.csv")
    from shipid.models import get_model

    c3 = float(get_model("kcs-response", "synthetic-truth").params_series()["c3"])
    assert abs(doc["coef"]["c3"] - c3) < 3 * doc["coef_std"]["c3"]
    text = capsys.readouterr().out
    assert "c3" in text and "wrote" in text
    before = out.read_bytes()
    assert main(args) == 2
    assert "--force" in capsys.readouterr().err
    assert out.read_bytes() == before


def test_fit_with_measured_gap_reports_rows_and_succeeds(tmp_path, capsys):
    lines = _lines(SRC["kcs_zz_m10"])
    for k in range(300, 320):
        f = lines[k].split(",")
        f[6] = ""  # r missing
        lines[k] = ",".join(f)
    p = _write(tmp_path, "gappy.csv", lines)
    out = tmp_path / "g.json"
    assert main(["fit", str(p), "--estimate", "c2,c3", "--passes", "1", "-o", str(out), "--no-progress"]) == 0
    err = capsys.readouterr().err
    assert "missing samples" in err and "r 20" in err and "301" in err


def test_fit_usage_errors_exit_2(tmp_path, capsys):
    assert main(["fit", str(SRC["kcs_zz_m10"])]) == 2  # no -o
    assert main(["fit", str(SRC["kcs_zz_m10"]), "-o", str(tmp_path / "x.json"), "--model", "nope"]) == 2
    assert "unknown model 'nope'" in capsys.readouterr().err
    assert main(["fit", str(SRC["kcs_zz_m10"]), "-o", str(tmp_path / "x.json"), "--units", "psi"]) == 2
    assert main(["fit", str(SRC["kcs_zz_m10"]), "-o", str(tmp_path / "x.json"), "--fixed", "zz=1"]) == 2


def test_models_lists_kcs_response(capsys):
    assert main(["models"]) == 0
    out = capsys.readouterr().out
    assert "kcs-response" in out and "a1" in out and "table3" in out


@pytest.mark.slow
def test_demo_runs_and_recovers_the_truth(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert main(["demo"]) == 0
    out = capsys.readouterr().out
    assert "16/16 coefficients within 3 sigma" in out
    (folder,) = list(tmp_path.glob("shipid-demo-*"))
    for f in ("result.json", "coefficients.csv", "replay_rmse.csv", "replay.png", "report_known_truth.html",
              "report.html"):
        assert (folder / f).stat().st_size > 0
    # each report says what it demonstrates
    part1 = (folder / "report_known_truth.html").read_text()
    assert "known coefficients" in part1 and "16/16 coefficients are within 3 standard deviations" in part1
    assert "cannot represent exactly" in (folder / "report.html").read_text()


def test_fit_meas_std_option_reaches_the_filter(tmp_path):
    out = tmp_path / "m.json"
    # exit 3 is allowed: noise levels set by hand that differ from the data's may make the consistency
    # verdict say so; this test is about the option reaching the filter
    assert main(["fit", str(SRC["kcs_zz_m10"]), "--estimate", "c2", "--passes", "1", "--meas-std", "v=0.001,r=0.0005",
                 "-o", str(out), "--no-progress"]) in (0, 3)
    ms = json.loads(out.read_text())["settings"]["meas_std"]
    assert ms["v"] == 0.001 and ms["r"] == 0.0005


def test_fit_noise_not_estimable_names_the_cli_option(tmp_path, capsys, monkeypatch):
    import shipid.identify.identifier as ident

    monkeypatch.setattr(ident, "noise_std_from_data", lambda arrays: np.zeros(6))
    rc = main(["fit", str(SRC["kcs_zz_m10"]), "--estimate", "c2", "-o", str(tmp_path / "x.json"), "--no-progress"])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and "--meas-std CH=STD" in err and "meas_std={" not in err and len(err.splitlines()) == 1


@pytest.mark.parametrize("bad,needle", [("v=abc", "'abc' is not a valid value"), ("v=-1", "positive standard deviation"),
                                        ("v", "NAME=VALUE")])
def test_fit_meas_std_bad_values(bad, needle, tmp_path, capsys):
    assert main(["fit", str(SRC["kcs_zz_m10"]), "--meas-std", bad, "-o", str(tmp_path / "x.json")]) == 2
    err = capsys.readouterr().err
    assert "--meas-std" in err and needle in err


@pytest.mark.parametrize("argv,needle", [
    (["fit", "{log}", "-o", "{log}", "--force"], "would replace the input file"),
    (["fit", "{log}", "--model", "{res}", "-o", "{res}", "--force"], "would replace the input file"),
    (["metrics", "{log}", "-o", "{log}", "--force"], "would replace the input file"),
    (["simulate", "{res}", "--turning", "35", "-o", "{res}", "--force"], "would replace the input file"),
    (["fit", "{log}", "-o", ""], "empty file name"),
    (["fit", "{log}", "-o", "{tmp}"], "is a folder"),
    (["fit", "{log}", "-o", "{tmp}/nofolder/r.json"], "does not exist"),
    (["fit", "{log}", "--fixed", "a8=nan", "-o", "{tmp}/r.json"], "finite value"),
    (["fit", "{log}", "--fixed", "a8=ten", "-o", "{tmp}/r.json"], "'ten' is not a number"),
    (["fit", "{log}", "--lpp", "0", "-o", "{tmp}/r.json"], "--lpp 0"),
    (["simulate", "mmg:kvlcc2", "--turning", "35", "--lpp", "0"], "--lpp 0"),
    (["simulate", "mmg:kvlcc2", "--turning", "nan"], "--turning nan"),
    (["simulate", "mmg:kvlcc2", "--turning", "35", "--speed", "-1"], "--speed -1"),
    (["sweep", "mmg:kcs", "--rudder", "nan"], "finite numbers"),
    (["metrics", "{log}", "--reference-offset", "nan"], "--reference-offset nan"),
    (["metrics", "{log}", "--lpp", "-3"], "--lpp -3"),
])
def test_cli_option_and_output_errors(argv, needle, tmp_path, capsys):
    res = tmp_path / "res.json"
    res.write_text(json.dumps({"model": "kcs-response", "coef": {"c3": 0.2}}))
    log = tmp_path / "log.csv"
    log.write_bytes(SRC["kcs_zz_m10"].read_bytes())
    before = {p: p.read_bytes() for p in tmp_path.iterdir() if p.is_file()}
    argv = [a.format(log=log, res=res, tmp=tmp_path) for a in argv]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and needle in err and len(err) <= 300, err
    assert {p: p.read_bytes() for p in tmp_path.iterdir() if p.is_file()} == before


def test_divergence_warning_is_one_plain_sentence(capsys):
    import warnings

    from shipid.cli import _show_warning

    old = warnings.showwarning
    warnings.showwarning = _show_warning("shipid fit")
    try:
        warnings.warn("EKF identification: the filter diverged at t = 12 s", RuntimeWarning)
    finally:
        warnings.showwarning = old
    err = capsys.readouterr().err
    assert err == "shipid fit: warning: EKF identification: the filter diverged at t = 12 s\n"


def test_long_error_messages_are_cut_to_300_characters(tmp_path, capsys):
    log = tmp_path / "l.csv"
    log.write_bytes(SRC["kcs_zz_m10"].read_bytes())
    assert main(["fit", str(log), "--fixed", "a" * 5000 + "=1", "-o", str(tmp_path / "r.json")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err) <= 300 and err.startswith("shipid fit: error:") and "\n" not in err


def test_models_lists_meanings_and_units(capsys):
    assert main(["models"]) == 0
    out = capsys.readouterr().out
    assert "u [m/s]" in out and "delta [rad]" in out and "n [rps]" in out


def test_models_kcs_equation_text_matches_the_model():
    """The equations `shipid models` prints for kcs-response are the model's (evaluated and compared)."""
    from shipid.commands.models import PARAMETER_NOTES
    from shipid.models import get_model

    m = get_model("kcs-response", "synthetic-truth")
    rng = np.random.default_rng(1)
    x = rng.normal(size=6)
    u = rng.normal(size=2)
    env = {**dict(zip(m.param_names, m.params)), **dict(zip(m.state_names, x)), **dict(zip(m.input_names, u))}
    text = PARAMETER_NOTES["kcs-response"].rsplit(" (", 1)[0]
    got = {}
    for eq in text.split(";"):
        lhs, rhs = eq.split("=")
        expr = re.sub(r"(?<=[\w)])\s+(?=[\w(])", "*", rhs.strip().replace("^", "**"))  # implicit products
        got[lhs.strip()] = eval(expr, {}, env)
    f = m.rhs(0.0, x, u)
    np.testing.assert_allclose([got["du/dt"], got["dv/dt"], got["dr/dt"]], f[3:], rtol=1e-12)
