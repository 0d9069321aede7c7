"""The project describes what the software does and why (with citations to papers and data), never how it got
there: no text in the tree names a work session, a numbered round, an issue, a commit, or a document that is not
in the repository.  That history belongs in git's log.

The patterns catch history, not ordinary words: "random seed", "rounded", "round trip" and "the seed model" pass;
"session 6", "round 9", "issue 13", "SPEC.md", "seed 002" and "commit 19b6f0f" do not.
"""
from __future__ import annotations

import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]

#: What counts as history (case-insensitive).
PATTERNS = {
    "a work session": r"\bsessions?\s+\d",
    "a numbered round": r"\brounds?\s+\d",
    "an issue number": r"\bissues?\s+#?\d",
    "a pre-registered round": r"\bpre-registered\s+(round|list|rule)s?\b",
    "a document outside the repository": r"\b(SPEC|DESIGN)\.md\b",
    "a seed paper by number": r"\bseeds?\s+0\d\d\b",
    "a commit": r"\bcommit(s|ted)?\b[^.\n]{0,40}?\b(?=[0-9a-f]{0,39}\d)(?=[0-9a-f]{0,39}[a-f])[0-9a-f]{7,40}\b",
}
_RX = [(what, re.compile(rx, re.IGNORECASE)) for what, rx in PATTERNS.items()]

#: The product, its tests and the studies (cleaned of history).
CODE = ["shipid", "tests", "benchmarks", "studies", "notebooks", "data/README.md"]
#: The documentation site and the README.
DOCS = ["docs", "README.md"]
SUFFIXES = {".py", ".md", ".ipynb", ".json", ".txt", ".toml", ".yaml", ".yml", ".cfg", ".html", ".csv"}


def _files(roots):
    for r in roots:
        p = REPO / r
        if p.is_file():
            yield p
        elif p.is_dir():
            for f in sorted(p.rglob("*")):
                if (f.is_file() and f.suffix in SUFFIXES and "__pycache__" not in f.parts and "_build" not in f.parts
                        and f.name != Path(__file__).name):  # _build: the generated documentation site
                    if f.suffix == ".csv" and f.stat().st_size > 200_000:
                        continue  # large data tables: numbers, not prose
                    yield f


def history(roots) -> list[str]:
    """``file:line: [what] text`` of every line that names history."""
    out = []
    for f in _files(roots):
        try:
            text = f.read_text(encoding="utf-8")
        except UnicodeDecodeError:
            continue
        for i, line in enumerate(text.splitlines(), 1):
            for what, rx in _RX:
                if rx.search(line):
                    out.append(f"{f.relative_to(REPO)}:{i}: [{what}] {line.strip()[:140]}")
                    break
    return out


def test_code_tests_studies_and_notebooks_carry_no_history():
    hits = history(CODE)
    assert not hits, f"{len(hits)} lines name history; say what the code does and why instead:\n" + "\n".join(hits)


def test_docs_and_readme_carry_no_history():
    hits = history(DOCS)
    assert not hits, f"{len(hits)} lines name history; say what the software does and why instead:\n" + "\n".join(hits)


@pytest.mark.parametrize("line, is_history", [
    ("chosen by leave-one-run-out (session 6, rule fixed before any variant ran)", True),
    ("Session 4 (same rule, older identifier) had 2.29", True),
    ("the pre-registered round 4 chose G1", True),
    ("added in round 7", True),
    ("see issue #13 and issue 27", True),
    ("the KCS model of seed 002 (SPEC.md section 1)", True),
    ("committed before the hold-out ran (commit 19b6f0f)", True),
    ("settings were fixed (commits ac40ea2 and 47b2268)", True),
    ("the random seed 7 of the synthetic logs", False),
    ("values rounded to 3 digits; a round trip through JSON", False),
    ("the seed model kcs-response starts response-nl", False),
    ("the 2 sessions of one operator", False),
    ("commit the result atomically (write then rename)", False),
])
def test_the_patterns_tell_history_from_ordinary_words(tmp_path, line, is_history):
    assert any(rx.search(line) for _, rx in _RX) == is_history
