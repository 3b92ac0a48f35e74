"""Track.position_sigmas_m: the planner's widening for all predicted positions at once must equal,
bit for bit, position_sigma_m one position at a time (the stack's commands feed the simulation)."""

import math

import numpy as np

from pedsafe_sumo.control.baseline_planner import PathArrays
from pedsafe_sumo.control.kalman_tracker import Track


def test_hand_computed_variance_along_the_direction():
    # Var(x + t vx) = c_xx + 2 t c_xvx + t^2 c_vxvx = 0.04 + 2 * 2 * 0.01 + 4 * 0.25 = 1.08 along x;
    # along y the y entries alone: 0.09 + 4 * 0.16 = 0.73.
    cov = np.zeros((4, 4))
    cov[0, 0], cov[2, 2], cov[0, 2], cov[2, 0] = 0.04, 0.25, 0.01, 0.01
    cov[1, 1], cov[3, 3] = 0.09, 0.16
    track = Track("p", 0.0, 0.0, 1.0, 0.0, cov, 0.0)
    sigmas = track.position_sigmas_m([(1.0, 0.0), (0.0, 1.0)], [2.0, 2.0])
    assert math.isclose(sigmas[0], math.sqrt(1.08), rel_tol=1e-12)
    assert math.isclose(sigmas[1], math.sqrt(0.73), rel_tol=1e-12)


def test_equal_bit_for_bit_to_one_at_a_time():
    rng = np.random.default_rng(7)
    times = (np.arange(31) * 0.1).tolist()
    for _ in range(300):
        a = rng.normal(size=(4, 4)) * 10.0 ** rng.uniform(-3, 1, size=(4, 4))
        track = Track("p", 0.0, 0.0, 1.0, 0.0, a @ a.T, 0.0)
        angles = rng.uniform(0.0, 2 * math.pi, len(times))
        directions = [(math.cos(x), -math.sin(x)) for x in angles]
        batch = track.position_sigmas_m(directions, times)
        one_by_one = [track.position_sigma_m(d, t) for d, t in zip(directions, times)]
        assert batch == one_by_one


def test_path_normals_at_several_distances_equal_one_at_a_time():
    # Three segments: east from 0 m, north from 10 m, west from 15 m (unit vectors by hand).
    path = PathArrays(
        np.array([0.0, 10.0, 10.0]),
        np.array([0.0, 0.0, 5.0]),
        np.array([1.0, 0.0, -1.0]),
        np.array([0.0, 1.0, 0.0]),
        np.array([0.0, 10.0, 15.0]),
        np.array([10.0, 5.0, 20.0]),
        1,
    )
    distances = np.array([-3.0, 0.0, 9.99, 10.0, 14.0, 15.0, 40.0])
    expected = [(0.0, 1.0)] * 3 + [(-1.0, 0.0)] * 2 + [(0.0, -1.0)] * 2  # left of east, north, west
    assert [tuple(row) for row in path.normals_at(distances).tolist()] == expected
    assert [path.normal_at(float(s)) for s in distances] == expected
