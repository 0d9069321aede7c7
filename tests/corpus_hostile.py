"""Hostile corpus: generated cases run in child processes with bounded time and memory.

Every case builds its files under a fresh folder ``ROOT`` (inputs in ``ROOT/in``, the outputs allowed in
``ROOT/out``, a user's files beside them in ``ROOT``), runs ``python -m shipid ...`` (or a short Python
program for the library's entry points) with a wall-clock timeout and ``RLIMIT_AS``, and is judged on:

* ``traceback``: a Python traceback on stderr, or an exit by a signal the case did not send;
* ``hang``: still running at the timeout;
* ``silent``: a case that must be refused or flagged ran to exit 0 without the words that say so
  (or was refused with a message that names the wrong cause);
* ``clear``: refused with one line of at most 300 characters (exit 2), or flagged as the case requires;
* ``ok``: a case that must work, worked;
* and, for every case, ``input_modified`` (a byte of ``ROOT/in`` changed), ``escaped`` (a file outside
  ``ROOT/out`` and ``ROOT/in`` created or changed), ``device_replaced`` (a FIFO, device, socket or folder
  named as an output is no longer one) and ``lost`` (a campaign member that had finished when the run was
  killed has no result file afterwards, or a killed single-output command left a partial file).

``python tests/corpus_hostile.py [--all] [--jobs N]`` prints the counts; ``tests/test_corpus_hostile.py``
asserts them (a fast sample in the default suite, every case under ``slow``).
"""
from __future__ import annotations

import hashlib
import io
import json
import os
import random
import re
import resource
import signal
import socket
import stat
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

REPO = Path(__file__).resolve().parents[1]
DATA = REPO / "data"
LOG = DATA / "kcs_zz_m10.csv"
#: Address space of a case (bytes): room for numba/LLVM and Dask, not for an unbounded allocation.
MEMORY_LIMIT = 6 * 2**30
TIMEOUT = 240.0


@dataclass
class Case:
    name: str
    cls: str  # case class (campaign, outputs, loader, sizes, sensors, api, kill, ...)
    argv: list | Callable  # CLI arguments ("{in}", "{out}", "{root}" replaced) or callable(root) -> argv
    build: Callable | None = None  # build(root): writes the inputs
    expect: str = "error"  # "error" (exit 2, one line), "flag" (words on stdout/stderr, exit any), "ok"
    needles: tuple = ()  # words the error/flag must contain (case-insensitive, any of each tuple entry)
    python: str | None = None  # a Python program instead of the CLI (prints its result; see API cases)
    timeout: float = TIMEOUT
    kill: tuple | None = None  # (signal, earliest s, latest s): send it at a random time in that window
    resume: bool = False  # after a kill: run again with --resume and check every member finished
    fast: bool = False  # in the default suite's sample
    special: tuple = ()  # names under ROOT/out that are FIFOs/devices/sockets/folders and must stay so
    members: tuple = ()  # campaign member names (for the kill cases)
    post: Callable | None = None  # post(root) -> reason the result is wrong despite the exit (or None)


# ----------------------------------------------------------------------------- file makers
def _log_frame():
    import pandas as pd

    lines = LOG.read_text().splitlines()
    head = [ln for ln in lines if ln.startswith("#")]
    body = "\n".join(ln for ln in lines if not ln.startswith("#"))
    return head, pd.read_csv(io.StringIO(body))


def _write_frame(path: Path, head, df, *, text_edit=None) -> Path:
    text = "\n".join(head) + "\n" + df.to_csv(index=False)
    if text_edit is not None:
        text = text_edit(text)
    path.write_text(text, encoding="utf-8")
    return path


def _edited_log(name, edit=None, text_edit=None, header_edit=None):
    def build(root):
        head, df = _log_frame()
        if edit is not None:
            df = edit(df.copy())
        if header_edit is not None:
            df = df.rename(columns=header_edit)
        _write_frame(root / "in" / name, head, df, text_edit=text_edit)
    return build


def _copy_log(root, name="log.csv"):
    (root / "in" / name).write_bytes(LOG.read_bytes())


_RESULT_CACHE: dict = {}


