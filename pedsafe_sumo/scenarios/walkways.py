"""The pedestrian's walk on the walkable network around a crossing (approach staging, docs/engine.md,
"Approach staging"): the walk along the approach's sidewalk to the step-off point (the walk-in), and the
walk on from the crossing's far end off the scene (the walk-on).

A sidewalk here is a lane of a road (not of a junction) that pedestrians may use and cars may not, as
netconvert builds them (`sidewalks.guess`, or the OSM import's sidewalks); SUMO draws it by its
centreline and width. Polylines are in the network frame, metres.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import sumolib

Point = tuple[float, float]

#: A step-off point this close to the sidewalk's centreline stands on it: the walk-in goes straight to it
#: (a tenth of a step; the pedestrian's body is 0.6 m across).
ON_CENTRELINE_M = 0.1


@dataclass(frozen=True)
class Walkway:
    """A sidewalk lane of the network: its id, drawn centreline and width."""

    lane_id: str
    shape: tuple[Point, ...]
    width_m: float


def polyline_length_m(points) -> float:
    """Drawn length of a polyline [m]."""
    return sum(math.dist(p, q) for p, q in zip(points[:-1], points[1:]))


def point_at(shape, offset_m: float) -> Point:
    x, y = sumolib.geomhelper.positionAtShapeOffset(list(shape), offset_m)
    return float(x), float(y)


def shape_between(shape, from_m: float, to_m: float) -> list[Point]:
    """The part of a polyline between two offsets along it (from_m <= to_m), its vertices included."""
    points = [point_at(shape, from_m)]
    done_m = 0.0
    for p, q in zip(shape[:-1], shape[1:]):
        done_m += math.dist(p, q)
        if from_m < done_m < to_m:
            points.append((float(q[0]), float(q[1])))
    end = point_at(shape, to_m)
    if math.dist(end, points[-1]) > 1e-9:
        points.append(end)
    return points


def sidewalk_offset_m(sidewalk_shape, xy: Point) -> float:
    """Offset along the sidewalk's centreline of its point nearest `xy` [m]."""
    shape = list(sidewalk_shape)
    return float(sumolib.geomhelper.polygonOffsetWithMinimumDistanceToPoint(xy, shape, perpendicular=False))


def walk_in(sidewalk_shape, step_off_xy: Point, along_m: float) -> tuple[Point, ...]:
    """The walk to the step-off point along the sidewalk, coming from upstream (the sidewalk of an approach
    runs towards its junction): `along_m` metres along the centreline (fewer where the sidewalk begins
    sooner) to its point nearest the step-off point, without the step-off point itself. Empty when
    `along_m` is 0 and the step-off point lies on the centreline."""
    to_m = sidewalk_offset_m(sidewalk_shape, step_off_xy)
    points = shape_between(sidewalk_shape, max(to_m - along_m, 0.0), to_m)
    if math.dist(points[-1], step_off_xy) < ON_CENTRELINE_M:
        # The step-off point is on the centreline: no step aside to it.
        points.pop()
    return tuple(points)


def sidewalk_before_m(sidewalk_shape, step_off_xy: Point) -> float:
    """How far the sidewalk runs upstream of its point nearest the step-off point [m]."""
    return sidewalk_offset_m(sidewalk_shape, step_off_xy)


def walk_on(
    end_xy: Point,
    heading: Point,
    walk_on_m: float,
    walkways: tuple[Walkway, ...],
    away_from: Point,
    exclude: str = "",
) -> tuple[Point, ...]:
    """The walk on from the crossing's far end `end_xy`, `walk_on_m` metres, without `end_xy` itself:
    straight on in the crossing's direction (`heading`, a unit vector) until it reaches a sidewalk (a
    walkway other than `exclude`: the sidewalk the pedestrian came from), then along that sidewalk's
    centreline in the direction that leads away from `away_from` (the junction; beyond the sidewalk's end,
    straight on). Straight on all the way where no sidewalk is reached."""
    if walk_on_m <= 0:
        return ()
    reach = _first_sidewalk(end_xy, heading, walk_on_m, walkways, exclude)
    if reach is None:
        return ((end_xy[0] + heading[0] * walk_on_m, end_xy[1] + heading[1] * walk_on_m),)
    walkway, step_m, offset_m = reach
    on = point_at(walkway.shape, offset_m)
    left_m = walk_on_m - step_m
    length_m = polyline_length_m(walkway.shape)
    ahead = point_at(walkway.shape, min(offset_m + 1.0, length_m))
    back = point_at(walkway.shape, max(offset_m - 1.0, 0.0))
    forward = math.dist(ahead, away_from) >= math.dist(back, away_from)
    if forward:
        points = shape_between(walkway.shape, offset_m, min(offset_m + left_m, length_m))
        beyond_m = offset_m + left_m - length_m
        tail = walkway.shape[-2:]
    else:
        points = list(reversed(shape_between(walkway.shape, max(offset_m - left_m, 0.0), offset_m)))
        beyond_m = left_m - offset_m
        tail = (walkway.shape[1], walkway.shape[0])
    points[0] = on
    if beyond_m > 1e-9:
        # The sidewalk ends (at the edge of the network): on, straight, out of the scene.
        (px, py), (qx, qy) = tail
        norm = math.hypot(qx - px, qy - py)
        last = points[-1]
        points.append((last[0] + beyond_m * (qx - px) / norm, last[1] + beyond_m * (qy - py) / norm))
    return tuple(points)


