"""Which side of the road traffic keeps to: one sign, read once from the network, carried by the geometry.

`keep_side` is +1.0 where traffic keeps right and -1.0 where it keeps left. Every place that stages
something "towards the median" or "towards the kerb" multiplies the left normal of the direction of
travel, (-sin h, cos h), by it: in right-hand traffic the median lies to the left of travel, in
left-hand traffic to the right. SUMO numbers lanes the same way on both sides (lane 0 is the kerb-side
lane, the outermost), so a lane index means the same in both; only the geometry is mirrored. The
turns follow: the near-side turn (across the kerb-side crosswalk, without crossing oncoming traffic)
is SUMO's "r" in right-hand traffic and "l" in left-hand traffic, the far-side turn the other one
(`near_turn_letter`, `far_turn_letter`).

What the data says about the side:
- a SUMO network built for left-hand traffic (netconvert `--lefthand`) has `lefthand="true"` on its
  <net> root: known for certain (`network_is_lefthand`);
- OpenStreetMap data names the side where a way or relation carries `driving_side=left`
  (`osm_drives_left`); countries carry it on their boundary relation, which a junction's clip seldom
  holds;
- the junction's place: a few regions in which every land keeps left and no land border meets
  right-hand traffic (LEFTHAND_REGIONS: Australia with its left-hand neighbours, New Zealand). Elsewhere
  a bounding box is wrong at borders where the side changes (Hong Kong and Shenzhen, Macau and Zhuhai,
  Thailand and Laos, Japan and the Russian Kurils, Great Britain and the French coast inside its box),
  so the build says so in its summary (TRAFFIC_SIDE_NOTE) and takes `--lefthand` from the user.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from pathlib import Path

#: Right-hand traffic: the median lies to the left of travel.
KEEP_RIGHT = 1.0
#: Left-hand traffic: the median lies to the right of travel.
KEEP_LEFT = -1.0

#: (name, south, north, west, east) [deg]: boxes in which every land keeps left and none borders
#: right-hand traffic. Source: the driving side per country (https://en.wikipedia.org/wiki/Left-
#: _and_right-hand_traffic). Australia's box (10-44 S, 112-154 E) also holds southern Papua New Guinea,
#: Timor-Leste and the Lesser Sunda islands of Indonesia, all left-hand; it stops west of New Caledonia
#: (France, right-hand, from 163.5 E). New Zealand's (34-48 S, 165-179 E) holds only New Zealand.
LEFTHAND_REGIONS = (
    ("Australia", -44.0, -10.0, 112.0, 154.0),
    ("New Zealand", -48.0, -34.0, 165.0, 179.0),
)

#: The build summary's line on the traffic side of a network built from OpenStreetMap in right-hand traffic.
TRAFFIC_SIDE_NOTE = (
    "traffic side: right-hand (netconvert's default). The build cannot tell from OSM data alone whether "
    "the junction's traffic keeps left (UK, Ireland, Japan, India, South Africa, Hong Kong, ...) unless "
    "the data says driving_side=left or the junction lies in Australia or New Zealand: there, rebuild "
    "with --lefthand."
)


#: What a batch on a left-hand site prints once: how the scenarios' names read there.
LEFTHAND_MEANING = (
    "site {site} keeps left (left-hand traffic): every scenario is staged mirrored; right_turn is the "
    "near-side turn (a LEFT turn here, from the kerb lane across the kerb-side crosswalk), left_turn the "
    "far-side turn (a RIGHT turn here, from the median lane across oncoming traffic)"
)


#: The Euro NCAP suite on a left-hand site (pedsafe_sumo/ncap/staging.py stages its nearside pedestrian
#: from the right of travel and its nearside turn as a right turn): refused in one line.
NCAP_LEFTHAND_REFUSAL = (
    "site {site} keeps left (left-hand traffic): the Euro NCAP tests are staged for right-hand traffic only "
    "(nearside from the right of travel); the scenarios (batch, episode) are staged mirrored there"
)


def lefthand_note(reason: str) -> str:
    """The build summary's line on a network built for left-hand traffic, and why."""
    return (
        f"traffic side: left-hand ({reason}); netconvert --lefthand built it and every scenario is staged "
        "mirrored (docs/sites.md, 'Left-hand traffic')"
    )


