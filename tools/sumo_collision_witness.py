"""SUMO's own collision output against `python -m pedsafe_sumo.conflicts`, contact by contact.

    python tools/sumo_collision_witness.py --net NET.xml --routes A.rou.xml,B.rou.xml --out DIR \\
        [--end 400] [--step-length 0.1] [--fcd-period 1] [--fcd-begin 0] [--seed N]

Runs sumo on the scenario with junction collision checks (`--collision.check-junctions true`, vehicle
and person collisions only warned, `--collision.mingap-factor 0`: only bodies that overlap), writes its
FCD (every --fcd-period s from --fcd-begin) and its collision output, runs the conflicts tool on the FCD
with the network, and prints one line per vehicle-person contact of either side:

- `both`: SUMO reports the pair's collision and the tool has a contact of the pair around that time
  (its label, collision or geometry artefact, is printed);
- `sumo only`: a collision SUMO reports that the tool does not find;
- `tool only`: a contact of the tool that SUMO does not report, with the reason:
  `walkingarea` (the person is on a walking area or a sidewalk, which the tool labels a geometry
  artefact); `person box` (the tool's circle of half the person's width touches the car, SUMO's person
  box never does: SUMO draws a person as a box `length` long behind its position, 0.215 m for its
  default pedestrian); `cut corner` (SUMO's bounding boxes overlap, but SUMO's passenger-car polygon,
  the box with its four corners cut off, overlaps the person only where the person is on a walking
  area or never: SUMO tests a person on a junction against that polygon); or `unexplained`.

For a collision both report, `sumo_polygon_time_s` is the first FCD step of the tool's contact at which
SUMO's car polygon overlaps the person off a walking area (SUMO reports that step when its FCD is
written at every step).

SUMO's test, in the order of one simulation step (src/microsim/MSNet.cpp, MSNet::simulationStep): the
pedestrian model moves the persons (a begin-of-step event), the vehicles move, then each internal lane
with junction checks tests every vehicle on it (also the back of one that left it) against the persons
on the crossings among its link's foe lanes and on the link's one or two foe walking areas
(MSLane::detectCollisions, MSLane::detectPedestrianJunctionCollision): first the vehicle's bounding box
(MSVehicle::getBoundingBox: from the front bumper to its back position on the lane, the vehicle's
width), then its
polygon (MSVehicle::getBoundingPoly: for the passenger shapes, 0.6 of the width at both bumpers and the
full width from 0.1 to 0.9 of the length), against the person's box (MSTransportable::getBoundingBox).
The FCD of that step is written after all of this, with the positions SUMO tested.

The table is also written to DIR/witness.csv. Bad input: one line, exit 2.
"""

from __future__ import annotations

import csv
import math
import subprocess
import sys
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
import shapely

from pedsafe_sumo.cli import OneLineParser
from pedsafe_sumo.conflicts.__main__ import main as conflicts_main
from pedsafe_sumo.conflicts.fcd import read_fcd
from pedsafe_sumo.sumo_binaries import sumo_binary
from pedsafe_sumo.sumo_net import read_net
from pedsafe_sumo.units import sumo_angle_to_yaw_rad

#: SUMO's collision types between a vehicle and a person (collision output documentation, "Collision
#: Types"); the person is always the victim.
PERSON_COLLISION_TYPES = ("sharedLane", "crossing", "walkingarea", "junctionPedestrian")
#: SUMO's default pedestrian type (vType documentation, "Default Vehicle Type Parameters": length
#: 0.215 m, width 0.48 m) and passenger car (5 m x 1.8 m): the sizes of the types this tool compares.
SUMO_PERSON_LENGTH_M = 0.215
SUMO_PERSON_WIDTH_M = 0.48
SUMO_CAR_LENGTH_M = 5.0
SUMO_CAR_WIDTH_M = 1.8
#: SUMO's polygon of a passenger car (MSVehicle::getBoundingPoly, the passenger shapes of the default
#: car): half-widths, as fractions of the width, at distances behind the front bumper, as fractions of the
#: length; the other side mirrors it.
SUMO_CAR_POLYGON = ((0.0, 0.3), (0.1, 0.5), (0.9, 0.5), (1.0, 0.3))
#: Where the tool judges a contact not to be a meeting SUMO allows (docs/conflicts.md, "Where vehicles
#: and persons meet").
APART_MEETINGS = ("walkingarea", "sidewalk")
#: sumo's own default of --seed (sumo --help).
SUMO_DEFAULT_SEED = 23423