def _first_sidewalk(end_xy: Point, heading: Point, walk_on_m: float, walkways, exclude: str):
    """(walkway, metres straight on until its centreline, offset along it there) of the first sidewalk
    the straight walk from `end_xy` reaches within `walk_on_m`, or None."""
    best = None
    far = (end_xy[0] + heading[0] * walk_on_m, end_xy[1] + heading[1] * walk_on_m)
    for walkway in walkways:
        if walkway.lane_id == exclude:
            continue
        done_m = 0.0
        for p, q in zip(walkway.shape[:-1], walkway.shape[1:]):
            hit = _segment_hit(end_xy, far, p, q)
            if hit is not None:
                t, u = hit
                step_m = t * walk_on_m
                if best is None or step_m < best[1]:
                    best = (walkway, step_m, done_m + u * math.dist(p, q))
            done_m += math.dist(p, q)
    return best


def _segment_hit(a: Point, b: Point, p: Point, q: Point) -> tuple[float, float] | None:
    """(fraction along a-b, fraction along p-q) where the two segments cross, or None."""
    d1x, d1y, d2x, d2y = b[0] - a[0], b[1] - a[1], q[0] - p[0], q[1] - p[1]
    denom = d1x * d2y - d1y * d2x
    if abs(denom) < 1e-12:
        return None
    t = ((p[0] - a[0]) * d2y - (p[1] - a[1]) * d2x) / denom
    u = ((p[0] - a[0]) * d1y - (p[1] - a[1]) * d1x) / denom
    if 0 <= t <= 1 and 0 <= u <= 1:
        return t, u
    return None


def network_walkways(net) -> tuple[Walkway, ...]:
    """Every sidewalk of a sumolib network (see the module's docstring)."""
    return tuple(
        Walkway(lane.getID(), tuple((float(x), float(y)) for x, y in lane.getShape()), float(lane.getWidth()))
        for edge in net.getEdges(withInternal=False)
        if edge.getFunction() == ""
        for lane in edge.getLanes()
        if lane.allows("pedestrian") and not lane.allows("passenger")
    )


def reaching_sidewalk(walkways: tuple[Walkway, ...], xy: Point) -> Walkway | None:
    """The sidewalk that reaches `xy` (a crosswalk's end), or None: the one whose centreline passes
    nearest it, if within its own width. A crosswalk's kerb end lies at a sidewalk's edge, half its width
    from the centreline, or a little more at a rounded corner (on Xueqing 2.5 m from the 3 m sidewalks at
    the corners the turning scenarios' crosswalks start from); a median refuge lies a carriageway beyond
    the nearest one (5.1 m and 8.1 m)."""
    best: tuple[float, Walkway] | None = None
    for walkway in walkways:
        gap_m = math.dist(point_at(walkway.shape, sidewalk_offset_m(walkway.shape, xy)), xy)
        if gap_m <= walkway.width_m and (best is None or gap_m < best[0]):
            best = (gap_m, walkway)
    return best[1] if best else None


def towards(shape, xy: Point) -> tuple[Point, ...]:
    """The polyline oriented to end at its end nearer `xy` (a sidewalk of a road leaving a junction runs
    away from it: walked towards the junction, it is walked against its drawing order)."""
    points = tuple((float(x), float(y)) for x, y in shape)
    return points if math.dist(points[-1], xy) <= math.dist(points[0], xy) else points[::-1]
