"""Clip an OpenStreetMap extract to a circle around a study intersection.

Linear ways (roads, paths) are cut exactly at the circle: where a segment crosses the boundary a new
node is interpolated on the circle, so an arm of the intersection keeps its full length up to the
boundary even when the next OSM node is far outside, and no edge runs kilometres away. Areas
(buildings, green areas) are kept whole when every node lies within `area_keep_factor * radius`
of the centre and at least one lies inside the circle; larger areas (a campus outline, a district
landuse) are dropped, since cutting a polygon open would break it and they occlude nothing.
Relations are kept only when every member they reference survived whole.

New objects get negative ids (the OSM convention for objects not in the database), numbered in a
fixed order, so the same input always gives the same file.
"""

from __future__ import annotations

import argparse
import math
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import NoReturn

import osmium
import osmium.io
from osmium.osm import mutable
from pyproj import Transformer

from pedsafe_sumo.network.attribution import add_attribution_comment
from pedsafe_sumo.network.coordinates import NEGATIVE_HELP, parse_lat_lon, with_negative_values

#: The largest clip: a study site is an intersection, not a town (tools/build_network.py --radius has the
#: same bound).
MAX_CLIP_RADIUS_M = 2000.0

#: Keys whose presence marks a closed way as an area rather than a closed line (a roundabout).
AREA_KEYS = ("building", "landuse", "natural", "leisure", "amenity", "area", "building:part")


class ClipError(ValueError):
    """The input cannot be clipped (not OSM data, centre outside the data, nothing inside)."""


@dataclass
class _Node:
    lon: float
    lat: float
    tags: dict[str, str]
    attrs: dict


@dataclass
class _Way:
    refs: list[int]
    tags: dict[str, str]
    attrs: dict


@dataclass
class _Relation:
    members: list[tuple[str, int, str]]
    tags: dict[str, str]
    attrs: dict


@dataclass
class ClipResult:
    """What was written, for the summary line."""

    nodes: int
    ways: int
    relations: int
    boundary_nodes: int
    split_ways: int
    dropped_areas: int = 0
    kept_way_ids: set[int] = field(default_factory=set)


def _attrs(obj) -> dict:
    return {
        "version": obj.version,
        "visible": True,
        "changeset": obj.changeset,
        "timestamp": obj.timestamp,
        "uid": obj.uid,
        "user": obj.user,
    }


def read_osm(path: Path) -> tuple[dict[int, _Node], dict[int, _Way], dict[int, _Relation]]:
    """All nodes, ways and relations of an OSM file, in memory (study-area extracts are small)."""
    if not path.is_file():
        raise ClipError(f"OSM file not found: {path}")
    with open(path, "rb") as handle:
        head = handle.read(4096).lstrip()
    if not (head.startswith(b"<?xml") or head.startswith(b"<osm")) or b"<osm" not in head:
        raise ClipError(f"{path} is not an OpenStreetMap XML file (no <osm> root element)")
    nodes: dict[int, _Node] = {}
    ways: dict[int, _Way] = {}
    relations: dict[int, _Relation] = {}
    try:
        for obj in osmium.FileProcessor(str(path)):
            if obj.is_node():
                if obj.location.valid():
                    nodes[obj.id] = _Node(obj.location.lon, obj.location.lat, dict(obj.tags), _attrs(obj))
            elif obj.is_way():
                ways[obj.id] = _Way([n.ref for n in obj.nodes], dict(obj.tags), _attrs(obj))
            elif obj.is_relation():
                members = [(m.type, m.ref, m.role) for m in obj.members]
                relations[obj.id] = _Relation(members, dict(obj.tags), _attrs(obj))
    except RuntimeError as exc:
        raise ClipError(f"{path} could not be read as OSM data: {exc}") from None
    if not nodes:
        raise ClipError(f"{path} holds no OSM nodes")
    return nodes, ways, relations


def _is_area(way: _Way) -> bool:
    closed = len(way.refs) >= 4 and way.refs[0] == way.refs[-1]
    return closed and any(key in way.tags for key in AREA_KEYS) and way.tags.get("area") != "no"


def _circle_crossings(ax: float, ay: float, bx: float, by: float, radius: float) -> list[float]:
    """Parameters t in (0, 1) where segment a->b crosses the circle |p| = radius, in increasing order."""
    dx, dy = bx - ax, by - ay
    qa = dx * dx + dy * dy
    if qa == 0.0:
        return []
    qb = 2.0 * (ax * dx + ay * dy)
    qc = ax * ax + ay * ay - radius * radius
    disc = qb * qb - 4.0 * qa * qc
    if disc <= 0.0:
        return []
    root = math.sqrt(disc)
    ts = [(-qb - root) / (2.0 * qa), (-qb + root) / (2.0 * qa)]
    return [t for t in ts if 0.0 < t < 1.0]


