"""PathArrays.project (compiled, control/path_kernels.py): the distance along the path and the signed
lateral offset, by hand on a known path, and bit for bit the numpy form on random paths and points (the
stack's commands feed the simulation)."""

import math

import numpy as np

from pedsafe_sumo.control.agent import EgoState
from pedsafe_sumo.control.baseline_planner import PathArrays, path_threat
from pedsafe_sumo.control.kalman_tracker import Track
from pedsafe_sumo.control.path_kernels import widening_rows


def l_path() -> PathArrays:
    # East 10 m from (0, 0), then north 5 m from (10, 0).
    return PathArrays(
        np.array([0.0, 10.0]),
        np.array([0.0, 0.0]),
        np.array([1.0, 0.0]),
        np.array([0.0, 1.0]),
        np.array([0.0, 10.0]),
        np.array([10.0, 5.0]),
        1,
    )


def test_hand_worked_points():
    path = l_path()
    # (4, 2): 4 m along the first segment, 2 m to its left. (12, 3): 3 m up the second (13 m along), 2 m
    # to its right (east of a northward segment). (-3, -1): before the start, the first segment extended
    # backwards: -3 m, 1 m right. (10, 9): past the end, the last one extended: 19 m, on it.
    s, lat = path.project(np.array([4.0, 12.0, -3.0, 10.0]), np.array([2.0, 3.0, -1.0, 9.0]))
    assert s.tolist() == [4.0, 13.0, -3.0, 19.0]
    assert lat.tolist() == [2.0, -2.0, -1.0, 0.0]
    # A point at the corner's outside: nearest to the end of the first segment and the start of the
    # second at the same offset; the first of the two counts (distance 10, offset sqrt(2) to the right).
    s, lat = path.project(11.0, -1.0)
    assert s.tolist() == [10.0] and math.isclose(lat[0], -math.sqrt(2.0), rel_tol=1e-15)


def test_equal_bit_for_bit_to_the_numpy_form():
    rng = np.random.default_rng(3)
    for _ in range(2000):
        n_seg = int(rng.integers(1, 6))
        heading = np.cumsum(rng.uniform(-1.0, 1.0, n_seg))
        ux, uy = np.cos(heading), np.sin(heading)
        length = rng.uniform(0.5, 40.0, n_seg)
        start = np.concatenate(([0.0], np.cumsum(length)[:-1]))
        x = rng.uniform(-100, 100) + np.concatenate(([0.0], np.cumsum(ux * length)[:-1]))
        y = rng.uniform(-100, 100) + np.concatenate(([0.0], np.cumsum(uy * length)[:-1]))
        path = PathArrays(x, y, ux, uy, start, length, int(rng.integers(1, n_seg + 1)))
        px = x[0] + rng.uniform(-60, 60, 31)
        py = y[0] + rng.uniform(-60, 60, 31)
        px[:3] = x[rng.integers(0, n_seg, 3)]  # on the path's corners: ties between segments
        py[:3] = y[rng.integers(0, n_seg, 3)] if rng.random() < 0.5 else py[:3]
        first = int(rng.integers(0, n_seg))
        compiled = path.project(px, py, first)
        reference = path.project_numpy(px, py, first)
        assert compiled[0].tolist() == reference[0].tolist()
        assert compiled[1].tolist() == reference[1].tolist()
        one = path.project(float(px[5]), float(py[5]), first)
        assert one[0].tolist() == reference[0][5:6].tolist() and one[1].tolist() == reference[1][5:6].tolist()


