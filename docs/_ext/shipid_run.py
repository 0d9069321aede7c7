"""Sphinx directive ``{shipid}``: run shell commands during the build and show their output.

Each line of the block is one command, run with ``bash`` in a work folder of the page
(``<build>/../work/<page>``, emptied when the page is read) that has the repository's
``data/`` beside it and, when the measured data sets exist next to the repository, ``../shared``.
``shipid`` runs this checkout's package (``python -m shipid``).  A command's expected exit
status is written as a comment on its line (``# exit 3``); any other status fails the build.
Option ``:needs: PATH`` (relative to the work folder) shows the commands without running them
when PATH is absent, and says so on the page.  ``:output: none`` hides the output;
``:lines: N`` shows at most N lines of it (head and tail).
"""
from __future__ import annotations

import os
import re
import shlex
import shutil
import subprocess
import sys
import time
from pathlib import Path

from docutils import nodes
from docutils.parsers.rst import directives
from sphinx.util import logging
from sphinx.util.docutils import SphinxDirective

logger = logging.getLogger(__name__)
ANSI = re.compile(r"\x1b\[[0-9;?]*[A-Za-z]")
EXIT = re.compile(r"#.*\bexit (\d+)\b")


def _work_root(app) -> Path:
    return Path(app.outdir).resolve().parent / "work"


def work_folder(app, docname: str) -> Path:
    return _work_root(app) / docname.replace("/", "__")


def _prepare(app, docname: str) -> Path:
    root = _work_root(app)
    root.mkdir(parents=True, exist_ok=True)
    repo = Path(app.config.shipid_run_repo)
    shared = repo.parent / "shared"
    link = root / "shared"
    if shared.is_dir() and not link.exists():
        link.symlink_to(shared, target_is_directory=True)
    bindir = root / "bin"
    if not (bindir / "shipid").exists():
        bindir.mkdir(exist_ok=True)
        script = bindir / "shipid"
        script.write_text(f'#!/bin/sh\nexec {shlex.quote(sys.executable)} -m shipid "$@"\n')
        script.chmod(0o755)
    work = work_folder(app, docname)
    if not work.exists():
        work.mkdir(parents=True)
        (work / "data").symlink_to(repo / "data", target_is_directory=True)
    return work


def _clean(text: str) -> list[str]:
    lines = []
    for line in ANSI.sub("", text).splitlines():
        if "\r" in line:  # a progress bar redrawn in place: keep what the terminal would show last
            line = [p for p in line.split("\r") if p.strip()][-1:] or [""]
            line = line[0]
        lines.append(line.rstrip())
    while lines and not lines[-1]:
        lines.pop()
    return lines


class ShipidRun(SphinxDirective):
    has_content = True
    option_spec = {
        "needs": directives.unchanged,
        "output": directives.unchanged,
        "lines": directives.nonnegative_int,
    }

    def run(self):
        app = self.env.app
        work = _prepare(app, self.env.docname)
        needs = self.options.get("needs")
        show_output = self.options.get("output", "show") != "none"
        max_lines = self.options.get("lines", 30)
        commands = [c for c in self.content if c.strip()]
        skip = bool(needs) and not (work / needs).exists()
        shown: list[str] = []
        env = dict(os.environ)
        env["PATH"] = str(_work_root(app) / "bin") + os.pathsep + env.get("PATH", "")
        env["COLUMNS"] = "100"
        env.setdefault("OPENBLAS_NUM_THREADS", "1")
        for cmd in commands:
            shown.append(f"$ {cmd}")
            if skip:
                continue
            m = EXIT.search(cmd)
            expected = int(m.group(1)) if m else 0
            t0 = time.perf_counter()
            proc = subprocess.run(["bash", "-c", cmd], cwd=work, env=env, capture_output=True,
                                  text=True, timeout=1200)
            took = time.perf_counter() - t0
            logger.info(f"[shipid] {self.env.docname}: {took:6.1f} s  {cmd}")
            out = _clean(proc.stdout + proc.stderr)
            if proc.returncode != expected:
                tail = " | ".join(out[-6:])
                logger.warning(f"command exited {proc.returncode}, the page says {expected}: {cmd} :: {tail}",
                               location=(self.env.docname, self.lineno))
            if show_output and out:
                if len(out) > max_lines:
                    head = max_lines * 2 // 3
                    tail_n = max_lines - head
                    out = out[:head] + [f"... ({len(out) - max_lines} more lines)"] + out[-tail_n:]
                shown.extend(out)
        block = nodes.literal_block("\n".join(shown), "\n".join(shown))
        block["language"] = "console"
        result = [block]
        if skip:
            note = nodes.note()
            note += nodes.paragraph(text=(f"Not run when this page was built: {needs} is not present "
                                          "(a measured data set kept beside the repository). "
                                          "The commands are shown as written."))
            result.append(note)
        return result


def _purge(app, env, docname):
    work = work_folder(app, docname)
    if work.exists():
        shutil.rmtree(work)


def setup(app):
    app.add_config_value("shipid_run_repo", "", "env")
    app.add_directive("shipid", ShipidRun)
    app.connect("env-purge-doc", _purge)
    return {"version": "1.0", "parallel_read_safe": False, "parallel_write_safe": True}