class WitnessError(ValueError):
    """Bad input; the message says what."""


@dataclass(frozen=True)
class SumoCollision:
    time_s: float
    vehicle_id: str
    person_id: str
    kind: str
    lane: str


def run_sumo(
    net: Path,
    routes: list[Path],
    out: Path,
    end_s: float,
    step_s: float,
    fcd_period_s: float,
    fcd_begin_s: float,
    seed: int = SUMO_DEFAULT_SEED,
) -> tuple[Path, Path]:
    """Run sumo with collision checks; (FCD file, collision output file)."""
    out.mkdir(parents=True, exist_ok=True)
    fcd, collisions = out / "fcd.xml", out / "collisions.xml"
    command = [
        sumo_binary("sumo"),
        "-n", str(net),
        "-r", ",".join(str(r) for r in routes),
        "--begin", "0",
        "--end", f"{end_s:g}",
        "--step-length", f"{step_s:g}",
        "--collision.check-junctions", "true",
        "--collision.action", "warn",
        "--intermodal-collision.action", "warn",
        "--collision.mingap-factor", "0",
        "--collision-output", str(collisions),
        "--fcd-output", str(fcd),
        "--device.fcd.period", f"{fcd_period_s:g}",
        "--device.fcd.begin", f"{fcd_begin_s:g}",
        "--no-step-log", "true",
        "--seed", str(seed),
    ]  # fmt: skip
    done = subprocess.run(command, capture_output=True, text=True)
    if done.returncode != 0:
        lines = done.stderr.strip().splitlines()
        errors = [line for line in lines if line.startswith("Error")]
        raise WitnessError(f"sumo failed: {(errors or lines or [str(done.returncode)])[0]}")
    return fcd, collisions


def sumo_person_collisions(path: Path, begin_s: float = -math.inf) -> list[SumoCollision]:
    """The vehicle-person collisions of a SUMO collision output from `begin_s` on: the first of each pair."""
    first: dict[tuple[str, str], SumoCollision] = {}
    for element in ET.parse(path).getroot().iter("collision"):
        if element.get("type") not in PERSON_COLLISION_TYPES:
            continue
        hit = SumoCollision(
            float(element.get("time", "nan")),
            element.get("collider", ""),
            element.get("victim", ""),
            element.get("type", ""),
            element.get("lane", ""),
        )
        if hit.time_s >= begin_s and (hit.vehicle_id, hit.person_id) not in first:
            first[(hit.vehicle_id, hit.person_id)] = hit
    return sorted(first.values(), key=lambda c: (c.time_s, c.vehicle_id, c.person_id))


def _axes(yaw_rad: float) -> tuple[float, float, float, float]:
    """The heading (cos, sin) and the normal to its left."""
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    return c, s, -s, c


def _box(x_m: float, y_m: float, yaw_rad: float, back_m: float, length_m: float, width_m: float):
    """A rectangle from (x, y) back `length_m` along the heading, `width_m` wide (SUMO's bounding box)."""
    c, s, nx, ny = _axes(yaw_rad)
    fx, fy = x_m - back_m * c, y_m - back_m * s
    bx, by = fx - length_m * c, fy - length_m * s
    nx, ny = nx * 0.5 * width_m, ny * 0.5 * width_m
    return shapely.Polygon([(fx + nx, fy + ny), (bx + nx, by + ny), (bx - nx, by - ny), (fx - nx, fy - ny)])


