"""A site from any SUMO network: the network kept as it is, the junction chosen by id or by a point of the
network's own frame, the occluders from a polygon file (optional).

    python tools/build_network.py --net my.net.xml --junction J3 --out sites/mine
    python tools/build_network.py --net my.net.xml --at -12.5,30 --polygons my.poly.xml --out sites/mine

No OpenStreetMap data and no geo-projection are needed: the site file records `source_net` (the network it
was made from) and no geo-reference (`center_lat`/`center_lon` are null; `center_xy` is the chosen point in
the network frame). The poles, sumocfg, view and site file are derived as for a site built from OSM
(:mod:`.build`), with the same digests, so every command takes the folder as `--site DIR` and an edit is
refused until `--refresh` re-derives them. The polygons are the user's, like the network: the build copies
them into `<name>.poly.xml` (no file: none, so nothing hides a pedestrian but the vehicles), and `--refresh`
keeps them as they are.

A network built for left-hand traffic (lefthand="true") keeps its side, and the scenarios are staged
mirrored on it (network.traffic_side). A network the scenarios cannot be staged on is refused in one
line: a junction that is not signalised, one whose approaches have no sidewalk or that has no crosswalk
(with the netconvert options that add them).
"""

from __future__ import annotations

import gzip
import json
import math
import re
import shutil
import tempfile
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import sumolib

from pedsafe_sumo.network.approaches import (
    choose_approach,
    junction_legs,
    signal_group,
)
from pedsafe_sumo.network.build import BuildReport, stage_poles_and_views
from pedsafe_sumo.network.errors import BuildError
from pedsafe_sumo.network.poles import HostingScorer
from pedsafe_sumo.network.site_files import commit_staged, relative_to
from pedsafe_sumo.network.sites import DERIVED_MARKER, content_digest, derived_marker
from pedsafe_sumo.network.traffic_side import network_is_lefthand, side_problem
from pedsafe_sumo.sumo_net import read_net

#: What a network without sidewalks or crosswalks needs, in the words of netconvert's own options.
ADD_WALKWAYS = (
    "add them with netconvert -s IN.net.xml --sidewalks.guess true --crossings.guess true -o OUT.net.xml"
)
#: A polygon file with no polygons: the site of a network given without --polygons.
EMPTY_POLYGONS = (
    '<?xml version="1.0" encoding="UTF-8"?>\n'
    "<!-- No occluders: the site was built from a SUMO network without a polygon file. -->\n"
    "<additional>\n</additional>\n"
)


def parse_xy(text: str) -> tuple[float, float]:
    """(x, y) in metres of the network frame from 'X,Y' (ValueError naming the value otherwise)."""
    try:
        x, y = (float(part) for part in text.split(","))
    except ValueError:
        raise ValueError(f"a point must be X,Y in metres of the network's frame, got '{text}'") from None
    if not (math.isfinite(x) and math.isfinite(y)):
        raise ValueError(f"a point must be X,Y in metres of the network's frame, got '{text}'")
    return x, y


