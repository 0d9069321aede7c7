"""Locate the bundled sample data (inside the wheel, or ``data/`` in a source checkout)."""
from __future__ import annotations

from pathlib import Path

__all__ = ["bundled_data_dir", "bundled_kcs_logs"]


def bundled_data_dir() -> Path:
    """Folder with the bundled logs: ``shipid/_bundled_data`` in an installed wheel,
    the repository's ``data/`` folder in a source (editable) checkout."""
    here = Path(__file__).resolve().parent
    for cand in (here / "_bundled_data", here.parent / "data"):
        if (cand / "README.md").is_file():
            return cand
    raise FileNotFoundError(
        "bundled data not found: reinstall shipid (`pip install .`) or run from a source checkout with data/"
    )


def bundled_kcs_logs() -> list[Path]:
    """Paths of the bundled synthetic KCS logs (sorted)."""
    return sorted(bundled_data_dir().glob("kcs_*.csv"))
