"""Shared fixtures: synthetic KCS logs with known truth, paths to shared data."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from shipid.models import get_model

REPO = Path(__file__).resolve().parents[1]
MARIN_DIR = REPO.parent / "shared" / "data" / "kvlcc2_marin"


@pytest.fixture(scope="session")
def kcs_truth():
    """The kcs-response model with the documented synthetic truth."""
    return get_model("kcs-response", "synthetic-truth")


@pytest.fixture(scope="session")
def kcs_logs(kcs_truth):
    """{name: (noisy frame, truth frame)} of the four bundled-recipe trials (seeded)."""
    from shipid.synthetic import make_kcs_logs

    return make_kcs_logs(kcs_truth, seed=7)


@pytest.fixture(scope="session")
def kcs_fit(kcs_truth, kcs_logs):
    """An EKF fit of all four synthetic logs from a 30 %-perturbed start."""
    from shipid.identify import EKFIdentifier

    rng = np.random.default_rng(3)
    start = kcs_truth.with_params(kcs_truth.params * (1 + 0.3 * rng.standard_normal(kcs_truth.np)))
    return EKFIdentifier(start, n_passes=2).fit([f for f, _ in kcs_logs.values()])


@pytest.fixture
def marin_dir():
    if not MARIN_DIR.is_dir():
        pytest.skip(f"measured KVLCC2 data not found at {MARIN_DIR} (../shared/data/kvlcc2_marin beside the repo)")
    return MARIN_DIR


# ------------------------------------------------------------------ CPU time per test (opt-in)
# ``SHIPID_TEST_CPU=FOLDER python -m pytest ...`` writes one line per test phase (setup, call, teardown) to
# FOLDER/cpu-<pid>.tsv: node id, phase, CPU seconds of this process (all its threads) plus its waited-for children
# (subprocesses, notebook kernels), wall seconds.  On a shared machine the CPU time ranks the slow tests where
# --durations (wall time) ranks the busy moments; ``python benchmarks/suite_cpu_report.py FOLDER`` sums it up.
_CPU_DIR = __import__("os").environ.get("SHIPID_TEST_CPU")


def _cpu_now():
    import resource
    import time

    ch = resource.getrusage(resource.RUSAGE_CHILDREN)
    return time.process_time() + ch.ru_utime + ch.ru_stime, time.perf_counter()


def _cpu_phase(item, phase):
    import os

    c0, w0 = _cpu_now()
    yield
    c1, w1 = _cpu_now()
    with open(os.path.join(_CPU_DIR, f"cpu-{os.getpid()}.tsv"), "a", encoding="utf-8") as fh:
        fh.write(f"{item.nodeid}\t{phase}\t{c1 - c0:.3f}\t{w1 - w0:.3f}\n")


if _CPU_DIR:
    @pytest.hookimpl(hookwrapper=True)
    def pytest_runtest_setup(item):
        yield from _cpu_phase(item, "setup")

    @pytest.hookimpl(hookwrapper=True)
    def pytest_runtest_call(item):
        yield from _cpu_phase(item, "call")

    @pytest.hookimpl(hookwrapper=True)
    def pytest_runtest_teardown(item):
        yield from _cpu_phase(item, "teardown")
