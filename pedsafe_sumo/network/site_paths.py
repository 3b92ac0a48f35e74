"""The paths a site file names, as a build reads and writes them (docs/trust.md).

A site folder may come from someone else, and its site file names OSM data by path (`source_osm`,
`clip_osm`). A build (`tools/build_network.py --site`, `python -m pedsafe_sumo.site --site`) reads
such a path only inside the site folder or the repository's osm/ (the shipped OSM data), and writes
only inside the site folder; the shipped sites under networks/ keep their clip in the
repository's osm/, which their rebuild writes. A path the user gives on the command line (--osm,
--osm-out, --out) is taken as given. A link planted at the name of a file the build writes (or at its
temporary name) that leads out of the folder is refused too.
"""

from __future__ import annotations

from pathlib import Path

from pedsafe_sumo import NETWORKS_DIR
from pedsafe_sumo.confine import ConfinementError, check_entries, is_inside
from pedsafe_sumo.network.sites import OSM_DIR, SITE_FILE_SUFFIXES, Site, SiteError

#: Every file a build writes in a site folder, by suffix (the clip kept in the folder included).
BUILT_SUFFIXES = (*SITE_FILE_SUFFIXES, "osm")


def may_read(site: Site, path: Path) -> bool:
    """Whether a build may read `path`, named by the site file of `site`."""
    return is_inside(path, site.directory) or is_inside(path, OSM_DIR)


def source_to_read(site: Site, refuse: bool = False) -> Path | None:
    """The site's source extract, or None when the site file names none or names one where a build may
    not read it (then SiteError, one line, with `refuse`)."""
    source = site.source_osm
    if source is None or may_read(site, source):
        return source
    if refuse:
        raise SiteError(
            f"site {site.name}: its site file names source_osm {source}, outside the site folder and the "
            "repository's osm/: refused (give the OSM file with --osm)"
        )
    return None


def clip_to_read(site: Site) -> Path:
    """The site's clip; SiteError (one line) when its site file puts it where a build may not read."""
    if not may_read(site, site.clip_osm):
        raise SiteError(
            f"site {site.name}: its site file names clip_osm {site.clip_osm}, outside the site folder and "
            "the repository's osm/: refused (give the OSM file with --osm)"
        )
    return site.clip_osm


def check_targets(site: Site | None, out_dir: Path, name: str, clip_out: Path | None) -> None:
    """SiteError (one line) unless a build of site `name` into `out_dir` writing the clip to `clip_out`
    (None: no clip written, or the user named it) stays where the site file may send it."""
    try:
        check_entries(
            out_dir,
            [f"{name}.{suffix}{tmp}" for suffix in BUILT_SUFFIXES for tmp in ("", ".tmp")],
            f"site {name}",
        )
    except ConfinementError as exc:
        raise SiteError(str(exc)) from None
    if site is None or clip_out is None:
        return
    # A shipped site keeps its clip in the repository's osm/ (osm/<name>.osm), which its rebuild writes.
    roots = [site.directory, *([OSM_DIR] if is_inside(site.directory, NETWORKS_DIR) else [])]
    tmp = clip_out.with_name(clip_out.name + ".tmp")
    if any(is_inside(clip_out, root) and is_inside(tmp, root) for root in roots):
        return
    raise SiteError(
        f"site {site.name}: its site file names clip_osm {site.clip_osm}, outside the site folder: a build "
        "writes only there (name the clip's place with --osm-out)"
    )


def check_site_folder(site: Site, out_dir: Path) -> None:
    """SiteError when a build of `site` into its own folder would write elsewhere: a site file named
    after another site than its folder sends the build to that folder's sibling."""
    if out_dir.resolve() != site.directory.resolve():
        raise SiteError(
            f"{site.directory} holds the site file of '{site.name}', whose build would write {out_dir}: "
            "give --out"
        )
