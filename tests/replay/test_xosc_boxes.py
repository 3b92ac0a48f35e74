"""replay --export-xosc read as a player reads it: every entity's box rebuilt from the file alone by
OpenSCENARIO's rules (tests/replay/xosc_boxes.py: reference point + heading + BoundingBox Center and
Dimensions, the rear axle as a vehicle's reference point), compared with the case log.

- the first step at which the ego's box and the pedestrian's box overlap is the logged first contact
  (clearance <= 0), and the step before has none;
- the ego's rebuilt box centre is the logged footprint centre at every step;
- no box of a vehicle or pedestrian overlaps another's except the ego's and the pedestrian's;
- a vehicle that appears during the episode is added (AddEntityAction) at its first logged time;
- the traffic light states, read back through the OpenDRIVE's signals, are phases of the site's program.
"""

from __future__ import annotations

import itertools
import xml.etree.ElementTree as ET

import pandas as pd
import pytest
from replay_runs import case_files, run_cli
from xosc_boxes import read_entities

from pedsafe_sumo.network.sites import get_site

EPISODE, CONDITION = 0, "sv"
#: Positions are written with Python's repr and read back: exact but for float rounding of ~300 m values.
POSITION_TOL_M = 1e-9


@pytest.fixture(scope="module")
def exported(replay_run, tmp_path_factory):
    out = tmp_path_factory.mktemp("xosc_boxes") / "case.xosc"
    proc = run_cli(
        "pedsafe_sumo.replay",
        str(replay_run),
        *("--episode", str(EPISODE), "--condition", CONDITION, "--export-xosc", str(out)),
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    log = pd.read_parquet(case_files(replay_run, EPISODE, CONDITION)[0])
    return out, log


@pytest.mark.slow
def test_the_boxes_first_touch_at_the_logged_first_contact(exported):
    xosc_path, log = exported
    entities = read_entities(xosc_path)
    ego, ped = entities["ego"], entities["ped"]
    times = log["time_s"].tolist()
    contact = (log["clearance_m"] <= 0).to_numpy()
    assert contact.any(), "the exported case is a collision"
    first_contact = int(contact.argmax())
    overlapping = [k for k, t in enumerate(times) if ego.box(t).intersects(ped.box(t))]
    assert overlapping and overlapping[0] == first_contact
    assert first_contact > 0 and not ego.box(times[first_contact - 1]).intersects(
        ped.box(times[first_contact - 1])
    )


@pytest.mark.slow
def test_the_ego_box_is_the_logged_footprint_and_its_rear_axle_the_reference_point(exported):
    xosc_path, log = exported
    root = ET.parse(xosc_path).getroot()
    for vehicle in root.iter("Vehicle"):
        # OpenSCENARIO: a vehicle's reference point is its rear axle (positionX is measured from it).
        assert float(vehicle.find("Axles/RearAxle").get("positionX")) == 0.0
        assert float(vehicle.find("Axles/FrontAxle").get("positionX")) > 0.0
        assert float(vehicle.find("BoundingBox/Center").get("x")) > 0.0  # the body lies ahead of it
    ego = read_entities(xosc_path)["ego"]
    for t, x, y, yaw, length, width in log[
        ["time_s", "ego_x_m", "ego_y_m", "ego_yaw_rad", "ego_length_m", "ego_width_m"]
    ].itertuples(index=False):
        box = ego.box(t)
        assert box.centroid.x == pytest.approx(x, abs=POSITION_TOL_M)
        assert box.centroid.y == pytest.approx(y, abs=POSITION_TOL_M)
        assert box.area == pytest.approx(length * width)
        assert ego.vertices[t][2] == pytest.approx(yaw, abs=POSITION_TOL_M)


@pytest.mark.slow
def test_no_two_boxes_overlap_but_the_ego_and_the_pedestrian(exported):
    xosc_path, log = exported
    entities = read_entities(xosc_path)
    assert len(entities) > 10  # the kerb-lane vehicles and the background traffic are there
    overlaps = set()
    for t in log["time_s"]:
        present = [(name, e.box(t)) for name, e in entities.items() if e.present(t)]
        for (a, box_a), (b, box_b) in itertools.combinations(present, 2):
            if box_a.intersects(box_b):
                overlaps.add(tuple(sorted((a, b))))
    assert overlaps == {("ego", "ped")}


@pytest.mark.slow
def test_a_vehicle_that_appears_later_is_added_at_its_first_logged_step(exported):
    xosc_path, log = exported
    root = ET.parse(xosc_path).getroot()
    placed = {p.get("entityRef") for p in root.findall("Storyboard/Init/Actions/Private")}
    first_s = float(log["time_s"].iloc[0])
    entities = read_entities(xosc_path)
    late = {name: e for name, e in entities.items() if min(e.vertices) > first_s}
    assert late, "the case has vehicles that enter after the first step"
    for name, entity in late.items():
        assert name not in placed
        assert entity.added_s == min(entity.vertices)
        add = next(
            a
            for a in root.iter("EntityAction")
            if a.get("entityRef") == name and a.find("AddEntityAction") is not None
        )
        position = add.find("AddEntityAction/Position/WorldPosition")
        x, y, h = entity.vertices[entity.added_s]
        assert (float(position.get("x")), float(position.get("y")), float(position.get("h"))) == (x, y, h)
    for name, entity in entities.items():
        if name not in late:
            assert name in placed and entity.added_s == 0.0


#: OpenSCENARIO lamp modes (red;yellow;green) and SUMO's state characters as the colours they show.
LAMP_COLOURS = {"on;off;off": "r", "off;on;off": "y", "off;off;on": "g", "on;on;off": "u", "off;off;off": "O"}
SUMO_COLOURS = {"r": "r", "y": "y", "Y": "y", "g": "g", "G": "g", "s": "g", "u": "u", "O": "O"}


@pytest.mark.slow
def test_the_traffic_light_states_are_phases_of_the_site_program(exported):
    xosc_path, log = exported
    signals = {
        s.get("id"): s.get("name") for s in ET.parse(xosc_path.with_suffix(".xodr")).getroot().iter("signal")
    }
    assert signals and all(i.isdigit() for i in signals)  # integer ids, SUMO's link as the name
    root = ET.parse(xosc_path).getroot()
    net = ET.parse(get_site("xueqing").file("net.xml")).getroot()
    phases = {logic.get("id"): [p.get("state") for p in logic.iter("phase")] for logic in net.iter("tlLogic")}
    shown: dict[str, dict[int, str]] = {}
    history = []
    for event in root.iter("Event"):
        actions = list(event.iter("TrafficSignalStateAction"))
        if not actions:
            continue
        for action in actions:
            tls_id, index = signals[action.get("name")].rsplit("_", 1)
            shown.setdefault(tls_id, {})[int(index)] = LAMP_COLOURS[action.get("state")]
        when = float(event.find(".//SimulationTimeCondition").get("value"))
        history.append((when, {tls: dict(links) for tls, links in shown.items()}))
    assert history and history[0][0] == 0.0
    assert [t for t, _ in history] == sorted(t for t, _ in history)
    assert all(t <= log["time_s"].iloc[-1] for t, _ in history)
    for _when, state in history:
        for tls_id, links in state.items():
            as_phases = [{k: SUMO_COLOURS[p[k]] for k in links} for p in phases[tls_id]]
            assert links in as_phases
    # every signal of the road shows a state from the start
    assert sum(len(links) for links in history[0][1].values()) == len(signals)