def _car_polygon(x_m: float, y_m: float, yaw_rad: float, length_m: float, width_m: float):
    """SUMO's polygon of a passenger car with its front bumper at (x, y): SUMO_CAR_POLYGON."""
    c, s, nx, ny = _axes(yaw_rad)
    side = [(x_m - d * length_m * c, y_m - d * length_m * s, h * width_m) for d, h in SUMO_CAR_POLYGON]
    left = [(px + h * nx, py + h * ny) for px, py, h in side]
    right = [(px - h * nx, py - h * ny) for px, py, h in reversed(side)]
    return shapely.Polygon(left + right)


@dataclass(frozen=True)
class ShapeOverlap:
    """One FCD step of a (vehicle, person) pair: the person's edge and whether SUMO's shapes overlap."""

    time_s: float
    person_edge: str
    box: bool
    polygon: bool


def sumo_shape_overlaps(
    fcd: Path, pairs: dict[tuple[str, str], tuple[float, float]]
) -> dict[tuple[str, str], list[ShapeOverlap]]:
    """For each (vehicle, person) pair, every FCD step within [begin, end] at which both are in the FCD:
    whether the person's box (from its position back along its angle, MSTransportable::getBoundingBox)
    overlaps the car's bounding box (from its front bumper back along its heading) and the car's polygon
    (SUMO_CAR_POLYGON). The FCD angle of a vehicle is the direction from its back to its front, so the
    box is SUMO's own."""
    found: dict[tuple[str, str], list[ShapeOverlap]] = {pair: [] for pair in pairs}
    if not pairs:
        return found
    begin_s = min(b for b, _ in pairs.values())
    end_s = max(e for _, e in pairs.values())
    for step in read_fcd(fcd):
        if step.time_s < begin_s:
            continue
        if step.time_s > end_s:
            break
        vehicles = {v: k for k, v in enumerate(step.vehicles.ids)}
        persons = {p: k for k, p in enumerate(step.persons.ids)}
        for (v, p), (b, e) in pairs.items():
            if not (b <= step.time_s <= e) or v not in vehicles or p not in persons:
                continue
            i, j = vehicles[v], persons[p]
            x_m, y_m = step.vehicles.x_m[i], step.vehicles.y_m[i]
            yaw_rad = float(sumo_angle_to_yaw_rad(step.vehicles.angle_deg[i]))
            person = _box(
                step.persons.x_m[j], step.persons.y_m[j],
                float(sumo_angle_to_yaw_rad(step.persons.angle_deg[j])),
                0.0, SUMO_PERSON_LENGTH_M, SUMO_PERSON_WIDTH_M,
            )  # fmt: skip
            box = _box(x_m, y_m, yaw_rad, 0.0, SUMO_CAR_LENGTH_M, SUMO_CAR_WIDTH_M).intersects(person)
            polygon = box and _car_polygon(x_m, y_m, yaw_rad, SUMO_CAR_LENGTH_M, SUMO_CAR_WIDTH_M).intersects(
                person
            )
            found[(v, p)].append(ShapeOverlap(step.time_s, step.persons.places[j], box, polygon))
    return found


def walkingarea_edges(net: Path) -> set[str]:
    """The ids of the network's walking areas."""
    return {
        e.getID()
        for e in read_net(str(net), withInternal=True, withPedestrianConnections=True).getEdges(
            withInternal=True
        )
        if e.getFunction() == "walkingarea"
    }


def first_polygon_contact_s(overlaps: list[ShapeOverlap], walkingareas: set[str]) -> float:
    """The first FCD time at which SUMO's car polygon overlaps the person off a walking area (NaN if none)."""
    return next((o.time_s for o in overlaps if o.polygon and o.person_edge not in walkingareas), math.nan)


