"""pedsafe_sumo.replay.xosc's bookkeeping on a hand-made three-step episode (a stand-in for the TraCI
handle, the real netconvert and ASAM's real checker): who is exported, where a SUMO front bumper puts
the centre and the rear axle, the pedestrian's heading, a vehicle that leaves removed at its time, one
that enters added at its first step, a background person, the traffic light's changes. The end-to-end
export of a real case is tests/replay/test_xosc_export.py and tests/replay/test_xosc_boxes.py."""

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
#: A background person from the second step on (front x, y, SUMO angle), walking east; SUMO's size.
PERSON_STEPS = [{}, {"ped_3": (50.0, 40.0, 90.0)}, {"ped_3": (51.0, 40.0, 90.0)}]
PERSON_SIZE = (0.215, 0.478, 1.72)
#: The Xueqing junction's light (37 links) per step: link 0 green, turning yellow at the third step.
TLS_ID = "cluster_12817118532_12817118533_12817118534_12817118535_#15more"
LIGHT_STEPS = ["G" + "r" * 36, "G" + "r" * 36, "y" + "r" * 36]


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


class FakePersons:
    def __init__(self) -> None:
        self.step = 0

    def getIDList(self):  # noqa: N802 (TraCI's names)
        # The scenario's pedestrian is in SUMO too; the recorder takes them from the log row.
        return ["ped", *PERSON_STEPS[self.step]]

    def getPosition(self, pid):  # noqa: N802
        return PERSON_STEPS[self.step][pid][:2]

    def getAngle(self, pid):  # noqa: N802
        return PERSON_STEPS[self.step][pid][2]

    def getLength(self, pid):  # noqa: N802
        return PERSON_SIZE[0]

    def getWidth(self, pid):  # noqa: N802
        return PERSON_SIZE[1]

    def getHeight(self, pid):  # noqa: N802
        return PERSON_SIZE[2]

    def getColor(self, pid):  # noqa: N802
        return (10, 20, 30, 255)


class FakeLights:
    def __init__(self) -> None:
        self.step = 0

    def getIDList(self):  # noqa: N802 (TraCI's names)
        return [TLS_ID]

    def getRedYellowGreenState(self, tls_id):  # noqa: N802
        return LIGHT_STEPS[self.step]


def record() -> TrackRecorder:
    vehicles, persons, lights = FakeVehicles(), FakePersons(), FakeLights()
    api = SimpleNamespace(vehicle=vehicles, person=persons, trafficlight=lights)
    recorder = TrackRecorder(
        0.3, 1.6, (40, 140, 60), initial_heading_rad=0.5, vehicle_rgb={"ego": (30, 110, 255)}
    )
    ped_velocities = [(0.0, 0.0), (0.0, 1.2), (0.0, 1.2)]
    for step, (vx, vy) in enumerate(ped_velocities):
        vehicles.step = persons.step = lights.step = step
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
    assert list(recorder.exported_vehicles()) == ["ego", "latecomer", "leaver"]
    assert recorder.entered_later() == ["latecomer", "ped_3"]
    ego = recorder.vehicles["ego"]
    assert ego.x_m == pytest.approx([102.3, 103.3, 104.3]) and ego.colour_rgb == (30, 110, 255)
    # SUMO angle 0 = north: the centre is half the 4 m length south of the front bumper.
    leaver = recorder.vehicles["leaver"]
    assert leaver.x_m == pytest.approx([20.0, 20.0]) and leaver.y_m == pytest.approx([8.0, 9.0])
    assert leaver.yaw_rad == pytest.approx([math.pi / 2] * 2) and leaver.colour_rgb == (255, 255, 0)
    # SUMO angle 180 = south: the centre is 2.5 m north of the front bumper, from the second step on.
    latecomer = recorder.vehicles["latecomer"]
    assert latecomer.times_s == pytest.approx([0.1, 0.15]) and latecomer.y_m == pytest.approx([2.5, 1.5])
    # Standing: the path's direction given at the start; walking north: pi/2.
    assert recorder.pedestrian.yaw_rad == pytest.approx([0.5, math.pi / 2, math.pi / 2])
    assert (recorder.pedestrian.length_m, recorder.pedestrian.width_m) == (0.6, 0.6)
    # The background person: SUMO's size, centre half its 0.215 m length behind its front (walking east).
    person = recorder.persons["ped_3"]
    assert person.x_m == pytest.approx([50.0 - 0.1075, 51.0 - 0.1075]) and person.yaw_rad == pytest.approx(
        [0, 0]
    )
    assert (person.length_m, person.width_m, person.colour_rgb) == (0.215, 0.478, (10, 20, 30))
    changes = recorder.signal_changes
    assert [c.state[:2] for c in changes] == ["Gr", "yr"]
    assert [c.time_s for c in changes] == pytest.approx([0.05, 0.15])


