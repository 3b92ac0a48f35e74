"""The oncoming through movement of a left-turning ego, and the oncoming vehicle that hides its pedestrian.

left_turn: "permissive left on green against the parallel crosswalk, hidden by opposing traffic".
Where the signal program lets the opposing approach move while the ego turns left (a two-phase plan, e.g.
networks/xueqing_two_phase), a vehicle of the opposing approach driving straight through the junction
stands, at the start, between the ego and the pedestrian waiting at the crosswalk the ego turns across:
its body across the line of sight from the ego's roof sensor (the LiDAR, at the box centre) to the
pedestrian. SUMO inserts vehicles on edges only, so a vehicle that stands on a junction's internal lane at
the start is inserted on its approach and moved there before the first step (`VehicleSetup.internal_lane_id`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import sumolib

from pedsafe_sumo.network.sites import Site
from pedsafe_sumo.scenarios.geometry import (
    default_arm,
    lane_pos_to_offset_m,
    load_approach,
    offset_to_lane_pos_m,
    opposite_leg,
)
from pedsafe_sumo.scenarios.signals import SignalStagingError, load_junction_signals
from pedsafe_sumo.scenarios.upstream import RoadLane, connection_lanes, position_on, road_lane, upstream_road
from pedsafe_sumo.sumo_net import read_net

#: The arm across the junction from each arm.
OPPOSITE_ARM = {"N": "S", "S": "N", "E": "W", "W": "E"}


@dataclass(frozen=True)
class OncomingPath:
    """The straight movement of the opposing approach's median lane: that lane, the junction's internal
    lane(s), the lane beyond; and its two edges."""

    arm: str
    lanes: tuple[RoadLane, ...]
    route: tuple[str, str]
    #: The road before the approach lane, straight on through the junctions before it (their internal
    #: lanes included), in driving order, and its edges (upstream.upstream_road, every straight
    #: connection followed): approach staging starts the oncoming vehicle there when the approach is
    #: shorter than its run to the conflict (`extended`).
    upstream_lanes: tuple[RoadLane, ...] = ()
    upstream_edges: tuple[str, ...] = ()

    def extended(self) -> OncomingPath:
        """The path with the road before the approach lane in front of it (lanes and route)."""
        return OncomingPath(
            self.arm,
            (*self.upstream_lanes, *self.lanes),
            (*self.upstream_edges, *self.route),  # type: ignore[arg-type]
        )

    def stop_line_m(self) -> float:
        """SUMO distance from the start of the `extended` path to the end of the approach lane (where
        the junction begins)."""
        return sum(lane.length_m for lane in self.upstream_lanes) + self.lanes[0].length_m


class OncomingError(ValueError):
    """The site has no oncoming through movement for the ego's approach."""


@lru_cache(maxsize=16)
def load_oncoming(site: Site, arm: str | None = None) -> OncomingPath:
    """The oncoming through movement for an ego coming in from `arm` (None: the site's own approach): from
    the median lane of the opposite arm's approach, straight on."""
    arm = arm or default_arm(site)
    try:
        opposite = OPPOSITE_ARM.get(arm) or opposite_leg(site, arm)
        approach = load_approach(site, opposite)
    except ValueError as exc:
        raise OncomingError(f"no oncoming traffic for the {arm} approach: {exc}") from None
    net = read_net(str(site.file("net.xml")), withInternal=True)
    lane = net.getLane(approach.lane_ids[-1])  # the median lane: the through lane nearest the ego's turn
    straight = [c for c in lane.getOutgoing() if c.getDirection() == "s"]
    if not straight:
        raise OncomingError(
            f"lane {lane.getID()} of the {opposite} approach (the oncoming lane) has no straight movement"
        )
    connection = straight[0]
    upstream = upstream_road(net, lane)
    return OncomingPath(
        arm=opposite,
        lanes=tuple(road_lane(ln) for ln in connection_lanes(net, connection)),
        route=(connection.getFrom().getID(), connection.getTo().getID()),
        upstream_lanes=upstream.lanes,
        upstream_edges=upstream.edges,
    )


def _segment_crossing(a, b, p, q) -> float | None:
    """Where segment a-b meets segment p-q, as the fraction along p-q, or None."""
    d1x, d1y, d2x, d2y = b[0] - a[0], b[1] - a[1], q[0] - p[0], q[1] - p[1]
    denom = d1x * d2y - d1y * d2x
    if abs(denom) < 1e-12:
        return None
    t = ((p[0] - a[0]) * d2y - (p[1] - a[1]) * d2x) / denom
    u = ((p[0] - a[0]) * d1y - (p[1] - a[1]) * d1x) / denom
    return u if 0.0 <= t <= 1.0 and 0.0 <= u <= 1.0 else None


def sight_line_pos_m(path: OncomingPath, eye_xy, target_xy) -> float | None:
    """SUMO distance (lane-length metres from the start of the opposing approach lane) at which the oncoming
    path first crosses the line of sight from `eye_xy` to `target_xy`; None when it does not."""
    done_m = 0.0
    for lane in path.lanes:
        drawn_m = 0.0
        for p, q in zip(lane.shape[:-1], lane.shape[1:]):
            u = _segment_crossing(eye_xy, target_xy, p, q)
            if u is not None:
                return done_m + offset_to_lane_pos_m(lane.shape, lane.length_m, drawn_m + u * math.dist(p, q))
            drawn_m += math.dist(p, q)
        done_m += lane.length_m
    return None


def lane_position(path: OncomingPath, front_pos_m: float) -> tuple[str, float]:
    """(lane id, position on it) of a front `front_pos_m` SUMO metres along the path; beyond its end, the last
    lane's end."""
    return position_on(path.lanes, front_pos_m)


def point_at(path: OncomingPath, pos_m: float) -> tuple[float, float]:
    """Where SUMO draws position `pos_m` (lane-length metres along the path)."""
    lane_id, on_lane_m = lane_position(path, pos_m)
    lane = next(ln for ln in path.lanes if ln.lane_id == lane_id)
    offset = lane_pos_to_offset_m(lane.shape, lane.length_m, on_lane_m)
    x_m, y_m = sumolib.geomhelper.positionAtShapeOffset(lane.shape, offset)[:2]
    return float(x_m), float(y_m)


def oncoming_signal_problem(site: Site, arm: str | None, ego_lane_id: str, ego_to_edge: str) -> str | None:
    """Why the site's signal program cannot stage an oncoming vehicle for a left turn from `ego_lane_id` onto
    `ego_to_edge` (one line), or None: no oncoming through movement, or no phase showing green to it and to
    the ego's turn together (split phasing, as on Xueqing)."""
    try:
        path = load_oncoming(site, arm)
        approach = load_approach(site, arm or default_arm(site))
        junction = load_junction_signals(site.file("net.xml"), approach.junction_id)
        ego_link = junction.vehicle_link(ego_lane_id, ego_to_edge)
        link = junction.vehicle_link(path.lanes[0].lane_id, path.route[1])
    except (OncomingError, SignalStagingError, ValueError) as exc:
        return str(exc)
    if not any(state[ego_link] in "Gg" and state[link] in "Gg" for state in junction.program.states):
        return (
            "the signal program never shows green to the oncoming through movement from "
            f"{path.lanes[0].lane_id} (link {link}) while the ego's turn (link {ego_link}) has green: "
            "no vehicle comes the other way"
        )
    return None
