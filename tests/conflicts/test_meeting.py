"""Where vehicles and persons may meet, on the shipped Xueqing network (networks/xueqing).

Junction 11799850922: the right turn from edge 1270645006 is the internal lane :11799850922_0_0; it passes
the corner walking area :11799850922_w1 and then runs over the pedestrian crossing :11799850922_c0. A 5 m x
1.8 m car (SUMO's passenger car) and standing persons 0.48 m wide (radius 0.24 m), written by hand in FCD:

- artefact: the car's front 6.27 m along the turning lane; a person stands on the walking area at
  (221.71, 119.77); the car moves at 3 m/s (one FCD step). The test checks from the network's own
  shapes that the point is inside the walking area's polygon and inside the car's footprint grown by
  the radius: the drawn turn cuts the corner. SUMO has no foe link between a vehicle lane and a walking
  area, so the overlap is a geometry artefact, not a collision.
- crossing: a person stands on the crossing where its centre line meets the turning lane's, and the car's
  centre is on that point: a collision.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
import sumolib
from matplotlib.path import Path as PolygonPath

from pedsafe_sumo import REPO_ROOT
from pedsafe_sumo.conflicts.__main__ import main
from pedsafe_sumo.sumo_net import read_net

NET = REPO_ROOT / "networks" / "xueqing" / "xueqing.net.xml"
TURN = ":11799850922_0_0"
WALKINGAREA = ":11799850922_w1"
CROSSING = ":11799850922_c0"
CAR_LENGTH_M, CAR_WIDTH_M, PERSON_RADIUS_M = 5.0, 1.8, 0.24
TYPES = (
    '<routes><vType id="car_t" length="5" width="1.8"/>'
    '<vType id="ped_t" vClass="pedestrian" width="0.48"/></routes>'
)


@pytest.fixture(scope="module")
def net():
    return read_net(NET, withInternal=True, withPedestrianConnections=True)


def navi_angle_deg(dx: float, dy: float) -> float:
    """SUMO's angle: degrees clockwise from north."""
    return (90.0 - math.degrees(math.atan2(dy, dx))) % 360.0


def write(path, car_front, heading, person, person_edge, steps: int = 1):
    (fx, fy), (px, py) = car_front, person
    lines = ["<fcd-export>"]
    for k in range(steps):
        lines += [
            f'<timestep time="{k:.2f}">',
            f'<vehicle id="car" x="{fx:.4f}" y="{fy:.4f}" angle="{navi_angle_deg(*heading):.4f}" '
            f'type="car_t" speed="3.00" lane="{TURN}"/>',
            f'<person id="p" x="{px:.4f}" y="{py:.4f}" angle="0.00" type="ped_t" speed="0.00" '
            f'edge="{person_edge}"/>',
            "</timestep>",
        ]
    path.write_text("\n".join(lines + ["</fcd-export>"]) + "\n")
    return path


def run(tmp_path, fcd, *extra) -> pd.Series:
    types = tmp_path / "types.xml"
    types.write_text(TYPES)
    out = tmp_path / f"{fcd.stem}.csv"
    assert main([str(fcd), "--out", str(out), "--types", str(types), "--quiet", *extra]) == 0
    table = pd.read_csv(out, keep_default_na=False, na_values=[""])
    assert len(table) == 1
    return table.iloc[0]


def overlaps(centre, heading, point) -> bool:
    """The circle at `point` overlaps the car's rectangle (centre, unit heading): by projection."""
    d = np.subtract(point, centre)
    along = abs(d @ heading)
    across = abs(d @ np.array([-heading[1], heading[0]]))
    return along <= CAR_LENGTH_M / 2 + PERSON_RADIUS_M and across <= CAR_WIDTH_M / 2 + PERSON_RADIUS_M


def artefact_case(net):
    shape = net.getLane(TURN).getShape()
    front = sumolib.geomhelper.positionAtShapeOffset(shape, 6.27)
    yaw = sumolib.geomhelper.rotationAtShapeOffset(shape, 6.27)
    heading = np.array([math.cos(yaw), math.sin(yaw)])
    person = (221.71, 119.77)
    centre = np.array(front) - CAR_LENGTH_M / 2 * heading
    walk = net.getEdge(WALKINGAREA).getLanes()[0].getShape()
    assert PolygonPath(walk).contains_point(person)  # the person is on the walking area
    assert overlaps(centre, heading, person)  # and under the car drawn on its turning lane
    return front, heading, person


def test_turn_across_a_walking_area_corner_is_an_artefact(net, tmp_path):
    front, heading, person = artefact_case(net)
    fcd = write(tmp_path / "corner.fcd.xml", front, heading, person, WALKINGAREA)
    row = run(tmp_path, fcd, "--net", str(NET))
    assert row["min_clearance_m"] < 0  # the shapes overlap
    assert row["meeting"] == "walkingarea"
    assert not row["collision"] and row["geometry_artefact"]


def test_without_the_network_the_contact_stays_a_collision(net, tmp_path):
    front, heading, person = artefact_case(net)
    fcd = write(tmp_path / "corner.fcd.xml", front, heading, person, WALKINGAREA)
    row = run(tmp_path, fcd)
    assert pd.isna(row["meeting"]) and row["collision"] and not row["geometry_artefact"]


def test_person_on_the_crossing_under_the_turn_is_a_collision(net, tmp_path):
    # Where the crossing's centre line meets the turning lane's: solve a + s (b - a) = c + u (d - c).
    walk_line = net.getEdge(CROSSING).getLanes()[0].getShape()
    turn = net.getLane(TURN).getShape()
    found = None
    for a, b in zip(turn[:-1], turn[1:]):
        for c, d in zip(walk_line[:-1], walk_line[1:]):
            m = np.array([[b[0] - a[0], c[0] - d[0]], [b[1] - a[1], c[1] - d[1]]])
            s, u = np.linalg.solve(m, np.subtract(c, a))
            if 0 <= s <= 1 and 0 <= u <= 1:
                found = (np.array(a) + s * np.subtract(b, a), np.subtract(b, a))
    assert found is not None  # the turn runs over the crossing
    point, direction = found
    heading = direction / np.linalg.norm(direction)
    front = point + CAR_LENGTH_M / 2 * heading  # the car's centre on the point
    fcd = write(tmp_path / "crossing.fcd.xml", tuple(front), heading, tuple(point), CROSSING)
    row = run(tmp_path, fcd, "--net", str(NET))
    assert row["min_clearance_m"] == pytest.approx(-(CAR_WIDTH_M / 2 + PERSON_RADIUS_M), abs=1e-3)
    assert row["meeting"] == "crossing"
    assert row["collision"] and not row["geometry_artefact"]