def clip_osm(
    source: Path,
    target: Path,
    center_lat: float,
    center_lon: float,
    radius_m: float,
    area_keep_factor: float = 1.5,
) -> ClipResult:
    """Write the part of `source` within `radius_m` of the centre to `target` (OSM XML)."""
    if radius_m <= 0:
        raise ClipError(f"radius must be positive, got {radius_m} m")
    nodes, ways, relations = read_osm(Path(source))

    lons = [n.lon for n in nodes.values()]
    lats = [n.lat for n in nodes.values()]
    if not (min(lats) <= center_lat <= max(lats) and min(lons) <= center_lon <= max(lons)):
        raise ClipError(
            f"centre ({center_lat:.5f}, {center_lon:.5f}) lies outside the data of {source} "
            f"(lat {min(lats):.5f}..{max(lats):.5f}, lon {min(lons):.5f}..{max(lons):.5f})"
        )

    # Azimuthal equidistant projection centred on the intersection: distances from the centre are exact.
    to_local = Transformer.from_crs(
        "EPSG:4326",
        f"+proj=aeqd +lat_0={center_lat} +lon_0={center_lon} +datum=WGS84 +units=m",
        always_xy=True,
    )
    to_geo = Transformer.from_crs(to_local.target_crs, "EPSG:4326", always_xy=True)
    local = {nid: to_local.transform(n.lon, n.lat) for nid, n in nodes.items()}

    def inside(nid: int) -> bool:
        x, y = local[nid]
        return x * x + y * y <= radius_m * radius_m

    out_nodes: dict[int, _Node] = {}
    out_ways: dict[int, _Way] = {}
    whole_ways: set[int] = set()
    boundary_ids: dict[tuple[int, int, int], int] = {}
    next_new_id = -1
    split_ways = 0
    dropped_areas = 0

    def new_id() -> int:
        nonlocal next_new_id
        value = next_new_id
        next_new_id -= 1
        return value

    def boundary_node(a: int, b: int, which: int, t: float) -> int:
        # Two ways sharing a segment share the boundary node on it.
        key = (min(a, b), max(a, b), which if a < b else 1 - which)
        if key not in boundary_ids:
            (ax, ay), (bx, by) = local[a], local[b]
            lon, lat = to_geo.transform(ax + t * (bx - ax), ay + t * (by - ay))
            nid = new_id()
            boundary_ids[key] = nid
            out_nodes[nid] = _Node(round(lon, 7), round(lat, 7), {}, {})
        return boundary_ids[key]

    for way_id in sorted(ways):
        way = ways[way_id]
        refs = [r for r in way.refs if r in nodes]
        if len(refs) < 2 or not any(inside(r) for r in refs) and not _segments_cross(refs, local, radius_m):
            continue
        if _is_area(way):
            if all(math.hypot(*local[r]) <= area_keep_factor * radius_m for r in refs):
                out_ways[way_id] = _Way(refs, way.tags, way.attrs)
                whole_ways.add(way_id)
            else:
                dropped_areas += 1
            continue
        pieces = _cut_linear(refs, inside, local, radius_m, boundary_node)
        pieces = [p for p in pieces if len(p) >= 2]
        if not pieces:
            continue
        if len(pieces) == 1 and pieces[0] == refs:
            whole_ways.add(way_id)
        else:
            split_ways += 1
        for index, piece in enumerate(pieces):
            piece_id = way_id if index == 0 else new_id()
            out_ways[piece_id] = _Way(piece, way.tags, way.attrs if index == 0 else {})

    referenced = {r for w in out_ways.values() for r in w.refs}
    for nid, node in nodes.items():
        if nid in referenced or (node.tags and inside(nid)):
            out_nodes.setdefault(nid, node)

    out_relations: dict[int, _Relation] = {}
    for rel_id in sorted(relations):
        rel = relations[rel_id]
        ok = bool(rel.members) and all(
            (mtype == "n" and ref in out_nodes) or (mtype == "w" and ref in whole_ways)
            for mtype, ref, _ in rel.members
        )
        if ok:
            out_relations[rel_id] = rel

    if not any("highway" in w.tags for w in out_ways.values()):
        raise ClipError(
            f"no road lies within {radius_m:.0f} m of ({center_lat:.5f}, {center_lon:.5f}) in {source}"
        )

    _write(Path(target), out_nodes, out_ways, out_relations, center_lat, center_lon, radius_m)
    return ClipResult(
        nodes=len(out_nodes),
        ways=len(out_ways),
        relations=len(out_relations),
        boundary_nodes=len(boundary_ids),
        split_ways=split_ways,
        dropped_areas=dropped_areas,
        kept_way_ids=set(out_ways),
    )


