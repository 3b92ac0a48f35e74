"""Build a study site from OpenStreetMap: clip, netconvert, polyconvert, roadside poles, sumocfg, site file.

Everything is made in a staging directory under relative file names, so the configuration that
netconvert and polyconvert write into their headers is the same on every machine, and nothing in
the target directories is touched until every step has succeeded: a failed build leaves the
committed network as it was.

Usage (see tools/build_network.py):
    python tools/build_network.py --site xueqing
    python tools/build_network.py --osm big.osm --center 40.0064,116.3462 --radius 200 --name mysite \
        --out sites/mysite
    python tools/build_network.py --osm argentina.osm --center -34.6037,-58.3816 --name obelisco \
        --out sites/obelisco
    python tools/build_network.py --refresh sites/mysite    # after editing sites/mysite/mysite.net.xml

South of the equator and west of Greenwich the centre is negative, in either spelling
(`--center -34.6,-58.4`, `--center=-34.6,-58.4`). The network is built for left-hand traffic
(netconvert --lefthand) when `--lefthand` says so, when the OSM data says driving_side=left, or when the
centre lies in a region where all traffic keeps left (network.traffic_side.LEFTHAND_REGIONS); a network
given with --net keeps its own side (lefthand="true"). Otherwise it is built for right-hand traffic and
the summary says the build cannot tell the traffic side from OSM data alone.

The folder written is a site (pedsafe_sumo.network.sites): every command takes it as --site DIR. Its
derived files (site file, poles, polygons) carry the digest of the network they were made from, so a
network edited afterwards is refused until --refresh re-derives them from it (docs/sites.md).

The steps live in their own modules: :mod:`.clip` (the OSM clip), :mod:`.convert` (netconvert,
polyconvert), :mod:`.approaches` (the intersection and its approaches), :mod:`.poles` (the roadside
poles), :mod:`.site_files` (sumocfg, view, site file, copying into the folder); the command line is
:mod:`pedsafe_sumo.site.build_command`.
"""

from __future__ import annotations

import re
import shutil
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import sumolib

from pedsafe_sumo.network.approaches import (
    approach_nodes,
    choose_approach,
    junction_legs,
    leg_named,
    signal_group,
)
from pedsafe_sumo.network.clip import ClipError, clip_osm, read_osm
from pedsafe_sumo.network.convert import (
    SUMO_TYPEMAPS,
    URBAN_SPEEDS_TYPEMAP,
    convert_network,
    convert_polygons,
    lane_defaults,
    stage_tool_inputs,
)
from pedsafe_sumo.network.errors import BuildError
from pedsafe_sumo.network.poles import HostingScorer, place_approach_poles, side_kerb_corner, write_rsu
from pedsafe_sumo.network.site_files import (
    commit_staged,
    finish_products,
    relative_to,
    write_site_file,
    write_sumocfg,
    write_view,
)
from pedsafe_sumo.network.traffic_lights import junctions_problem
from pedsafe_sumo.network.traffic_side import (
    lefthand_region,
    network_is_lefthand,
    network_keep_side,
    osm_drives_left,
    side_problem,
)
from pedsafe_sumo.sumo_net import read_net

__all__ = ["BuildError", "BuildReport", "build_site"]


@dataclass
class BuildReport:
    name: str
    out_dir: Path
    clip_path: Path
    written: list[Path]
    unchanged: list[Path]
    main_junction: str
    seconds: float
    lane_defaults: dict | None = None
    signal_nodes: list | None = None
    #: Why the network keeps left ("" when it keeps right): the summary's traffic-side line.
    lefthand_reason: str = ""