def tool_only_reason(meeting: str, overlaps: list[ShapeOverlap], walkingareas: set[str]) -> str:
    """Why SUMO does not report a contact of the tool (module docstring)."""
    if meeting in APART_MEETINGS:
        return "walkingarea"
    if not any(o.box for o in overlaps):
        return "person box"
    if math.isnan(first_polygon_contact_s(overlaps, walkingareas)):
        return "cut corner"
    return "unexplained"


def compare(
    table: pd.DataFrame, sumo: list[SumoCollision], fcd: Path, fcd_period_s: float, walkingareas: set[str]
) -> list[dict]:
    """One line per contact of either side (module docstring). `sumo_polygon_time_s`: for a collision
    both report, the first FCD step of the tool's contact at which SUMO's car polygon overlaps the
    person off a walking area (SUMO's own test, rebuilt from the FCD)."""
    contacts = table[table["collision"] | table["geometry_artefact"]]
    lines: list[dict] = []
    matched: dict[int, dict] = {}
    for hit in sumo:
        rows = contacts[
            (contacts["vehicle_id"] == hit.vehicle_id)
            & (contacts["person_id"] == hit.person_id)
            & (contacts["begin_s"] <= hit.time_s + fcd_period_s)
            & (contacts["end_s"] >= hit.time_s - fcd_period_s)
        ]
        line = {
            "vehicle_id": hit.vehicle_id,
            "person_id": hit.person_id,
            "sumo_time_s": hit.time_s,
            "sumo_type": hit.kind,
            "sumo_lane": hit.lane,
        }
        if rows.empty:
            lines.append(
                {**line, "side": "sumo only", "tool_time_s": math.nan, "tool_label": "", "reason": ""}
            )
            continue
        row = rows.iloc[0]
        label = "collision" if row["collision"] else "geometry artefact"
        both = {
            **line,
            "side": "both",
            "tool_time_s": float(row["contact_time_s"]),
            "tool_label": label,
            "tool_meeting": row["meeting"],
            "tool_clearance_m": float(row["min_clearance_m"]),
            "reason": "",
        }
        matched[int(rows.index[0])] = both
        lines.append(both)
    unmatched = contacts[~contacts.index.isin(list(matched))]
    windows: dict[tuple[str, str], tuple[float, float]] = {}
    for index, r in contacts.iterrows():
        if index in matched or r["meeting"] not in APART_MEETINGS:
            pair = (r["vehicle_id"], r["person_id"])
            begin_s = float(r["begin_s"] if index in matched else r["contact_time_s"])
            old = windows.get(pair, (begin_s, float(r["end_s"])))
            windows[pair] = (min(old[0], begin_s), max(old[1], float(r["end_s"])))
    overlaps = sumo_shape_overlaps(fcd, windows)
    for index, both in matched.items():
        row = contacts.loc[index]
        pair_overlaps = [
            o
            for o in overlaps.get((both["vehicle_id"], both["person_id"]), [])
            if float(row["begin_s"]) <= o.time_s <= float(row["end_s"])
        ]
        both["sumo_polygon_time_s"] = first_polygon_contact_s(pair_overlaps, walkingareas)
    for r in unmatched.itertuples():
        pair_overlaps = [
            o
            for o in overlaps.get((r.vehicle_id, r.person_id), [])
            if float(r.contact_time_s) <= o.time_s <= float(r.end_s)
        ]
        reason = tool_only_reason(r.meeting, pair_overlaps, walkingareas)
        lines.append(
            {
                "vehicle_id": r.vehicle_id,
                "person_id": r.person_id,
                "sumo_time_s": math.nan,
                "sumo_type": "",
                "sumo_lane": "",
                "side": "tool only",
                "tool_time_s": float(r.contact_time_s),
                "tool_label": "collision" if r.collision else "geometry artefact",
                "tool_meeting": r.meeting,
                "tool_clearance_m": float(r.min_clearance_m),
                "reason": reason,
            }
        )
    return sorted(
        lines, key=lambda d: d["sumo_time_s"] if math.isfinite(d["sumo_time_s"]) else d["tool_time_s"]
    )


