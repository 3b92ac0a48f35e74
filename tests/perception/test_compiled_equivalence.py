"""The compiled kernels against the vectorised numpy reference on random scenes.

``perceive`` runs the numba kernels of ``pedsafe_sumo.perception.kernels``; ``perceive_reference``
runs the straightforward numpy implementation (``sensors.plan_*`` / ``finish_*``,
``raycast.cast_rays_numpy``). On 200 random scenes (fixed seed) with vehicles, pedestrians (some
pressed against vehicles, some in groups), buildings, hedges, canopy blocks and trees, both must
report the same detections and the same rule inputs (to 1e-9).
"""

from __future__ import annotations

import math

import numpy as np
from perception_scenes import make_suite

from pedsafe_sumo.perception import (
    EgoPose,
    Pedestrians,
    StaticOccluders,
    V2ILink,
    VehicleBoxes,
    WorldSnapshot,
)
from pedsafe_sumo.perception.pipeline import perceive, perceive_reference
from pedsafe_sumo.perception.raycast import cast_rays, cast_rays_numpy
from pedsafe_sumo.perception.world import RoadsideUnit

N_SCENES = 200
TOL = 1e-9


def _colour(rng, palette):
    # Half the time one of a few colours, so that clothing often matches what stands behind it.
    if rng.random() < 0.5:
        return palette[rng.integers(len(palette))]
    return tuple(int(v) for v in rng.integers(0, 256, 3))


def random_scene(rng: np.random.Generator):
    palette = [(200, 30, 30), (30, 60, 160), (120, 120, 120), (230, 200, 40)]
    ego_yaw = float(rng.uniform(-math.pi, math.pi))
    ex, ey = rng.uniform(-20, 20, 2)
    fwd = np.array([math.cos(ego_yaw), math.sin(ego_yaw)])
    left = np.array([-fwd[1], fwd[0]])
    vehicles = [("ego", float(ex), float(ey), ego_yaw, 4.5, 1.8, 1.5, _colour(rng, palette))]
    for k in range(int(rng.integers(0, 14))):
        along, across = rng.uniform(-10, 60), rng.uniform(-15, 15)
        x, y = np.array([ex, ey]) + along * fwd + across * left
        yaw, length = float(rng.uniform(-math.pi, math.pi)), float(rng.uniform(3.5, 12))
        width, height = float(rng.uniform(1.6, 2.6)), float(rng.uniform(1.3, 3.5))
        vehicles.append((f"v{k}", float(x), float(y), yaw, length, width, height, _colour(rng, palette)))
    peds = []
    for k in range(int(rng.integers(1, 7))):
        mode = rng.random()
        if mode < 0.25 and len(vehicles) > 1:  # pressed against (or close to) a vehicle
            v = vehicles[int(rng.integers(1, len(vehicles)))]
            ang = rng.uniform(-math.pi, math.pi)
            reach = 0.5 * math.hypot(v[4], v[5]) * rng.uniform(0.3, 1.1) + rng.uniform(0.0, 0.8)
            x, y = v[1] + reach * math.cos(ang), v[2] + reach * math.sin(ang)
        elif mode < 0.4 and peds:  # next to another pedestrian
            x, y = peds[-1][1] + rng.uniform(-0.8, 0.8), peds[-1][2] + rng.uniform(-0.8, 0.8)
        else:  # ahead of the ego, mostly inside the camera's field of view
            dist, bearing = rng.uniform(3, 110), rng.uniform(-1.2, 1.2)
            x = ex + dist * math.cos(ego_yaw + bearing)
            y = ey + dist * math.sin(ego_yaw + bearing)
        peds.append((f"p{k}", float(x), float(y), float(rng.uniform(0.2, 0.35)), float(rng.uniform(1.0, 2.0)),
                     _colour(rng, palette)))  # fmt: skip
    polygons = []
    for k in range(int(rng.integers(0, 5))):
        cx, cy = np.array([ex, ey]) + rng.uniform(5, 70) * fwd + rng.uniform(-30, 30) * left
        n = int(rng.integers(3, 7))
        ang = np.sort(rng.uniform(0, 2 * math.pi, n))
        rad = rng.uniform(2, 12, n)
        shape = np.column_stack([cx + rad * np.cos(ang), cy + rad * np.sin(ang)])
        kind, z0, z1 = [("building", 0.0, float(rng.uniform(3, 30))), ("canopy", 2.5, 8.0),
                        ("hedge", 0.0, 1.2)][int(rng.integers(3))]  # fmt: skip
        polygons.append((f"b{k}", kind, shape, z0, z1, _colour(rng, palette)))
    cylinders = []
    for _ in range(int(rng.integers(0, 4))):
        x, y = np.array([ex, ey]) + rng.uniform(3, 50) * fwd + rng.uniform(-8, 8) * left
        cylinders.append((float(x), float(y), 0.15, 0.0, 2.5, (90, 60, 30)))
        cylinders.append((float(x), float(y), 2.0, 2.5, float(rng.uniform(5, 9)), (40, 110, 40)))
    static = StaticOccluders.build(polygons, cylinders)

    def build(rows, n_fields, cls):
        return cls.build(*[[row[k] for row in rows] for k in range(n_fields)])

    snap = WorldSnapshot(0.0, build(vehicles, 8, VehicleBoxes), build(peds, 6, Pedestrians), static)
    # A pole looking at the scene from the side, 6 m up, pitched 20-40 degrees down.
    px, py = np.array([ex, ey]) + rng.uniform(10, 40) * fwd + rng.uniform(-25, 25) * left
    toward = math.atan2(ey + 25 * fwd[1] - py, ex + 25 * fwd[0] - px)
    unit = RoadsideUnit("rsu", float(px), float(py), 6.0, toward, math.radians(float(rng.uniform(20, 40))))
    return snap, EgoPose(float(ex), float(ey), ego_yaw, "ego"), unit


