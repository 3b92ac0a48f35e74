"""The pedestrian's line of sight to the ego, on hand-built scenes (perception's ray casting).

Scene: the ego (4.5 m x 1.8 m x 1.5 m) at the origin heading +x; the pedestrian (radius 0.3 m) at
(0, -10) with eyes at 1.55 m. The rays aim at (2.025, 0), (0, 0) and (-2.025, 0), 1.2 m high (0.8 of
the ego's height): they drop 0.35 m over 10 m, so they are still above 1.37 m at y = -5.
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "perception"))

from perception_scenes import ego_box, world  # noqa: E402

from pedsafe_sumo.behaviour.sight import ego_in_sight  # noqa: E402
from pedsafe_sumo.perception import StaticOccluders  # noqa: E402

PED = ("ped", 0.0, -10.0, 0.3, 1.66, (200, 30, 30))
EYES = (0.0, -10.0, 1.55)


def test_an_open_view_sees_the_ego():
    assert ego_in_sight(world([ego_box()], [PED]), 0, EYES)


def test_a_building_in_between_hides_it():
    wall = StaticOccluders.build(
        polygons=[("b", "building", [(-20, -6), (20, -6), (20, -5), (-20, -5)], 0.0, 10.0, (200, 190, 175))]
    )
    assert not ego_in_sight(world([ego_box()], [PED], static=wall), 0, EYES)


def test_an_suv_in_between_hides_it_but_a_car_beside_that_line_does_not():
    # SUV 1.75 m high across all three rays (x -2.4..2.4 at y = -5): the rays are below its roof.
    suv = ("suv", 0.0, -5.0, 0.0, 4.8, 1.9, 1.75, (0, 0, 0))
    assert not ego_in_sight(world([ego_box(), suv], [PED]), 0, EYES)
    # The same SUV moved to x 1..5.8: the rays to the middle and the rear pass beside it.
    aside = ("suv", 3.4, -5.0, 0.0, 4.8, 1.9, 1.75, (0, 0, 0))
    assert ego_in_sight(world([ego_box(), aside], [PED]), 0, EYES)
    # A vehicle index other than the ego's: the SUV itself is in sight from there, the ego is not.
    assert ego_in_sight(world([ego_box(), suv], [PED]), 1, EYES)
