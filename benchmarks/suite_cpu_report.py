"""Sum the per-test CPU times written with ``SHIPID_TEST_CPU=FOLDER`` (tests/conftest.py).

    python benchmarks/suite_cpu_report.py FOLDER [--top 60]

Prints the total CPU and wall seconds of all test phases, then the tests with the most CPU seconds (setup,
which runs a module's shared fixtures for its first test, counted separately so that a slow fixture shows).
"""
from __future__ import annotations

import argparse
import collections
from pathlib import Path


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folder")
    ap.add_argument("--top", type=int, default=60)
    a = ap.parse_args(argv)
    cpu, wall = collections.defaultdict(float), collections.defaultdict(float)
    for f in Path(a.folder).glob("cpu-*.tsv"):
        for line in f.read_text(encoding="utf-8").splitlines():
            node, phase, c, w = line.split("\t")
            cpu[(node, phase)] += float(c)
            wall[(node, phase)] += float(w)
    print(f"{len({n for n, _ in cpu})} tests: CPU {sum(cpu.values()):.0f} s, wall {sum(wall.values()):.0f} s "
          "(summed over the workers)")
    for (node, phase), c in sorted(cpu.items(), key=lambda kv: -kv[1])[:a.top]:
        print(f"{c:8.1f} s CPU {wall[(node, phase)]:8.1f} s wall  {phase:<8} {node}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
