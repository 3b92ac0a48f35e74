"""Background pedestrians: persons walking between sidewalk ends of different arms, across the crosswalks.

Arrivals are a Poisson process over the whole site (`arrival_rate_per_h`). Each person draws an origin and a
destination among the pedestrian ends at fringe nodes (different fringe nodes, so every walk passes the
junction and uses at least one crossing; SUMO's pedestrian router picks the crossings), and its attributes
from the age-group mixture. The attributes are kept on the person as SUMO <param>s (ped_age_years,
ped_age_group, ped_gender, ped_risk, ped_speed_mps) so any result can be joined to them; the walking speed is
applied through the walk's `speed` attribute, which SUMO uses instead of the vType's desired speed.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from pedsafe_sumo.demand.routes_xml import attrs
from pedsafe_sumo.demand.sampling import PedestrianAttributes, poisson_departures_s, sample_pedestrians
from pedsafe_sumo.demand.site import PedestrianEnd

PED_VTYPE_ID = "bg_pedestrian"


@dataclass(frozen=True)
class Person:
    person_id: str
    depart_s: float
    origin: PedestrianEnd
    destination: PedestrianEnd
    attributes: PedestrianAttributes


def generate_pedestrians(
    ends: list[PedestrianEnd],
    pedestrians: dict[str, Any],
    duration_s: float,
    seed_seq: np.random.SeedSequence,
) -> list[Person]:
    """All persons departing in [0, duration_s), sorted by departure time."""
    fringe_nodes = sorted({end.fringe_node for end in ends})
    if len(fringe_nodes) < 2:
        return []  # nowhere to walk to: a site without two sidewalk arms has no pedestrian demand
    rng = np.random.default_rng(seed_seq)
    departs_s = poisson_departures_s(rng, pedestrians["arrival_rate_per_h"] / 3600.0, duration_s)
    n = departs_s.size
    people = sample_pedestrians(rng, pedestrians, n)
    out = []
    for k in range(n):
        origin = ends[int(rng.integers(len(ends)))]
        targets = [e for e in ends if e.fringe_node != origin.fringe_node]
        destination = targets[int(rng.integers(len(targets)))]
        out.append(Person(f"ped_{k}", round(float(departs_s[k]), 2), origin, destination, people[k]))
    return out


def pedestrian_lines(persons: list[Person]) -> list[str]:
    """The pedestrian vType and persons of the pedestrian route file, as XML lines."""
    lines = [
        "    <!-- speedDev 0 and each walk's own speed: the drawn walking speed is the speed SUMO walks. -->",
        "    <vType " + attrs(id=PED_VTYPE_ID, vClass="pedestrian", speedDev="0") + "/>",
    ]
    for p in persons:
        a = p.attributes
        lines.append(
            "    <person "
            + attrs(
                id=p.person_id,
                type=PED_VTYPE_ID,
                depart=f"{p.depart_s:.2f}",
                departPos=f"{p.origin.pos_m:.2f}",
            )
            + ">"
        )
        for key, value in (
            ("ped_age_years", str(a.age_years)),
            ("ped_age_group", a.age_group),
            ("ped_gender", a.gender),
            ("ped_risk", a.risk),
            ("ped_speed_mps", f"{a.speed_mps:.3f}"),
        ):
            lines.append(f"        <param {attrs(key=key, value=value)}/>")
        lines.append(
            "        <walk "
            + attrs(
                **{"from": p.origin.edge_id},
                to=p.destination.edge_id,
                arrivalPos=f"{p.destination.pos_m:.2f}",
                speed=f"{a.speed_mps:.3f}",
            )
            + "/>"
        )
        lines.append("    </person>")
    return lines