def keep_side(lefthand: bool) -> float:
    """KEEP_LEFT for left-hand traffic, else KEEP_RIGHT."""
    return KEEP_LEFT if lefthand else KEEP_RIGHT


def near_turn_letter(side: float) -> str:
    """SUMO's direction of the near-side turn (from the kerb lane, across no oncoming traffic)."""
    return "r" if side > 0 else "l"


def far_turn_letter(side: float) -> str:
    """SUMO's direction of the far-side turn (from the median lane, across oncoming traffic)."""
    return "l" if side > 0 else "r"


def network_is_lefthand(net_file: Path) -> bool:
    """True when the network's <net> root says lefthand="true" (netconvert --lefthand); False for a file
    that cannot be read (the site checks name that problem)."""
    try:
        for _, element in ET.iterparse(net_file, events=("start",)):
            return element.get("lefthand", "false").lower() == "true"
    except (OSError, ET.ParseError):
        return False
    return False


def network_keep_side(net_file: Path) -> float:
    """keep_side of the network in `net_file` (sumolib does not read its lefthand attribute)."""
    return keep_side(network_is_lefthand(net_file))


def osm_drives_left(osm_file: Path) -> bool:
    """True when any way, node or relation of the OSM file carries driving_side=left."""
    for _, element in ET.iterparse(osm_file, events=("end",)):
        if element.tag == "tag" and element.get("k") == "driving_side" and element.get("v") == "left":
            return True
        if element.tag in ("node", "way", "relation"):
            element.clear()
    return False


def lefthand_region(lat: float, lon: float) -> str | None:
    """The LEFTHAND_REGIONS name of the place (lat, lon), or None."""
    for name, south, north, west, east in LEFTHAND_REGIONS:
        if south <= lat <= north and west <= lon <= east:
            return name
    return None


def drawn_keep_side(net) -> float | None:
    """The side a sumolib network draws its traffic on: where lane 0 (the kerb-side lane) of its roads
    lies beside lane 1, seen along the direction of travel (right: KEEP_RIGHT, left: KEEP_LEFT), by the
    majority of its roads of two lanes or more; None when it has none."""
    votes = 0
    for edge in net.getEdges(withInternal=False):
        if edge.getFunction() or edge.getLaneNumber() < 2:
            continue
        kerb, next_lane = edge.getLane(0).getShape(), edge.getLane(1).getShape()
        (ax, ay), (bx, by) = next_lane[0], next_lane[-1]
        if math.dist((ax, ay), (bx, by)) < 1e-6:
            continue
        mx, my = (
            kerb[len(kerb) // 2]
            if len(kerb) > 2
            else ((kerb[0][0] + kerb[-1][0]) / 2, (kerb[0][1] + kerb[-1][1]) / 2)
        )
        # The cross product of travel and the step to the kerb lane: negative when it lies to the right.
        cross = (bx - ax) * (my - ay) - (by - ay) * (mx - ax)
        votes += -1 if cross > 0 else 1
    if votes == 0:
        return None
    return KEEP_RIGHT if votes > 0 else KEEP_LEFT


def side_problem(net, net_file: Path, shown: str) -> str | None:
    """Why the network's lefthand attribute and the side its lanes are drawn on disagree (one line: a
    network marked lefthand="true" by hand over a right-hand drawing, or the reverse), or None."""
    said = network_keep_side(net_file)
    drawn = drawn_keep_side(net)
    if drawn is None or drawn == said:
        return None
    says = 'says lefthand="true"' if said < 0 else "says right-hand traffic (no lefthand attribute)"
    draws = "right" if drawn > 0 else "left"
    return (
        f"{shown} {says} but draws the kerb-side lane of its roads on the {draws} of travel: rebuild it "
        "with netconvert (--lefthand for left-hand traffic) so that both agree"
    )
