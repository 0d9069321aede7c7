"""notebooks/04_routing.ipynb runs top to bottom (SHIPID_FAST=1)."""
import os
from pathlib import Path

import nbformat
import pytest

NB = Path(__file__).resolve().parents[1] / "notebooks" / "04_routing.ipynb"


def test_routing_notebook_runs(monkeypatch):
    nbclient = pytest.importorskip("nbclient")
    monkeypatch.setenv("SHIPID_FAST", "1")
    monkeypatch.setenv("OPENBLAS_NUM_THREADS", "1")
    root = str(NB.parents[1])
    monkeypatch.setenv("PYTHONPATH", root + os.pathsep + os.environ.get("PYTHONPATH", ""))
    nb = nbformat.read(NB, as_version=4)
    nbclient.NotebookClient(nb, timeout=120, kernel_name="python3", resources={"metadata": {"path": root}}).execute()
    out = "".join(o.get("text", "") for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", []))
    assert "PMP:" in out and "saving vs DOPSO" in out
