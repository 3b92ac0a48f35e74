"""The report on a small real batch: every table and figure written.

The AD stack never brakes, so every pair collides and is kept as a case: the case figure has a pair
to draw whatever the seed.
"""

from __future__ import annotations

import subprocess
import sys

import matplotlib.image
import pandas as pd
import pytest

from pedsafe_sumo import REPO_ROOT
from pedsafe_sumo.scenarios.specs import SCENARIOS


@pytest.mark.slow
def test_report_on_a_small_batch_writes_every_table_and_figure(tmp_path):
    out = tmp_path / "run"
    batch = subprocess.run(
        [
            sys.executable,
            "-m",
            "pedsafe_sumo.batch",
            "--scenario",
            "all",
            "--episodes",
            "2",
            "--workers",
            "2",
            "--out",
            str(out),
            "--algorithm",
            "tests.sim.plugin_agents:NeverBrakes",
        ],
        capture_output=True,
        text=True,
        cwd=REPO_ROOT,
        timeout=600,
    )
    assert batch.returncode == 0, batch.stderr[-2000:]
    report = subprocess.run(
        [sys.executable, "-m", "pedsafe_sumo.report", str(out)],
        capture_output=True,
        text=True,
        cwd=REPO_ROOT,
        timeout=300,
    )
    assert report.returncode == 0, report.stderr[-2000:]
    assert "case figure: jaywalking episode" in report.stdout
    for name in ("injury_vs_age", "injury_vs_speed", "first_detection_distance", "case_speed_vs_frame"):
        image = matplotlib.image.imread(out / "figures" / f"{name}.png")
        assert image.shape[0] > 100 and float(image[..., :3].std()) > 0.01
    table = pd.read_csv(out / "tables" / "table1.csv")
    # --scenario all runs every scenario the site hosts and names the others ("skipping scenario ...").
    skipped = {name for name in SCENARIOS if f"skipping scenario '{name}'" in batch.stdout}
    assert sorted(table["scenario"].unique()) == sorted(set(SCENARIOS) - skipped)
    assert (table["n"] == 2).all() and (table["n_error"] == 0).all()
    for name in ("table1.md", "paired.csv", "paired.md"):
        assert (out / "tables" / name).stat().st_size > 0
