"""The notebooks (jupytext percent scripts in notebooks/) execute without errors."""

from __future__ import annotations

from pathlib import Path

import pytest

NOTEBOOKS = Path(__file__).resolve().parents[1] / "notebooks"


@pytest.mark.slow
@pytest.mark.parametrize("name", ["paper_vs_graph", "hive_walkthrough"])
def test_notebook_runs(name: str) -> None:
    jupytext = pytest.importorskip("jupytext", reason="needs the test extra (jupytext)")
    nbclient = pytest.importorskip("nbclient", reason="needs the test extra (nbclient)")
    pytest.importorskip("ipykernel", reason="needs the test extra (ipykernel)")
    notebook = jupytext.read(NOTEBOOKS / f"{name}.py")
    nbclient.NotebookClient(notebook, timeout=300, kernel_name="python3",
                            resources={"metadata": {"path": str(NOTEBOOKS)}}).execute()
    outputs = [o for c in notebook.cells if c.cell_type == "code" for o in c.get("outputs", [])]
    assert not [o for o in outputs if o.get("output_type") == "error"]
    text = "".join(o.get("text", "") for o in outputs if o.get("name") == "stdout")
    if name == "paper_vs_graph":
        assert "graph MAE" in text and "paper MAE (Table III)" in text
    else:
        assert "bag:" in text
