"""Study sites: a site is a folder, never an entry in code.

A site folder (networks/<name>/, or any path) holds the files tools/build_network.py writes:
<name>.net.xml (the network), <name>.poly.xml (buildings and other occluders), <name>.rsu.add.xml (the
roadside camera poles), <name>.sumocfg and <name>.view.xml (sumo-gui), and <name>.site.json, the site
file: name, description, centre, clip radius, where its OpenStreetMap data came from, the main junction,
the roadside poles, and the hashes that tie the derived files to the network they were made from.

`resolve_site(name_or_path)` is the one way every command finds a site (`--site NAME_OR_PATH`):
- a name (letters, digits, '_' or '-') is the folder <name>/ of the first folder of the search path that
  holds one: each folder of $PEDSAFE_NETWORKS_DIR (separated by ':', ';' on Windows), then the shipped
  sites (networks/ of the checkout, or the installed package's copy);
- anything else (it has a '/', or is '.' or '..') is the path of the folder itself.
It reads the site file and checks that the derived files (site file, poles, polygons) were made from the
network in the folder: a network edited since, or a pole or building moved by hand, is refused in one
line that names the command that re-derives them (see docs/sites.md).
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

from pedsafe_sumo import NETWORKS_DIR, REPO_ROOT
from pedsafe_sumo.network.traffic_lights import junctions_problem

OSM_DIR = REPO_ROOT / "osm"
#: Environment variable naming folders of site folders (<folder>/<site>/<site>.net.xml, ...) searched
#: before the shipped sites: the user's own sites, or a batch on a modified copy of a shipped site. Read at
#: every lookup, so worker processes started by a batch see what the batch saw.
NETWORKS_DIR_ENV = "PEDSAFE_NETWORKS_DIR"
#: The help text of every command's --site.
SITE_HELP = (
    "study site: a name (the folder NAME in $PEDSAFE_NETWORKS_DIR's folders, then in the shipped sites) or "
    "the path of a site folder written by `pedsafe-sumo site build` [xueqing]"
)
DEFAULT_SITE = "xueqing"
#: Files every site folder holds, by suffix; the first four are read by the episodes.
SITE_FILE_SUFFIXES = ("net.xml", "poly.xml", "rsu.add.xml", "site.json", "sumocfg", "view.xml")
#: Derived files that carry the hash of the network they were made from (see derived_marker).
DERIVED_SUFFIXES = ("poly.xml", "rsu.add.xml")
SITE_NAME = re.compile(r"[A-Za-z0-9_-]+")
GENERATED_ON = re.compile(r"<!-- generated on .*? by Eclipse SUMO")
DERIVED_MARKER = re.compile(r"<!-- derived from (\S+) sha256 ([0-9a-f]{64}) -->")


class SiteError(ValueError):
    """A site that cannot be found or used; the message is one line naming the problem."""


#: The name the commands catch for a site they cannot find or use (the same class as SiteError).
UnknownSiteError = SiteError


@dataclass(frozen=True)
class Site:
    """A signalised intersection built from OpenStreetMap: its folder and what its site file says."""

    name: str
    directory: Path
    description: str
    #: The centre in degrees; None for a site built from a SUMO network without a geo-reference.
    center_lat: float | None
    center_lon: float | None
    radius_m: float
    #: The OpenStreetMap extract the site was clipped from (None: unknown, e.g. built from a clip).
    source_osm: Path | None
    #: The clipped OpenStreetMap file the build keeps (rebuilds without the source start from it).
    clip_osm: Path
    #: Corner of the main junction where the roadside camera pole stands, and the arm it watches.
    rsu_corner: str = "NW"
    rsu_watch_arm: str = "N"
    #: The SUMO network the site was built from (tools/build_network.py --net), None for a site built
    #: from OpenStreetMap; such a site has no geo-reference.
    source_net: Path | None = None
    #: The junction the site was built at (its site file's main_junction).
    main_junction: str = ""

    @property
    def network_dir(self) -> Path:
        return self.directory

    def file(self, suffix: str) -> Path:
        """A file of the site, e.g. file('net.xml') -> networks/xueqing/xueqing.net.xml."""
        return self.directory / f"{self.name}.{suffix}"

    @property
    def rebuild_command(self) -> str:
        """The command that re-derives the site file, poles and polygons from the folder's network."""
        return f"pedsafe-sumo site build --refresh {_shown(self.directory)}"


def _shown(path: Path) -> str:
    try:
        return str(path.resolve().relative_to(Path.cwd().resolve()))
    except ValueError:
        return str(path)


def networks_dirs() -> list[Path]:
    """The search path of site names: each folder of $PEDSAFE_NETWORKS_DIR, then the shipped sites."""
    own = [Path(entry) for entry in os.environ.get(NETWORKS_DIR_ENV, "").split(os.pathsep) if entry]
    return [*own, NETWORKS_DIR]


