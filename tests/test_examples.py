"""examples/quickstart.ipynb runs from top to bottom in a fresh kernel (nbclient), and what it shows is
the run it made: Table I's counts are those of the episodes.parquet it wrote, counted here; the figure
is an image. The notebook is kept without outputs (what it shows depends on the machine's run)."""

from __future__ import annotations

import pandas as pd
import pytest

from pedsafe_sumo import REPO_ROOT

nbformat = pytest.importorskip("nbformat")
nbclient = pytest.importorskip("nbclient")

NOTEBOOK = REPO_ROOT / "examples" / "quickstart.ipynb"


def tagged_output(notebook, tag: str) -> dict:
    """The result (execute_result or display_data) of the cell tagged `tag`."""
    cell = next(c for c in notebook.cells if tag in c.get("metadata", {}).get("tags", []))
    return next(o for o in cell.outputs if o.output_type in ("execute_result", "display_data"))


def test_the_notebook_is_kept_without_outputs():
    notebook = nbformat.read(NOTEBOOK, as_version=4)
    code = [cell for cell in notebook.cells if cell.cell_type == "code"]
    assert code and all(not cell.outputs and cell.execution_count is None for cell in code)


@pytest.mark.slow
def test_quickstart_notebook_runs_and_shows_its_run(tmp_path):
    notebook = nbformat.read(NOTEBOOK, as_version=4)
    client = nbclient.NotebookClient(
        notebook, timeout=1200, kernel_name="python3", resources={"metadata": {"path": str(tmp_path)}}
    )
    client.execute()  # raises CellExecutionError, with the cell's traceback, if a cell fails

    rows = pd.read_parquet(tmp_path / "quickstart-run" / "episodes.parquet")
    assert len(rows) == 6  # 3 pairs, SV and V2I
    # Table I as the notebook shows it (its text form: a header line, then one line per row).
    text = tagged_output(notebook, "table-one")["data"]["text/plain"].splitlines()
    header = text[0].split()
    shown = pd.DataFrame([line.split()[1:] for line in text[1:]], columns=header)
    assert list(shown["condition"]) == ["sv", "v2i"]
    for _, line in shown.iterrows():
        mine = rows[(rows["condition"] == line["condition"]) & (rows["status"] == "ok")]
        n = int(line["n"])
        assert n == len(mine) == 3
        assert int(line["n_error"]) == int((rows["condition"] == line["condition"]).sum()) - len(mine)
        assert round(float(line["collision_rate"]) * n) == int(mine["collision"].sum())
        assert (
            abs(float(line["conflict_rate"]) * n - int((mine["conflict"] & ~mine["collision"]).sum())) < 1e-3
        )
    figure = tagged_output(notebook, "figure")
    assert figure["data"]["image/png"]
