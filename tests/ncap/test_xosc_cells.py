"""A Euro NCAP cell exports as OpenSCENARIO the way any logged case does: through the replay tool
(scenario = the cell id, episode 0), ASAM's checker passing and the trajectories the cell's case log."""

from __future__ import annotations

import math
import os
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pandas as pd
import pytest

from pedsafe_sumo import REPO_ROOT
from tests.replay.asam_qc import run_checker

TESTS_DIR = Path(__file__).parent
CELL = "CPNA-25_10kmh"


def run(module: str, *args: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO_ROOT), str(TESTS_DIR)])}
    return subprocess.run(
        [sys.executable, "-m", module, *args], capture_output=True, text=True, env=env, timeout=300
    )


@pytest.mark.slow
def test_an_ncap_cell_exports_as_a_checked_openscenario(tmp_path):
    out = tmp_path / "ncap"
    done = run(
        "pedsafe_sumo.ncap",
        *("--out", str(out), "--tests", "CPNA-25", "--speeds", "10", "--condition", "sv"),
        *("--algorithm", "agents:NeverBrakes"),
    )
    assert done.returncode == 0, done.stderr
    assert pd.read_csv(out / "ncap.csv")["cell_id"].tolist() == [CELL]

    xosc_path = tmp_path / "cell.xosc"
    replay = run(
        "pedsafe_sumo.replay",
        *(
            str(out),
            "--scenario",
            CELL,
            "--episode",
            "0",
            "--condition",
            "sv",
            "--export-xosc",
            str(xosc_path),
        ),
    )
    assert replay.returncode == 0, replay.stdout + replay.stderr
    assert "trajectory matches the log" in replay.stdout

    results = run_checker("xosc", xosc_path, tmp_path)
    assert [r for r in results if r.status != "completed" or r.issues] == []

    (case_log,) = (out / "cases").glob("*.parquet")
    log = pd.read_parquet(case_log)
    root = ET.parse(xosc_path).getroot()
    for entity, x_column, y_column in (("ego", "ego_x_m", "ego_y_m"), ("ped", "ped_x_m", "ped_y_m")):
        group = next(
            g
            for g in root.iter("ManeuverGroup")
            if [r.get("entityRef") for r in g.iter("EntityRef")] == [entity]
        )
        vertices = list(group.iter("Vertex"))
        assert len(vertices) == len(log)
        # The vertex is the reference point; the box centre is the BoundingBox Center ahead of it
        # along the heading (a vehicle's rear axle; a pedestrian's own centre, Center x = 0).
        ahead_m = float(root.find(f".//ScenarioObject[@name='{entity}']/*/BoundingBox/Center").get("x"))
        positions = [v.find("Position/WorldPosition") for v in vertices]
        headings = [float(p.get("h")) for p in positions]
        xs = [float(p.get("x")) + ahead_m * math.cos(h) for p, h in zip(positions, headings)]
        ys = [float(p.get("y")) + ahead_m * math.sin(h) for p, h in zip(positions, headings)]
        assert max(abs(a - b) for a, b in zip(xs, log[x_column])) < 1e-9
        assert max(abs(a - b) for a, b in zip(ys, log[y_column])) < 1e-9
