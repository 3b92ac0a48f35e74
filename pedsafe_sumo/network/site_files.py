"""The files of a site folder besides the network, polygons and poles: the sumo-gui configuration and view,
the site file, and the step that copies a finished build into the folder.
"""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import sumolib

from pedsafe_sumo import OSM_ATTRIBUTION
from pedsafe_sumo.network.attribution import add_attribution_comment
from pedsafe_sumo.network.sites import comparable_text, content_digest, derived_marker


def write_sumocfg(path: Path, name: str) -> None:
    path.write_text(
        '<?xml version="1.0" encoding="UTF-8"?>\n'
        "<!-- Open with: sumo-gui -c "
        + path.name
        + "   (or netedit -s "
        + name
        + ".net.xml to edit the network)\n"
        "     Demand is added by the episode engine or on the command line: -r ../../routes/"
        + name
        + ".*.rou.xml -->\n"
        "<configuration>\n"
        "    <input>\n"
        f'        <net-file value="{name}.net.xml"/>\n'
        f'        <additional-files value="{name}.poly.xml,{name}.rsu.add.xml"/>\n'
        "    </input>\n"
        "    <time>\n"
        '        <step-length value="0.05"/>\n'
        "    </time>\n"
        "    <processing>\n"
        '        <pedestrian.model value="striping"/>\n'
        '        <collision.check-junctions value="true"/>\n'
        "    </processing>\n"
        "    <gui_only>\n"
        f'        <gui-settings-file value="{name}.view.xml"/>\n'
        "    </gui_only>\n"
        "</configuration>\n",
        encoding="utf-8",
    )


def write_view(path: Path, junction_xy: tuple[float, float]) -> None:
    path.write_text(
        '<?xml version="1.0" encoding="UTF-8"?>\n'
        "<!-- sumo-gui view of the study site: centred on the main junction, real-world colours. -->\n"
        "<viewsettings>\n"
        '    <scheme name="real world"/>\n'
        f'    <viewport zoom="200" x="{junction_xy[0]:.2f}" y="{junction_xy[1]:.2f}"/>\n'
        '    <delay value="50"/>\n'
        "</viewsettings>\n",
        encoding="utf-8",
    )


def _insert_after_declaration(path: Path, line: str) -> None:
    text = path.read_text(encoding="utf-8")
    end = text.index("?>") + 2 if text.startswith("<?xml") else 0
    path.write_text(text[:end] + "\n" + line + text[end:], encoding="utf-8")


def relative_to(folder: Path, path: Path | None) -> str | None:
    """`path` as the site file records it: relative to the site folder (so a checkout can move)."""
    if path is None:
        return None
    return os.path.relpath(os.path.abspath(path), os.path.abspath(folder))


def finish_products(stage: Path, products: list[str], net_file: str, derived: tuple[str, ...]) -> None:
    """Put the OSM attribution into every product and, into the files derived from the network, the
    digest of that network (pedsafe_sumo.network.sites checks it)."""
    for product in products:
        add_attribution_comment(stage / product)
    marker = derived_marker(stage / net_file)
    for name in derived:
        _insert_after_declaration(stage / name, marker)


def write_site_file(stage: Path, site_info: dict, net_file: str, derived: tuple[str, ...]) -> Path:
    """The site file: `site_info` (the build's settings and findings) with the SUMO version, the OSM
    attribution and the digests that tie the derived files to the network."""
    name = site_info["name"]
    record = {
        **site_info,
        "sumo_version": sumolib.version.gitDescribe(),
        "attribution": OSM_ATTRIBUTION,
        "net_sha256": content_digest(stage / net_file),
        "derived_sha256": {p: content_digest(stage / p) for p in derived},
    }
    path = stage / f"{name}.site.json"
    path.write_text(json.dumps(record, indent=2, ensure_ascii=False) + "\n", encoding="utf-8")
    return path


def commit_staged(targets: list[tuple[Path, Path]]) -> tuple[list[Path], list[Path]]:
    """Copy each staged file to its target, atomically; (written, unchanged). A file that differs only in
    SUMO's "generated on" time is left as it is, so rebuilding an unchanged site does not touch the
    checkout."""
    written, unchanged = [], []
    for staged, target in targets:
        if target.exists() and comparable_text(target) == comparable_text(staged):
            unchanged.append(target)
            continue
        tmp_target = target.with_name(target.name + ".tmp")
        shutil.copyfile(staged, tmp_target)
        os.replace(tmp_target, target)
        written.append(target)
    return written, unchanged