def stage_poles_and_views(
    stage: Path,
    name: str,
    net,
    group,
    junction,
    rsu_watch_arm: str,
    rsu_corner: str | None,
    hosting_scorer,
) -> tuple[str, list, dict]:
    """The site's roadside poles (one per approach), sumo-gui view and SUMO configuration written into
    `stage` around `junction`: (the corner of the watched approach's pole, the poles, the approaches'
    info). A junction several lights control is refused first (BuildError): it cannot be staged (one
    program per episode), and the poles' scorer stages the scenarios."""
    side = network_keep_side(stage / f"{name}.net.xml")
    rsu_corner = rsu_corner or side_kerb_corner(leg_named(junction_legs(group), rsu_watch_arm), side)
    approaches = approach_nodes(net, group, rsu_watch_arm, junction)
    several = junctions_problem(
        stage / f"{name}.net.xml", [junction.getID(), *(n.getID() for n in approaches.values())]
    )
    if several:
        raise BuildError(several)
    rsu_units, approach_info = place_approach_poles(
        stage, name, net, approaches, rsu_corner, rsu_watch_arm, f"{name}.poly.xml", hosting_scorer
    )
    write_rsu(stage / f"{name}.rsu.add.xml", rsu_units)
    write_view(stage / f"{name}.view.xml", junction.getCoord())
    write_sumocfg(stage / f"{name}.sumocfg", name)
    return rsu_corner, rsu_units, approach_info


def build_site(
    osm_path: Path,
    center_lat: float,
    center_lon: float,
    radius_m: float,
    name: str,
    out_dir: Path,
    clip_out: Path,
    clip: bool = True,
    patches_dir: Path | None = None,
    rsu_corner: str | None = "NW",
    rsu_watch_arm: str | None = "N",
    description: str = "",
    source_osm: Path | None = None,
    net_from: Path | None = None,
    *,
    hosting_scorer: HostingScorer,
    lefthand: bool = False,
) -> BuildReport:
    """Build the site folder `out_dir` from an OSM file; see the module docstring.

    With `net_from` (a .net.xml, e.g. one edited in netedit) no netconvert runs: that network is kept as
    it is and the polygons (polyconvert over `osm_path`, projected with the network's own geo-reference),
    roadside poles, sumocfg and site file are derived from it. `source_osm` is recorded in the site file
    as where the data came from (default: `osm_path` when it is clipped). `hosting_scorer` judges the
    pole placements (see :mod:`.poles`). `lefthand`: the user says the junction's traffic keeps left
    (the build also finds it in the data: module docstring)."""
    started = time.perf_counter()
    if not re.fullmatch(r"[A-Za-z0-9_-]+", name):
        raise BuildError(f"site name '{name}' must be letters, digits, '_' or '-'")
    osm_path = Path(osm_path)
    clipping = clip and net_from is None
    if source_osm is None and clipping:
        source_osm = osm_path
    net_file, poly_file, rsu_file = f"{name}.net.xml", f"{name}.poly.xml", f"{name}.rsu.add.xml"
    with tempfile.TemporaryDirectory(prefix=f"pedsafe_build_{name}_") as tmp:
        stage = Path(tmp)
        staged_osm = _stage_osm(stage / f"{name}.osm", osm_path, center_lat, center_lon, radius_m, clipping)
        stage_tool_inputs(stage)
        if net_from is not None:
            _stage_network(net_from, stage / net_file)  # the network as the user left it
            lefthand_reason = (
                'the network says lefthand="true"' if network_is_lefthand(stage / net_file) else ""
            )
        else:
            lefthand_reason = _lefthand_reason(lefthand, staged_osm, center_lat, center_lon)
            convert_network(
                stage, name, staged_osm.name, net_file, patches_dir, lefthand=bool(lefthand_reason)
            )
        dropped_underground = convert_polygons(stage, net_file, staged_osm.name, poly_file)
        net = _read_network(stage / net_file, net_from or net_file)
        side = side_problem(net, stage / net_file, str(net_from or net_file))
        if side:
            raise BuildError(side)
        group, junction, rsu_watch_arm = _main_approach(net, center_lat, center_lon, rsu_watch_arm)
        rsu_corner, rsu_units, approach_info = stage_poles_and_views(
            stage, name, net, group, junction, rsu_watch_arm, rsu_corner, hosting_scorer
        )
        products = [net_file, poly_file, rsu_file, f"{name}.view.xml", f"{name}.sumocfg"]
        finish_products(stage, products, net_file, derived=(poly_file, rsu_file))
        defaults = lane_defaults(
            staged_osm,
            [*(stage / t for t in SUMO_TYPEMAPS), stage / URBAN_SPEEDS_TYPEMAP.name],
        )
        site_info = {
            "name": name,
            "description": description,
            "center_lat": center_lat,
            "center_lon": center_lon,
            "radius_m": radius_m,
            "source_osm": relative_to(out_dir, source_osm),
            "clip_osm": relative_to(out_dir, clip_out),
            "rsu_corner": rsu_corner,
            "rsu_watch_arm": rsu_watch_arm,
            "main_junction": junction.getID(),
            "main_junction_xy": [round(c, 2) for c in junction.getCoord()],
            # Every signal node of the intersection (more than one when netconvert split it).
            "signal_nodes": [n.getID() for n in group],
            # OSM road classes without a lane tag and the lanes per direction the build gave them.
            "lane_defaults": defaults,
            # Polygons OSM puts below ground, left out of the occluders (convert.convert_polygons).
            "underground_polygons_dropped": dropped_underground,
            # "roadside_unit": the corner pole, whose watched arm is the scenarios' approach.
            "roadside_unit": rsu_units[0],
            # Every approach (arm -> its signal node and poles), the site's own first: --approach ARM.
            "approaches": approach_info,
            "roadside_units": rsu_units,
        }
        site_file = write_site_file(stage, site_info, net_file, derived=(poly_file, rsu_file))

        # Every step succeeded: only now touch the target directories.
        out_dir.mkdir(parents=True, exist_ok=True)
        targets = [(stage / p, out_dir / p) for p in [*products, site_file.name]]
        if clipping:
            clip_out.parent.mkdir(parents=True, exist_ok=True)
            targets.append((staged_osm, clip_out))
        written, unchanged = commit_staged(targets)
    return BuildReport(
        name,
        out_dir,
        clip_out,
        written,
        unchanged,
        junction.getID(),
        time.perf_counter() - started,
        defaults,
        [n.getID() for n in group],
        lefthand_reason,
    )


