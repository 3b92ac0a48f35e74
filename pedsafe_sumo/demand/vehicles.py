"""Background vehicles: exponential headways per entering lane, lognormal desired speeds, turning movements.

How the speeds reach SUMO (the mechanism the validation measures):
- SUMO drives a vehicle at most at min(vType maxSpeed, speedFactor * lane speed limit). Each vehicle gets its
  own `speedFactor` = v_desired / (speed limit of its entering lane), with the vType's speedDev = 0 and a
  maxSpeed far above the lognormal's tail, so on the approach its desired speed is exactly v_desired drawn
  from the non-intersection lognormal; `departSpeed="desired"` inserts it at that speed. The Krauss dawdling
  (`sigma`) is a parameter (0 by default): SUMO's default 0.5 randomly slows free-flowing vehicles and shifts
  the measured speeds below the drawn ones.
- Through the junction nothing is forced: the lower intersection speeds come from SUMO's own junction model
  (signal stops and start-up, deceleration for turns whose internal lanes netconvert limits by curvature,
  yielding to foes and pedestrians). The intersection lognormal is therefore a validation target, not an
  input; docs/demand_validation.md reports how close SUMO gets.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from pedsafe_sumo.demand.routes_xml import attrs
from pedsafe_sumo.demand.sampling import poisson_departures_s
from pedsafe_sumo.demand.site import EnteringLane, Route
from pedsafe_sumo.sampling.distributions import Lognormal

MOVEMENTS = ("left", "straight", "right")
VTYPE_ID = "bg_passenger"
#: vType maxSpeed (m/s): SUMO's passenger default, 200 km/h. P(v > 55.6 m/s) under the non-intersection fit is
#: 3e-6, so the cap never shapes the distribution.
VTYPE_MAX_SPEED_MPS = 55.56


@dataclass(frozen=True)
class Vehicle:
    vehicle_id: str
    depart_s: float
    lane: EnteringLane
    route_id: str
    movement: str
    desired_speed_mps: float

    @property
    def speed_factor(self) -> float:
        return self.desired_speed_mps / self.lane.speed_limit_mps


def movement_probabilities(lane: EnteringLane, traffic: dict[str, Any]) -> dict[str, float]:
    """Configured shares restricted to the movements this lane offers, renormalised to sum to 1."""
    offered = {m: float(traffic[f"turn_share_{m}"]) for m in MOVEMENTS if m in lane.routes_by_movement}
    total = sum(offered.values())
    if total <= 0:  # every offered movement has share 0: spread evenly rather than drop the lane
        return {m: 1.0 / len(offered) for m in offered}
    return {m: share / total for m, share in offered.items()}


def route_ids(lanes: list[EnteringLane]) -> dict[tuple[str, ...], str]:
    """A stable id for every distinct route: entering edge, movement and a counter."""
    ids: dict[tuple[str, ...], str] = {}
    for lane in lanes:
        for movement in sorted(lane.routes_by_movement):
            for route in lane.routes_by_movement[movement]:
                if route.edges not in ids:
                    count = sum(1 for edges in ids if edges[0] == route.edges[0])
                    ids[route.edges] = f"r_{route.edges[0]}_{route.movement}_{count}"
    return ids


def speed_limit_scale(speed_limit_mps: float, traffic: dict[str, Any]) -> float:
    """Factor on a speed drawn from the fits for a road whose limit is `speed_limit_mps`: the ratio to the
    limit where the fits were measured (traffic.fit_speed_limit_mps; the rule and its source are in
    params/defaults.toml)."""
    return speed_limit_mps / traffic["fit_speed_limit_mps"]


def background_speed_scale(speed_limit_mps: float, traffic: dict[str, Any]) -> float:
    """Factor on a background vehicle's desired speed drawn from the non-intersection fit, entering on a
    lane whose limit is `speed_limit_mps`: speed_limit_scale when traffic.background_speed_limit_scaled,
    else 1 (the draw as it is)."""
    return speed_limit_scale(speed_limit_mps, traffic) if traffic["background_speed_limit_scaled"] else 1.0


def desired_speed_distribution(traffic: dict[str, Any]) -> Lognormal:
    """The law of a background vehicle's desired speed at the fits' speed limit (before the limit scaling):
    the non-intersection fit itself (the literal reading of the paper), or under traffic.desired_speed_law =
    "calibrated" the lognormal calibrated so that the speeds SUMO measures on the approach follow the fit
    (python -m pedsafe_sumo.demand.calibrate, docs/demand.md)."""
    if traffic["desired_speed_law"] == "calibrated":
        return Lognormal(
            traffic["desired_speed_calibrated_log_mu"], traffic["desired_speed_calibrated_log_sigma"]
        )
    return Lognormal(traffic["speed_nonintersection_log_mu"], traffic["speed_nonintersection_log_sigma"])


def generate_vehicles(
    lanes: list[EnteringLane], traffic: dict[str, Any], duration_s: float, seed_seq: np.random.SeedSequence
) -> list[Vehicle]:
    """All vehicles departing in [0, duration_s), sorted by departure time then id.

    Each lane draws from its own child of `seed_seq` (lanes in id order), so lanes are independent and adding
    a lane elsewhere does not change this lane's vehicles.
    """
    speeds = desired_speed_distribution(traffic)
    ids = route_ids(lanes)
    ordered = sorted(lanes, key=lambda lane: lane.lane_id)
    vehicles: list[Vehicle] = []
    for lane, child in zip(ordered, seed_seq.spawn(len(ordered)), strict=True):
        rng = np.random.default_rng(child)
        departs_s = poisson_departures_s(rng, traffic["headway_rate_per_s"], duration_s)
        n = departs_s.size
        probs = movement_probabilities(lane, traffic)
        movements = list(probs)
        chosen = rng.choice(len(movements), size=n, p=np.array([probs[m] for m in movements]))
        route_pick = rng.random(n)
        # The same draws either way (the rng's state does not depend on the scale): the scale only
        # multiplies them (traffic.background_speed_limit_scaled, docs/sites.md speed limits).
        desired_mps = speeds.sample(rng, n) * background_speed_scale(lane.speed_limit_mps, traffic)
        for k in range(n):
            options: list[Route] = lane.routes_by_movement[movements[chosen[k]]]
            route = options[min(int(route_pick[k] * len(options)), len(options) - 1)]
            vehicles.append(
                Vehicle(
                    f"veh_{lane.lane_id}_{k}",
                    round(float(departs_s[k]), 2),
                    lane,
                    ids[route.edges],
                    route.movement,
                    float(desired_mps[k]),
                )
            )
    vehicles.sort(key=lambda v: (v.depart_s, v.vehicle_id))
    return vehicles


def vehicle_lines(vehicles: list[Vehicle], lanes: list[EnteringLane], traffic: dict[str, Any]) -> list[str]:
    """The vType, routes and vehicles of the vehicle route file, as XML lines."""
    lines = [
        "    <!-- speedDev 0: each vehicle's own speedFactor carries its lognormal desired speed (see "
        "pedsafe_sumo/demand/vehicles.py). -->",
        "    <vType "
        + attrs(
            id=VTYPE_ID,
            vClass="passenger",
            length=f"{traffic['vehicle_length_m']:g}",
            minGap=f"{traffic['vehicle_min_gap_m']:g}",
            maxSpeed=f"{VTYPE_MAX_SPEED_MPS:g}",
            speedDev="0",
            sigma=f"{traffic['driver_imperfection_sigma']:g}",
        )
        + "/>",
    ]
    for edges, rid in sorted(route_ids(lanes).items(), key=lambda item: item[1]):
        lines.append(f"    <route {attrs(id=rid, edges=' '.join(edges))}/>")
    for v in vehicles:
        lines.append(
            "    <vehicle "
            + attrs(
                id=v.vehicle_id,
                type=VTYPE_ID,
                route=v.route_id,
                depart=f"{v.depart_s:.2f}",
                departLane=str(v.lane.index),
                departSpeed="desired",
                speedFactor=f"{v.speed_factor:.5f}",
            )
            + ">"
        )
        lines.append(f'        <param key="desired_speed_mps" value="{v.desired_speed_mps:.3f}"/>')
        lines.append(f'        <param key="movement" value="{v.movement}"/>')
        lines.append("    </vehicle>")
    return lines
