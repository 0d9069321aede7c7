"""shipid.report: the self-contained HTML validation report.

The report of a real (small) EKF fit is parsed: tags balance, the expected sections and numbers are
there, every image is an embedded PNG, nothing points outside the file, user text is escaped; it is
written atomically and never overwrites without force; and it renders in headless Chromium (Debian
package ``chromium``) to a non-blank screenshot when the browser is installed.
"""
from __future__ import annotations

import base64
import hashlib
import html
import io
import os
import re
import subprocess
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest

from shipid._io import OutputExistsError
from shipid.cli import main
from shipid.datasets import bundled_kcs_logs
from shipid.identify import EKFIdentifier
from shipid.logs import TrialLog, read_log
from shipid.models import get_model
from shipid.report import write_report

PATHS = {p.stem: p for p in bundled_kcs_logs()}
CHROMIUM = Path("/usr/bin/chromium")
EST = ["b1", "b2", "b3", "b4", "c1", "c2", "c3"]
EVIL = "<script>alert('x')</script>&zz"
VOID = {"meta", "img", "br", "hr", "link", "input", "col", "area", "base", "wbr", "source"}


class _Doc(HTMLParser):
    """Collects tags, attributes, ids and text; checks that non-void tags nest and close properly."""

    def __init__(self):
        super().__init__(convert_charrefs=True)
        self.stack, self.tags, self.attrs, self.ids, self.text, self.errors = [], [], [], set(), [], []

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        self.tags.append(tag)
        self.attrs.append((tag, a))
        if "id" in a:
            self.ids.add(a["id"])
        if tag not in VOID:
            self.stack.append(tag)

    def handle_startendtag(self, tag, attrs):
        self.handle_starttag(tag, attrs)
        if tag not in VOID:
            self.stack.pop()

    def handle_endtag(self, tag):
        if not self.stack or self.stack[-1] != tag:
            self.errors.append(f"</{tag}> closes {self.stack[-1:] or 'nothing'}")
        else:
            self.stack.pop()

    def handle_data(self, data):
        self.text.append(data)


def _parse(text: str) -> _Doc:
    d = _Doc()
    d.feed(text)
    d.close()
    return d


@pytest.fixture(scope="module")
def fitted():
    """A quick real fit: the yaw/sway coefficients from one zigzag, one EKF pass (the surge ones held)."""
    log = read_log(PATHS["kcs_zz_p20_rpm"])
    truth = get_model("kcs-response", "synthetic-truth")
    rng = np.random.default_rng(1)
    start = truth.with_params({k: v * (1 + 0.2 * rng.standard_normal()) if k in EST else v
                               for k, v in zip(truth.param_names, truth.params)})
    ident = EKFIdentifier(start, estimate=EST, n_passes=1, progress=False).fit([log])
    return ident, log


@pytest.fixture(scope="module")
def report(fitted, tmp_path_factory):
    ident, log = fitted
    held = read_log(PATHS["kcs_tc_p35"])
    cols = {c: held.data[c].to_numpy() for c in held.channels}
    evil = TrialLog.from_arrays(held.time, name=EVIL, ship=held.ship, **cols)  # in memory, hostile name
    path = tmp_path_factory.mktemp("report") / "report.html"
    write_report(ident.result(), [log, evil], path, identifier=ident, title="Test report")
    return path, ident


