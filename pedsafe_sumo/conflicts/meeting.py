"""Where SUMO's network lets a vehicle and a walking person meet, from their FCD lane and edge.

SUMO moves persons only on lanes that allow pedestrians (sidewalks, crossings, walking areas, shared
lanes) and gives a vehicle right of way rules against a person only where their paths belong to the same
place: a pedestrian crossing (the foe links of the junction's internal lanes over it) and a lane both may
use (a shared lane, or a road without sidewalk on which persons walk). A walking area is no foe of any
vehicle lane, and a sidewalk is a lane no vehicle enters: a vehicle's footprint that overlaps a person
there exists only because of how the network is drawn (a turning internal lane drawn across the corner
of a walking area, a wide vehicle beside the kerb), and SUMO itself does not see the two meet.

`MeetingRules(net)(vehicle_lane, person_edge)` -> (meeting, may_meet): the kind of place (MEETING_*),
and True where the network lets them meet, False where it does not, None when the ids are not in the
network (the judgement is left open).
"""

from __future__ import annotations

import sumolib

#: The person is on a pedestrian crossing.
MEETING_CROSSING = "crossing"
#: The vehicle is on a lane that allows pedestrians too (a shared lane).
MEETING_SHARED = "shared"
#: The person walks on a road edge without a sidewalk (a lane the vehicles use).
MEETING_ROAD = "road"
#: The person is on a walking area: no vehicle lane is its foe in SUMO.
MEETING_WALKINGAREA = "walkingarea"
#: The person is on an edge with a sidewalk, where SUMO keeps persons and no vehicle drives.
MEETING_SIDEWALK = "sidewalk"

#: A vehicle class every road lane allows, to tell a sidewalk (pedestrians only) from a road or shared
#: lane (SUMO's default vehicle class).
ROAD_CLASS = "passenger"


class MeetingRules:
    """The meeting rules of one network (read with internal lanes and pedestrian edges)."""

    def __init__(self, net: sumolib.net.Net) -> None:
        self.function: dict[str, str] = {}
        self.lanes: set[str] = set()
        #: lanes that allow pedestrians: a vehicle on one shares it with them
        self.walkable_lanes: set[str] = set()
        #: edges with a lane for pedestrians only (a sidewalk), on which SUMO keeps its persons
        self.edges_with_sidewalk: set[str] = set()
        for edge in net.getEdges(withInternal=True):
            function = edge.getFunction() or "normal"
            self.function[edge.getID()] = function
            for lane in edge.getLanes():
                self.lanes.add(lane.getID())
                if lane.allows("pedestrian"):
                    self.walkable_lanes.add(lane.getID())
                    if not lane.allows(ROAD_CLASS) and function in ("normal", "internal"):
                        self.edges_with_sidewalk.add(edge.getID())

    def __call__(self, vehicle_lane: str, person_edge: str) -> tuple[str, bool | None]:
        function = self.function.get(person_edge)
        if function is None or vehicle_lane not in self.lanes:
            return "", None
        if vehicle_lane in self.walkable_lanes:
            return MEETING_SHARED, True
        if function == "crossing":
            return MEETING_CROSSING, True
        if function == "walkingarea":
            return MEETING_WALKINGAREA, False
        if person_edge in self.edges_with_sidewalk:
            return MEETING_SIDEWALK, False
        return MEETING_ROAD, True
