"""The near pairs of a timestep: vehicle centres within the interaction radius of a person, by vehicle then
by person, the same whether the distances are all computed or a k-d tree finds them.

Hand-built: radius 5 m; vehicles at (0, 0) and (100, 0); persons at (3, 4) (exactly 5 m from the first
vehicle: a 3-4-5 triangle, so on the radius and counted), (0, 5.01) (just outside), (-1, 0) (1 m away) and
(100, -2) (2 m from the second vehicle).
"""

from __future__ import annotations

import numpy as np

import pedsafe_sumo.conflicts.interactions as interactions
from pedsafe_sumo.conflicts.interactions import pairs_within

VX, VY = np.array([0.0, 100.0]), np.array([0.0, 0.0])
PX, PY = np.array([3.0, 0.0, -1.0, 100.0]), np.array([4.0, 5.01, 0.0, -2.0])


def test_pairs_on_and_within_the_radius_in_vehicle_then_person_order():
    vi, pj = pairs_within(VX, VY, PX, PY, 5.0)
    assert vi.tolist() == [0, 0, 1] and pj.tolist() == [0, 2, 3]


def test_the_k_d_tree_of_a_crowded_timestep_finds_the_same_pairs(monkeypatch):
    monkeypatch.setattr(interactions, "BRUTE_FORCE_PAIRS", 0)
    vi, pj = pairs_within(VX, VY, PX, PY, 5.0)
    assert vi.tolist() == [0, 0, 1] and pj.tolist() == [0, 2, 3]
    rng = np.random.default_rng(1)
    vx, vy, px, py = (rng.uniform(0.0, 200.0, 300) for _ in range(4))
    tree_pairs = pairs_within(vx, vy, px, py, 20.0)
    monkeypatch.setattr(interactions, "BRUTE_FORCE_PAIRS", 10**9)
    all_pairs = pairs_within(vx, vy, px, py, 20.0)
    # and both against the distances computed here, pair by pair
    expected = [
        (i, j) for i in range(300) for j in range(300) if np.hypot(vx[i] - px[j], vy[i] - py[j]) <= 20.0
    ]
    for vi, pj in (tree_pairs, all_pairs):
        assert list(zip(vi.tolist(), pj.tolist())) == expected
    assert len(expected) > 100