def test_report_structure_and_content(report):
    path, ident = report
    text = path.read_text(encoding="utf-8")
    doc = _parse(text)
    assert doc.errors == [] and doc.stack == [], (doc.errors, doc.stack)
    for sec in ("summary", "imo", "coefficients", "identifiability", "model", "logs", "inputs", "versions",
                "log1", "log2"):
        assert sec in doc.ids, sec
    plain = " ".join(doc.text)
    res = ident.result()
    # coefficient table: every estimated coefficient with its value, sigma and 95 % interval
    for name in EST:
        v, sd = res.coef[name], res.coef_std[name]
        row = re.search(rf'<tr><td class="l">{name}</td><td class="l">([^<]*)</td>((?:<td>[^<]*</td>)+)</tr>', text)
        assert row, name
        assert html.unescape(row.group(1)) == UNITS[name], name  # every coefficient with its SI unit
        cells = [float(c) for c in re.findall(r"<td>([^<]*)</td>", row.group(2))]
        # value, sigma, CI low, CI high, relative sigma [%]
        np.testing.assert_allclose(cells[:4], [v, sd, v - 1.96 * sd, v + 1.96 * sd], rtol=5.01e-3)  # 3-5 significant digits
        assert cells[4] == pytest.approx(100 * sd / abs(v), abs=0.051)  # printed with one decimal
    assert "relative σ [%]" in plain and "95 % CI low" in plain
    # identifiability: condition number and each warning of the fit
    assert f"{res.diagnostics['condition_number']:.3g}" in plain
    for w in res.diagnostics["warnings"]:
        assert w in plain
    # IMO table: the 20/20 zigzag's first-overshoot criterion, measured and predicted verdicts
    assert "overshoot1 [deg]" in plain and "tactical diameter [L]" in plain
    assert plain.count("pass") + plain.count("FAIL") >= 6
    # inputs: the fitted log with its sha256; the in-memory held-out log; versions
    assert log_sha(PATHS["kcs_zz_p20_rpm"]) in plain
    assert "(in memory)" in plain
    assert "Held out" in plain
    for pkg in ("shipid", "numpy", "scipy", "pandas", "matplotlib"):
        assert pkg in plain
    assert "kcs-response" in plain and "ekf" in plain
    # figures: correlation heat-map + per log time series, track, residuals; innovations for the fitted log only
    alts = [a.get("alt", "") for t, a in doc.attrs if t == "img"]
    assert sum(a.startswith("innovations") for a in alts) == 1
    assert "correlation heat-map" in alts
    for kind in ("time series", "track", "residuals"):
        assert sum(a.startswith(kind) for a in alts) == 2, kind
    assert "was not part of the identifier" in plain


def test_report_reads_as_a_hand_over_document(fitted, tmp_path):
    """Default title naming the ship and the logs' folder, a plain-language summary first, one sentence under
    each section heading, no markup or Python reprs, and tracks in metres only."""
    ident, log = fitted
    path = tmp_path / "r.html"
    write_report(ident.result(), [PATHS["kcs_zz_p20_rpm"], PATHS["kcs_tc_p35"]], path, identifier=ident)
    text = path.read_text(encoding="utf-8")
    doc = _parse(text)
    title = re.search(r"<h1>([^<]*)</h1>", text).group(1)
    assert html.unescape(title) == "KCS model 1:52.67 — kcs-response model on 2 log(s) from data"
    intro = re.search(r'</h1>\s*<div class="verdict"[^>]*>.*?</div>\s*<p class="intro">([^<]*)</p>', text, re.S)
    assert intro, "the verdict banner follows the title, then the summary paragraph"
    summary = html.unescape(intro.group(1))
    assert summary.startswith("This report checks a kcs-response model fitted by an extended Kalman filter to 1 "
                              "log(s) (kcs_zz_p20_rpm), estimating 7 of its 16 coefficients.")
    assert "median track error of" in summary and "(1 not used in the fit)" in summary
    for sec in re.findall(r"<h2 [^>]*>[^<]*</h2>(.{0,12})", text):
        assert sec.startswith("<p"), sec  # each section opens with a sentence
    plain = " ".join(doc.text)
    assert ":func:" not in plain and "{'" not in plain and "``" not in plain
    tracks = re.findall(r'alt="track [^"]*"', text)
    assert len(tracks) == 2


#: The unit column's text for each kcs-response coefficient: the model's SI unit, "–" when non-dimensional.
UNITS = {k: "–" if u in ("-", "1") else u.replace("^2", "²") for k, u in get_model("kcs-response").units.items()}


def test_model_label_and_plain_text():
    from shipid.environment import with_environment
    from shipid.report.html import _options_text, model_label, plain

    class R:
        model = "with-environment"
    env = with_environment(get_model("lowspeed"), wind="esso-osaka-3m", current="constant")
    assert model_label(R(), env) == "lowspeed with wind and current"
    assert plain("Wind and current as parts of the model protocol: :func:`with_environment` / "
                 ":class:`~shipid.environment.model.EnvironmentModel`.") == (
        "Wind and current as parts of the model protocol: with_environment / EnvironmentModel.")
    assert _options_text({"lpp": 3.0, "wind": {"kind": "fujiwara", "AL": 0.5}, "current": True}) == (
        "lpp: 3; wind: (kind fujiwara, AL 0.5); current: True")