def _result(root, name="r.json"):
    """A fit result of the bundled zigzag (made once per corpus run)."""
    if "r" not in _RESULT_CACHE:
        d = Path(tempfile.mkdtemp(prefix="corpus-result-"))
        import atexit
        import shutil

        atexit.register(shutil.rmtree, d, True)
        subprocess.run([sys.executable, "-m", "shipid", "fit", str(LOG), "-o", str(d / "r.json")], cwd=REPO,
                       capture_output=True, timeout=300)
        _RESULT_CACHE["r"] = (d / "r.json").read_bytes()
    (root / "in" / name).write_bytes(_RESULT_CACHE["r"])


def _both(*builders):
    def build(root):
        for b in builders:
            b(root)
    return build


BOMB = ("a: &a [x, x, x, x, x, x, x, x, x]\nb: &b [*a, *a, *a, *a, *a, *a, *a, *a, *a]\n"
        "c: &c [*b, *b, *b, *b, *b, *b, *b, *b, *b]\nd: &d [*c, *c, *c, *c, *c, *c, *c, *c, *c]\n"
        "e: &e [*d, *d, *d, *d, *d, *d, *d, *d, *d]\nf: &f [*e, *e, *e, *e, *e, *e, *e, *e, *e]\n"
        "g: &g [*f, *f, *f, *f, *f, *f, *f, *f, *f]\nh: &h [*g, *g, *g, *g, *g, *g, *g, *g, *g]\n"
        "i: &i [*h, *h, *h, *h, *h, *h, *h, *h, *h]\n")


#: The same chain as the value of a campaign fit's ``fixed`` mapping (a type the campaign file accepts).
BOMB_CAMPAIGN = "fits:\n  - name: m1\n    logs: [log.csv]\n    fixed:\n" + "".join("      " + ln + "\n" for ln in BOMB.splitlines())


def _text(name, text):
    def build(root):
        (root / "in" / name).write_text(text, encoding="utf-8")
    return build


def _sparse(name, size):
    def build(root):
        with open(root / "in" / name, "wb") as fh:
            fh.write(b'{"fits": [')
            fh.truncate(size)
    return build


def _campaign(doc, name="c.json", logs=("log.csv",)):
    def build(root):
        for lg in logs:
            if not (root / "in" / lg).exists():
                _copy_log(root, lg)
        (root / "in" / name).write_text(json.dumps(doc), encoding="utf-8")
        (root / "result.json").write_text('{"a user file": true}\n')  # what a member named '..' would replace
    return build


def _fit(name, log="log.csv", **kw):
    return {"name": name, "logs": [log], "passes": 1, **kw}


def _special(kind, name):
    """Make ROOT/out/NAME a FIFO, a character device (a private copy of /dev/null), a socket or a folder."""
    def build(root):
        p = root / "out" / name
        if kind == "fifo":
            os.mkfifo(p)
        elif kind == "device":
            try:
                os.mknod(p, 0o666 | stat.S_IFCHR, os.makedev(1, 3))
            except PermissionError:
                os.mkfifo(p)  # not root: a FIFO stands in for the device
        elif kind == "socket":
            s = socket.socket(socket.AF_UNIX)
            s.bind(str(p))
            s.close()
        else:
            p.mkdir()
    return build


def _silent_server():
    """A TCP port that accepts connections and never answers (a scheduler that does not respond)."""
    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen(64)
    held = []

    def loop():
        while True:
            try:
                c, _ = srv.accept()
            except OSError:
                return
            held.append(c)
    threading.Thread(target=loop, daemon=True).start()
    return srv, srv.getsockname()[1]