COLUMNS = (
    "side",
    "vehicle_id",
    "person_id",
    "sumo_time_s",
    "sumo_type",
    "sumo_lane",
    "sumo_polygon_time_s",
    "tool_time_s",
    "tool_label",
    "tool_meeting",
    "tool_clearance_m",
    "reason",
)


def witness(
    net: Path,
    routes: list[Path],
    out: Path,
    end_s: float = 400.0,
    step_s: float = 0.1,
    fcd_period_s: float = 1.0,
    fcd_begin_s: float = 0.0,
    seed: int = SUMO_DEFAULT_SEED,
) -> list[dict]:
    """Run SUMO and the conflicts tool on the scenario and compare (module docstring)."""
    fcd, collision_file = run_sumo(net, routes, out, end_s, step_s, fcd_period_s, fcd_begin_s, seed)
    table_path = out / "conflicts.csv"
    table_path.unlink(missing_ok=True)
    if conflicts_main([str(fcd), "--net", str(net), "--out", str(table_path), "--quiet"]) != 0:
        raise WitnessError("the conflicts tool failed on SUMO's FCD")
    table = pd.read_csv(
        table_path, dtype={"vehicle_id": str, "person_id": str, "meeting": str}, keep_default_na=False
    )
    for column in ("contact_time_s", "min_clearance_m"):
        table[column] = pd.to_numeric(table[column].replace("", np.nan))
    sumo = sumo_person_collisions(collision_file, fcd_begin_s)
    lines = compare(table, sumo, fcd, fcd_period_s, walkingarea_edges(net))
    with open(out / "witness.csv", "w", newline="", encoding="utf-8") as handle:
        writer = csv.DictWriter(handle, fieldnames=COLUMNS, extrasaction="ignore")
        writer.writeheader()
        writer.writerows(lines)
    return lines


def main(argv: list[str] | None = None) -> int:
    parser = OneLineParser(prog="tools/sumo_collision_witness.py", description=__doc__.splitlines()[0])
    parser.add_argument("--net", type=Path, required=True)
    parser.add_argument("--routes", required=True, help="route files, comma-separated")
    parser.add_argument("--out", type=Path, required=True, help="folder for SUMO's outputs and witness.csv")
    parser.add_argument("--end", type=float, default=400.0, help="simulated time, s [400]")
    parser.add_argument("--step-length", type=float, default=0.1, help="SUMO step, s [0.1]")
    parser.add_argument("--fcd-period", type=float, default=1.0, help="FCD period, s [1]")
    parser.add_argument("--fcd-begin", type=float, default=0.0, help="first FCD time, s [0]")
    parser.add_argument(
        "--seed", type=int, default=SUMO_DEFAULT_SEED, help=f"sumo's --seed [{SUMO_DEFAULT_SEED}]"
    )
    args = parser.parse_args(argv)
    routes = [Path(r) for r in args.routes.split(",")]
    try:
        for path in (args.net, *routes):
            if not path.is_file():
                raise WitnessError(f"file not found: {path}")
        if not (0 < args.step_length <= args.fcd_period) or args.end <= args.fcd_begin:
            raise WitnessError("need 0 < --step-length <= --fcd-period and --fcd-begin < --end")
        lines = witness(
            args.net, routes, args.out, args.end, args.step_length, args.fcd_period, args.fcd_begin, args.seed
        )
    except WitnessError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    for line in lines:
        print(
            f"{line['side']:9}  {line['vehicle_id']:>6} {line['person_id']:>6}  "
            f"sumo {line['sumo_time_s']:7.2f} {line['sumo_type']:10} "
            f"polygon {line.get('sumo_polygon_time_s', math.nan):7.2f}  tool {line['tool_time_s']:7.2f} "
            f"{line['tool_label']:17} {line.get('tool_meeting', ''):11} {line.get('reason', '')}"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
