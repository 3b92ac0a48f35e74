"""The command line of the site build (tools/build_network.py): build a site folder, or re-derive one from its
edited network, and print what the site can host.

Usage: see :mod:`pedsafe_sumo.network.build`. The pole placements are judged by the scenarios' hosting
check (`hosting_scorer`), and the summary lists the scenarios the site hosts: this module is where the
network build meets the scenarios.
"""

from __future__ import annotations

import sys
from pathlib import Path

from pedsafe_sumo import WRITE_ROOT
from pedsafe_sumo.cli import OneLineParser
from pedsafe_sumo.io.outputs import check_output_dir, check_output_file
from pedsafe_sumo.network.approaches import leg_argument
from pedsafe_sumo.network.build import BuildError, BuildReport, build_site
from pedsafe_sumo.network.coordinates import NEGATIVE_HELP, parse_lat_lon, with_negative_values
from pedsafe_sumo.network.from_net import build_site_from_net, parse_xy
from pedsafe_sumo.network.site_paths import check_site_folder, check_targets, clip_to_read, source_to_read
from pedsafe_sumo.network.sites import SiteError, resolve_site
from pedsafe_sumo.network.traffic_side import TRAFFIC_SIDE_NOTE, lefthand_note, network_is_lefthand
from pedsafe_sumo.scenarios.hosting import hosting_scorer
from pedsafe_sumo.site.staged_hosting import staged_hosting_lines

#: Clip radius of a new site when --radius is not given [m]: the junction and about 150 m of each arm.
DEFAULT_RADIUS_M = 200.0
#: Largest clip radius [m]: an intersection study site, not a town; netconvert's time grows with the area.
MAX_RADIUS_M = 2000.0


#: The options of a build from OpenStreetMap, which a build from a SUMO network (--net) does not take.
OSM_OPTIONS = ("osm", "center", "radius", "osm_out", "patches", "no_clip", "refresh", "lefthand")
#: The options only a build from a SUMO network takes.
NET_OPTIONS = ("junction", "at", "polygons")


def _refresh(parser, folder: Path) -> BuildReport:
    """Re-derive a site folder's site file, poles and polygons from its (edited) network."""
    try:
        site = resolve_site(folder if "/" in str(folder) else f"./{folder}", verify=False)
    except SiteError as exc:
        parser.exit(2, f"build_network: error: {exc}\n")
    if site.source_net is not None:
        return refresh_from_net(site)
    clip_to_read(site)  # a clip where the site file may name it, and no link out (docs/trust.md)
    check_targets(None, site.directory, site.name, None)
    if not site.clip_osm.is_file():
        parser.exit(
            2,
            f"build_network: error: {site.clip_osm} (the site's OSM clip, for the polygons) is missing\n",
        )
    return build_site(
        site.clip_osm,
        site.center_lat,
        site.center_lon,
        site.radius_m,
        site.name,
        site.directory,
        site.clip_osm,
        clip=False,
        rsu_corner=site.rsu_corner,
        rsu_watch_arm=site.rsu_watch_arm,
        description=site.description,
        source_osm=site.source_osm,
        net_from=site.file("net.xml"),
        hosting_scorer=hosting_scorer,
    )


