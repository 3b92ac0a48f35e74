"""--export-fcd writes SUMO floating car data that SUMO's own tools read: sumolib parses it back to the
logged positions, and tools/plot_trajectories.py and tools/traceExporter.py run on it."""

from __future__ import annotations

import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import sumo
import sumolib
from replay_runs import case_files, run_cli

from pedsafe_sumo.io.cases import read_case

SUMO_TOOLS = Path(sumo.SUMO_HOME) / "tools"
EPISODE, CONDITION = 1, "v2i"


@pytest.fixture(scope="module")
def exported(replay_run, tmp_path_factory):
    out = tmp_path_factory.mktemp("fcd") / "case.fcd.xml"
    proc = run_cli(
        "pedsafe_sumo.replay",
        str(replay_run),
        *("--episode", str(EPISODE), "--condition", CONDITION, "--export-fcd", str(out)),
        env={k: v for k, v in os.environ.items() if k != "DISPLAY"},  # no display needed
    )
    assert proc.returncode == 0, proc.stderr
    log, meta = read_case(case_files(replay_run, EPISODE, CONDITION)[0])
    return out, log, meta


@pytest.mark.slow
def test_sumolib_reads_the_logged_positions_back(exported):
    path, log, meta = exported
    setup = meta["setup"]
    ego_length_m = setup.ego.size.length_m
    ego, ped, times, vehicle_ids = [], [], [], set()
    for step, vehicle in sumolib.xml.parse_fast_nested(
        str(path), "timestep", ["time"], "vehicle", ["id", "x", "y", "angle", "speed"]
    ):
        vehicle_ids.add(vehicle.id)
        if vehicle.id == "ego":
            times.append(float(step.time))
            ego.append([float(vehicle.x), float(vehicle.y), float(vehicle.angle), float(vehicle.speed)])
    for _, person in sumolib.xml.parse_fast_nested(
        str(path), "timestep", ["time"], "person", ["id", "x", "y", "angle", "speed", "edge"]
    ):
        assert person.id == "ped" and person.edge
        ped.append([float(person.x), float(person.y), float(person.speed)])
    ego, ped = np.array(ego), np.array(ped)

    assert len(ego) == len(ped) == len(log)
    assert np.allclose(times, log["time_s"], atol=1e-9)
    # FCD has SUMO's vehicle position, the middle of the front bumper, and SUMO's angle (degrees
    # clockwise from north); the log has the footprint centre: half a length back along the heading.
    heading = np.radians(ego[:, 2])
    centre_x = ego[:, 0] - ego_length_m / 2 * np.sin(heading)
    centre_y = ego[:, 1] - ego_length_m / 2 * np.cos(heading)
    assert np.abs(centre_x - log["ego_x_m"]).max() < 1e-5
    assert np.abs(centre_y - log["ego_y_m"]).max() < 1e-5
    assert np.abs(ego[:, 3] - log["ego_speed_mps"]).max() < 1e-5
    assert np.abs(ped[:, 0] - log["ped_x_m"]).max() < 1e-6
    assert np.abs(ped[:, 1] - log["ped_y_m"]).max() < 1e-6
    assert np.abs(ped[:, 2] - np.hypot(log["ped_vx_mps"], log["ped_vy_mps"])).max() < 1e-6
    # The scene's other vehicles are there too: the occluders and the queue of the kerb lane.
    assert {v.vehicle_id for v in setup.parked} <= vehicle_ids


@pytest.mark.slow
def test_sumolib_output_parser_reads_every_timestep(exported):
    path, log, meta = exported
    steps = list(sumolib.output.parse(str(path), "timestep"))
    assert len(steps) == len(log)
    last = steps[-1]
    assert float(last.time) == pytest.approx(log["time_s"].iloc[-1])
    (person,) = last.person
    assert (float(person.x), float(person.y)) == pytest.approx(
        (log["ped_x_m"].iloc[-1], log["ped_y_m"].iloc[-1]), abs=1e-6
    )
    ego = next(v for v in last.vehicle if v.id == "ego")
    # On a lane of its route, at a finite position along it.
    assert ego.lane.rsplit("_", 1)[0] in meta["setup"].ego_route and math.isfinite(float(ego.pos))


@pytest.mark.slow
@pytest.mark.parametrize(
    ("plot", "persons"), [("xy", False), ("ts", False), ("ts", True)], ids=["xy", "ts", "persons"]
)
def test_plot_trajectories_runs_on_the_export(exported, tmp_path, plot, persons):
    path, _, _ = exported
    png = tmp_path / "trajectories.png"
    command = [
        sys.executable,
        str(SUMO_TOOLS / "plot_trajectories.py"),
        "-t",
        plot,
        "--blind",
        "-o",
        str(png),
    ]
    proc = subprocess.run(
        [*command, *(["--persons"] if persons else []), str(path)],
        capture_output=True,
        text=True,
        timeout=120,
        env={**os.environ, "MPLBACKEND": "Agg"},
    )
    assert proc.returncode == 0, proc.stderr
    assert png.stat().st_size > 5000


@pytest.mark.slow
def test_trace_exporter_converts_the_export(exported, tmp_path):
    path, log, _ = exported
    gpsdat = tmp_path / "case.gpsdat"
    proc = subprocess.run(
        [
            sys.executable,
            str(SUMO_TOOLS / "traceExporter.py"),
            "--fcd-input",
            str(path),
            "--gpsdat-output",
            str(gpsdat),
        ],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 0, proc.stderr
    ego_rows = [line.split("\t") for line in gpsdat.read_text().splitlines() if line.startswith("ego\t")]
    assert len(ego_rows) == len(log)
