"""Both notebooks execute top to bottom on tiny data (nbclient), and are stored without outputs."""
from __future__ import annotations

import json
import os
import pathlib

import nbformat
import pytest
from nbclient import NotebookClient

INLINE = "module://matplotlib_inline.backend_inline"  # figures become outputs, as in Jupyter
NOTEBOOKS = pathlib.Path(__file__).resolve().parents[2] / "notebooks"


def _execute(name: str, env: dict[str, str], cwd: pathlib.Path) -> nbformat.NotebookNode:
    nb = nbformat.read(NOTEBOOKS / name, as_version=4)
    old = {k: os.environ.get(k) for k in env}
    os.environ.update(env)  # the kernel inherits this process's environment
    try:
        NotebookClient(nb, timeout=600, kernel_name="python3", resources={"metadata": {"path": str(cwd)}}).execute()
    finally:
        for k, v in old.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
    return nb


@pytest.mark.parametrize("name", ["scaling.ipynb", "results.ipynb"])
def test_notebooks_are_stored_without_outputs(name):
    # outputs of one machine's run go stale with every change and bloat the history; the notebooks are
    # executed by the test below instead
    nb = nbformat.read(NOTEBOOKS / name, as_version=4)
    code = [c for c in nb.cells if c.cell_type == "code"]
    assert code, f"{name}: no code cells"
    assert not any(c.outputs for c in code), f"{name}: clear its outputs before committing"
    assert all(c.execution_count is None for c in code), f"{name}: clear its execution counts before committing"


def _figures(nb) -> int:
    return sum(1 for c in nb.cells if c.cell_type == "code" for o in c.outputs
               if "image/png" in o.get("data", {}))


def test_scaling_then_results_notebooks_run_on_tiny_data(tmp_path, structural_model):
    root = str(NOTEBOOKS.parents[0])
    env = {"BP_WORK": str(tmp_path / "work"), "BP_AREAS": "40,70", "BP_WORKERS": "1,2", "BP_DENSITY": "1000",
           "BP_SEED": "5", "BP_MODEL": structural_model, "PYTHONPATH": root, "MPLBACKEND": INLINE}
    nb = _execute("scaling.ipynb", env, tmp_path)
    assert _figures(nb) >= 3  # throughput plots, floor plan, 3D detections
    for area in (40, 70):
        for w in (1, 2):
            run = tmp_path / "work" / f"run-{area}m2-{w}w"
            assert (run / "report.html").is_file() and (run / "metrics.json").is_file()
    run = tmp_path / "work" / "run-70m2-2w"
    nb = _execute("results.ipynb", {"BP_RUN": str(run), "PYTHONPATH": root, "MPLBACKEND": INLINE}, tmp_path)
    assert _figures(nb) >= 2  # AP bars and the spaces' footprints
    spaces = json.loads((run / "spaces.geojson").read_text())["features"]
    text = "".join(o.get("text", "") + json.dumps(o.get("data", {})) for c in nb.cells if c.cell_type == "code"
                   for o in c.outputs)
    assert str(len(spaces)) in text
    # opened from notebooks/ after make demo (no BP_RUN): it finds ../demo-output
    (tmp_path / "demo-output").symlink_to(run, target_is_directory=True)
    (tmp_path / "notebooks").mkdir()
    saved = os.environ.pop("BP_RUN", None)
    try:
        nb = _execute("results.ipynb", {"PYTHONPATH": root, "MPLBACKEND": INLINE}, tmp_path / "notebooks")
    finally:
        if saved is not None:
            os.environ["BP_RUN"] = saved
    assert _figures(nb) >= 2