def main(argv: list[str] | None = None) -> int:
    parser = OneLineParser(
        prog="build_network",
        description="Build a SUMO study site folder (net, polygons, roadside units, sumocfg, site file) from "
        "OpenStreetMap, or from any SUMO network (--net); every command takes the folder as --site.",
    )
    parser.add_argument(
        "--site",
        default="xueqing",
        help="existing site (name or folder) whose settings are the defaults [xueqing]",
    )
    parser.add_argument("--osm", type=Path, help="OSM XML file to clip (default: the site's source extract)")
    parser.add_argument(
        "--center",
        type=parse_lat_lon,
        metavar="LAT,LON",
        help=f"LAT,LON of the intersection in degrees (default: the site's); {NEGATIVE_HELP}",
    )
    parser.add_argument(
        "--radius",
        type=float,
        help=f"clip radius in metres, above 0 and at most {MAX_RADIUS_M:g} (default: the site's)",
    )
    parser.add_argument("--name", help="name of the built site (default: --site's)")
    parser.add_argument("--description", help="one line saying where the junction is")
    parser.add_argument(
        "--out",
        "--out-dir",
        dest="out_dir",
        type=Path,
        help="the site folder to write (default: networks/NAME)",
    )
    parser.add_argument("--osm-out", type=Path, help="where the clipped OSM goes (default: the site's clip)")
    parser.add_argument(
        "--patches",
        type=Path,
        help="folder of *.nod/edg/con/tll.xml patches (default: networks/NAME/patches)",
    )
    parser.add_argument("--rsu-corner", choices=["NE", "NW", "SE", "SW"], help="corner of the camera pole")
    parser.add_argument(
        "--rsu-watch", type=leg_argument, help="leg the roadside camera watches (N, E, S, W, NE, ..., B055)"
    )
    parser.add_argument(
        "--no-clip",
        action="store_true",
        help="use --osm as it is (an already clipped file, e.g. osm/xueqing.osm)",
    )
    parser.add_argument(
        "--refresh",
        type=Path,
        metavar="DIR",
        help="keep the network of site folder DIR as it is (e.g. edited in netedit) and re-derive its site "
        "file, poles and polygons from it",
    )
    parser.add_argument(
        "--net",
        type=Path,
        metavar="FILE.net.xml",
        help="build the site from this SUMO network, kept as it is (no OSM data, no geo-projection "
        "needed), at --junction or --at; --out names the folder",
    )
    parser.add_argument("--junction", metavar="ID", help="with --net: the signalised junction of the site")
    parser.add_argument(
        "--at",
        metavar="X,Y",
        help="with --net: a point in the network's own frame (m); the site's junction is the signalised one "
        "nearest it (within 60 m). Negative values: --at -12.5,30 or --at=-12.5,30",
    )
    parser.add_argument(
        "--polygons",
        type=Path,
        metavar="FILE.poly.xml",
        help="with --net: buildings and trees (SUMO polygons in the network's frame) that hide pedestrians "
        "from the cameras (default: none)",
    )
    parser.add_argument(
        "--lefthand",
        action="store_true",
        help="the junction's traffic keeps left: netconvert builds the network for left-hand traffic and the "
        "scenarios are staged mirrored (found without it where the OSM data says driving_side=left or the "
        "junction lies in Australia or New Zealand; a network given with --net keeps its own side)",
    )
    argv = sys.argv[1:] if argv is None else argv
    args = parser.parse_args(with_negative_values(parser, argv, ["--center", "--at"]))
    _check_source_options(parser, args)
    try:
        if args.refresh is not None:
            report = _refresh(parser, args.refresh)
        elif args.net is not None:
            report = _build_from_net(parser, args)
        else:
            report = _build(parser, args)
    except (BuildError, SiteError) as exc:
        parser.exit(2, f"build_network: error: {exc}\n")
    print(f"built {report.name} in {report.seconds:.1f} s: main junction {report.main_junction}")
    if report.lefthand_reason:
        print(f"  {lefthand_note(report.lefthand_reason)}")
    elif args.net is None and not _from_net(report):
        print(f"  NOTE: {TRAFFIC_SIDE_NOTE}")
    if args.net is not None or _from_net(report):
        print("  no geo-reference: the site lives in the network's own frame (x, y in metres)")
    if report.signal_nodes and len(report.signal_nodes) > 1:
        print(
            f"  the intersection has {len(report.signal_nodes)} signal nodes: "
            + ", ".join(report.signal_nodes)
        )
    for road_type, entry in (report.lane_defaults or {}).items():
        print(
            f"  lane default: {entry['ways']} {road_type} way(s) without a lane tag get "
            f"{entry['lanes_per_direction']} lane(s) per direction"
        )
    for path in report.written:
        print(f"  wrote     {path}")
    for path in report.unchanged:
        print(f"  unchanged {path}")
    print("scenarios:")
    for line in staged_hosting_lines(resolve_site(str(report.out_dir.resolve()))):
        print(line)
    print(f"  use it: --site {report.out_dir}")
    return 0


def _check_source_options(parser, args) -> None:
    """--net excludes the OSM build's options; --junction, --at and --polygons need --net."""

    def flag(name: str) -> str:
        return "--" + name.replace("_", "-")

    if args.net is not None:
        given = [flag(n) for n in OSM_OPTIONS if getattr(args, n) not in (None, False)]
        if given:
            parser.exit(
                2,
                f"build_network: error: --net builds from a SUMO network: {', '.join(given)} "
                "belong to a build from OpenStreetMap\n",
            )
        if (args.junction is None) == (args.at is None):
            parser.exit(
                2,
                "build_network: error: --net needs the junction: --junction ID or --at X,Y "
                "(the network's frame), one of them\n",
            )
        return
    given = [flag(n) for n in NET_OPTIONS if getattr(args, n) is not None]
    if given:
        parser.exit(2, f"build_network: error: {', '.join(given)} need --net FILE.net.xml\n")


def _from_net(report: BuildReport) -> bool:
    try:
        return resolve_site(str(report.out_dir.resolve()), verify=False).source_net is not None
    except SiteError:
        return False