def available_sites() -> list[str]:
    """Names of the site folders on the search path (networks_dirs)."""
    names = {
        d.name
        for root in networks_dirs()
        if root.is_dir()
        for d in root.iterdir()
        if d.is_dir() and (d / f"{d.name}.site.json").is_file()
    }
    return sorted(names)


def site_folder(name_or_path: str | os.PathLike) -> Path:
    """The folder a --site value names (see the module docstring); SiteError if there is none."""
    text = str(name_or_path)
    if SITE_NAME.fullmatch(text):
        for root in networks_dirs():
            if (root / text).is_dir():
                return root / text
        known = ", ".join(available_sites()) or "none"
        looked = ", ".join(str(root) for root in networks_dirs())
        raise SiteError(
            f"unknown site '{text}' (known: {known}; looked in {looked}): give a site folder's path "
            f"(--site ./{text}) or add the folder that holds {text}/ to ${NETWORKS_DIR_ENV}"
        )
    folder = Path(text)
    if folder.is_file():
        raise SiteError(f"{folder} is a file: --site takes a site's name or its folder")
    if not folder.is_dir():
        raise SiteError(f"site folder {folder} does not exist")
    return folder


def _site_file_in(folder: Path) -> Path:
    named = folder / f"{folder.resolve().name}.site.json"
    if named.is_file():
        return named
    found = sorted(folder.glob("*.site.json"))
    if len(found) == 1:
        return found[0]
    if not found:
        raise SiteError(
            f"{folder} is not a site folder (no <name>.site.json): build one with "
            f"pedsafe-sumo site build --osm FILE --center LAT,LON --name NAME --out {folder}"
        )
    raise SiteError(f"{folder} holds several site files ({', '.join(p.name for p in found)}): keep one")


def _path_in_site(folder: Path, value) -> Path | None:
    if not value:
        return None
    path = Path(value)
    return path if path.is_absolute() else (folder / path)


def _one_line(exc: BaseException) -> str:
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__


def _degrees(info: dict, key: str) -> float | None:
    """A centre coordinate of the site file: null only for a site built from a SUMO network."""
    if info.get(key) is None and info.get("source_net"):
        return None
    return float(info[key])


def read_site_file(path: Path, name: str) -> dict:
    try:
        info = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        raise SiteError(f"site {name}: cannot parse {path}: {_one_line(exc)}") from None
    if not isinstance(info, dict):
        raise SiteError(f"site {name}: cannot parse {path}: not a JSON object")
    return info


def resolve_site(name_or_path: str | os.PathLike = DEFAULT_SITE, verify: bool = True) -> Site:
    """The site a --site value names, checked unless verify is False: a junction of the site several
    traffic lights control (network.traffic_lights) is refused, whatever else changed (no rebuild
    helps), then verify_site. A network built for left-hand traffic is staged mirrored
    (network.traffic_side)."""
    folder = site_folder(name_or_path)
    site_file = _site_file_in(folder)
    name = site_file.name.removesuffix(".site.json")
    info = read_site_file(site_file, name)
    try:
        site = Site(
            name=name,
            directory=folder,
            description=str(info.get("description", "")),
            center_lat=_degrees(info, "center_lat"),
            center_lon=_degrees(info, "center_lon"),
            radius_m=float(info["radius_m"]),
            source_osm=_path_in_site(folder, info.get("source_osm")),
            clip_osm=_path_in_site(folder, info.get("clip_osm")) or folder / f"{name}.osm",
            rsu_corner=str(info.get("rsu_corner", "NW")),
            rsu_watch_arm=str(info.get("rsu_watch_arm", "N")),
            source_net=_path_in_site(folder, info.get("source_net")),
            main_junction=str(info.get("main_junction", "")),
        )
    except (KeyError, TypeError, ValueError) as exc:
        raise SiteError(f"site {name}: {site_file} lacks a valid {_one_line(exc)}") from None
    if verify:
        several = _several_lights(site, info)
        if several:
            raise SiteError(f"site {name}: {several}")
        verify_site(site, info)
    return site


def _several_lights(site: Site, info: dict) -> str | None:
    """junctions_problem of the site's main junction and its approaches' junctions (a network that
    cannot be read is left to verify_site to name)."""
    approaches = info.get("approaches") if isinstance(info.get("approaches"), dict) else {}
    junctions = [
        info.get("main_junction"),
        *(a.get("junction") for a in approaches.values() if isinstance(a, dict)),
    ]
    try:
        return junctions_problem(site.file("net.xml"), [str(j) for j in junctions if j])
    except (OSError, ET.ParseError):
        return None


#: Kept for the callers written when sites were entries of a dict.
get_site = resolve_site