# ----------------------------------------------------------------------------- the cases
def cases() -> list[Case]:
    out: list[Case] = []
    add = out.append

    # campaigns: names, confinement, stale outputs, verdicts, workers, scheduler
    for label, name, fast in [("dotdot", "..", True), ("dot", ".", False), ("newline", "a\n", False),
                              ("summary-name", "campaign.json", False), ("slash", "a/b", False),
                              ("tab", "a\tb", False), ("nul", "a\u0000b", False), ("journal-name", ".journal", False)]:
        add(Case(f"campaign-name-{label}", "campaign", ["campaign", "{in}/c.json", "-o", "{out}", "--workers", "1",
                                                        "--force"],
                 _campaign({"fits": [_fit(name)]}), needles=("name",), fast=fast))
    add(Case("campaign-into-user-folder-no-force", "campaign",
             ["campaign", "{in}/c.json", "-o", "{out}/x", "--workers", "1"],
             _both(_campaign({"fits": [_fit("m1")]}), lambda root: ((root / "out" / "x" / "m1").mkdir(parents=True),
                                                                    (root / "out" / "x" / "m1" / "keep.txt").write_text("mine"))),
             needles=("--force",)))
    add(Case("campaign-force-stale-result", "campaign",
             ["campaign", "{in}/c.json", "-o", "{out}", "--workers", "1", "--force"],
             _both(_campaign({"fits": [_fit("m1", log="bad.csv")]}, logs=()), _text("bad.csv", "time,x\n1,2\n"),
                   lambda root: ((root / "out" / "m1").mkdir(),
                                 (root / "out" / "m1" / "result.json").write_text('{"stale": true}'))),
             expect="flag", needles=("fail",),
             post=lambda root: "a failed member's old result kept" if (root / "out" / "m1" / "result.json").exists()
             else None))
    add(Case("campaign-flagged-member", "campaign", ["campaign", "{in}/c.json", "-o", "{out}", "--workers", "1"],
             _both(_edited_log("vflip.csv", edit=lambda d: d.assign(**{"v [m/s]": -d["v [m/s]"]})),
                   _campaign({"fits": [_fit("m1", log="vflip.csv", passes=2)]}, logs=())),
             expect="flag", needles=("flagged", "not consistent", "defect")))
    add(Case("campaign-workers-huge", "campaign", ["campaign", "{in}/c.json", "-o", "{out}", "--workers", "100000"],
             _campaign({"fits": [_fit("m1")]}), needles=("--workers",), timeout=120))
    add(Case("campaign-workers-zero", "campaign", ["campaign", "{in}/c.json", "-o", "{out}", "--workers", "0"],
             _campaign({"fits": [_fit("m1")]}), needles=("workers",)))
    add(Case("campaign-scheduler-silent", "campaign",
             ["campaign", "{in}/c.json", "-o", "{out}", "--scheduler", "tcp://127.0.0.1:{port}"],
             _campaign({"fits": [_fit("m1")]}), needles=("--scheduler",), timeout=120))
    add(Case("campaign-yaml-bomb", "loader", ["campaign", "{in}/c.yaml", "-o", "{out}"],
             _both(_copy_log, _text("c.yaml", BOMB_CAMPAIGN)),
             needles=("c.yaml", "alias"), fast=True, timeout=120))
    add(Case("campaign-sparse-1gb", "loader", ["campaign", "{in}/c.json", "-o", "{out}"], _sparse("c.json", 2**30),
             needles=("c.json", "MiB"), timeout=120))
    add(Case("campaign-deep-json", "loader", ["campaign", "{in}/c.json", "-o", "{out}"],
             _text("c.json", "[" * 100_000 + "]" * 100_000), needles=("c.json",)))
    add(Case("campaign-deep-yaml", "loader", ["campaign", "{in}/c.yaml", "-o", "{out}"],
             _text("c.yaml", "[" * 5000 + "]" * 5000), needles=("c.yaml",)))
    add(Case("campaign-ok", "campaign", ["campaign", "{in}/c.json", "-o", "{out}", "--workers", "1"],
             _campaign({"fits": [_fit("m1")]}), expect="ok"))

    # outputs that are not regular files, with --force, in every command that writes
    cmds = {
        "fit": (["fit", "{in}/log.csv", "-o", "{out}/X", "--force", "--passes", "1"], _copy_log),
        "validate": (["validate", "{in}/r.json", "{in}/log.csv", "-o", "{out}/X", "--force"], _both(_copy_log, _result)),
        "report": (["report", "{in}/r.json", "{in}/log.csv", "-o", "{out}/X", "--force"], _both(_copy_log, _result)),
        "simulate": (["simulate", "kcs-response:synthetic-truth", "--turning", "35", "-o", "{out}/X", "--force"], None),
        "sample": (["sample", "{in}/r.json", "{in}/log.csv", "-o", "{out}/X", "--force", "--steps", "10",
                    "--walkers", "32"], _both(_copy_log, _result)),
        "log": (["log", "{in}/log.csv", "-o", "{out}/X", "--force"], _copy_log),
        "metrics": (["metrics", "{in}/log.csv", "-o", "{out}/X", "--force"], _copy_log),
    }
    for cmd, (argv, build) in cmds.items():
        for kind in ("fifo", "device", "socket", "folder"):
            b = _special(kind, "X")
            add(Case(f"output-{kind}-{cmd}", "outputs", argv, _both(build, b) if build else b,
                     needles=("regular file", "is a folder"), special=("X",),
                     fast=(cmd == "log" and kind == "device")))

    # structured files: alias bombs, sizes, nesting
    add(Case("schema-yaml-bomb", "loader", ["log", "{in}/log.csv", "--schema", "{in}/s.yaml"],
             _both(_copy_log, _text("s.yaml", BOMB)), needles=("s.yaml", "alias"), fast=True, timeout=120))
    add(Case("ship-yaml-bomb", "loader", ["log", "{in}/log.csv", "--ship", "{in}/ship.yaml"],
             _both(_copy_log, _text("ship.yaml", BOMB)), needles=("ship.yaml", "alias"), timeout=120))
    add(Case("schema-yaml-anchor-flood", "loader", ["log", "{in}/log.csv", "--schema", "{in}/s.yaml"],
             _both(_copy_log, _text("s.yaml", "columns: {time: &t time}\nunits:\n" + "".join(f"  k{i}: *t\n" for i in range(20000)))),
             needles=("s.yaml",)))
    add(Case("ship-json-sparse", "loader", ["log", "{in}/log.csv", "--ship", "{in}/ship.json"],
             _both(_copy_log, _sparse("ship.json", 2**30)), needles=("ship.json", "MiB")))
    add(Case("result-json-sparse", "loader", ["validate", "{in}/r.json", "{in}/log.csv", "-o", "{out}/v.json"],
             _both(_copy_log, _sparse("r.json", 2**30)), needles=("r.json", "MiB")))
    add(Case("samples-json-deep", "loader",
             ["validate", "{in}/r.json", "{in}/log.csv", "--draws", "4", "--samples", "{in}/s.json", "-o", "{out}/v.json"],
             _both(_copy_log, _result, _text("s.json", "[" * 100_000 + "]" * 100_000)), needles=("s.json",)))
    add(Case("samples-json-sparse", "loader",
             ["validate", "{in}/r.json", "{in}/log.csv", "--draws", "4", "--samples", "{in}/s.json", "-o", "{out}/v.json"],
             _both(_copy_log, _result, _sparse("s.json", 2**30)), needles=("s.json", "MiB")))
    add(Case("wind-json-deep", "loader", ["fit", "{in}/log.csv", "--wind", "{in}/w.json", "-o", "{out}/r.json"],
             _both(_copy_log, _text("w.json", "[" * 100_000 + "]" * 100_000)), needles=("w.json",)))
    add(Case("problem-yaml-bomb", "loader", ["plan", "{in}/p.yaml", "-o", "{out}/p.json"], _text("p.yaml", BOMB),
             needles=("p.yaml",), timeout=120))
    add(Case("log-meta-bomb", "loader", ["log", "{in}/m.csv"],
             _text("m.csv", "# shipid-log: " + "[" * 100_000 + "]" * 100_000 + "\n" + LOG.read_text()),
             needles=("m.csv",)))

    # sizes
    add(Case("sample-walkers-1e9", "sizes",
             ["sample", "{in}/r.json", "{in}/log.csv", "-o", "{out}/s.json", "--walkers", "1000000000", "--steps", "30"],
             _both(_copy_log, _result), needles=("--walkers", "GiB"), timeout=120))
    add(Case("sample-steps-1e12", "sizes",
             ["sample", "{in}/r.json", "{in}/log.csv", "-o", "{out}/s.json", "--steps", "1000000000000"],
             _both(_copy_log, _result), needles=("--steps", "GiB"), timeout=120))
    add(Case("sample-thin-past-steps", "sizes",
             ["sample", "{in}/r.json", "{in}/log.csv", "-o", "{out}/s.json", "--thin", "1000", "--steps", "30"],
             _both(_copy_log, _result), needles=("--thin",)))
    add(Case("validate-draws-1e9", "sizes", ["validate", "{in}/r.json", "{in}/log.csv", "--draws", "1000000000",
                                             "-o", "{out}/v.json"],
             _both(_copy_log, _result), needles=("--draws",), timeout=120))
    add(Case("campaign-draws-1e9", "sizes", ["campaign", "{in}/c.json", "-o", "{out}", "--workers", "1"],
             _campaign({"fits": [_fit("m1", draws=1000000000)]}), needles=("draws",), timeout=120))
    add(Case("metrics-reference-offset-1e308", "sizes", ["metrics", "{in}/log.csv", "--reference-offset", "1e308"],
             _copy_log, needles=("--reference-offset",), fast=True))

    # sensor faults and reader edges
    add(Case("gyro-5pct-high", "sensors", ["log", "{in}/g.csv"],
             _edited_log("g.csv", edit=lambda d: d.assign(**{"r [rad/s]": d["r [rad/s]"] * 1.05})),
             expect="flag", needles=("yaw rate", "gyro", "scale")))
    add(Case("propeller-dead", "sensors", ["log", "{in}/n.csv"],
             _edited_log("n.csv", edit=lambda d: d.assign(**{"n [rps]": 0.0})), expect="flag",
             needles=("propeller", "'n'")))
    add(Case("header-cyrillic-p", "sensors", ["log", "{in}/h.csv"],
             _edited_log("h.csv", header_edit={"psi [rad]": "\u0440si [rad]"}), expect="flag",
             needles=("look-alike", "U+0440", "cyrillic")))
    add(Case("header-fullwidth-u", "sensors", ["log", "{in}/h.csv"],
             _edited_log("h.csv", header_edit={"u [m/s]": "\uff55 [m/s]"}), expect="flag",
             needles=("look-alike", "U+FF55", "full-width", "fullwidth")))
    add(Case("header-zero-width", "sensors", ["log", "{in}/h.csv"],
             _edited_log("h.csv", header_edit={"r [rad/s]": "r\u200b [rad/s]"}), expect="flag",
             needles=("zero-width", "U+200B", "invisible")))
    add(Case("heading-rad-under-deg", "sensors", ["log", "{in}/h.csv"],
             _edited_log("h.csv", header_edit={"psi [rad]": "psi [deg]"}), needles=("psi",)))
    add(Case("truncated-last-row", "sensors", ["log", "{in}/t.csv"],
             _edited_log("t.csv", text_edit=lambda t: t.rstrip("\n")[:-7]), expect="flag",
             needles=("last row", "truncated")))
    add(Case("symlink-loop", "sensors", ["log", "{in}/loop.csv"],
             lambda root: (os.symlink("loop2.csv", root / "in" / "loop.csv"),
                           os.symlink("loop.csv", root / "in" / "loop2.csv")), needles=("loop", "symbolic link")))
    add(Case("schema-sign-unknown-channel", "sensors", ["log", "{in}/log.csv", "--schema", "{in}/s.json"],
             _both(_copy_log, _text("s.json", json.dumps({"signs": {"zz": -1}}))), needles=("zz",)))
    add(Case("schema-meas-std-unknown-channel", "sensors", ["fit", "{in}/log.csv", "--schema", "{in}/s.json",
                                                            "-o", "{out}/r.json"],
             _both(_copy_log, _text("s.json", json.dumps({"meas_std": {"zz": 0.1}}))), needles=("zz",)))

    # library entry points (scipy-style argument checks or a failure flag)
    pre = ("import numpy as np, warnings; warnings.simplefilter('ignore')\n"
           "from shipid.models import get_model\nm = get_model('kcs-response', 'synthetic-truth')\n")
    api = {
        "validate-substeps-0": (pre + "from shipid.validation import validate\n"
                                f"validate(m, [{str(LOG)!r}], substeps=0)\n", ("substeps",)),
        "simulate-x0-none": (pre + "from shipid.simulate import simulate\nt = np.arange(0, 10, 0.1)\n"
                             "simulate(m, None, t, np.zeros((t.size, 2)) + [0, 9])\n", ("x0",)),
        "ekf-model-string": ("from shipid.identify import EKFIdentifier\nEKFIdentifier('kcs-response')\n", ("model",)),
        "simulate-nan-t": (pre + "from shipid.simulate import simulate\nt = np.arange(0, 10, 0.1); t[5] = np.nan\n"
                           "r = simulate(m, [0, 0, 0, 1.7, 0, 0], t, np.zeros((t.size, 2)) + [0, 9])\n"
                           "print('FLAG' if not r.success else ('SILENT' if not np.isfinite(np.asarray(r.state)).all()"
                           " else 'OK'))\n", ("t",)),
        "simulate-inf-x0": (pre + "from shipid.simulate import simulate\nt = np.arange(0, 10, 0.1)\n"
                            "r = simulate(m, [0, 0, 0, np.inf, 0, 0], t, np.zeros((t.size, 2)) + [0, 9])\n"
                            "print('FLAG' if not r.success else ('SILENT' if not np.isfinite(np.asarray(r.state)).all()"
                            " else 'OK'))\n", ("x0",)),
    }
    for name, (code, needles) in api.items():
        add(Case(f"api-{name}", "api", [], None, python=code, needles=needles, fast=name == "ekf-model-string"))

    # interruptions
    names = ("m1", "m2", "m3", "m4", "m5", "m6")
    camp3 = _campaign({"fits": [_fit(n) for n in names]})
    for i, (sig, lo, hi) in enumerate([(signal.SIGTERM, 5, 12), (signal.SIGKILL, 5, 12), (signal.SIGTERM, 8, 16),
                                       (signal.SIGKILL, 8, 16), (signal.SIGINT, 5, 12), (signal.SIGKILL, 4, 20)]):
        add(Case(f"campaign-kill-{sig.name}-{i}", "kill",
                 ["campaign", "{in}/c.json", "-o", "{out}", "--workers", "1", "--progress"], camp3,
                 expect="any", kill=(sig, lo, hi), resume=True, members=names))
    add(Case("sample-sigint", "kill", ["sample", "{in}/r.json", "{in}/log.csv", "-o", "{out}/s.json", "--steps", "100000"],
             _both(_copy_log, _result), expect="any", kill=(signal.SIGINT, 15, 20)))
    for i, sig in enumerate((signal.SIGKILL, signal.SIGTERM)):
        add(Case(f"fit-kill-{sig.name}", "kill", ["fit", "{in}/log.csv", "-o", "{out}/r.json"], _copy_log,
                 expect="any", kill=(sig, 3, 8)))
    return out


