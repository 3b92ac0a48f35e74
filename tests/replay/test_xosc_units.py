"""pedsafe_sumo.replay.xosc's bookkeeping on a hand-made three-step episode (a stand-in for the TraCI
handle, the real netconvert and ASAM's real checker): who is exported, where a SUMO front bumper puts
the centre, the pedestrian's heading, a vehicle that leaves removed at its time, one that enters left
out. The end-to-end export of a real case is tests/replay/test_xosc_export.py."""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from types import SimpleNamespace

import pytest
from asam_qc import run_checker

from pedsafe_sumo.network.sites import get_site
from pedsafe_sumo.replay.xosc import TrackRecorder, write_xosc

STEP_S = 0.05
#: Per step: vehicle id -> (SUMO front-bumper x, y, SUMO angle in degrees clockwise from north).
STEPS = [
    {"ego": (104.6, 50.0, 90.0), "leaver": (20.0, 10.0, 0.0)},
    {"ego": (105.6, 50.0, 90.0), "leaver": (20.0, 11.0, 0.0), "latecomer": (0.0, 0.0, 180.0)},
    {"ego": (106.6, 50.0, 90.0), "latecomer": (0.0, -1.0, 180.0)},
]
SIZES = {"ego": (4.6, 1.8, 1.5), "leaver": (4.0, 1.7, 1.4), "latecomer": (5.0, 2.0, 1.6)}


class FakeVehicles:
    def __init__(self) -> None:
        self.step = 0

    def getIDList(self):  # noqa: N802 (TraCI's names)
        return list(STEPS[self.step])

    def getPosition(self, vid):  # noqa: N802
        return STEPS[self.step][vid][:2]

    def getAngle(self, vid):  # noqa: N802
        return STEPS[self.step][vid][2]

    def getLength(self, vid):  # noqa: N802
        return SIZES[vid][0]

    def getWidth(self, vid):  # noqa: N802
        return SIZES[vid][1]

    def getHeight(self, vid):  # noqa: N802
        return SIZES[vid][2]

    def getColor(self, vid):  # noqa: N802
        return (255, 255, 0, 255)  # SUMO's default, as for a vehicle coloured through its type


def record() -> TrackRecorder:
    vehicles = FakeVehicles()
    api = SimpleNamespace(vehicle=vehicles)
    recorder = TrackRecorder(
        0.3, 1.6, (40, 140, 60), initial_heading_rad=0.5, vehicle_rgb={"ego": (30, 110, 255)}
    )
    ped_velocities = [(0.0, 0.0), (0.0, 1.2), (0.0, 1.2)]
    for step, (vx, vy) in enumerate(ped_velocities):
        vehicles.step = step
        time_s = (step + 1) * STEP_S
        # The log's ego is the footprint centre: 2.3 m behind the front bumper heading east.
        row = {
            "time_s": time_s,
            "ego_x_m": STEPS[step]["ego"][0] - 2.3,
            "ego_y_m": 50.0,
            "ego_yaw_rad": 0.0,
            "ped_x_m": 110.0,
            "ped_y_m": 45.0 + step * 0.06,
            "ped_vx_mps": vx,
            "ped_vy_mps": vy,
        }
        recorder(api, row)
    return recorder


def test_who_is_exported_and_where():
    recorder = record()
    assert list(recorder.exported_vehicles()) == ["ego", "leaver"]
    assert recorder.left_out() == ["latecomer"]
    ego = recorder.vehicles["ego"]
    assert ego.x_m == pytest.approx([102.3, 103.3, 104.3]) and ego.colour_rgb == (30, 110, 255)
    # SUMO angle 0 = north: the centre is half the 4 m length south of the front bumper.
    leaver = recorder.vehicles["leaver"]
    assert leaver.x_m == pytest.approx([20.0, 20.0]) and leaver.y_m == pytest.approx([8.0, 9.0])
    assert leaver.yaw_rad == pytest.approx([math.pi / 2] * 2) and leaver.colour_rgb == (255, 255, 0)
    # Standing: the path's direction given at the start; walking north: pi/2.
    assert recorder.pedestrian.yaw_rad == pytest.approx([0.5, math.pi / 2, math.pi / 2])
    assert (recorder.pedestrian.length_m, recorder.pedestrian.width_m) == (0.6, 0.6)


@pytest.mark.slow
def test_a_vehicle_that_leaves_is_removed_one_step_later_and_the_checker_passes(tmp_path):
    recorder = record()
    xosc_path, xodr_path = write_xosc(
        recorder, get_site("xueqing").file("net.xml"), tmp_path / "unit.xosc", "unit test", STEP_S
    )
    root = ET.parse(xosc_path).getroot()
    names = [o.get("name") for o in root.iter("ScenarioObject")]
    assert names == ["ego", "leaver", "ped"]
    (delete_event,) = [e for e in root.iter("Event") if e.find(".//DeleteEntityAction") is not None]
    assert delete_event.find(".//EntityAction").get("entityRef") == "leaver"
    when = float(delete_event.find(".//SimulationTimeCondition").get("value"))
    assert when == pytest.approx(2 * STEP_S + STEP_S)
    results = run_checker("xosc", xosc_path, tmp_path)
    assert [r for r in results if r.status != "completed" or r.issues] == []
    assert sorted(p.name for p in tmp_path.iterdir() if p.suffix in (".xosc", ".xodr", ".tmp")) == [
        "unit.xodr",
        "unit.xosc",
    ]


def test_a_failed_export_leaves_an_earlier_one_as_it_was(tmp_path):
    earlier = {tmp_path / "case.xosc": "earlier scenario", tmp_path / "case.xodr": "earlier road"}
    for path, text in earlier.items():
        path.write_text(text)
    with pytest.raises(RuntimeError, match="netconvert could not write OpenDRIVE"):
        write_xosc(record(), tmp_path / "missing.net.xml", tmp_path / "case.xosc", "unit test", STEP_S)
    assert {p: p.read_text() for p in tmp_path.iterdir()} == earlier
