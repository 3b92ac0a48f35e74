"""research/roadside_view_xueyuan.py: the pole's view of a pedestrian behind a box, against sight lines
worked out by hand, and the queue's roles around the gap (no SUMO)."""

from __future__ import annotations

import importlib.util
import math
import sys

import numpy as np

from pedsafe_sumo import REPO_ROOT
from pedsafe_sumo.params import load_params
from pedsafe_sumo.perception.pipeline import SensorSuite
from pedsafe_sumo.perception.surfaces import KIND_VEHICLE
from pedsafe_sumo.perception.world import (
    Pedestrians,
    RoadsideUnit,
    StaticOccluders,
    VehicleBoxes,
    WorldSnapshot,
)

_spec = importlib.util.spec_from_file_location(
    "roadside_view_xueyuan", REPO_ROOT / "research" / "roadside_view_xueyuan.py"
)
tool = importlib.util.module_from_spec(_spec)
sys.modules[_spec.name] = tool
_spec.loader.exec_module(tool)

# A pole 6 m high at the origin looking east, its axis meeting the ground at the pedestrian 50 m out.
UNIT = RoadsideUnit("pole", 0.0, 0.0, 6.0, 0.0, math.atan2(6.0, 50.0))
SUITE = SensorSuite.from_params(load_params()["perception"], [UNIT])
PED = Pedestrians.build(["ped"], [50.0], [0.0], [0.3], [1.6], [[40, 140, 60]])


def _world(boxes: list[tuple]) -> WorldSnapshot:
    """Boxes (x, y, length, width, height), all heading east."""
    n = len(boxes)
    columns = list(zip(*boxes, strict=True)) if boxes else [[]] * 5
    vehicles = VehicleBoxes.build(
        [f"v{i}" for i in range(n)], columns[0], columns[1], [0.0] * n, columns[2], columns[3], columns[4],
        np.full((n, 3), 200.0),
    )  # fmt: skip
    return WorldSnapshot(0.0, vehicles, PED, StaticOccluders.empty())


def test_nothing_in_the_way_every_sample_seen() -> None:
    share, detected, kind, index, in_image, visible, height_px = tool.pole_view(
        _world([]), SUITE, SUITE.roadside_poses[0], 0
    )
    assert share == 1.0 and visible.all() and in_image.all()
    # f = 960 px (1920 px, 90 degrees); 1.6 m at about 50 m: about 31 px.
    assert abs(height_px - 960 * 1.6 / 50) < 1.0


def test_a_car_before_the_pedestrian_leaves_the_two_top_rows() -> None:
    # A 1.5 m high box from x = 44 to 46 m across the sight line. The ray to a sample at height z on the
    # pedestrian's facing side (x_s = 49.7-49.82 m) is 6 - (6 - z) x / x_s high at x; lowest in the box at
    # x = 46: row 0.74 (z = 1.184 m) passes at 1.54 m, row 0.58 (0.928 m) at 1.31 m (blocked). Of the six
    # rows (0.1 ... 0.9 of 1.6 m) the two top ones stay in sight: 10 of 30 samples.
    share, _, kind, index, _, visible, _ = tool.pole_view(
        _world([(45.0, 0.0, 2.0, 3.0, 1.5)]), SUITE, SUITE.roadside_poses[0], 0
    )
    assert share == 10 / 30
    heights = np.tile([0.1, 0.26, 0.42, 0.58, 0.74, 0.9], 5)
    assert (visible == (heights >= 0.74)).all()
    assert (kind[~visible] == KIND_VEHICLE).all() and (index[~visible] == 0).all()


def test_a_box_beside_the_sight_line_hides_nothing() -> None:
    share = tool.pole_view(_world([(45.0, 5.0, 2.0, 3.0, 3.0)]), SUITE, SUITE.roadside_poses[0], 0)[0]
    assert share == 1.0


def test_subset_keeps_the_chosen_boxes() -> None:
    world = _world([(45.0, 0.0, 2.0, 3.0, 3.0), (20.0, 5.0, 2.0, 3.0, 3.0)])
    assert tool.pole_view(world, SUITE, SUITE.roadside_poses[0], 0)[0] == 0.0
    kept = tool.subset(world, np.array([False, True]))
    assert kept.vehicles.ids == ("v1",)
    assert tool.pole_view(kept, SUITE, SUITE.roadside_poses[0], 0)[0] == 1.0


def test_queue_roles_around_the_gap() -> None:
    # Heading east; the pedestrian crosses at x = 24: queued_2 (centre 30) is the nearest ahead,
    # queued_1 (centre 20) the nearest behind, queued_0 another; a background vehicle gets no role.
    vehicles = VehicleBoxes.build(
        ["queued_0", "queued_1", "queued_2", "bg"], [10.0, 20.0, 30.0, 26.0], [0.0, 0.0, 0.0, 3.2],
        [0.0] * 4, [4.6] * 4, [1.8] * 4, [1.5] * 4, np.zeros((4, 3)),
    )  # fmt: skip
    roles = tool.queue_roles_at(vehicles, 24.0, 2.0)
    assert roles == {
        "queued_0": "queue, other",
        "queued_1": "queue, behind the gap",
        "queued_2": "queue, ahead of the gap",
    }
    assert tool.role_of("bg", roles) == "background vehicle" and tool.role_of("ego", roles) == "ego"