# ----------------------------------------------------------------------------- running and judging
def _state(root: Path) -> dict:
    snap = {}
    for dirpath, dirs, files in os.walk(root):
        for n in dirs + files:
            p = Path(dirpath) / n
            st = os.lstat(p)
            if stat.S_ISREG(st.st_mode):
                h = hashlib.sha256(p.read_bytes()).hexdigest()
                snap[p] = ("file", h)
            elif stat.S_ISLNK(st.st_mode):
                snap[p] = ("link", os.readlink(p))
            elif stat.S_ISDIR(st.st_mode):
                snap[p] = ("dir", None)
            else:
                snap[p] = (stat.S_IFMT(st.st_mode), st.st_rdev)
    return snap


def _limits():
    resource.setrlimit(resource.RLIMIT_AS, (MEMORY_LIMIT, MEMORY_LIMIT))
    os.setsid()
    # a runner started in the background inherits SIGINT ignored; the case must see Ctrl-C as a user would
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _run(argv, root, timeout, kill=None, env=None):
    """Run; returns (rc, stdout, stderr, hung, sent signal)."""
    fo, fe = open(root / ".stdout", "w+"), open(root / ".stderr", "w+")
    proc = subprocess.Popen(argv, cwd=REPO, stdout=fo, stderr=fe, preexec_fn=_limits, env=env)
    sent = None
    hung = False
    t0 = time.monotonic()
    try:
        if kill is not None:
            sig, lo, hi = kill
            at = random.uniform(lo, hi)
            try:
                proc.wait(timeout=at)
            except subprocess.TimeoutExpired:
                proc.send_signal(sig)
                sent = sig
        proc.wait(timeout=max(1.0, timeout - (time.monotonic() - t0)))
    except subprocess.TimeoutExpired:
        hung = True
    finally:
        if proc.poll() is None:
            try:
                os.killpg(proc.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            proc.wait()
    # children of the process group (Dask workers) must not outlive the case
    try:
        os.killpg(proc.pid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        pass
    fo.seek(0)
    fe.seek(0)
    out, err = fo.read(), fe.read()
    fo.close()
    fe.close()
    os.unlink(root / ".stdout")
    os.unlink(root / ".stderr")
    return proc.returncode, out, err, hung, sent


def _has(text: str, needles) -> bool:
    low = text.lower()
    return all(any(n.lower() in low for n in (w if isinstance(w, tuple) else (w,))) for w in ([needles] if needles else []))


def _any(text: str, needles) -> bool:
    low = text.lower()
    return not needles or any(n.lower() in low for n in needles)


def run_case(case: Case, base: Path | None = None, port: int | None = None) -> dict:
    """Run one case; returns its record (``outcome`` and the orthogonal checks)."""
    root = Path(tempfile.mkdtemp(prefix="case-", dir=base))
    (root / "in").mkdir()
    (root / "out").mkdir()
    if case.build is not None:
        case.build(root)
    before = _state(root)
    fill = {"in": root / "in", "out": root / "out", "root": root, "port": port}
    if case.python is not None:
        prog = ("import sys\ntry:\n" + "".join("    " + ln + "\n" for ln in case.python.splitlines())
                + "except (ValueError, TypeError) as exc:\n    print(f'ERROR {type(exc).__name__}: {exc}', "
                  "file=sys.stderr)\n    sys.exit(2)\n")
        argv = [sys.executable, "-c", prog]
    else:
        args = case.argv(root) if callable(case.argv) else case.argv
        argv = [sys.executable, "-m", "shipid"] + [str(a).format(**fill) for a in args]
    rc, out, err, hung, sent = _run(argv, root, case.timeout, case.kill)
    after = _state(root)
    rec = {"name": case.name, "cls": case.cls, "rc": rc, "hung": hung, "stderr": err[-3000:], "stdout": out[-2000:],
           "sent": int(sent) if sent is not None else None, "post": case.post(root) if case.post else None}
    rec["outcome"] = judge(case, rec)
    changed = {p for p in set(before) | set(after) if before.get(p) != after.get(p)}
    rec["input_modified"] = sorted(str(p.relative_to(root)) for p in changed if (root / "in") in p.parents)
    rec["escaped"] = sorted(str(p.relative_to(root)) for p in changed
                            if (root / "in") not in p.parents and (root / "out") not in p.parents
                            and p not in (root / "in", root / "out") and not p.name.startswith(".std"))
    rec["device_replaced"] = [n for n in case.special if after.get(root / "out" / n, ("?",))[0]
                              != before[root / "out" / n][0]]
    rec["lost"] = _lost(case, root, err, sent) if case.kill else 0
    if case.resume and sent is not None:
        rec["resume"] = _resume(case, root, fill)
    rec["seconds"] = None
    return rec


def judge(case: Case, rec: dict) -> str:
    """The outcome of a case from its record (exit status, stdout, stderr, the post-check)."""
    rc, out, err = rec["rc"], rec["stdout"], rec["stderr"]
    sent = rec.get("sent")
    if rec["hung"]:
        return "hang"
    if "Traceback (most recent call last)" in err or (rc is not None and rc < 0 and -rc != (sent or 0)):
        return "traceback"
    lines = [ln for ln in err.strip().splitlines() if ln.strip()]
    last = lines[-1] if lines else ""
    plain = len(last) <= 300 and "[Errno" not in last and ".tmp'" not in last  # no raw OS text, no temporaries
    if case.expect == "error":
        if case.python is not None:  # a library call: a clear exception, or a failure flag
            if rc == 2 and plain and _any(last, case.needles):
                outcome = "clear"
            elif rc == 0 and "FLAG" in out:
                outcome = "clear"
            else:
                outcome = "silent"
        else:
            outcome = "clear" if rc == 2 and plain and _any(last, case.needles) else "silent"
    elif case.expect == "flag":
        outcome = "clear" if _any(out + err, case.needles) and (rc != 0 or "warn" in (out + err).lower()) else "silent"
    elif case.expect == "ok":
        outcome = "ok" if rc == 0 else "silent"
    else:  # interrupted: any exit without a traceback
        outcome = "clear"
    if outcome in ("clear", "ok") and rec.get("post"):
        outcome = "silent"
    return outcome


def _finished_members(err: str) -> int:
    """Members finished according to the progress bar (``k/N``; the last count printed)."""
    counts = [int(a) for a, b in re.findall(r"\|\s*(\d+)/(\d+)\s*\[", err)]
    return max(counts) if counts else 0


def _valid_json(p: Path) -> bool:
    try:
        json.loads(p.read_text())
        return True
    except (OSError, ValueError):
        return False


def _lost(case: Case, root: Path, err: str, sent) -> int:
    if case.members:
        present = sum(_valid_json(root / "out" / m / "result.json") for m in case.members)
        return max(0, _finished_members(err) - present)
    # a single-output command: a partial file is a loss
    bad = 0
    for p in (root / "out").rglob("*"):
        if p.is_file() and p.suffix == ".json" and not _valid_json(p):
            bad += 1
    return bad


def _resume(case: Case, root: Path, fill: dict) -> dict:
    """Rerun with --resume: every member finished, those finished before kept byte for byte."""
    kept = {m: (root / "out" / m / "result.json").read_bytes() for m in case.members
            if _valid_json(root / "out" / m / "result.json")}
    args = [str(a).format(**fill) for a in case.argv if a != "--progress"] + ["--resume"]
    rc, out, err, hung, _ = _run([sys.executable, "-m", "shipid"] + args, root, case.timeout)
    done = sum(_valid_json(root / "out" / m / "result.json") for m in case.members)
    same = all((root / "out" / m / "result.json").read_bytes() == b for m, b in kept.items()
               if (root / "out" / m / "result.json").exists())
    return {"rc": rc, "complete": done == len(case.members) and not hung, "kept": same, "err": err[-300:]}


def summarise(records: list[dict]) -> dict:
    return {"cases": len(records),
            "clear": sum(r["outcome"] in ("clear", "ok") for r in records),
            "tracebacks": sum(r["outcome"] == "traceback" for r in records),
            "hangs": sum(r["outcome"] == "hang" for r in records),
            "silent": sum(r["outcome"] == "silent" for r in records),
            "inputs_modified": sum(bool(r["input_modified"]) for r in records),
            "escaped": sum(bool(r["escaped"]) for r in records),
            "devices_replaced": sum(bool(r["device_replaced"]) for r in records),
            "outputs_lost": sum(r["lost"] for r in records),
            "resumes_incomplete": sum(1 for r in records
                                      if r.get("resume") and not (r["resume"]["complete"] and r["resume"]["kept"]))}


def run_all(selected: list[Case], jobs: int = 1, seed: int = 0, verbose: bool = True) -> list[dict]:
    random.seed(seed)
    base = Path(tempfile.mkdtemp(prefix="shipid-corpus-"))
    srv, port = _silent_server()
    records = []
    try:
        from concurrent.futures import ThreadPoolExecutor

        def one(c):
            t0 = time.monotonic()
            r = run_case(c, base, port)
            r["seconds"] = round(time.monotonic() - t0, 1)
            if verbose:
                extra = "".join(f" {k}={r[k]}" for k in ("input_modified", "escaped", "device_replaced", "lost") if r[k])
                print(f"{r['outcome']:9s} {c.name} rc={r['rc']} {r['seconds']}s{extra} "
                      f"{(r['stderr'].strip().splitlines() or [''])[-1][:200]!r}", flush=True)
                if r.get("resume"):
                    print(f"          resume: {r['resume']}", flush=True)
            return r
        with ThreadPoolExecutor(max_workers=jobs) as ex:
            records = list(ex.map(one, selected))
    finally:
        srv.close()
        import shutil

        shutil.rmtree(base, ignore_errors=True)
    return records


def main(argv=None) -> int:
    import argparse

    ap = argparse.ArgumentParser(description="Run the hostile corpus and print its counts.")
    ap.add_argument("--fast", action="store_true", help="the default suite's sample only")
    ap.add_argument("--only", default=None, help="cases whose name contains this text")
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", default=None, help="write the records to this file")
    ap.add_argument("--rejudge", default=None, help="judge the records of this file again (no runs)")
    a = ap.parse_args(argv)
    if a.rejudge:
        by_name = {c.name: c for c in cases()}
        recs = json.loads(Path(a.rejudge).read_text())["records"]
        for r in recs:
            r.setdefault("post", r.get("why"))
            if r["name"] in by_name:
                r["outcome"] = judge(by_name[r["name"]], r)
        for r in recs:
            print(f"{r['outcome']:9s} {r['name']}")
        print(json.dumps(summarise(recs)))
        return 0
    only = a.only.split(",") if a.only else None
    sel = [c for c in cases() if (not a.fast or c.fast) and (only is None or any(o in c.name for o in only))]
    recs = run_all(sel, a.jobs, a.seed)
    s = summarise(recs)
    print(json.dumps(s))
    if a.json:
        Path(a.json).write_text(json.dumps({"summary": s, "records": recs}, indent=1, default=str))
    return 0


if __name__ == "__main__":
    sys.exit(main())