def _vertices(root, name: str) -> list[tuple[float, float, float, float]]:
    group = next(
        g for g in root.iter("ManeuverGroup") if [r.get("entityRef") for r in g.iter("EntityRef")] == [name]
    )
    return [
        (float(v.get("time")), *(float(v.find("Position/WorldPosition").get(k)) for k in "xyh"))
        for v in group.iter("Vertex")
    ]


@pytest.mark.slow
def test_entities_enter_and_leave_at_their_steps_and_the_checker_passes(tmp_path):
    recorder = record()
    xosc_path, xodr_path = write_xosc(
        recorder, get_site("xueqing").file("net.xml"), tmp_path / "unit.xosc", "unit test", STEP_S
    )
    root = ET.parse(xosc_path).getroot()
    names = [o.get("name") for o in root.iter("ScenarioObject")]
    assert names == ["ego", "latecomer", "leaver", "ped", "ped_3"]
    assert {p.get("entityRef") for p in root.findall("Storyboard/Init/Actions/Private")} == {
        "ego",
        "leaver",
        "ped",
    }

    # The ego's reference point is its rear axle: 20 % of 4.6 m ahead of the rear, 1.38 m behind the
    # centre; the box Center 1.38 m ahead of it; colour #1E6EFF (30, 110, 255).
    ego = root.find(".//ScenarioObject[@name='ego']/Vehicle")
    assert float(ego.find("BoundingBox/Center").get("x")) == pytest.approx(1.38)
    assert float(ego.find("Axles/RearAxle").get("positionX")) == 0.0
    assert float(ego.find("Axles/FrontAxle").get("positionX")) == pytest.approx(0.6 * 4.6)
    assert ego.find("Properties/Property[@name='color']").get("value") == "#1E6EFF"
    assert [v[1] for v in _vertices(root, "ego")] == pytest.approx([100.92, 101.92, 102.92])

    # The latecomer (5 m, heading south) is added at its first step, at its rear axle: 1.5 m north of
    # its centre (0, 2.5).
    adds = {
        e.find(".//EntityAction").get("entityRef"): e
        for e in root.iter("Event")
        if e.find(".//AddEntityAction") is not None
    }
    assert sorted(adds) == ["latecomer", "ped_3"]
    add = adds["latecomer"]
    assert float(add.find(".//SimulationTimeCondition").get("value")) == pytest.approx(0.1)
    where = add.find(".//AddEntityAction/Position/WorldPosition")
    assert (float(where.get("x")), float(where.get("y"))) == pytest.approx((0.0, 4.0))
    assert add.find(".//FollowTrajectoryAction") is not None  # and follows its path from there
    assert _vertices(root, "latecomer")[-1][:3] == pytest.approx((0.15, 0.0, 3.0))

    (delete_event,) = [e for e in root.iter("Event") if e.find(".//DeleteEntityAction") is not None]
    assert delete_event.find(".//EntityAction").get("entityRef") == "leaver"
    when = float(delete_event.find(".//SimulationTimeCondition").get("value"))
    assert when == pytest.approx(2 * STEP_S + STEP_S)

    # The background person: a Pedestrian whose reference point is its centre, added at 0.1 s.
    person = root.find(".//ScenarioObject[@name='ped_3']/Pedestrian")
    assert float(person.find("BoundingBox/Center").get("x")) == 0.0
    assert _vertices(root, "ped_3")[0][:2] == pytest.approx((0.1, 50.0 - 0.1075))
    assert float(adds["ped_3"].find(".//SimulationTimeCondition").get("value")) == pytest.approx(0.1)

    # The light: every signal netconvert drew for the junction's links at t = 0, then link 0 yellow.
    signal_of_link = {s.get("name"): s.get("id") for s in ET.parse(xodr_path).getroot().iter("signal")}
    light_events = [e for e in root.iter("Event") if e.find(".//TrafficSignalStateAction") is not None]
    assert [float(e.find(".//SimulationTimeCondition").get("value")) for e in light_events] == pytest.approx(
        [0.0, 0.15]
    )
    first = {a.get("name"): a.get("state") for a in light_events[0].iter("TrafficSignalStateAction")}
    assert set(first) == set(signal_of_link.values())
    assert first[signal_of_link[f"{TLS_ID}_0"]] == "off;off;on"
    assert {v for k, v in first.items() if k != signal_of_link[f"{TLS_ID}_0"]} == {"on;off;off"}
    (change,) = light_events[1].iter("TrafficSignalStateAction")
    assert (change.get("name"), change.get("state")) == (signal_of_link[f"{TLS_ID}_0"], "off;on;off")

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