def _lefthand_reason(told: bool, staged_osm: Path, center_lat: float, center_lon: float) -> str:
    """Why the network is built for left-hand traffic, or "" (right-hand): the user's --lefthand, the
    OSM data's driving_side=left, or the centre's region (network.traffic_side)."""
    if told:
        return "--lefthand"
    if osm_drives_left(staged_osm):
        return "the OSM data says driving_side=left"
    region = lefthand_region(center_lat, center_lon)
    if region is not None:
        return f"the junction lies in {region}, where all traffic keeps left"
    return ""


def _stage_osm(
    staged_osm: Path, osm_path: Path, center_lat: float, center_lon: float, radius_m: float, clip: bool
) -> Path:
    """The OSM data of the site in the staging directory: the clip around the centre, or the file as it is."""
    try:
        if clip:
            clip_osm(osm_path, staged_osm, center_lat, center_lon, radius_m)
        else:
            read_osm(osm_path)  # validates that it is OSM data
            shutil.copyfile(osm_path, staged_osm)
    except ClipError as exc:
        raise BuildError(str(exc)) from None
    return staged_osm


def _stage_network(net_from: Path, staged_net: Path) -> None:
    """The given network, kept as it is: nothing of it is rebuilt."""
    try:
        shutil.copyfile(net_from, staged_net)
    except OSError as exc:
        raise BuildError(f"cannot read {net_from}: {exc.strerror}") from None


def _read_network(path: Path, shown_as: Path | str) -> sumolib.net.Net:
    try:
        return read_net(str(path), withInternal=True)
    except Exception as exc:  # sumolib raises bare SAX errors on a broken network
        raise BuildError(f"cannot read the network {shown_as}: {exc}") from None


def _main_approach(
    net: sumolib.net.Net, center_lat: float, center_lon: float, watch_arm: str | None
) -> tuple[list, sumolib.net.node.Node, str]:
    """(signal nodes of the intersection, main junction, watched arm). The approach the scenarios use is the
    watched arm when given, else the best one of every signal node of the intersection (netconvert may
    split it into several); its node is the main junction."""
    center_xy = net.convertLonLat2XY(center_lon, center_lat)
    group = signal_group(net, center_xy)
    junction, chosen_arm = choose_approach(net, group, watch_arm)
    if watch_arm is not None and chosen_arm != watch_arm:
        legs = ", ".join(leg.name for leg in junction_legs(group))
        raise BuildError(f"the main junction has no leg {watch_arm} (legs: {legs})")
    return group, junction, chosen_arm
