"""Detection rules of the onboard camera, onboard LiDAR and roadside camera on hand-built scenes.

Numbers worked out by hand (ego at the origin heading east; camera at (1.5, 0, 1.6), f = 640 px;
LiDAR at (0, 0, 1.9), channels every 40/31 = 1.2903 deg from -25 deg, azimuths every 0.2 deg).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from perception_scenes import BLUE, EGO, RED, YELLOW, ego_box, make_suite, pole, world

from pedsafe_sumo.perception import EgoPose, perceive


def run(suite, snap, seed=0):
    return perceive(snap, EGO, suite, np.random.default_rng(seed), snap.time_s)


def test_pedestrian_in_the_open_30m_ahead_is_seen_by_camera_and_lidar(suite):
    # Pedestrian centre 30 m in front of the camera: x = 1.5 + 30.
    snap = world([ego_box()], [("p", 31.5, 0.0, 0.25, 1.75, RED)])
    det = run(suite, snap)
    cam, lid = det.diagnostics["camera"], det.diagnostics["lidar"]
    # Projected height: f * h / Z = 640 * 1.75 / 30.
    assert cam.height_px[0] == pytest.approx(640 * 1.75 / 30)
    assert cam.visible_fraction[0] == 1.0
    assert cam.contrast_fraction[0] == 1.0
    # LiDAR: azimuths within asin(0.25/31.5) = 0.455 deg -> k = -2..2 (5 beams); the pedestrian spans
    # elevations atan(-1.9/31.25) = -3.48 deg .. atan(-0.15/31.25) = -0.28 deg -> channels 17, 18, 19
    # (-3.06, -1.77, -0.48 deg): 15 returns.
    assert lid.n_returns[0] == 15
    assert not lid.merged[0]
    assert det.camera.ids == ("p",) and det.lidar.ids == ("p",)
    assert det.sv.ids == ("p",)
    assert det.camera.distance_m[0] == pytest.approx(31.5)


def _hidden_scene(params, with_pole=True):
    # A parked van (5 x 2 x 2.6 m) centred at (15, -3) spans x 12.5..17.5, y -4..-2. The pedestrian at
    # (22, -4.5): the sight line from the camera (1.5, 0) enters the van's footprint at x = 12.5
    # (y = -2.41) and leaves at x = 17.5 (y = -3.51), below the van's roof (z <= 1.75 < 2.6); from the
    # LiDAR (0, 0) it enters at y = -2.56. The pedestrian's +-0.25 m keeps every ray inside the van.
    van = ("van", 15.0, -3.0, 0.0, 5.0, 2.0, 2.6, (240, 240, 240))
    snap = world([ego_box(), van], [("p", 22.0, -4.5, 0.25, 1.75, RED)])
    # Pole 7.5 m south of the pedestrian, 6 m high, looking north, pitched down 30 deg: the feet are
    # atan(6/7.5) = 38.7 deg below horizontal, the head atan(4.25/7.5) = 29.5 deg, both in the image.
    units = [pole(22.0, -12.0, 6.0, 0.0, 30.0)] if with_pole else []
    return snap, make_suite(params, units=units)


def test_pedestrian_behind_parked_van_hidden_onboard_but_seen_by_roadside_camera(params):
    snap, suite = _hidden_scene(params)
    det = run(suite, snap)
    assert det.diagnostics["camera"].visible_fraction[0] == 0.0
    assert det.diagnostics["lidar"].n_returns[0] == 0
    assert det.sv.ids == ()
    rsu = det.diagnostics["roadside"][0]
    assert rsu.visible_fraction[0] == 1.0
    assert rsu.height_px[0] > 20
    assert det.roadside.ids == ("p",)


def test_parked_van_removed_the_same_pedestrian_is_seen_onboard(params):
    snap, suite = _hidden_scene(params)
    snap = world([ego_box()], [("p", 22.0, -4.5, 0.25, 1.75, RED)])
    det = run(suite, snap)
    assert det.camera.ids == ("p",) and det.lidar.ids == ("p",)


def test_lidar_range_and_camera_resolution_limit(params, suite):
    # 103.5 m ahead of the camera (105 m from the LiDAR): beyond the 100 m range; projected height
    # 640 * 1.75 / 103.5 = 10.8 px < 20 px.
    det = run(suite, world([ego_box()], [("p", 105.0, 0.0, 0.25, 1.75, RED)]))
    assert det.diagnostics["lidar"].n_returns[0] == 0
    assert det.diagnostics["camera"].height_px[0] == pytest.approx(640 * 1.75 / 103.5)
    assert det.sv.ids == ()
    # 99 m: in range but sparse. Azimuth half-width asin(0.25/99) = 0.145 deg < 0.2 deg: one azimuth;
    # elevations atan(-1.9/98.75) = -1.10 deg .. atan(-0.15/98.75) = -0.09 deg hold only the -0.48 deg
    # channel: one return < 5.
    det = run(suite, world([ego_box()], [("p", 99.0, 0.0, 0.25, 1.75, RED)]))
    assert det.diagnostics["lidar"].n_returns[0] == 1
    assert det.sv.ids == ()
    # With a 40 m range: at 35 m, 5 azimuths (asin(0.25/35) = 0.41 deg) x 3 channels (-3.06, -1.77,
    # -0.48 deg within -3.13..-0.25 deg) = 15 returns; at 45 m, out of range.
    short = make_suite(params, {"perception.lidar.range_m": 40.0})
    det = run(
        short, world([ego_box()], [("near", 35.0, 0.0, 0.25, 1.75, RED), ("far", 45.0, 0.0, 0.25, 1.75, RED)])
    )
    assert list(det.diagnostics["lidar"].n_returns) == [15, 0]
    assert det.lidar.ids == ("near",)


def test_outside_camera_fov_only_lidar_sees(suite):
    # Bearing from the camera atan2(10, 3.5) = 70.7 deg > 45 deg half FOV; behind the ego as well.
    det = run(
        suite,
        world([ego_box()], [("side", 5.0, 10.0, 0.25, 1.75, RED), ("back", -20.0, 0.0, 0.25, 1.75, RED)]),
    )
    assert det.camera.ids == ()
    assert set(det.lidar.ids) == {"side", "back"}


def _blend_scene(clothing, gap_centre_to_vehicle_m=0.3):
    # Pedestrian 20 m ahead of the camera at x = 21.5. A vehicle stands crosswise behind them (yaw 90
    # deg: length along y, width 1.8 m along x), its near face gap_centre_to_vehicle_m behind the
    # pedestrian's centre. Camera samples up to 0.9 * 1.75 = 1.575 m; rays continued past the
    # pedestrian hit the 1.5 m high vehicle for the five lower sample rows and pass over its roof for
    # the top row: 5/6 of the samples have the vehicle behind them.
    face = 21.5 + gap_centre_to_vehicle_m
    waiting = ("waiting", face + 0.9, 0.0, np.pi / 2, 4.5, 1.8, 1.5, BLUE)
    return world([ego_box(), waiting], [("p", 21.5, 0.0, 0.25, 1.75, clothing)])


def test_same_colour_as_vehicle_right_behind_defeats_camera_and_lidar(suite):
    det = run(suite, _blend_scene(BLUE))
    cam, lid = det.diagnostics["camera"], det.diagnostics["lidar"]
    assert cam.visible_fraction[0] == 1.0
    assert cam.contrast_fraction[0] == pytest.approx(1 / 6)
    # LiDAR: the silhouette returns sit about 0.25 m beside the centre; the vehicle face 0.3 m behind
    # the centre is hit by the beams just beside the pedestrian, sqrt(0.3^2 + ~0^2) < 0.5 m: merged.
    assert lid.n_returns[0] >= 5
    assert lid.merged[0]
    assert det.sv.ids == ()


def test_different_colour_in_front_of_vehicle_lets_the_camera_detect(suite):
    det = run(suite, _blend_scene(YELLOW))
    assert det.diagnostics["camera"].contrast_fraction[0] == 1.0
    assert det.camera.ids == ("p",)
    assert det.lidar.ids == ()  # still merged into the vehicle


def test_lidar_separates_pedestrian_one_metre_in_front_of_vehicle(suite):
    det = run(suite, _blend_scene(BLUE, gap_centre_to_vehicle_m=1.0))
    assert det.lidar.ids == ("p",)


def test_building_hides_pedestrian(params):
    from pedsafe_sumo.perception import StaticOccluders

    # A 10 m tall building footprint x 10..14, y -3..3 between the ego and a pedestrian at x = 25.
    square = np.array([[10, -3], [14, -3], [14, 3], [10, 3]], dtype=float)
    static = StaticOccluders.build([("b1", "building", square, 0.0, 10.0, (200, 190, 175))])
    det = run(make_suite(params), world([ego_box()], [("p", 25.0, 0.0, 0.25, 1.75, RED)], static))
    assert det.diagnostics["camera"].visible_fraction[0] == 0.0
    assert det.diagnostics["lidar"].n_returns[0] == 0
    # A 1 m low wall hides the legs only: samples at 0.1, 0.26, 0.42 x 1.75 m = 0.18, 0.46, 0.74 m are
    # below the wall's sight line? The sight line from 1.6 m to sample height z crosses x = 14 at
    # 1.6 + (z - 1.6) * 12.5 / 23.25; below 1 m for z < 0.48 m: two of six rows hidden.
    static = StaticOccluders.build([("w", "hedge", square, 0.0, 1.0, (60, 110, 50))])
    det = run(make_suite(params), world([ego_box()], [("p", 25.0, 0.0, 0.25, 1.75, RED)], static))
    assert det.diagnostics["camera"].visible_fraction[0] == pytest.approx(4 / 6)


def test_tree_crown_hides_nothing_below_it_but_trunk_hides_a_slice(params):
    from pedsafe_sumo.perception import StaticOccluders

    # Crown 2.5..8 m above a point between camera and pedestrian: the camera at 1.6 m sees under it.
    static = StaticOccluders.build(cylinders=[(12.0, 0.0, 2.0, 2.5, 8.0, (60, 110, 50))])
    det = run(make_suite(params), world([ego_box()], [("p", 25.0, 0.0, 0.25, 1.75, RED)], static))
    assert det.diagnostics["camera"].visible_fraction[0] == 1.0
    # A 0.15 m trunk on the centre line at x = 22, 20.5 m from the camera. Sample columns sit at lateral
    # 0, +-0.1, +-0.2 m on the pedestrian's front (x = 25 - 0.25 sqrt(1 - s^2)), so their sight lines
    # pass the trunk at 0, +-0.1 * 20.5 / 23.27 = 0.088 m and +-0.2 * 20.5 / 23.35 = 0.176 m off axis:
    # three columns hidden behind the trunk, the two outer ones (0.176 > 0.15) visible.
    static = StaticOccluders.build(cylinders=[(22.0, 0.0, 0.15, 0.0, 2.5, (90, 70, 50))])
    det = run(make_suite(params), world([ego_box()], [("p", 25.0, 0.0, 0.25, 1.75, RED)], static))
    assert det.diagnostics["camera"].visible_fraction[0] == pytest.approx(2 / 5)


def test_random_miss_probability_one_removes_every_detection(params):
    suite = make_suite(
        params, {"perception.camera.miss_probability": 1.0, "perception.lidar.miss_probability": 1.0}
    )
    det = run(suite, world([ego_box()], [("p", 31.5, 0.0, 0.25, 1.75, RED)]))
    assert det.diagnostics["camera"].detected[0] and det.diagnostics["lidar"].detected[0]
    assert det.sv.ids == ()


def test_ego_box_does_not_hide_its_own_view(suite):
    # The LiDAR sits inside the ego box (centre, 1.9 m over a 1.5 m roof is above it, but the camera
    # 1.5 m ahead sits on the bumper plane at 1.6 m): without skipping the ego the camera would be blocked.
    tall_ego = ("ego", 0.0, 0.0, 0.0, 4.5, 1.8, 2.0, (255, 255, 255))
    det = run(
        suite, world([tall_ego], [("p", 31.5, 0.0, 0.25, 1.75, RED), ("q", -20.0, 0.0, 0.25, 1.75, RED)])
    )
    assert det.camera.ids == ("p",)
    assert set(det.lidar.ids) == {"p", "q"}


def test_ego_hides_a_pedestrian_from_the_roadside_camera(params):
    # Regression: the ego's own box is ignored by its own sensors only. Pole at (22, -12, 6 m) looking
    # north, pitched 30 deg down; pedestrian at (22, -4.5). An ego van (4.5 x 1.8 x 2.6 m, heading
    # east) centred at (22, -5.8) spans y -6.7..-4.9: the sight line to the highest sample
    # (1.575 m, on the front at y = -4.75) is at z = 6 - 4.425 * 7.1 / 7.25 = 1.67 m < 2.6 m when it
    # leaves the van's far side, so every sample is hidden.
    suite = make_suite(params, units=[pole(22.0, -12.0, 6.0, 0.0, 30.0)])
    ped = ("p", 22.0, -4.5, 0.25, 1.75, RED)
    van = ("ego", 22.0, -5.8, 0.0, 4.5, 1.8, 2.6, (255, 255, 255))
    ego = EgoPose(22.0, -5.8, 0.0, "ego")
    det = perceive(world([van], [ped]), ego, suite, np.random.default_rng(0), 0.0)
    assert det.diagnostics["roadside"][0].visible_fraction[0] == 0.0
    assert det.roadside.ids == ()
    det = perceive(world([], [ped]), ego, suite, np.random.default_rng(0), 0.0)
    assert det.roadside.ids == ("p",)


def test_pedestrian_at_the_image_edge_is_partly_visible(suite):
    # Centre 28.3 m from the camera at a bearing of 44.9 deg (left image edge at 45 deg). The sample
    # columns sit 0, +-0.1, +-0.2 m across the silhouette, i.e. +-0.20 and +-0.41 deg around 44.9:
    # the two columns on the left (45.1, 45.3 deg) fall outside the image, three of five remain.
    b = math.radians(44.9)
    ped = ("p", 1.5 + 28.3 * math.cos(b), 28.3 * math.sin(b), 0.25, 1.75, RED)
    det = run(suite, world([ego_box()], [ped]))
    assert det.diagnostics["camera"].visible_fraction[0] == pytest.approx(3 / 5)
    assert det.camera.ids == ("p",)


def test_projected_height_threshold_near_56m(suite):
    # 20 px for a 1.75 m pedestrian at Z = 640 * 1.75 / 20 = 56 m: 55 m gives 20.4 px, 57 m 19.6 px.
    det = run(
        suite, world([ego_box()], [("near", 56.5, 0.0, 0.25, 1.75, RED), ("far", 58.5, 3.0, 0.25, 1.75, RED)])
    )
    assert det.diagnostics["camera"].height_px == pytest.approx([640 * 1.75 / 55, 640 * 1.75 / 57])
    assert det.camera.ids == ("near",)


def test_lidar_merges_a_pedestrian_against_a_wall_but_not_two_pedestrians_together(params):
    from pedsafe_sumo.perception import StaticOccluders

    # Wall face at x = 20.3, 0.3 m behind the centre of a pedestrian at x = 20 (as for the vehicle).
    wall = np.array([[20.3, -10], [30, -10], [30, 10], [20.3, 10]], dtype=float)
    static = StaticOccluders.build([("b", "building", wall, 0.0, 10.0, (200, 190, 175))])
    det = run(make_suite(params), world([ego_box()], [("p", 20.0, 0.0, 0.25, 1.75, RED)], static))
    assert det.diagnostics["lidar"].merged[0] and det.lidar.ids == ()
    # Two pedestrians shoulder to shoulder (centres 0.55 m apart) in the open: both separate clusters
    # for the rule (pedestrian returns never merge a pedestrian).
    det = run(
        make_suite(params),
        world([ego_box()], [("a", 20.0, 0.275, 0.25, 1.75, RED), ("b", 20.0, -0.275, 0.25, 1.75, RED)]),
    )
    assert set(det.lidar.ids) == {"a", "b"}


def test_empty_worlds_and_missing_ego_are_handled(params):
    from pedsafe_sumo.perception import PerceptionSystem

    system = PerceptionSystem(make_suite(params, units=[pole()]), link_rng=np.random.default_rng(1))
    rng = np.random.default_rng(0)
    for snap in (world(), world([ego_box()]), world(peds=[("p", 31.5, 0.0, 0.25, 1.75, RED)])):
        det = system.perceive(snap, EgoPose(0.0, 0.0, 0.0, "not-in-snapshot"), rng, 0.0)
        assert det.sv.ids == det.camera.ids == det.lidar.ids
        assert set(det.v2i.ids) >= set(det.sv.ids)
    assert det.sv.ids == ("p",)
