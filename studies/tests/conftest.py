"""Fixtures of the study tests: the synthetic KCS truth and the measured data folders beside the repository."""
from __future__ import annotations

from pathlib import Path

import pytest

from shipid.models import get_model

REPO = Path(__file__).resolve().parents[2]
MARIN_DIR = REPO.parent / "shared" / "data" / "kvlcc2_marin"
ESSO_DIR = REPO.parent / "shared" / "data" / "esso_osaka_frt"


@pytest.fixture(scope="session")
def kcs_truth():
    """The kcs-response model with the documented synthetic truth."""
    return get_model("kcs-response", "synthetic-truth")
