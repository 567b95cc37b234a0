"""Run every notebook here and save it with its outputs, so that its figures show when the repository is browsed.

Usage (from the repository root, in the environment the README sets up): ``python notebooks/execute.py [NAME ...]``.
Figures are stored as PNG at 72 dpi with a 64-colour palette (line plots lose nothing visible, the files shrink
about threefold) to keep the repository small; ``tests/test_notebooks.py`` executes them again.
"""

from __future__ import annotations

import base64
import io
import os
import sys
import tempfile
from pathlib import Path

import nbclient
import nbformat
from PIL import Image

HERE = Path(__file__).resolve().parent
DPI = 72  # [dots per inch] of the stored figures


def _small_png(encoded: str) -> str:
    """A base64 PNG re-encoded with an adaptive 64-colour palette."""
    image = Image.open(io.BytesIO(base64.b64decode(encoded))).convert("RGB")
    buffer = io.BytesIO()
    image.quantize(colors=64).save(buffer, format="PNG", optimize=True)
    return base64.b64encode(buffer.getvalue()).decode("ascii")


def execute(path: Path) -> None:
    notebook = nbformat.read(path, as_version=4)
    with tempfile.TemporaryDirectory() as work:
        rc = Path(work) / "matplotlibrc"
        rc.write_text(f"figure.dpi: {DPI}\nsavefig.dpi: {DPI}\n")
        os.environ["MATPLOTLIBRC"] = str(rc)
        os.environ.pop("MPLBACKEND", None)  # the kernel's inline backend: figures become image/png outputs
        client = nbclient.NotebookClient(
            notebook, timeout=900, kernel_name="python3", resources={"metadata": {"path": work}}
        )
        client.execute()
    for number, cell in enumerate(notebook.cells):
        cell.setdefault("id", f"cell-{number}")  # stable ids (nbformat 4.5), not random ones per run
        if cell.cell_type == "code":
            cell.metadata.pop("execution", None)  # timings would change on every run
            for output in cell.get("outputs", []):
                if "image/png" in output.get("data", {}):
                    output["data"]["image/png"] = _small_png(output["data"]["image/png"])
    nbformat.write(notebook, path)
    print(f"{path.name}: {path.stat().st_size / 1024:.0f} KiB")


if __name__ == "__main__":
    names = sys.argv[1:]
    for path in sorted(HERE.glob("*.ipynb")):
        if not names or path.stem in names or path.name in names:
            execute(path)
