"""The example notebook, executed headless as a user would run it (issue 13)."""

from __future__ import annotations

import nbformat
from nbclient import NotebookClient

from conftest import REPO

NOTEBOOK = REPO / "docs" / "examples" / "tortwin.ipynb"


def test_the_example_notebook_runs_without_errors():
    notebook = nbformat.read(NOTEBOOK, as_version=4)
    client = NotebookClient(
        notebook,
        timeout=600,
        kernel_name="python3",
        resources={"metadata": {"path": str(NOTEBOOK.parent)}},
    )
    client.execute()  # raises CellExecutionError with the cell and its traceback
    outputs = [o for cell in notebook.cells if cell.cell_type == "code" for o in cell.get("outputs", [])]
    assert not [o for o in outputs if o.get("output_type") == "error"]
    images = [o for o in outputs if "image/png" in o.get("data", {})]
    assert len(images) >= 3, "the plots of mu at the sites, mu(d) and the residuals"
    text = "".join(o.get("text", "") for o in outputs)
    assert "Found rail_ageing" in text, text
    # The rerun viewer where rerun-notebook is installed (it is in CI).
    try:
        import rerun_notebook  # noqa: F401
    except ImportError:
        return
    widgets = [o for o in outputs if "application/vnd.jupyter.widget-view+json" in o.get("data", {})]
    assert widgets, "the rerun viewer widget"
