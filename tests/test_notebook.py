"""notebooks/quickstart.ipynb runs top to bottom at a tiny size, so it cannot rot."""
import os

import nbformat
import pytest
from nbclient import NotebookClient

NB = os.path.join(os.path.dirname(__file__), "..", "notebooks", "quickstart.ipynb")


def test_quickstart_notebook_executes(tmp_path, monkeypatch):
    monkeypatch.setenv("FOVEATED_MI_NB_SIZE", "32")
    monkeypatch.setenv("FOVEATED_MI_VARIANT", "llvm_ad_rgb")
    nb = nbformat.read(NB, as_version=4)
    client = NotebookClient(nb, timeout=600, kernel_name="python3",
                            resources={"metadata": {"path": str(tmp_path)}})
    client.execute()
    outputs = "".join(o.get("text", "") for c in nb.cells if c.cell_type == "code"
                      for o in c.get("outputs", []))
    assert "PSNR" in outputs and "llvm_ad_rgb" in outputs
    assert any(o.get("output_type") == "display_data" for c in nb.cells
               if c.cell_type == "code" for o in c.get("outputs", [])), "no figure produced"
