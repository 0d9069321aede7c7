"""Peak memory of reading a long text log, per row, against the finished log's own size per row.

    python benchmarks/bench_log_memory.py [ROWS]

Writes a ROWS-row (default 500 000), 9-column log of about 70-byte rows to a temporary folder, reads it with
``shipid.logs.read_log`` in a child process and prints the child's peak resident memory above that of a child
that only imports shipid, per row, and the ratio to the bytes a row of the finished log holds (measured in the
same run).  ``shipid.logs.reader.LOG_BYTES_PER_ROW`` (the estimate a log is refused by before it is read) must
stay above the per-row figure.
"""
from __future__ import annotations

import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))  # this checkout's shipid, as the children (run in REPO) import it

CHILD = """
import resource, sys, warnings
warnings.simplefilter("ignore")
from shipid.logs import read_log
if sys.argv[1] != "-":
    log = read_log(sys.argv[1], lpp=4.36)
    print(len(log), int(log.data.memory_usage(index=False).sum()))
print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)
"""


def main(rows: int = 500_000) -> None:
    from shipid.logs.reader import LOG_BYTES_PER_ROW

    t = np.arange(rows) * 0.1
    df = pd.DataFrame({"time [s]": t, "x [m]": 1.7 * t, "y [m]": np.sin(t / 50), "psi [rad]": 0.01 * np.sin(t / 30),
                       "u [m/s]": 1.7 + 0 * t, "v [m/s]": 0.01 * np.cos(t / 30), "r [rad/s]": 0.01 / 30 * np.cos(t / 30),
                       "delta [rad]": 0.1 * np.sign(np.sin(t / 30)), "n [rps]": 9 + 0 * t})
    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "long.csv"
        df.to_csv(p, index=False, float_format="%.6g")
        size = p.stat().st_size
        base = int(subprocess.run([sys.executable, "-c", CHILD, "-"], capture_output=True, text=True, cwd=REPO,
                                  check=True).stdout.split()[-1])
        out = subprocess.run([sys.executable, "-c", CHILD, str(p)], capture_output=True, text=True, cwd=REPO,
                             check=True).stdout
        n, data_bytes = (int(v) for v in out.split()[:2])
        peak = int(out.split()[-1])
    per_row = (peak - base) * 1024 / n
    print(f"{n} rows, {size / n:.0f} bytes a row in the file")
    print(f"peak above the imports: {(peak - base) / 1024:.0f} MB = {per_row:.0f} bytes a row")
    print(f"finished log: {data_bytes / n:.0f} bytes a row; reading costs {per_row / (data_bytes / n):.1f} x that")
    print(f"estimate used to refuse a log before reading it: {LOG_BYTES_PER_ROW} bytes a row "
          f"({'above' if LOG_BYTES_PER_ROW >= per_row else 'BELOW'} the measurement)")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 500_000)
