"""Study sites: where each intersection is, and where its files live."""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path

from pedsafe_sumo import NETWORKS_DIR, REPO_ROOT

OSM_DIR = REPO_ROOT / "osm"
#: The unmodified OpenStreetMap export the team shares beside the repository (not shipped).
SHARED_OSM_SOURCE = REPO_ROOT.parent / "shared" / "data" / "osm" / "haidian_xueqing.osm"
#: Environment variable naming another folder of built networks (<folder>/<site>/<site>.net.xml, ...)
#: in place of networks/: a batch on a modified copy of a site, or a package installed away from its
#: checkout. Read at every lookup, so worker processes started by a batch see what the batch saw.
NETWORKS_DIR_ENV = "PEDSAFE_NETWORKS_DIR"


@dataclass(frozen=True)
class Site:
    """A signalised intersection built from OpenStreetMap."""

    name: str
    description: str
    center_lat: float
    center_lon: float
    radius_m: float
    source_osm: Path
    #: Corner of the main junction where the roadside camera pole stands, and the arm it watches.
    rsu_corner: str = "NW"
    rsu_watch_arm: str = "N"

    @property
    def clip_osm(self) -> Path:
        return OSM_DIR / f"{self.name}.osm"

    @property
    def network_dir(self) -> Path:
        override = os.environ.get(NETWORKS_DIR_ENV)
        return (Path(override) if override else NETWORKS_DIR) / self.name

    def file(self, suffix: str) -> Path:
        """A file of the built site, e.g. file('net.xml') -> networks/xueqing/xueqing.net.xml."""
        return self.network_dir / f"{self.name}.{suffix}"


SITES: dict[str, Site] = {
    "xueqing": Site(
        name="xueqing",
        description="Xueqing Road (学清路) x Shibanfang South Road (石板房南路) / Linye Daxue North Road, "
        "Haidian, Beijing",
        center_lat=40.00640,
        center_lon=116.34620,
        radius_m=200.0,
        source_osm=SHARED_OSM_SOURCE,
    ),
}


class UnknownSiteError(KeyError):
    def __str__(self) -> str:
        return f"unknown site '{self.args[0]}' (known: {', '.join(sorted(SITES))})"


def get_site(name: str) -> Site:
    try:
        return SITES[name]
    except KeyError:
        raise UnknownSiteError(name) from None


def compass_sector(centre_xy: tuple[float, float], point_xy: tuple[float, float]) -> str:
    """ "N", "E", "S" or "W": the 90-degree sector of `point_xy` seen from `centre_xy` (network frame,
    y north). How the arms of a junction are named everywhere in the package."""
    bearing_deg = math.degrees(math.atan2(point_xy[0] - centre_xy[0], point_xy[1] - centre_xy[1])) % 360.0
    return "NESW"[int(((bearing_deg + 45.0) % 360.0) // 90.0)]
