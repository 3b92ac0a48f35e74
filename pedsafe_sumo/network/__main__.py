"""python -m pedsafe_sumo.network [--site xueqing] [--no-build]: build the study site and summarise it."""

from __future__ import annotations

import argparse
import sys

from pedsafe_sumo import OSM_ATTRIBUTION
from pedsafe_sumo.network.build import BuildError, build_site
from pedsafe_sumo.network.sites import SITES, UnknownSiteError, get_site
from pedsafe_sumo.network.summary import summarise


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m pedsafe_sumo.network", description=__doc__)
    parser.add_argument("--site", default="xueqing", help=f"one of: {', '.join(SITES)}")
    parser.add_argument("--no-build", action="store_true", help="summarise the committed network only")
    args = parser.parse_args(argv)
    try:
        site = get_site(args.site)
    except UnknownSiteError as exc:
        parser.exit(2, f"error: {exc}\n")
    if not args.no_build:
        # Rebuild from the committed clip when the shared source extract is not beside the checkout.
        from_source = site.source_osm.exists()
        try:
            report = build_site(
                site.source_osm if from_source else site.clip_osm,
                site.center_lat,
                site.center_lon,
                site.radius_m,
                site.name,
                site.network_dir,
                site.clip_osm,
                clip=from_source,
                patches_dir=site.network_dir / "patches",
                rsu_corner=site.rsu_corner,
                rsu_watch_arm=site.rsu_watch_arm,
            )
        except BuildError as exc:
            parser.exit(2, f"error: {exc}\n")
        origin = site.source_osm if from_source else site.clip_osm
        print(
            f"built {site.network_dir} from {origin} in {report.seconds:.1f} s "
            f"({len(report.written)} file(s) changed, {len(report.unchanged)} unchanged)"
        )
    for line in summarise(site).lines():
        print(line)
    print(f"  open it: sumo-gui -c {site.file('sumocfg')}   edit it: netedit -s {site.file('net.xml')}")
    print(f"  {OSM_ATTRIBUTION}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