def _segments_cross(refs: list[int], local: dict, radius_m: float) -> bool:
    return any(_circle_crossings(*local[a], *local[b], radius_m) for a, b in zip(refs, refs[1:]))


def _cut_linear(refs, inside, local, radius_m, boundary_node) -> list[list[int]]:
    """Runs of the way inside the circle, each closed by interpolated boundary nodes."""
    pieces: list[list[int]] = []
    current: list[int] = [refs[0]] if inside(refs[0]) else []
    for a, b in zip(refs, refs[1:]):
        a_in, b_in = inside(a), inside(b)
        if a_in and b_in:
            current.append(b)
            continue
        crossings = _circle_crossings(*local[a], *local[b], radius_m)
        if a_in and not b_in:
            current.append(boundary_node(a, b, 0, crossings[-1]) if crossings else a)
            pieces.append(current)
            current = []
        elif not a_in and b_in:
            current = [boundary_node(a, b, 0, crossings[0])] if crossings else []
            current.append(b)
        elif len(crossings) == 2:  # both ends outside, the segment passes through the circle
            pieces.append([boundary_node(a, b, 0, crossings[0]), boundary_node(a, b, 1, crossings[1])])
    if current:
        pieces.append(current)
    return pieces


def _write(target: Path, nodes, ways, relations, center_lat, center_lon, radius_m) -> None:
    target.parent.mkdir(parents=True, exist_ok=True)
    header = osmium.io.Header()
    header.set("generator", "pedsafe_sumo clip_osm")
    lats = [n.lat for n in nodes.values()]
    lons = [n.lon for n in nodes.values()]
    header.add_box(
        osmium.osm.Box(osmium.osm.Location(min(lons), min(lats)), osmium.osm.Location(max(lons), max(lats)))
    )
    tmp = target.with_name(target.name + ".tmp.osm")
    if tmp.exists():
        tmp.unlink()
    writer = osmium.SimpleWriter(str(tmp), header=header, overwrite=True)
    try:
        # OSM files list nodes, ways, relations each by id; negative (new) ids after positive ones.
        for nid in sorted(nodes, key=_id_order):
            node = nodes[nid]
            writer.add_node(mutable.Node(id=nid, location=(node.lon, node.lat), tags=node.tags, **node.attrs))
        for wid in sorted(ways, key=_id_order):
            way = ways[wid]
            writer.add_way(mutable.Way(id=wid, nodes=way.refs, tags=way.tags, **way.attrs))
        for rid in sorted(relations, key=_id_order):
            rel = relations[rid]
            writer.add_relation(mutable.Relation(id=rid, members=rel.members, tags=rel.tags, **rel.attrs))
    finally:
        writer.close()
    add_attribution_comment(tmp)
    tmp.replace(target)


def _id_order(obj_id: int) -> tuple[int, int]:
    return (0, obj_id) if obj_id > 0 else (1, -obj_id)


class _OneLineParser(argparse.ArgumentParser):
    """argparse whose errors are one line (exit 2). pedsafe_sumo.cli has the same for the commands; it sits
    above network/ (it imports the settings, which import the scenarios, which import network/)."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"clip_osm: error: {message}\n")


def main(argv: list[str] | None = None) -> int:
    parser = _OneLineParser(
        prog="clip_osm", description="Clip an OSM XML file to a circle, cutting ways at the boundary."
    )
    parser.add_argument("source", type=Path, help="OSM XML file")
    parser.add_argument("target", type=Path, help="clipped OSM XML file to write")
    parser.add_argument(
        "--center",
        required=True,
        type=parse_lat_lon,
        help=f"LAT,LON of the centre in degrees; {NEGATIVE_HELP}",
    )
    parser.add_argument(
        "--radius",
        type=float,
        required=True,
        help=f"radius in metres, above 0 and at most {MAX_CLIP_RADIUS_M:g}",
    )
    argv = sys.argv[1:] if argv is None else argv
    args = parser.parse_args(with_negative_values(parser, argv, ["--center"]))
    lat, lon = args.center
    if not 0 < args.radius <= MAX_CLIP_RADIUS_M:  # also false for NaN
        parser.exit(
            2, f"clip_osm: error: --radius must lie in (0, {MAX_CLIP_RADIUS_M:g}] m, got {args.radius}\n"
        )
    try:
        result = clip_osm(args.source, args.target, lat, lon, args.radius)
    except ClipError as exc:
        parser.exit(2, f"clip_osm: error: {exc}\n")
    print(
        f"wrote {args.target}: {result.nodes} nodes, {result.ways} ways "
        f"({result.split_ways} cut at the boundary, {result.boundary_nodes} boundary nodes), "
        f"{result.relations} relations, {result.dropped_areas} large areas dropped"
    )
    return 0
