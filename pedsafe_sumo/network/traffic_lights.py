"""Which traffic lights control a junction, read from the network's connections.

A traffic light's id need not be its junction's: netconvert names a light joined from several nodes'
signals `joinedS_...` (`tls.join`), one guessed over a cluster `joinedG_...`, one made from the signals
mapped at the stop lines `GS_<junction>` (`tls.guess-signals`), and one light may control several
junctions. What ties a light to a junction is the `tl` attribute of the junction's connections: those
from an edge that ends at the junction (vehicles) and from its walking areas onto its crossings
(pedestrians). Read with ElementTree (a site's network is small: Xueqing's 114 kB in 10 ms), so a
site's check at load can afford it.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections import Counter
from pathlib import Path


def junction_lights(net_file: Path, junction_id: str) -> dict[str, int]:
    """Traffic light id -> how many of the junction's connections it controls (sorted by id)."""
    ends_at: dict[str, str] = {}
    counts: Counter[str] = Counter()
    walking_prefix = f":{junction_id}_w"
    for _, element in ET.iterparse(net_file):
        if element.tag == "edge" and element.get("to") is not None:
            ends_at[element.get("id", "")] = element.get("to", "")
        elif element.tag == "connection" and element.get("tl"):
            source = element.get("from", "")
            # netconvert writes every <edge> before the first <connection>.
            if ends_at.get(source) == junction_id or source.startswith(walking_prefix):
                counts[element.get("tl", "")] += 1
        if element.tag in ("edge", "connection", "tlLogic", "junction"):
            element.clear()
    return dict(sorted(counts.items()))


def several_lights_problem(
    net_file: Path, junction_id: str, lights: dict[str, int] | None = None
) -> str | None:
    """One line when more than one light controls the junction's connections (the scenarios stage one
    light's program per episode), else None."""
    lights = junction_lights(net_file, junction_id) if lights is None else lights
    if len(lights) <= 1:
        return None
    counts = ", ".join(f"{tls_id} {count} links" for tls_id, count in lights.items())
    return (
        f"junction {junction_id} of {net_file.name} is controlled by {len(lights)} traffic lights "
        f"({counts}): the scenarios stage the signals of one traffic light per junction"
    )


def junctions_problem(net_file: Path, junction_ids) -> str | None:
    """several_lights_problem of the first of `junction_ids` (a site's main junction and its approaches'
    junctions) that several lights control, else None."""
    for junction_id in dict.fromkeys(junction_ids):
        problem = several_lights_problem(net_file, junction_id)
        if problem:
            return problem
    return None
