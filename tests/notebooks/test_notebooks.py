"""The notebooks in ``notebooks/``: stored clean (fast), and run top to bottom (slow).

The slow test executes each notebook with nbclient on the ``python3`` kernel, from the
notebooks folder, with MLflow pointed at a SQLite file in ``tmp_path`` and the notebook's
work directory (``CDPR_NOTEBOOK_WORK``) in ``tmp_path``. Each notebook asserts its own
figures against known truths (simulator truth, sensor noise, published EMPS errors), so a
failing assertion in a cell fails the test.
"""

from __future__ import annotations

import re
from pathlib import Path

import nbformat
import pytest

NOTEBOOK_DIR = Path(__file__).resolve().parents[2] / "notebooks"
NOTEBOOKS = sorted(NOTEBOOK_DIR.glob("*.ipynb"))
EXPECTED = {"01_virtual_lab", "02_model_comparison", "03_identification", "04_diagnose_emps"}
#: a code line that imports the package (no copied code: the notebooks call it)
IMPORTS_PACKAGE = re.compile(r"^\s*(import cdpr_pipeline\b|from cdpr_pipeline(\.\w+)* import )",
                             re.MULTILINE)
CELL_TIMEOUT_S = 600


def _read(path: Path) -> nbformat.NotebookNode:
    return nbformat.read(path, as_version=nbformat.NO_CONVERT)


def _code_cells(nb: nbformat.NotebookNode) -> list[nbformat.NotebookNode]:
    return [c for c in nb.cells if c.cell_type == "code"]


def test_the_four_notebooks_are_there():
    assert EXPECTED <= {p.stem for p in NOTEBOOKS}


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_notebook_is_valid_and_stored_without_outputs(path):
    nb = _read(path)
    nbformat.validate(nb)
    assert nb.nbformat == 4
    assert nb.metadata["kernelspec"]["name"] == "python3"
    code = _code_cells(nb)
    assert code, f"{path.name} has no code cell"
    for i, cell in enumerate(code):
        assert cell.outputs == [], f"{path.name}: code cell {i} is stored with outputs"
        assert cell.execution_count is None, f"{path.name}: code cell {i} has an execution count"
    assert any(IMPORTS_PACKAGE.search(c.source) for c in code), \
        f"{path.name} does not import cdpr_pipeline"


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_notebook_writes_under_its_work_directory_and_uses_the_default_tracking(path):
    nb = _read(path)
    source = "\n".join(c.source for c in _code_cells(nb))
    assert 'os.environ.get("CDPR_NOTEBOOK_WORK")' in source
    # no tracking.uri: $MLFLOW_TRACKING_URI, else MLflow's sqlite:///mlflow.db in the cwd, applies
    assert "tracking.uri" not in source
    assert nb.cells[0].cell_type == "markdown"


@pytest.mark.slow
@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_notebook_runs_top_to_bottom(path, tmp_path, monkeypatch):
    from nbclient import NotebookClient

    monkeypatch.setenv("MLFLOW_TRACKING_URI", f"sqlite:///{tmp_path / 'mlflow.db'}")
    monkeypatch.setenv("CDPR_NOTEBOOK_WORK", str(tmp_path))
    before = sorted(NOTEBOOK_DIR.rglob("*"))
    nb = nbformat.read(path, as_version=4)
    client = NotebookClient(nb, kernel_name="python3", timeout=CELL_TIMEOUT_S,
                            resources={"metadata": {"path": str(NOTEBOOK_DIR)}})
    try:
        client.execute()          # raises CellExecutionError, with the traceback, on any error
    finally:
        nbformat.write(nb, tmp_path / f"executed_{path.name}")    # for inspection
    errors = [o for c in _code_cells(nb) for o in c.outputs if o.output_type == "error"]
    assert not errors
    written = {p.name for p in tmp_path.iterdir()} - {"mlflow.db", f"executed_{path.name}"}
    assert written, "the notebook wrote nothing to its work directory"
    # everything went to the work directory: nothing new beside the notebooks (e.g. mlruns/)
    assert sorted(NOTEBOOK_DIR.rglob("*")) == before