def build_site_from_net(
    net_path: Path,
    name: str,
    out_dir: Path,
    *,
    junction_id: str | None = None,
    at_xy: tuple[float, float] | None = None,
    polygons: Path | None = None,
    polygons_text: str | None = None,
    rsu_corner: str | None = None,
    rsu_watch_arm: str | None = None,
    description: str = "",
    source_net: Path | None = None,
    hosting_scorer: HostingScorer,
) -> BuildReport:
    """Build the site folder `out_dir` from the SUMO network `net_path` (kept as it is) at the signalised
    junction `junction_id` or the one nearest `at_xy` (network frame); occluders from the polygon file
    `polygons` or the text `polygons_text` (a refresh keeps the folder's own), none without either.
    `source_net` is recorded as where the network came from (default: `net_path`)."""
    started = time.perf_counter()
    if not re.fullmatch(r"[A-Za-z0-9_-]+", name):
        raise BuildError(f"site name '{name}' must be letters, digits, '_' or '-'")
    if (junction_id is None) == (at_xy is None):
        raise BuildError("give the junction: --junction ID or --at X,Y (the network's frame), not both")
    net_path = Path(net_path)
    if not net_path.is_file():
        raise BuildError(f"--net {net_path}: no such file")
    if polygons is not None and not Path(polygons).is_file():
        raise BuildError(f"--polygons {polygons}: no such file")
    net_file, poly_file, rsu_file = f"{name}.net.xml", f"{name}.poly.xml", f"{name}.rsu.add.xml"
    with tempfile.TemporaryDirectory(prefix=f"pedsafe_build_{name}_") as tmp:
        stage = Path(tmp)
        _stage_network(net_path, stage / net_file)
        # A network built for left-hand traffic keeps its side: the scenarios are staged mirrored on it.
        lefthand_reason = 'the network says lefthand="true"' if network_is_lefthand(stage / net_file) else ""
        net = _read(stage / net_file, net_path)
        side = side_problem(net, stage / net_file, str(net_path))
        if side:
            raise BuildError(side)
        centre_xy = _centre(net, net_path, junction_id, at_xy)
        group = signal_group(net, centre_xy)
        walkways = walkway_problem(net, group, net_path)
        if walkways:
            raise BuildError(walkways)
        _stage_polygons(stage / poly_file, polygons, polygons_text)
        junction, rsu_watch_arm = _approach(net, group, rsu_watch_arm)
        rsu_corner, rsu_units, approach_info = stage_poles_and_views(
            stage, name, net, group, junction, rsu_watch_arm, rsu_corner, hosting_scorer
        )
        marker = derived_marker(stage / net_file)
        for derived in (poly_file, rsu_file):
            _insert_marker(stage / derived, marker)
        site_info = {
            "name": name,
            "description": description,
            # No geo-reference: the site lives in the network's own frame.
            "center_lat": None,
            "center_lon": None,
            "center_xy": [round(c, 2) for c in centre_xy],
            "radius_m": 0.0,
            "source_net": relative_to(out_dir, source_net or net_path),
            "source_osm": None,
            "clip_osm": None,
            "rsu_corner": rsu_corner,
            "rsu_watch_arm": rsu_watch_arm,
            "main_junction": junction.getID(),
            "main_junction_xy": [round(c, 2) for c in junction.getCoord()],
            "signal_nodes": [n.getID() for n in group],
            # The occluders' count (the user's polygon file; none without one).
            "polygons": sum(1 for _ in ET.parse(stage / poly_file).getroot().iter("poly")),
            "roadside_unit": rsu_units[0],
            "approaches": approach_info,
            "roadside_units": rsu_units,
            "sumo_version": sumolib.version.gitDescribe(),
            "net_sha256": content_digest(stage / net_file),
            "derived_sha256": {p: content_digest(stage / p) for p in (poly_file, rsu_file)},
        }
        site_file = stage / f"{name}.site.json"
        site_file.write_text(_json(site_info), encoding="utf-8")
        products = [net_file, poly_file, rsu_file, f"{name}.view.xml", f"{name}.sumocfg", site_file.name]
        out_dir.mkdir(parents=True, exist_ok=True)
        written, unchanged = commit_staged([(stage / p, out_dir / p) for p in products])
    return BuildReport(
        name,
        out_dir,
        out_dir / f"{name}.osm",
        written,
        unchanged,
        junction.getID(),
        time.perf_counter() - started,
        None,
        [n.getID() for n in group],
        lefthand_reason,
    )


def _stage_network(net_path: Path, staged: Path) -> None:
    """The network as it is, decompressed when it is gzipped (`.net.xml.gz`, as SUMO reads it)."""
    try:
        if net_path.name.endswith(".gz"):
            with gzip.open(net_path, "rb") as source, staged.open("wb") as target:
                shutil.copyfileobj(source, target)
        else:
            shutil.copyfile(net_path, staged)
    except (OSError, EOFError) as exc:
        raise BuildError(f"cannot read {net_path}: {getattr(exc, 'strerror', None) or exc}") from None


def _json(info: dict) -> str:
    return json.dumps(info, indent=2, ensure_ascii=False) + "\n"


def _read(path: Path, shown_as: Path) -> sumolib.net.Net:
    try:
        return read_net(str(path), withInternal=True)
    except Exception as exc:  # sumolib raises bare SAX errors on a broken network
        raise BuildError(f"cannot read the network {shown_as}: {str(exc).splitlines()[0]}") from None