def threat_one_sample_at_a_time(
    track, ego, path, first, ego_s_m, horizon_s, half_width_m, sigma_factor, sample_s
):
    """path_threat's rule as a loop over the samples in Python floats: the first sample the ego has not
    passed, within its length behind the ego's front, inside the corridor widened by sigma_factor
    standard deviations (worked out one position at a time, Track.position_sigma_m)."""
    times = np.arange(0.0, horizon_s + 1e-9, sample_s)
    if not track.moving:
        times = times[:1]
    px, py = track.x_m + track.vx_mps * times, track.y_m + track.vy_mps * times
    if not track.moving:
        px, py = np.array([track.x_m]), np.array([track.y_m])
    s, lat = (a.tolist() for a in path.project_numpy(px, py, first))
    front_offset = ego.length_m / 2
    for i, t in enumerate(times.tolist()):
        ped_lon = s[i] - ego_s_m
        if ped_lon - ego.speed_mps * t < -front_offset or ped_lon - front_offset < -ego.length_m:
            continue
        widen = sigma_factor * track.position_sigma_m(path.normal_at(s[i]), t) if track.moving else 0.0
        if abs(lat[i]) <= half_width_m + widen:
            return (track.ped_id, max(ped_lon - front_offset, 0.0), t, "path")
    return None


def test_path_threat_equals_the_loop_over_samples():
    rng = np.random.default_rng(11)
    found = 0
    for _ in range(3000):
        path = PathArrays(
            np.array([0.0, 40.0]), np.array([0.0, 0.0]), np.array([1.0, 0.0]), np.array([0.0, 1.0]),
            np.array([0.0, 40.0]), np.array([40.0, 30.0]), 1,
        )  # fmt: skip
        a = rng.normal(size=(4, 4)) * rng.uniform(0.01, 0.5)
        speed = rng.uniform(0.0, 2.0) if rng.random() < 0.8 else 0.0
        heading = rng.uniform(0, 2 * math.pi)
        track = Track(
            "p", rng.uniform(-5, 60), rng.uniform(-8, 8),
            speed * math.cos(heading), speed * math.sin(heading), a @ a.T, 0.0,
        )  # fmt: skip
        ego = EgoState(rng.uniform(-10, 30), 0.0, 0.0, rng.uniform(0.0, 15.0), 4.5, 1.8)
        ego_s_m = ego.x_m
        args = (track, ego, path, 0, ego_s_m, 3.0, 1.9, 2.0, 0.1)
        threat = path_threat(*args)
        expected = threat_one_sample_at_a_time(*args)
        got = None if threat is None else (threat.ped_id, threat.gap_m, threat.time_s, threat.reason)
        assert got == expected
        found += threat is not None
    assert 300 < found < 2700  # both outcomes exercised


def test_widening_rows_take_the_normals_of_normals_at():
    # Segments starting at 0, 10, 10 (one of no length), 15 m; distances before the start, on the
    # starts, between them, past the end, NaN (np.searchsorted places it last).
    path = PathArrays(
        np.zeros(4), np.zeros(4), np.array([1.0, 0.6, 0.0, -1.0]), np.array([0.0, 0.8, 1.0, 0.0]),
        np.array([0.0, 10.0, 10.0, 15.0]), np.array([10.0, 0.0, 5.0, 20.0]), 1,
    )  # fmt: skip
    s = np.array([-3.0, 0.0, 5.0, 9.999, 10.0, 12.0, 15.0, 40.0, math.nan])
    times = np.arange(len(s)) * 0.1
    for begin in (0, 4):
        rows = widening_rows(s, times, begin, path.start_m, path.ux, path.uy)
        normals = path.normals_at(s[begin:])
        expected = np.column_stack((normals, normals[:, 0] * times[begin:], normals[:, 1] * times[begin:]))
        assert rows[:, 0, :].tolist() == expected.tolist()
    # By hand: -3 m and 0 m on the first segment (normal (0, 1)), 10 m and 12 m on the third (its start
    # ties with the second's, the later one counts: normal (-1, 0)), NaN on the last (normal (0, -1)).
    rows = widening_rows(s, np.zeros(len(s)), 0, path.start_m, path.ux, path.uy)[:, 0, :2].tolist()
    assert rows[0] == rows[1] == [-0.0, 1.0] and rows[4] == rows[5] == [-1.0, 0.0] and rows[8] == [-0.0, -1.0]
