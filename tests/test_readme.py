"""The README's commands run as written, in order, in a fresh folder.

Every line of every ```bash and ```text block is a command (``#`` starts a comment; ``a && b`` is
two commands); placeholders of the ```text blocks are files this test writes from the bundled data
(``run.csv``: a bundled log with a heading column named ``Heading`` and degrees, deg/s and rpm, as a
trials logger might write it).  Every ```python block runs too, in the same folder, after the commands.  ``pip install`` and the test-suite command itself are not run here
(CI runs them), nor ``shipid demo`` (it writes only into a new folder of its own, so it cannot
collide, and ``tests/test_cli.py::test_demo_runs_and_recovers_the_truth`` runs it); every other
``shipid`` command is, in-process, from a new folder that has the
repository's ``data/`` beside it and, when present, the shared data one level up as
``../shared``.  Commands needing ``../shared`` are skipped (and counted) when it is absent.
Each must exit 0 and must not find its output already present (no two commands
write the same file)."""
from __future__ import annotations

import glob
import re
import shlex
import time
from pathlib import Path

import pytest

from shipid.cli import main

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared"


def readme_commands(text: str, with_exit: bool = False) -> list:
    """The commands of the README's ```bash blocks, in order; with ``with_exit``, pairs
    ``(command, expected exit status)``: 0 unless the line's comment says ``exit N`` (e.g. a fit
    the consistency verdict flags, exit 3, documented beside the command)."""
    out = []
    for block in re.findall(r"^```(?:bash|text)\n(.*?)^```", text, flags=re.S | re.M):
        for line in block.splitlines():
            words = shlex.split(line, comments=True)
            m = re.search(r"#.*\bexit (\d)\b", line)
            expected = int(m.group(1)) if m else 0
            cmd: list[str] = []
            for w in words + ["&&"]:
                if w == "&&":
                    if cmd:
                        out.append((shlex.join(cmd), expected) if with_exit else shlex.join(cmd))
                    cmd = []
                else:
                    cmd.append(w)
    return out


def test_readme_commands_are_found():
    cmds = readme_commands((REPO / "README.md").read_text())
    shipid = [c for c in cmds if c.startswith("shipid ")]
    assert len(shipid) >= 10 and "shipid demo" in shipid
    outputs = [c.split(" -o ")[1].split()[0] for c in shipid if " -o " in c]
    dup = {o for o in outputs if outputs.count(o) > 1}
    assert not dup, f"README commands write the same file twice: {dup}"
    # CSVs written beside a JSON (plan/route) must not collide with another output either
    beside = [o[:-5] + ".csv" for c, o in zip([c for c in shipid if " -o " in c], outputs)
              if c.split()[1] in ("plan", "route")]
    assert not set(beside) & set(outputs), set(beside) & set(outputs)
    # every placeholder file a command names is either bundled, written by this test or an output
    assert "run.csv" in " ".join(shipid)


def write_placeholders(folder: Path) -> None:
    """``run.csv``: the bundled 10/10 zigzag as another logger might write it (heading column
    'Heading', angles in degrees, rates in deg/s, propeller in rpm, no units in the header)."""
    import numpy as np

    import shipid

    log = shipid.read_log(REPO / "data" / "kcs_zz_m10.csv")
    d = log.data
    out = {"time": d["time"], "x": d["x"], "y": d["y"], "Heading": np.degrees(d["psi"]), "u": d["u"],
           "v": d["v"], "r": np.degrees(d["r"]), "delta": np.degrees(d["delta"]), "n": d["n"] * 60.0}
    import pandas as pd

    pd.DataFrame(out).to_csv(folder / "run.csv", index=False, float_format="%.10g")


def readme_python_blocks(text: str) -> list[str]:
    return re.findall(r"^```python\n(.*?)^```", text, flags=re.S | re.M)


@pytest.mark.slow
def test_readme_commands_run_in_sequence_in_a_fresh_folder(tmp_path, monkeypatch, capsys):
    work = tmp_path / "work"
    work.mkdir()
    (work / "data").symlink_to(REPO / "data", target_is_directory=True)
    if SHARED.is_dir():
        (tmp_path / "shared").symlink_to(SHARED, target_is_directory=True)
    monkeypatch.chdir(work)
    write_placeholders(work)
    ran, skipped = [], []
    for cmd, expected in readme_commands((REPO / "README.md").read_text(), with_exit=True):
        argv = shlex.split(cmd)
        if (argv[0] == "pip" or argv[:3] in (["python", "-m", "pytest"], ["python", "-m", "sphinx"])
                or argv[:2] == ["shipid", "demo"]):
            continue
        assert argv[0] == "shipid", f"README command not understood by this test: {cmd}"
        if "../shared" in cmd and not SHARED.is_dir():
            skipped.append(cmd)
            continue
        args = []
        for a in argv[1:]:
            hits = sorted(glob.glob(a)) if any(ch in a for ch in "*?[") else [a]
            assert hits, f"{cmd}: nothing matches {a}"
            args.extend(hits)
        if "-o" in args:
            out = Path(args[args.index("-o") + 1])
            assert not out.exists(), f"{cmd}: its output {out} was written by an earlier README command"
        t0 = time.perf_counter()
        rc = main(args)
        err = capsys.readouterr().err
        assert rc == expected, f"{cmd} -> exit {rc} (README says {expected}): {err[-500:]}"
        ran.append((cmd, time.perf_counter() - t0))
    with capsys.disabled():
        for cmd, dt in ran:
            print(f"  {dt:6.1f} s  {cmd}")
    assert len(ran) + len(skipped) >= 10  # every shipid command of the README except `shipid demo`
    for i, block in enumerate(readme_python_blocks((REPO / "README.md").read_text())):
        exec(compile(block, f"README.md python block {i + 1}", "exec"), {"__name__": "__readme__"})
    if skipped:
        print(f"skipped {len(skipped)} command(s) needing ../shared: {skipped}")