def _centre(
    net: sumolib.net.Net, net_path: Path, junction_id: str | None, at_xy: tuple[float, float] | None
) -> tuple[float, float]:
    """The point the intersection is looked for at: the junction named, or the point given (refused off the
    network's boundary)."""
    if junction_id is not None:
        if not net.hasNode(junction_id):
            raise BuildError(f"junction '{junction_id}' is not in {net_path}")
        node = net.getNode(junction_id)
        if not node.getType().startswith("traffic_light"):
            signalised = _signalised_ids(net)
            raise BuildError(
                f"junction '{junction_id}' of {net_path} is not signalised (type {node.getType()}): the "
                f"scenarios stage a signalised junction (the network's: {signalised})"
            )
        return node.getCoord()
    assert at_xy is not None
    xmin, ymin, xmax, ymax = net.getBoundary()
    x, y = at_xy
    if not (xmin <= x <= xmax and ymin <= y <= ymax):
        raise BuildError(
            f"--at {x:g},{y:g} is off the network {net_path} (it spans x {xmin:.1f} to {xmax:.1f}, "
            f"y {ymin:.1f} to {ymax:.1f} m)"
        )
    return at_xy


def _signalised_ids(net: sumolib.net.Net) -> str:
    ids = sorted(n.getID() for n in net.getNodes() if n.getType().startswith("traffic_light"))
    if not ids:
        return "none"
    return ", ".join(ids[:8]) + (f" and {len(ids) - 8} more" if len(ids) > 8 else "")


def walkway_problem(net: sumolib.net.Net, group: list, net_path: Path) -> str | None:
    """Why the intersection of `group` has nowhere to stage a pedestrian (one line), or None: no sidewalk on
    any road entering it, or no crosswalk at any of its nodes."""
    ids = {n.getID() for n in group}
    entering = [
        e
        for n in group
        for e in n.getIncoming()
        if e.getFunction() == "" and e.getFromNode().getID() not in ids
    ]
    sidewalk = any(e.getLane(0).getPermissions() == {"pedestrian"} for e in entering)
    crossing = any(
        e.getFunction() == "crossing" and any(e.getID().startswith(f":{i}_") for i in ids)
        for e in net.getEdges(withInternal=True)
    )
    missing = [what for what, there in (("sidewalks", sidewalk), ("crosswalks", crossing)) if not there]
    if not missing:
        return None
    return (
        f"junction {group[0].getID()} of {net_path} has no {' and no '.join(missing)}: the scenarios "
        f"stage the pedestrian on them; {ADD_WALKWAYS}"
    )


def _approach(net: sumolib.net.Net, group: list, watch_arm: str | None) -> tuple:
    junction, chosen_arm = choose_approach(net, group, watch_arm)
    if watch_arm is not None and chosen_arm != watch_arm:
        legs = ", ".join(leg.name for leg in junction_legs(group))
        raise BuildError(f"the main junction has no leg {watch_arm} (legs: {legs})")
    return junction, chosen_arm


def _stage_polygons(path: Path, polygons: Path | None, polygons_text: str | None) -> None:
    """The site's occluders: the polygon file given (checked to parse), the text kept by a refresh, or
    none."""
    if polygons is not None:
        try:
            root = ET.parse(polygons).getroot()
        except (OSError, ET.ParseError) as exc:
            raise BuildError(f"cannot parse --polygons {polygons}: {str(exc).splitlines()[0]}") from None
        if root.tag != "additional":
            raise BuildError(f"--polygons {polygons} is not a SUMO polygon file (its root is <{root.tag}>)")
        text = Path(polygons).read_text(encoding="utf-8")
    else:
        text = polygons_text if polygons_text is not None else EMPTY_POLYGONS
    path.write_text(DERIVED_MARKER.sub("", text).replace("?>\n\n", "?>\n", 1), encoding="utf-8")


def _insert_marker(path: Path, marker: str) -> None:
    text = path.read_text(encoding="utf-8")
    end = text.index("?>") + 2 if text.startswith("<?xml") else 0
    path.write_text(text[:end] + "\n" + marker + text[end:], encoding="utf-8")
