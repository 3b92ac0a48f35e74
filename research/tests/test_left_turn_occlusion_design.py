"""research/left_turn_occlusion_design.py: its geometry helpers against situations worked by hand."""

from __future__ import annotations

import importlib.util
import math
import sys

import numpy as np

from pedsafe_sumo import REPO_ROOT

# The script imports a sibling script of research/ by name, as when it is run from there.
sys.path.insert(0, str(REPO_ROOT / "research"))
_spec = importlib.util.spec_from_file_location(
    "left_turn_occlusion_design", REPO_ROOT / "research" / "left_turn_occlusion_design.py"
)
tool = importlib.util.module_from_spec(_spec)
sys.modules[_spec.name] = tool
_spec.loader.exec_module(tool)


def test_first_crossing_on_a_straight_path_with_scaled_positions():
    # The path runs along the x axis from 0 to 10 m; its positions are twice x (SUMO lengths longer
    # than drawn). The segment (2,-3)-(4,3) crosses y = 0 at x = 3: position 6. A vertical segment at
    # x = 20 misses it; one stopping short of y = 0 too.
    path_xy = np.array([[0.0, 0.0], [5.0, 0.0], [10.0, 0.0]])
    path_pos = np.array([0.0, 10.0, 20.0])
    eyes = np.array([[2.0, -3.0], [20.0, -1.0], [3.0, -3.0]])
    targets = np.array([[4.0, 3.0], [20.0, 1.0], [3.0, -1.0]])
    pos = tool.first_crossing_pos(eyes, targets, path_pos, path_xy)
    assert math.isclose(pos[0], 6.0)
    assert np.isnan(pos[1]) and np.isnan(pos[2])


def test_body_edges_lie_across_the_sight_line():
    # Eye at the origin looking along +x at (10, 0): the edges of a 0.3 m body are (10, +-0.3).
    edges = tool.body_edge_targets(np.array([[0.0, 0.0]]), np.array([[10.0, 0.0]]), 0.3)
    assert np.allclose(sorted(edges[:, 0, 1]), [-0.3, 0.0, 0.3])
    assert np.allclose(edges[:, 0, 0], 10.0)


def test_pedestrian_waits_then_walks():
    # From (0,0) towards (0,10) at 1.5 m/s: still at t <= 0, 3 m along at t = 2 s.
    track = tool.pedestrian_track(np.array([-1.0, 0.0, 2.0]), (0.0, 0.0), (0.0, 10.0), 1.5)
    assert np.allclose(track, [[0.0, 0.0], [0.0, 0.0], [0.0, 3.0]])


def test_covered_needs_the_whole_span_inside_the_body():
    # A 4.8 m body with its front at 10 m covers 5.2-10 m: [6, 9] yes, [5, 9] no (rear at 5.2), a NaN no.
    assert bool(tool.covered(10.0, 4.8, 6.0, 9.0))
    assert not bool(tool.covered(10.0, 4.8, 5.0, 9.0))
    assert not bool(tool.covered(10.0, 4.8, math.nan, 9.0))


def test_last_run_end_follows_the_run_past_the_window():
    times = np.arange(-2.0, 2.01, 0.5)  # -2, -1.5, ..., 2
    hidden = np.array([0, 1, 1, 0, 0, 1, 1, 1, 0], dtype=bool)  # runs [-1.5, -1] and [0.5, 1.5]
    assert tool.last_run_end(times, hidden, -2.0, 0.0) == -1.0
    assert tool.last_run_end(times, hidden, -2.0, 0.5) == 1.5  # the run starting at 0.5 goes on to 1.5
    assert np.isnan(tool.last_run_end(times, hidden, -0.5, 0.0))