def log_sha(p: Path) -> str:
    return hashlib.sha256(p.read_bytes()).hexdigest()


def test_report_is_self_contained(report):
    path, _ = report
    text = path.read_text(encoding="utf-8")
    doc = _parse(text)
    imgs = [a for t, a in doc.attrs if t == "img"]
    assert len(imgs) >= 8
    for a in imgs:
        src = a["src"]
        assert src.startswith("data:image/png;base64,"), src[:60]
        png = base64.b64decode(src.split(",", 1)[1], validate=True)
        assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 2000
    for t, a in doc.attrs:
        for key in ("src", "href", "action", "data"):
            val = a.get(key)
            if val is not None:
                assert not re.match(r"\s*(https?:|//|ftp:|file:)", val, re.I), (t, key, val[:80])
                assert key != "href" or val.startswith("#"), val
    assert not {"script", "link", "iframe", "object", "embed"} & set(doc.tags)
    assert "url(" not in text and "@import" not in text
    assert not re.search(r"https?://", text)


def test_user_text_is_escaped(report):
    path, _ = report
    text = path.read_text(encoding="utf-8")
    assert "<script" not in text
    assert "&lt;script&gt;alert(&#x27;x&#x27;)&lt;/script&gt;&amp;zz" in text
    assert EVIL in " ".join(_parse(text).text)


def test_report_never_overwrites_without_force(report, fitted):
    path, ident = report
    before = path.read_bytes()
    with pytest.raises(OutputExistsError, match="force"):
        write_report(ident.result(), [fitted[1]], path)
    assert path.read_bytes() == before
    leftovers = [p for p in path.parent.iterdir() if p.name.startswith(".report.html.")]
    assert leftovers == []


def test_cli_report(tmp_path, capsys, fitted):
    ident, _ = fitted
    r = ident.result().to_json(tmp_path / "result.json")
    out = tmp_path / "report.html"
    log = str(PATHS["kcs_zz_m10"])
    assert main(["report", str(r), log, "-o", str(out), "--title", "CLI report"]) == 0
    text = out.read_text(encoding="utf-8")
    assert "<title>CLI report</title>" in text and "kcs_zz_m10" in text
    assert _parse(text).errors == []
    capsys.readouterr()
    before = out.read_bytes()
    assert main(["report", str(r), log, "-o", str(out)]) == 2  # exists, no --force
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "report.html" in err[0] and "--force" in err[0]
    assert out.read_bytes() == before
    assert main(["report", str(tmp_path / "missing.json"), log, "-o", str(tmp_path / "x.html")]) == 2
    assert len(capsys.readouterr().err.strip().splitlines()) == 1
    assert not (tmp_path / "x.html").exists()


def test_report_renders_in_headless_chromium(report, tmp_path):
    if not CHROMIUM.exists():
        msg = "headless Chromium not installed (/usr/bin/chromium; Debian: apt-get install chromium)"
        if os.environ.get("CI"):
            pytest.fail(f"{msg}; CI is set, so the browser test must run (.ci/run installs it)")
        pytest.skip(msg)
    from PIL import Image

    path, _ = report
    shot = tmp_path / "shot.png"
    cmd = [str(CHROMIUM), "--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
           "--disable-component-update", "--disable-sync", "--no-first-run", f"--user-data-dir={tmp_path / 'ud'}",
           f"--screenshot={shot}", "--window-size=1200,3000", path.resolve().as_uri()]
    proc = subprocess.run(cmd, capture_output=True, timeout=120)
    assert shot.exists(), proc.stderr.decode(errors="replace")[-2000:]
    assert shot.stat().st_size > 50_000
    im = np.asarray(Image.open(io.BytesIO(shot.read_bytes())).convert("L"), dtype=float)
    assert im.shape == (3000, 1200)
    dark = im < 200
    assert dark.mean() > 0.02, "screenshot is (nearly) blank"
    # content all the way down the page (tables, then figures), not one small block
    rows_with_ink = dark.any(axis=1)
    assert rows_with_ink[:1000].mean() > 0.3 and rows_with_ink[2000:].mean() > 0.3
    assert im.std() > 20
