"""A site's SUMO files as SUMO inputs: they may not make SUMO write anything (docs/trust.md).

A site folder may come from someone else. Its .sumocfg and additional files are read by SUMO itself
(demand validation, sumo-gui in replay and `episode --gui`, tools/screenshot_site.py), and SUMO writes
whatever output they name: `<fcd-output value="..."/>` in a configuration, `<edgeData file="..."/>` or
a detector's `file=` in an additional file, `<snapshot file="..."/>` in view settings. Before any such
run, these files are checked and a site that names an output, or a file outside its folder, is refused
in one line; our commands pass the outputs they want on SUMO's command line themselves. A file that does
not parse, or a file the configuration names that is not there, is refused the same way, before any work.

The checks are by name, broad on purpose: a configuration option whose name holds "output", "dump",
"save", "prefix" or "file", or names a log, is refused unless it is one of the inputs a site's
configuration sets (net-file, additional-files, gui-settings-file, whose files are then checked in
turn); in additional and view files any `file`, `filename`, `output`, `dest` or `href` attribute is.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

from pedsafe_sumo.confine import ConfinementError, confined
from pedsafe_sumo.network.sites import Site, SiteError

#: The configuration options a site's .sumocfg may name files with (tools/build_network.py writes them).
CONFIG_INPUTS = {"net-file": "net", "additional-files": "additional", "gui-settings-file": "view"}
#: SUMO's one-letter names of options a configuration file may also use.
SHORT_NAMES = {
    "n": "net-file",
    "a": "additional-files",
    "r": "route-files",
    "l": "log",
    "c": "configuration-file",
}
WRITING_WORDS = ("output", "dump", "save", "prefix", "file")
LOG_OPTIONS = {"log", "log-file", "message-log", "error-log"}
#: Attributes through which an additional or view file writes (detectors, meandata, probes, timed events,
#: snapshots) or pulls in another file.
FILE_ATTRIBUTES = {"file", "filename", "output", "dest", "href"}
#: XML schema attributes every SUMO file may carry.
SCHEMA_ATTRIBUTES = ("xmlns", "{http://www.w3.org/2001/XMLSchema-instance}")


class SumoInputError(SiteError):
    """A site file that would make SUMO write or read elsewhere; the message is one line."""


def _parse(path: Path) -> ET.Element:
    try:
        return ET.parse(path).getroot()
    except (OSError, ET.ParseError) as exc:
        raise SumoInputError(f"cannot parse {path}: {str(exc).splitlines()[0]}") from None


def _file_attributes(path: Path) -> None:
    for element in _parse(path).iter():
        for name, value in element.attrib.items():
            if name.lower() in FILE_ATTRIBUTES:
                raise SumoInputError(
                    f'{path} names a file in <{element.tag} {name}="{value}">: a site\'s SUMO files may not '
                    "make SUMO write or read other files; remove it"
                )


def check_additional(path: Path) -> None:
    """SumoInputError when the additional file `path` names an output or another file."""
    _file_attributes(path)


def check_view(path: Path) -> None:
    """SumoInputError when the sumo-gui view settings `path` name a file (a snapshot, a decal)."""
    _file_attributes(path)


def _confined(folder: Path, value: str, what: str) -> Path:
    try:
        return confined(folder, value, what)
    except ConfinementError as exc:
        raise SumoInputError(str(exc)) from None


def config_inputs(cfg: Path) -> dict[str, list[Path]]:
    """The files the site configuration `cfg` names, by kind ("net", "additional", "view"), each inside
    its folder and checked; SumoInputError (one line) for an option that writes or a file elsewhere."""
    folder = cfg.parent
    found: dict[str, list[Path]] = {kind: [] for kind in CONFIG_INPUTS.values()}
    for element in _parse(cfg).iter():
        for name in element.attrib:
            if name != "value" and not name.startswith(SCHEMA_ATTRIBUTES):
                raise SumoInputError(f"{cfg}: <{element.tag} {name}=...> is not a SUMO option a site may set")
        option = SHORT_NAMES.get(element.tag, element.tag)
        value = element.get("value")
        if value is None:
            continue
        kind = CONFIG_INPUTS.get(option)
        if kind is None:
            if option in LOG_OPTIONS or any(word in option for word in WRITING_WORDS):
                raise SumoInputError(
                    f"{cfg} sets {option} ('{value}'): a site's configuration may not make SUMO write or "
                    "read other files; remove it"
                )
            continue
        for name in (part.strip() for part in value.split(",")):
            if name:
                found[kind].append(_confined(folder, name, f"{cfg} {option}"))
    for kind, paths in found.items():
        for path in paths:
            if not path.is_file():
                raise SumoInputError(f"{cfg} names the {kind} file {path.name}, which is not in {folder}")
    for path in found["additional"]:
        check_additional(path)
    for path in found["view"]:
        check_view(path)
    return found


def check_site_sumo_files(site: Site) -> None:
    """The site's configuration and view settings, as `sumo-gui -c` reads them: both present and parsed, the
    files the configuration names present in the folder, none of them naming an output (one line)."""
    for suffix in ("sumocfg", "view.xml"):
        if not site.file(suffix).is_file():
            raise SumoInputError(f"site {site.name}: {site.file(suffix)} is missing")
    config_inputs(site.file("sumocfg"))
    check_view(site.file("view.xml"))


def check_gui_inputs(additionals: list[Path], view: Path | None) -> None:
    """The site files sumo-gui loads in an episode (poly.xml, rsu.add.xml, its view settings)."""
    for path in additionals:
        check_additional(path)
    if view is not None:
        check_view(view)


def check_gui_site(site: Site, view: Path | None) -> None:
    """The site files sumo-gui loads in an episode: its polygons and poles (additional files) and the
    view settings `view` (the site's own, or None when the command passes its own)."""
    check_gui_inputs([site.file("poly.xml"), site.file("rsu.add.xml")], view)