def _same_camera(a, b):
    np.testing.assert_array_equal(a.detected, b.detected)
    np.testing.assert_allclose(a.visible_fraction, b.visible_fraction, rtol=0, atol=TOL)
    np.testing.assert_allclose(a.height_px, b.height_px, rtol=0, atol=TOL)
    np.testing.assert_allclose(a.contrast_fraction, b.contrast_fraction, rtol=0, atol=TOL)


def _same_sources(a, b):
    for name in ("camera", "lidar", "roadside", "v2i_received", "sv", "v2i"):
        sa, sb = getattr(a, name), getattr(b, name)
        assert sa.ids == sb.ids, name
        np.testing.assert_allclose(sa.xy_m, sb.xy_m, rtol=0, atol=TOL)
        np.testing.assert_allclose(sa.distance_m, sb.distance_m, rtol=0, atol=TOL)
    np.testing.assert_allclose(a.ego_camera_px, b.ego_camera_px, rtol=0, atol=1e-6)


def test_compiled_perception_matches_the_numpy_reference_on_random_scenes(params):
    rng = np.random.default_rng(20261121)
    totals = dict.fromkeys(("camera", "lidar", "roadside", "merged", "v2i_received", "pedestrians"), 0)
    for _ in range(N_SCENES):
        snap, ego, unit = random_scene(rng)
        overrides = {"perception": {"camera": {"miss_probability": float(rng.choice([0.0, 0.2]))},
                                    "v2i": {"latency_s": float(rng.choice([0.0, 0.1]))}}}  # fmt: skip
        suite = make_suite(params, overrides, units=[unit])
        seed = int(rng.integers(2**31))
        link_a = V2ILink(suite.v2i, np.random.default_rng(seed + 1))
        link_b = V2ILink(suite.v2i, np.random.default_rng(seed + 1))
        gen_a, gen_b = np.random.default_rng(seed), np.random.default_rng(seed)
        for step in range(3):  # three frames through one link: deliveries after the latency
            t = 0.05 * step
            frame = WorldSnapshot(t, snap.vehicles, snap.pedestrians, snap.static)
            ref = perceive_reference(frame, ego, suite, gen_a, t, link_a)
            new = perceive(frame, ego, suite, gen_b, t, link_b)
            _same_sources(ref, new)
            _same_camera(ref.diagnostics["camera"], new.diagnostics["camera"])
            _same_camera(ref.diagnostics["roadside"][0], new.diagnostics["roadside"][0])
            lr, ln = ref.diagnostics["lidar"], new.diagnostics["lidar"]
            np.testing.assert_array_equal(lr.n_returns, ln.n_returns)
            np.testing.assert_array_equal(lr.merged, ln.merged)
            np.testing.assert_array_equal(lr.detected, ln.detected)
        totals["camera"] += len(new.camera)
        totals["lidar"] += len(new.lidar)
        totals["roadside"] += len(new.roadside)
        totals["merged"] += int(ln.merged.sum())
        totals["v2i_received"] += len(new.v2i_received)
        totals["pedestrians"] += len(snap.pedestrians)
    # The scenes exercise every rule (not a comparison of empty results).
    assert all(v >= 10 for v in totals.values()), totals
    assert totals["camera"] < totals["pedestrians"] and totals["lidar"] < totals["pedestrians"], totals


def test_compiled_cast_matches_the_numpy_reference_on_random_rays():
    rng = np.random.default_rng(7)
    hits_seen = set()
    for _ in range(100):
        snap, ego, _ = random_scene(rng)
        n_groups = int(rng.integers(1, 8))
        counts = rng.integers(1, 40, n_groups)
        n = int(counts.sum())
        origin = np.column_stack([ego.x_m + rng.uniform(-3, 3, n), ego.y_m + rng.uniform(-3, 3, n),
                                  rng.uniform(0.2, 6, n)])  # fmt: skip
        direction = rng.normal(size=(n, 3))
        direction[:, 2] *= 0.2
        direction /= np.linalg.norm(direction, axis=1, keepdims=True)
        t_max = rng.uniform(5, 120, n)
        starts = np.cumsum(counts) - counts
        skip_ped = rng.integers(-1, len(snap.pedestrians), n)
        skip_veh = rng.integers(-1, len(snap.vehicles), n_groups)
        args = (snap, origin, direction, t_max, starts, counts, skip_ped, skip_veh)
        ref, new = cast_rays_numpy(*args), cast_rays(*args)
        np.testing.assert_array_equal(ref.kind, new.kind)
        np.testing.assert_array_equal(ref.index, new.index)
        np.testing.assert_allclose(ref.t_m, new.t_m, rtol=0, atol=TOL)
        hits_seen.update(int(k) for k in np.unique(new.kind))
    assert hits_seen == {0, 1, 2, 3, 4, 5}