def comparable_text(path: Path) -> str:
    """File text without the 'generated on <time>' part of SUMO's header comment."""
    return GENERATED_ON.sub("<!-- generated by Eclipse SUMO", path.read_text(encoding="utf-8"))


def content_digest(path: Path) -> str:
    """SHA-256 of a site file's text without SUMO's generation time (so a rebuild of an unchanged site
    has the same digests)."""
    return hashlib.sha256(comparable_text(path).encode("utf-8")).hexdigest()


def derived_marker(net_file: Path) -> str:
    """The XML comment a derived file carries: the network file it was made from and its digest."""
    return f"<!-- derived from {net_file.name} sha256 {content_digest(net_file)} -->"


def _parses(path: Path) -> str | None:
    """None when the file parses, else the parser's message (one line)."""
    try:
        if path.name.endswith(".json"):
            json.loads(path.read_text(encoding="utf-8"))
        else:
            ET.parse(path)
    except (OSError, UnicodeDecodeError, ValueError, ET.ParseError) as exc:
        return _one_line(exc)
    return None


def verify_site(site: Site, info: dict | None = None) -> None:
    """SiteError unless the site's files are present and its derived files were made from its network.

    The site file records the digest of the network and of each derived file; each derived file carries
    the network's digest (derived_marker); the poles of the site file are the POIs of rsu.add.xml. A
    network edited after the build (netedit, netconvert --offset), or a derived file changed by hand,
    breaks one of these and is named, with the command that re-derives the files."""
    for suffix in ("net.xml", "poly.xml", "rsu.add.xml", "site.json"):
        if not site.file(suffix).is_file():
            raise SiteError(f"site {site.name}: {site.file(suffix)} is missing")
    if info is None:
        info = read_site_file(site.file("site.json"), site.name)
    redo = f"re-derive them with {site.rebuild_command}"
    net_file = site.file("net.xml")
    recorded = info.get("net_sha256")
    if not recorded:
        raise SiteError(
            f"site {site.name}: {site.file('site.json').name} records no hash of the network it was made "
            f"from (built by an older tools/build_network.py): {redo}"
        )
    if content_digest(net_file) != recorded:
        problem = _parses(net_file)
        if problem:
            raise SiteError(f"site {site.name}: cannot parse {net_file}: {problem}")
        raise SiteError(
            f"site {site.name}: {net_file.name} changed after its site file, poles and polygons were made "
            f"from it: {redo}"
        )
    net_digest = recorded
    derived = info.get("derived_sha256", {})
    for suffix in DERIVED_SUFFIXES:
        path = site.file(suffix)
        problem = _parses(path)
        if problem:
            raise SiteError(f"site {site.name}: cannot parse {path}: {problem}")
        marker = DERIVED_MARKER.search(path.read_text(encoding="utf-8"))
        if marker is None or marker.group(2) != net_digest:
            raise SiteError(f"site {site.name}: {path.name} was not made from this {net_file.name}: {redo}")
        if derived.get(path.name) != content_digest(path):
            raise SiteError(f"site {site.name}: {path.name} was changed by hand after the build: {redo}")
    poles = {
        p.get("id"): (float(p.get("x")), float(p.get("y")))
        for p in ET.parse(site.file("rsu.add.xml")).getroot().iter("poi")
    }
    for unit in info.get("roadside_units", []):
        at = poles.get(unit.get("id"))
        if at is None or math.dist(at, (unit["x"], unit["y"])) > 0.01:
            raise SiteError(
                f"site {site.name}: pole {unit.get('id')} of {site.file('site.json').name} is not where "
                f"{site.file('rsu.add.xml').name} puts it: {redo}"
            )


def site_digests(site: Site) -> dict[str, str]:
    """SHA-256 of the bytes of every file of the site folder (run.json records them)."""
    return {
        site.file(s).name: hashlib.sha256(site.file(s).read_bytes()).hexdigest()
        for s in SITE_FILE_SUFFIXES
        if site.file(s).is_file()
    }


def site_reference(name_or_path: str | os.PathLike, site: Site) -> str:
    """How a batch names its site to its workers: a name stays a name (each worker looks it up the same
    way, $PEDSAFE_NETWORKS_DIR included); a path becomes absolute, so a worker's working folder does not
    matter."""
    text = str(name_or_path)
    return text if SITE_NAME.fullmatch(text) else str(site.directory.resolve())


def compass_sector(centre_xy: tuple[float, float], point_xy: tuple[float, float]) -> str:
    """ "N", "E", "S" or "W": the 90-degree sector of `point_xy` seen from `centre_xy` (network frame,
    y north). A leg of a junction alone in its sector is named by it (network.approaches.leg_names)."""
    bearing_deg = math.degrees(math.atan2(point_xy[0] - centre_xy[0], point_xy[1] - centre_xy[1])) % 360.0
    return "NESW"[int(((bearing_deg + 45.0) % 360.0) // 90.0)]
