"""The posterior-analysis notebook runs top to bottom on a small NUTS run, and its own checks hold."""

import os
from pathlib import Path

import pytest

NOTEBOOK = Path(__file__).resolve().parents[1] / "notebooks" / "posterior_analysis.ipynb"


@pytest.mark.slow  # ~5 min on 2 cores (the emulator's grid and NUTS); the control notebook is slow as well
def test_posterior_analysis_notebook_executes():
    nbformat = pytest.importorskip("nbformat")
    nbclient = pytest.importorskip("nbclient")
    nb = nbformat.read(NOTEBOOK, as_version=4)
    os.environ["GROWJAX_NOTEBOOK_QUICK"] = "1"  # inherited by the kernel: 0–2 s, 2 chains × 100 + 100
    client = nbclient.NotebookClient(nb, timeout=600, kernel_name="python3",
                                     resources={"metadata": {"path": str(NOTEBOOK.parent)}})
    client.execute()  # raises CellExecutionError on any failing cell, the notebook's assertions included
    outputs = "".join(o.get("text", "") for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", []))
    assert "R-hat max" in outputs and "share of measured points inside the band" in outputs
