"""notebooks/05_glider.ipynb runs top to bottom (fast configuration)."""
import os
from pathlib import Path

import nbformat
import pytest

NB = Path(__file__).resolve().parents[1] / "notebooks" / "05_glider.ipynb"


def test_notebook_runs(monkeypatch):
    nbclient = pytest.importorskip("nbclient")
    monkeypatch.setenv("SHIPID_FAST", "1")
    monkeypatch.setenv("MPLBACKEND", "Agg")
    root = str(NB.parents[1])
    monkeypatch.setenv("PYTHONPATH", root + os.pathsep + os.environ.get("PYTHONPATH", ""))
    nb = nbformat.read(NB, as_version=4)
    assert not any(c.get("outputs") for c in nb.cells if c.cell_type == "code"), "commit the notebook without outputs"
    client = nbclient.NotebookClient(nb, timeout=300, kernel_name="python3", resources={"metadata": {"path": root}})
    client.execute()
    text = "".join(o.get("text", "") for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", []))
    assert "returned to the surface" in text
