"""Every notebook in notebooks/ executes without error (public API only), and is committed with its outputs
(``python notebooks/execute.py``) so that its figures show when the repository is browsed."""

from __future__ import annotations

from pathlib import Path

import pytest

nbformat = pytest.importorskip("nbformat")
nbclient = pytest.importorskip("nbclient")

NOTEBOOKS = sorted((Path(__file__).resolve().parents[1] / "notebooks").glob("*.ipynb"))


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_notebook_executes(path, tmp_path, monkeypatch):
    notebook = nbformat.read(path, as_version=4)
    code = [cell for cell in notebook.cells if cell.cell_type == "code"]
    assert all(cell.get("execution_count") for cell in code), f"{path.name}: run notebooks/execute.py before committing"
    for cell in code:
        if _draws(cell):  # its figure is saved, so it shows when the repository is browsed
            assert any("image/png" in o.get("data", {}) for o in cell.get("outputs", [])), (path.name, cell.source)
    monkeypatch.setenv("MPLBACKEND", "Agg")
    client = nbclient.NotebookClient(
        notebook, timeout=600, kernel_name="python3", resources={"metadata": {"path": str(tmp_path)}}
    )
    client.execute()


def _draws(cell) -> bool:  # noqa: ANN001
    """Whether a code cell ends with a figure on screen (it creates one with matplotlib)."""
    return any(call in cell.source for call in ("plt.subplots(", "plt.figure(", "= plot_profiles("))


def test_all_capability_notebooks_exist():
    stems = {p.stem for p in NOTEBOOKS}
    assert "01_quickstart" in stems
