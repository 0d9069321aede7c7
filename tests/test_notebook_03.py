"""notebooks/03_optimal_control.ipynb runs top to bottom (fast configuration)."""
import os
from pathlib import Path

import nbformat
import pytest

NB = Path(__file__).parents[1] / "notebooks" / "03_optimal_control.ipynb"


def test_notebook_03_runs(monkeypatch):
    nbclient = pytest.importorskip("nbclient")
    monkeypatch.setenv("SHIPID_FAST", "1")
    monkeypatch.setenv("PYTHONPATH", str(NB.parents[1]) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    nb = nbformat.read(NB, as_version=4)
    client = nbclient.NotebookClient(nb, kernel_name="python3", timeout=600, resources={"metadata": {"path": str(NB.parent)}})
    client.execute()
    text = "".join(o.get("text", "") for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", []))
    assert "analytic: switch at" in text and "direct-slsqp" in text
