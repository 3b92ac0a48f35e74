"""The place lookup (lane and crossing at a point) of the conflicts tool: the same answers as sumolib's
own search, and no memory kept per lookup (sumolib's brute-force fallback, used when the rtree package
is missing, appends every lane of the net to a list it keeps on every call: ~1 kB per interaction)."""

from __future__ import annotations

import tracemalloc
import warnings

import numpy as np
import sumolib

from pedsafe_sumo.conflicts.places import SEARCH_RADIUS_M, PlaceFinder
from pedsafe_sumo.network.sites import get_site

NET = get_site("xueqing").file("net.xml")


def _sumolib_answer(finder: PlaceFinder, x: float, y: float) -> tuple[str, str]:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        lanes = finder.net.getNeighboringLanes(x, y, SEARCH_RADIUS_M, includeJunctions=True)
    if not lanes:
        return "", ""
    lane, _ = min(lanes, key=lambda pair: (pair[1], pair[0].getID()))
    edge = lane.getEdge()
    return lane.getID(), edge.getID() if edge.getFunction() == "crossing" else ""


def test_lookup_agrees_with_sumolib_on_lanes_crossings_and_empty_places():
    finder = PlaceFinder(NET)
    reference = PlaceFinder(NET)
    rng = np.random.default_rng(5)
    # Points near lane shapes (on them and up to 7 m off) and uniform over the net's extent.
    shapes = [lane.getShape(True) for edge in finder.net.getEdges() for lane in edge.getLanes()]
    near = [shapes[i][rng.integers(len(shapes[i]))] for i in rng.integers(len(shapes), size=150)]
    points = [(x + rng.uniform(-7, 7), y + rng.uniform(-7, 7)) for x, y in near]
    (x0, y0), (x1, y1) = finder.net.getBBoxXY()
    points += [(rng.uniform(x0, x1), rng.uniform(y0, y1)) for _ in range(150)]
    answers = [finder(x, y) for x, y in points]
    assert answers == [_sumolib_answer(reference, x, y) for x, y in points]
    assert any(crossing for _, crossing in answers) and any(lane == "" for lane, _ in answers)
    assert sum(lane != "" for lane, _ in answers) > 150


def test_lookups_keep_no_memory():
    finder = PlaceFinder(NET)
    for k in range(200):  # warm-up: first-call caches
        finder(100.0 + k % 50, 200.0)
    tracemalloc.start()
    try:
        before = tracemalloc.get_traced_memory()[0]
        for k in range(2000):
            finder(100.0 + k % 50, 200.0)
        grown = tracemalloc.get_traced_memory()[0] - before
    finally:
        tracemalloc.stop()
    # sumolib's fallback keeps 135 lane references (1 kB) per call: 2 MB over 2,000 calls.
    assert grown < 100_000, grown


def test_lane_distances_are_sumolibs_own_floats():
    """The lookup measures all segments of the near lanes at once; each lane's distance must be the very
    float sumolib's distancePointToPolygon gives (the nearest lane is chosen on it, ties by id)."""
    finder = PlaceFinder(NET)
    rng = np.random.default_rng(11)
    lanes = [lane for edge in finder.net.getEdges(withInternal=True) for lane in edge.getLanes()]
    compared = 0
    for _ in range(200):
        lane = lanes[rng.integers(len(lanes))]
        x, y = lane.getShape(True)[0][:2]
        x, y = x + rng.uniform(-6, 6), y + rng.uniform(-6, 6)
        expected = {}
        for other in lanes:
            d = sumolib.geomhelper.distancePointToPolygon((x, y), other.getShape(True))
            if d < SEARCH_RADIUS_M:
                expected[other.getID()] = d
        found = {lane.getID(): d for lane, d in finder._neighbouring_lanes(x, y)}
        assert found == expected
        compared += len(found)
    assert compared > 200


def test_many_points_at_once_give_the_answers_of_one_at_a_time():
    """`many` measures all points against all segments in one table: each answer must be the one point's
    own, with the same tie rule (nearest, then smallest lane id) and the same empty answers."""
    finder = PlaceFinder(NET)
    rng = np.random.default_rng(7)
    lanes = [lane for edge in finder.net.getEdges(withInternal=True) for lane in edge.getLanes()]
    points = []
    for _ in range(300):  # near lane vertices (where lanes meet, ties of distance are likely), and off them
        x, y = lanes[rng.integers(len(lanes))].getShape(True)[rng.integers(2)][:2]
        points.append((x + rng.choice([0.0, rng.uniform(-7, 7)]), y + rng.choice([0.0, rng.uniform(-7, 7)])))
    (x0, y0), (x1, y1) = finder.net.getBBoxXY()
    points += [(rng.uniform(x0, x1), rng.uniform(y0, y1)) for _ in range(100)]
    points += [(float("nan"), 0.0), points[0], points[0]]
    one_at_a_time = [PlaceFinder(NET)(x, y) for x, y in points]
    xs, ys = np.array([p[0] for p in points]), np.array([p[1] for p in points])
    assert finder.many(xs, ys) == one_at_a_time
    assert finder.many(xs, ys) == one_at_a_time  # the second time from the memory of found points
    assert any(crossing for _, crossing in one_at_a_time) and ("", "") in one_at_a_time