def _build_from_net(parser, args) -> BuildReport:
    """A site from the SUMO network --net (network.from_net), written to --out (default
    networks/NAME)."""
    try:
        at_xy = parse_xy(args.at) if args.at is not None else None
    except ValueError as exc:
        parser.exit(2, f"build_network: error: --at: {exc}\n")
    if args.out_dir is not None:
        name = args.name or args.out_dir.name
    else:
        name = args.name or args.net.name.removesuffix(".gz").removesuffix(".xml").removesuffix(".net")
    out_dir = args.out_dir or WRITE_ROOT / "networks" / name
    try:
        check_output_dir(out_dir, "--out", BuildError)
        check_targets(None, out_dir, name, None)
    except (BuildError, SiteError) as exc:
        parser.exit(2, f"build_network: error: {exc}\n")
    return build_site_from_net(
        args.net,
        name,
        out_dir,
        junction_id=args.junction,
        at_xy=at_xy,
        polygons=args.polygons,
        rsu_corner=args.rsu_corner,
        rsu_watch_arm=args.rsu_watch,
        description=args.description or "",
        hosting_scorer=hosting_scorer,
    )


def refresh_from_net(site) -> BuildReport:
    """Re-derive a site built from a SUMO network from its folder's (edited) network: the junction it was
    built at, its polygons kept as they are, its watched arm and corner."""
    poly = site.file("poly.xml")
    try:
        polygons_text = poly.read_text(encoding="utf-8")
    except OSError as exc:
        raise SiteError(f"site {site.name}: cannot read {poly}: {exc.strerror}") from None
    return build_site_from_net(
        site.file("net.xml"),
        site.name,
        site.directory,
        junction_id=site.main_junction,
        polygons_text=polygons_text,
        rsu_corner=site.rsu_corner,
        rsu_watch_arm=site.rsu_watch_arm,
        description=site.description,
        source_net=site.source_net,
        hosting_scorer=hosting_scorer,
    )


def _build(parser, args) -> BuildReport:
    new_site = args.name is not None and args.center is not None and args.osm is not None
    site = None
    if not new_site:
        try:
            site = resolve_site(args.site, verify=False)
        except SiteError as exc:
            parser.exit(2, f"build_network: error: {exc}\n")
    name = args.name or site.name
    same_site = site is not None and site.name == name
    lat, lon = args.center or (site.center_lat, site.center_lon)
    radius_m = args.radius if args.radius is not None else (site.radius_m if site else DEFAULT_RADIUS_M)
    if not 0 < radius_m <= MAX_RADIUS_M:  # also false for NaN
        parser.exit(
            2,
            f"build_network: error: radius must be positive and at most {MAX_RADIUS_M:g} m, got {radius_m}\n",
        )
    out_dir = args.out_dir or (site.directory.parent / name if site else WRITE_ROOT / "networks" / name)
    try:
        check_output_dir(out_dir, "--out", BuildError)
        if args.osm_out is not None:
            check_output_file(args.osm_out, "--osm-out", BuildError, make_parents=True)
    except BuildError as exc:
        parser.exit(2, f"build_network: error: {exc}\n")
    if site is not None and args.osm is None:
        osm = clip_to_read(site) if args.no_clip else source_to_read(site, refuse=True)
        if osm is None:
            parser.exit(2, f"build_network: error: site {site.name} records no source OSM: give --osm\n")
    else:
        osm = args.osm
    # The clip stays where the site keeps it (osm/xueqing.osm for the shipped site), else in its folder.
    default_clip = site.clip_osm if same_site and args.out_dir is None else out_dir / f"{name}.osm"
    if site is not None and args.out_dir is None and args.name is None:  # what the site file decides
        check_site_folder(site, out_dir)  # network/site_paths.py, docs/trust.md
    site_clip = same_site and args.out_dir is None and args.osm_out is None and not args.no_clip
    check_targets(site, out_dir, name, default_clip if site_clip else None)
    return build_site(
        osm,
        lat,
        lon,
        radius_m,
        name,
        out_dir,
        args.osm_out or default_clip,
        clip=not args.no_clip,
        patches_dir=args.patches or (site.directory if same_site else out_dir) / "patches",
        # A new site's watched arm is chosen by the build (choose_approach), its pole on that arm's kerb.
        rsu_corner=args.rsu_corner or (site.rsu_corner if same_site else None),
        rsu_watch_arm=args.rsu_watch or (site.rsu_watch_arm if same_site else None),
        description=args.description if args.description is not None else (site.description if site else ""),
        source_osm=(site.source_osm if same_site else None) if args.no_clip else osm,
        hosting_scorer=hosting_scorer,
        # A site rebuilt keeps its side.
        lefthand=args.lefthand
        or (site is not None and same_site and network_is_lefthand(site.file("net.xml"))),
    )


if __name__ == "__main__":
    raise SystemExit(main())
