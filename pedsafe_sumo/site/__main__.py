"""python -m pedsafe_sumo.site [--site NAME_OR_PATH] [--no-build]: build a study site and summarise it."""

from __future__ import annotations

import argparse
import sys

from pedsafe_sumo import OSM_ATTRIBUTION, SHIPPED_DIR
from pedsafe_sumo.network.build import BuildError, build_site
from pedsafe_sumo.network.site_paths import check_targets, clip_to_read, source_to_read
from pedsafe_sumo.network.sites import SITE_HELP, SiteError, UnknownSiteError, resolve_site
from pedsafe_sumo.network.summary import summarise
from pedsafe_sumo.network.sumo_inputs import check_site_sumo_files
from pedsafe_sumo.network.traffic_side import TRAFFIC_SIDE_NOTE, lefthand_note, network_is_lefthand
from pedsafe_sumo.scenarios.hosting import hosting_scorer
from pedsafe_sumo.site.build_command import refresh_from_net
from pedsafe_sumo.site.staged_hosting import staged_hosting_lines


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m pedsafe_sumo.site", description=__doc__)
    parser.add_argument("--site", default="xueqing", help=SITE_HELP)
    parser.add_argument("--no-build", action="store_true", help="summarise the site folder as it is")
    args = parser.parse_args(argv)
    try:
        # A rebuild re-derives everything, so a stale site is fine to start from; a summary is not.
        site = resolve_site(args.site, verify=args.no_build)
    except UnknownSiteError as exc:
        parser.exit(2, f"error: {exc}\n")
    if not args.no_build and site.directory.resolve().is_relative_to(SHIPPED_DIR):
        # An installed package holds neither the OSM data a rebuild reads nor a folder the user may write.
        parser.exit(
            2,
            f"error: site {site.name} is installed with the package: summarise it with --no-build; a rebuild "
            "runs in a checkout of the repository, where its OpenStreetMap data is\n",
        )
    if not args.no_build and site.source_net is not None:
        # A site built from a SUMO network: its network is the source, kept as it is.
        try:
            report = refresh_from_net(site)
        except (BuildError, UnknownSiteError) as exc:
            parser.exit(2, f"error: {exc}\n")
        print(f"re-derived {site.directory} from its network in {report.seconds:.1f} s")
    elif not args.no_build:
        # Rebuild from the committed clip when the source extract is not beside the checkout.
        # Only what the site file may name (network/site_paths.py, docs/trust.md).
        source = source_to_read(site)
        from_source = source is not None and source.exists()
        try:
            check_targets(site, site.directory, site.name, site.clip_osm if from_source else None)
            report = build_site(
                site.source_osm if from_source else clip_to_read(site),
                site.center_lat,
                site.center_lon,
                site.radius_m,
                site.name,
                site.directory,
                site.clip_osm,
                clip=from_source,
                patches_dir=site.directory / "patches",
                rsu_corner=site.rsu_corner,
                rsu_watch_arm=site.rsu_watch_arm,
                description=site.description,
                source_osm=site.source_osm,
                hosting_scorer=hosting_scorer,
                lefthand=network_is_lefthand(site.file("net.xml")),  # a site rebuilt keeps its side
            )
        except (BuildError, UnknownSiteError) as exc:
            parser.exit(2, f"error: {exc}\n")
        origin = site.source_osm if from_source else site.clip_osm
        print(
            f"built {site.directory} from {origin} in {report.seconds:.1f} s "
            f"({len(report.written)} file(s) changed, {len(report.unchanged)} unchanged)"
        )
        print(
            f"  {lefthand_note(report.lefthand_reason)}"
            if report.lefthand_reason
            else f"  NOTE: {TRAFFIC_SIDE_NOTE}"
        )
    try:  # `sumo-gui -c` (the line "open it" below) reads them
        check_site_sumo_files(site)
    except SiteError as exc:
        parser.exit(2, f"error: {exc}\n")
    for line in summarise(site).lines():
        print(line)
    print("  scenarios:")
    for line in staged_hosting_lines(resolve_site(args.site)):
        print(f"  {line}")
    print(f"  open it: sumo-gui -c {site.file('sumocfg')}   edit it: netedit -s {site.file('net.xml')}")
    if site.source_net is None:
        print(f"  {OSM_ATTRIBUTION}")
    else:
        print("  built from a SUMO network, no geo-reference: coordinates are the network's x, y in metres")
    return 0


if __name__ == "__main__":
    sys.exit(main())
