"""replay --export-xosc: a logged collision as ASAM OpenSCENARIO + OpenDRIVE.

- ASAM's own checkers (asam-qc-openscenarioxml, asam-qc-opendrive, from PyPI, their CLIs) pass on it;
- read back (scenariogeneration's parser, then plain XML for the vertices), every trajectory vertex of
  the ego is its reference point (the rear axle: the logged centre moved back by the box Center along
  its heading), every one of the pedestrian the logged position, at the logged time, and the kerb-lane
  vehicles stand where the recorded setup put them;
- the OpenDRIVE lines up with the SUMO net: points along the ego's SUMO lane fall on the matching
  driving lane of a road of the .xodr, and the header's offset is the way back to UTM.
"""

from __future__ import annotations

import json
import math
import xml.etree.ElementTree as ET

import pandas as pd
import pytest
from asam_qc import run_checker
from replay_runs import case_files, run_cli
from sumolib.geomhelper import positionAtShapeOffset
from xodr_lanes import OpenDrive

from pedsafe_sumo.network.sites import get_site
from pedsafe_sumo.sumo_net import read_net

EPISODE, CONDITION = 0, "sv"
#: Positions are written with Python's repr (scenariogeneration) and read back as floats: exact but for
#: the last bit; 1e-9 m is far below anything visible and far above float rounding of ~300 m values.
POSITION_TOL_M = 1e-9


