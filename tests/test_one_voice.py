"""One voice: what the README's fits, the demo and ``shipid models`` print, and the demo's reports, is one line
per finding of at most ~300 characters, with no internal names, raw solver strings, unrounded floats or
references to documents outside the repository."""
from __future__ import annotations

import re
from pathlib import Path

import pytest

from shipid.cli import main

ROOT = Path(__file__).parents[1]
DATA = ROOT / "data"
MARIN = ROOT.parent / "shared" / "data" / "kvlcc2_marin"

#: what user output must not contain (internal names, solver strings, documents not in the repository)
BANNED = [r"DEFAULT_START", r"DEFAULT_[A-Z]+", r"termination condition", r"`ftol`", r"`xtol`", r"every 1\. sample",
          r"every \d+\. sample", r"SPEC\.md", r"\bseed 00\d", r"\bseed-00\d", r"\bsession \d+", r"\bsessions? \d",
          r"\d\.\d{9,}"]   # a float printed with all its digits (e.g. 0.9040235294117647)


def _check(text: str, where: str, *, line_limit: int | None = 300) -> None:
    for pat in BANNED:
        m = re.search(pat, text)
        assert m is None, f"{where}: '{m.group(0)}' in ...{text[max(0, m.start() - 80):m.end() + 80]}..."
    if line_limit:
        long = [ln for ln in text.splitlines() if len(ln) > line_limit]
        assert not long, f"{where}: {len(long)} line(s) over {line_limit} characters, first: {long[0][:120]}..."


def _lines_once_per_kind(text: str) -> None:
    """No two warning lines of the same kind (the same first six words)."""
    heads = [" ".join(ln.split()[:6]) for ln in text.splitlines() if ln.startswith(("warning:", "note:"))]
    dup = {h for h in heads if heads.count(h) > 1 and not h.startswith("note: ") }
    assert not dup, dup


def test_readme_fit_on_the_bundled_logs_speaks_with_one_voice(tmp_path, capsys):
    rc = main(["fit", str(DATA / "kcs_tc_p35.csv"), str(DATA / "kcs_zz_m10.csv"), "--model", "kcs-response",
               "--lpp", "4.36", "-o", str(tmp_path / "result.json"), "--no-progress"])
    cap = capsys.readouterr()
    assert rc == 0, cap.err
    _check(cap.out + cap.err, "shipid fit (README, bundled logs)")
    _lines_once_per_kind(cap.err)
    assert "verdict: " in cap.out
    # the report of that fit
    rep = tmp_path / "report.html"
    assert main(["report", str(tmp_path / "result.json"), str(DATA / "kcs_tc_p35.csv"), "-o", str(rep),
                 "--no-progress"]) in (0, 1)
    cap = capsys.readouterr()
    _check(cap.out + cap.err, "shipid report")
    html = re.sub(r"<[^>]+>", " ", rep.read_text())
    html = re.sub(r"data:image/[^ \"]+", "", html)
    _check(html, "report.html", line_limit=None)
    assert "Verdict: " in rep.read_text()


def test_shipid_models_names_no_internal_documents(capsys):
    assert main(["models"]) == 0
    _check(capsys.readouterr().out, "shipid models", line_limit=None)


@pytest.mark.slow
def test_the_demo_speaks_with_one_voice(tmp_path, capsys):
    out = tmp_path / "demo"
    assert main(["demo", "-o", str(out), "--no-progress"]) == 0
    cap = capsys.readouterr()
    _check(cap.out + cap.err, "shipid demo")
    assert "16/16 coefficients within 3 sigma" in cap.out
    for name in ("report_known_truth.html", "report.html"):
        html = re.sub(r"<[^>]+>", " ", (out / name).read_text())
        _check(html, name, line_limit=None)


@pytest.mark.slow
@pytest.mark.skipif(not MARIN.is_dir(), reason=f"MARIN KVLCC2 data not found at {MARIN}")
@pytest.mark.parametrize("model", ["mmg", "response-nl", "kcs-response"])
def test_readme_marin_fits_speak_with_one_voice_and_are_no_defect(tmp_path, capsys, model):
    files = [str(MARIN / f"MARIN_FREE_KVLCC2_{k}_m.dat") for k in ("tc_35", "tc_-35", "zz_10", "zz_-10")]
    rc = main(["fit", *files, "--model", model, "-o", str(tmp_path / "r.json"), "--no-progress"])
    cap = capsys.readouterr()
    _check(cap.out + cap.err, f"shipid fit {model} (MARIN)")
    _lines_once_per_kind(cap.err)
    assert rc == 0, cap.err
