"""Turns from one-lane approaches, on the zhixin clip (tests/network/data/osm, ODbL) whose
north and south approaches have one vehicle lane each.

On networks with refuges the engine gives the scenario's pedestrian a walking route that ends on its
sidewalk (sim.staging.add_pedestrian), because otherwise a right_turn episode from the north approach
crashes libsumo 1.28 (segmentation fault). The mechanism (docs/sites.md): the pedestrian, moved by
person.moveToXY, steps off the crosswalk over the road turned into onto the median refuge of that divided
road, a walking area no sidewalk reaches; SUMO rebuilds the person's route to end on that walking area, its
pedestrian router finds no way from the refuge to the route's end (itself), and
MSPModel_Striping::getNextLane's fallback for that case reads the previous lane, which PState::moveToXY
passes as a null pointer. With that route the turns are staged there.
"""

from __future__ import annotations

import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import pandas as pd
import pytest

from pedsafe_sumo import REPO_ROOT
from pedsafe_sumo.network.sites import resolve_site

#: Moves the engine's pedestrian (sim.staging.add_pedestrian) along the north approach's right-turn
#: crosswalk and 2 m beyond its far end, as the behaviour model does (moveToXY, keepRoute=2, one step
#: each), and prints the edge it ends on.
MOVE_ONTO_REFUGE = textwrap.dedent(
    """
    import math, sys
    import libsumo as api
    from pedsafe_sumo.network.sites import resolve_site
    from pedsafe_sumo.scenarios.geometry import load_approach, load_turn
    from pedsafe_sumo.sim.staging import PED_ID, add_pedestrian
    site = resolve_site(sys.argv[1])
    refuges = sys.argv[2] == "refuges"
    approach, turn = load_approach(site, "N"), load_turn(site, "right", "N")
    api.start(["sumo", "-c", str(site.file("sumocfg")), "--no-step-log", "--no-warnings"])
    add_pedestrian(api, approach.sidewalk_lane_id.rsplit("_", 1)[0], "DEFAULT_PEDTYPE", refuges)
    (ax, ay), (bx, by) = turn.crosswalk_path
    length = math.dist((ax, ay), (bx, by))
    ux, uy = (bx - ax) / length, (by - ay) / length
    angle = math.degrees(math.atan2(ux, uy)) % 360.0  # SUMO: clockwise from north
    steps = int((length + 2.7) / 0.06)
    for k in range(steps + 1):
        along = -0.7 + 0.06 * k
        api.person.moveToXY(PED_ID, "", ax + ux * along, ay + uy * along, angle=angle, keepRoute=2,
                            matchThreshold=10.0)
        api.simulationStep()
    print("ended on", api.person.getRoadID(PED_ID))
    api.close()
    """
)


def _move_onto_refuge(folder: Path, mode: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-c", MOVE_ONTO_REFUGE, str(folder), mode],
        capture_output=True, text=True, cwd=REPO_ROOT, timeout=120,
    )  # fmt: skip


@pytest.mark.slow
def test_a_pedestrian_moved_onto_a_median_refuge_does_not_crash_sumo(zhixin):
    from pedsafe_sumo.scenarios.geometry import refuge_walkingareas

    refuges = refuge_walkingareas(resolve_site(str(zhixin)))
    assert refuges  # the west arm is a divided road: a refuge between its two crosswalks
    proc = _move_onto_refuge(zhixin, "refuges")
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert any(f"ended on {r}\n" in proc.stdout for r in refuges), proc.stdout
    # The same moves with the waiting stage alone (the staging before): SUMO dies of a segmentation fault.
    before = _move_onto_refuge(zhixin, "none")
    assert before.returncode == -signal.SIGSEGV, (before.returncode, before.stderr[-500:])


@pytest.mark.slow
def test_right_turns_from_the_one_lane_approaches_run_under_both_conditions(zhixin, tmp_path):
    out = tmp_path / "run"
    proc = subprocess.run(
        [sys.executable, "-m", "pedsafe_sumo.batch", "--scenario", "right_turn", "--approach", "all",
         "--episodes", "2", "--workers", "1", "--site", str(zhixin), "--out", str(out)],
        capture_output=True, text=True, cwd=REPO_ROOT, timeout=600,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-2000:]
    episodes = pd.read_parquet(out / "episodes.parquet")
    for arm in ("N", "S"):
        rows = episodes[episodes["approach"] == arm]
        assert sorted(rows["condition"]) == ["sv", "sv", "v2i", "v2i"]
        assert (rows["status"] == "ok").all(), rows["error"].tolist()
    # Staged from the one vehicle lane of each: the ego starts on it and turns right off it.
    from pedsafe_sumo.control.reference import ReferenceStack
    from pedsafe_sumo.params import load_params
    from pedsafe_sumo.scenarios.geometry import load_approach
    from pedsafe_sumo.scenarios.specs import get_scenario
    from pedsafe_sumo.sim.episode import EpisodeRunner

    site = resolve_site(str(zhixin))
    runner = EpisodeRunner(site, load_params(None), ReferenceStack)
    try:
        for arm in ("N", "S"):
            lanes = load_approach(site, arm).lane_ids
            setup = runner.draw_setup(get_scenario("right_turn").with_overrides({"approach": arm}), 1)
            assert len(lanes) == 1 and setup.ego.lane_id == lanes[0]
    finally:
        runner.close()