@pytest.fixture(scope="module")
def exported(replay_run, tmp_path_factory):
    out = tmp_path_factory.mktemp("xosc") / "case.xosc"
    proc = run_cli(
        "pedsafe_sumo.replay",
        str(replay_run),
        *("--episode", str(EPISODE), "--condition", CONDITION, "--export-xosc", str(out)),
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "trajectory matches the log" in proc.stdout
    return out, proc.stdout


def _vertices(xosc_path, entity: str) -> pd.DataFrame:
    """(time, x, y, h) of the entity's FollowTrajectoryAction polyline, read as plain XML."""
    root = ET.parse(xosc_path).getroot()
    for private in root.iter("ManeuverGroup"):
        actors = [ref.get("entityRef") for ref in private.iter("EntityRef")]
        if actors != [entity]:
            continue
        rows = [
            (float(v.get("time")), *(float(v.find("Position/WorldPosition").get(k)) for k in "xyh"))
            for v in private.iter("Vertex")
        ]
        return pd.DataFrame(rows, columns=["time_s", "x_m", "y_m", "h_rad"])
    raise AssertionError(f"no maneuver group of {entity} in {xosc_path}")


def _centres(xosc_path, entity: str) -> pd.DataFrame:
    """The vertices moved from the reference point to the box centre: Center.x ahead along the heading
    (OpenSCENARIO: the BoundingBox Center is given in the entity's frame, whose origin is that point)."""
    root = ET.parse(xosc_path).getroot()
    centre = root.find(f".//ScenarioObject[@name='{entity}']/*/BoundingBox/Center")
    ahead_m, left_m = float(centre.get("x")), float(centre.get("y"))
    vertices = _vertices(xosc_path, entity)
    cos_h, sin_h = vertices["h_rad"].map(math.cos), vertices["h_rad"].map(math.sin)
    vertices["x_m"] = vertices["x_m"] + ahead_m * cos_h - left_m * sin_h
    vertices["y_m"] = vertices["y_m"] + ahead_m * sin_h + left_m * cos_h
    return vertices


@pytest.mark.slow
def test_the_collision_case_exists_and_both_files_are_written(exported, replay_run):
    xosc_path, stdout = exported
    log = pd.read_parquet(case_files(replay_run, EPISODE, CONDITION)[0])
    assert (log["clearance_m"] <= 0).any(), "the exported case is a collision"
    assert xosc_path.is_file() and xosc_path.with_suffix(".xodr").is_file()
    road = ET.parse(xosc_path).getroot().find("RoadNetwork/LogicFile").get("filepath")
    assert road == "case.xodr"  # beside the scenario, relative: the pair moves together
    assert f"wrote {xosc_path}" in stdout


@pytest.mark.slow
def test_asam_openscenario_checker_passes(exported, tmp_path):
    results = run_checker("xosc", exported[0], tmp_path)
    # asam-qc-openscenarioxml 1.0.0 has 17 checks; all apply to OpenSCENARIO 1.2.
    assert len(results) == 17
    assert [r for r in results if r.status != "completed" or r.issues] == []


@pytest.mark.slow
def test_asam_opendrive_checker_passes(exported, tmp_path):
    results = run_checker("xodr", exported[0].with_suffix(".xodr"), tmp_path)
    assert [(r.checker_id, r.issues[:3]) for r in results if r.issues] == []
    assert [r for r in results if r.status not in ("completed", "skipped")] == []
    # A check is skipped only because it is defined for a later OpenDRIVE than the file's 1.6, never
    # because a check it depends on failed (the schema check first of all).
    skipped = [r for r in results if r.status == "skipped"]
    assert all("Version 1.6.0 is not valid according to definition setting" in r.summary for r in skipped)
    completed = {r.checker_id for r in results if r.status == "completed"}
    assert "check_asam_xodr_xml_valid_schema" in completed and len(completed) >= 10


@pytest.mark.slow
def test_read_back_the_trajectories_are_the_case_log(exported, replay_run):
    from scenariogeneration import xosc  # only this test reads the export back; half a second to import

    xosc_path = exported[0]
    scenario = xosc.ParseOpenScenario(str(xosc_path))
    names = [obj.name for obj in scenario.entities.scenario_objects]
    assert names[0] == "ego" and "ped" in names
    assert any(name.startswith(("occluder", "queued")) for name in names)

    log = pd.read_parquet(case_files(replay_run, EPISODE, CONDITION)[0])
    ego = _centres(xosc_path, "ego")
    ped = _vertices(xosc_path, "ped")
    ego_reference = _vertices(xosc_path, "ego")
    # The reference point is behind the centre: a vehicle's rear axle, not its footprint centre.
    assert (
        (ego_reference["x_m"] - log["ego_x_m"]).abs() + (ego_reference["y_m"] - log["ego_y_m"]).abs()
    ).min() > 1
    assert len(ego) == len(ped) == len(log)
    assert (ego["time_s"] - log["time_s"]).abs().max() < 1e-12
    for column, logged in (("x_m", "ego_x_m"), ("y_m", "ego_y_m"), ("h_rad", "ego_yaw_rad")):
        assert (ego[column] - log[logged]).abs().max() < POSITION_TOL_M, column
    for column, logged in (("x_m", "ped_x_m"), ("y_m", "ped_y_m")):
        assert (ped[column] - log[logged]).abs().max() < POSITION_TOL_M, column
    # While moving, the pedestrian faces the way the log says they move.
    moving = (log["ped_vx_mps"].abs() + log["ped_vy_mps"].abs()) > 0
    facing = [math.atan2(vy, vx) for vx, vy in zip(log["ped_vx_mps"][moving], log["ped_vy_mps"][moving])]
    assert (ped["h_rad"][moving] - facing).abs().max() < POSITION_TOL_M
    # The OpenSCENARIO clock runs the log's times: the storyboard stops at the last logged step.
    stop = ET.parse(xosc_path).getroot().find(".//StopTrigger//SimulationTimeCondition")
    assert float(stop.get("value")) == pytest.approx(log["time_s"].iloc[-1])


@pytest.mark.slow
def test_kerb_lane_vehicles_stand_where_the_recorded_setup_put_them(exported, replay_run):
    """Independent of the recorder: the case's setup (lane, front position, size) placed on the SUMO lane
    shape. SUMO places a vehicle at lane position p on the drawn shape at p * drawn / lane length."""
    xosc_path = exported[0]
    setup = json.loads(case_files(replay_run, EPISODE, CONDITION)[1].read_text())["setup"]
    net = read_net(get_site("xueqing").file("net.xml"))
    root = ET.parse(xosc_path).getroot()
    checked = 0
    for parked in setup["parked"]:
        lane = net.getLane(parked["lane_id"])
        shape = lane.getShape()
        drawn = sum(math.dist(a, b) for a, b in zip(shape, shape[1:]))
        scale = drawn / lane.getLength()
        length = parked["size"]["length_m"]
        cx, cy = positionAtShapeOffset(shape, (parked["front_pos_m"] - length / 2) * scale)
        vertices = _centres(xosc_path, parked["vehicle_id"])
        # A parked vehicle does not move: every vertex at its place (lane curvature within half a
        # length is what separates the chord from the arc: well under 5 cm on this straight kerb lane).
        assert math.hypot(vertices["x_m"].iloc[0] - cx, vertices["y_m"].iloc[0] - cy) < 0.05
        assert vertices["x_m"].std() < 1e-9 and vertices["y_m"].std() < 1e-9
        body = root.find(f".//ScenarioObject[@name='{parked['vehicle_id']}']/Vehicle")
        box = body.find("BoundingBox/Dimensions")
        assert float(box.get("length")) == length and float(box.get("width")) == parked["size"]["width_m"]
        colour = body.find("Properties/Property[@name='color']").get("value")
        assert colour == "#{:02X}{:02X}{:02X}".format(*parked["colour_rgb"])
        checked += 1
    assert checked >= 1
    ego = root.find(".//ScenarioObject[@name='ego']/Vehicle")
    assert ego.find("Properties/Property[@name='color']").get("value") == "#{:02X}{:02X}{:02X}".format(
        *setup["ego"]["colour_rgb"]
    )


@pytest.mark.slow
def test_the_road_lines_up_with_the_sumo_lanes(exported, replay_run):
    setup = json.loads(case_files(replay_run, EPISODE, CONDITION)[1].read_text())["setup"]
    net = read_net(get_site("xueqing").file("net.xml"))
    road = OpenDrive(exported[0].with_suffix(".xodr"))
    # The header keeps the way back to UTM: OpenDRIVE's offset is SUMO's netOffset negated.
    net_offset = net.getLocationOffset()
    assert road.header_offset_xy() == pytest.approx((-net_offset[0], -net_offset[1]), abs=0.01)

    lane = net.getLane(setup["ego"]["lane_id"])
    lanes_on_edge = len(lane.getEdge().getLanes())
    for share in (0.1, 0.3, 0.5, 0.7, 0.9):
        x, y = positionAtShapeOffset(lane.getShape(), share * lane.getLength())
        hits = road.lanes_at(x, y)
        assert len(hits) == 1, (share, hits)
        hit = hits[0]
        # SUMO numbers lanes from the right kerb (index 0), OpenDRIVE from the centre outwards (-1 ...).
        assert hit.lane_id == -(lanes_on_edge - lane.getIndex())
        assert hit.lane_type == "driving" and hit.width_m == pytest.approx(lane.getWidth())
        # Lane centres agree to within a tenth of a lane: netconvert fits curves (paramPoly3) through
        # SUMO's polyline, which cut corners by up to 0.14 m here; a frame error would be metres.
        assert hit.off_centre_m < lane.getWidth() / 10
        # Where the point lies in UTM (without netOffset) there is no road: the frames are not mixed up.
        assert road.lanes_at(x - net_offset[0], y - net_offset[1]) == []


def test_bad_export_arguments_are_one_line_and_exit_2(replay_run, tmp_path):
    for extra, says in (
        (["--export-xosc", str(tmp_path / "case.xml")], "give a file name ending in .xosc"),
        (
            ["--export-xosc", str(tmp_path / "case.xosc"), "--export-fcd", str(tmp_path / "c.fcd.xml")],
            "--export-xosc is a run of its own",
        ),
    ):
        proc = run_cli(
            "pedsafe_sumo.replay", str(replay_run), "--episode", "0", "--condition", "sv", *extra, timeout=300
        )
        assert proc.returncode == 2, proc.stderr
        assert len(proc.stderr.strip().splitlines()) == 1 and says in proc.stderr
    assert list(tmp_path.iterdir()) == []
