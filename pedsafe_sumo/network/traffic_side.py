"""Which side of the road traffic keeps to, and the refusal of left-hand traffic.

The scenarios stage right-hand traffic (the ego in the kerb-side lanes on the right of its road, the
corner pole on the arm's right kerb, right turns across the near crosswalk). A site whose traffic keeps
left would need every scenario staged mirrored, so until then it is refused in one line by the build
and by every command that loads a site to stage episodes on it.

What the data says:
- a SUMO network built for left-hand traffic (netconvert `--lefthand`) has `lefthand="true"` on its
  <net> root: known for certain;
- OpenStreetMap data names the side only where a way or relation carries `driving_side=left`, which
  few do (countries carry it on their boundary relation, which a junction's clip seldom holds). Without
  it netconvert builds right-hand traffic, and the build cannot tell whether the junction's country
  drives on the left: a bounding box per country is wrong at borders where the side changes (Hong Kong
  and Shenzhen, Macau and Zhuhai, Thailand and Laos, Japan and the Russian Kurils), so the build says so
  in its summary (TRAFFIC_SIDE_NOTE) and takes `--lefthand` from the user.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

#: The one line every refusal of a left-hand site carries.
LEFTHAND_REFUSAL = "left-hand traffic is not supported yet: the scenarios stage right-hand traffic"
#: The build summary's line on the traffic side of a network built from OpenStreetMap.
TRAFFIC_SIDE_NOTE = (
    "traffic side: right-hand (netconvert's default). The build cannot tell from OSM data alone whether "
    "the junction's traffic keeps left (UK, Ireland, Australia, New Zealand, Japan, India, South Africa, "
    "Hong Kong, ...): there, this network has the cars on the wrong side. Left-hand traffic is not "
    "supported yet; say --lefthand and the build stops."
)


def network_is_lefthand(net_file: Path) -> bool:
    """True when the network's <net> root says lefthand="true" (netconvert --lefthand); False for a file
    that cannot be read (the site checks name that problem)."""
    try:
        for _, element in ET.iterparse(net_file, events=("start",)):
            return element.get("lefthand", "false").lower() == "true"
    except (OSError, ET.ParseError):
        return False
    return False


def osm_drives_left(osm_file: Path) -> bool:
    """True when any way, node or relation of the OSM file carries driving_side=left."""
    for _, element in ET.iterparse(osm_file, events=("end",)):
        if element.tag == "tag" and element.get("k") == "driving_side" and element.get("v") == "left":
            return True
        if element.tag in ("node", "way", "relation"):
            element.clear()
    return False
