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
