"""netconvert and polyconvert: the SUMO tools that turn a staged OpenStreetMap clip into the site's network
(with the folder's patch files) and its occluder polygons.

Every tool runs in the staging directory on relative file names (see :mod:`.build`), with the option and
type-map files of this folder copied beside the clip.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import xml.etree.ElementTree as ET
from pathlib import Path

import sumo

from pedsafe_sumo.network.clip import read_osm
from pedsafe_sumo.network.errors import BuildError
from pedsafe_sumo.sumo_binaries import sumo_binary

HERE = Path(__file__).resolve().parent
NETCONVERT_OPTIONS = HERE / "netconvert.netccfg"
URBAN_SPEEDS_TYPEMAP = HERE / "urban_speeds.typ.xml"
OCCLUDER_TYPEMAP = HERE / "occluders.typ.xml"
SUMO_TYPEMAPS = ("osmNetconvert.typ.xml", "osmNetconvertPedestrians.typ.xml")
PATCH_KINDS = {
    "nod": "--node-files",
    "edg": "--edge-files",
    "con": "--connection-files",
    "tll": "--tllogic-files",
}
#: The type maps netconvert reads, in order (the last that defines a road class wins).
TYPE_FILES = ",".join([*SUMO_TYPEMAPS, URBAN_SPEEDS_TYPEMAP.name])


def _run(cmd: list[str], cwd: Path, step: str) -> str:
    proc = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True)
    if proc.returncode != 0:
        errors = [line for line in (proc.stderr + proc.stdout).splitlines() if line.startswith("Error")]
        detail = errors[0] if errors else (proc.stderr.strip().splitlines() or ["no output"])[-1]
        raise BuildError(f"{step} failed: {detail}")
    return proc.stderr


def _add_comment(path: Path, text: str) -> None:
    """Insert an XML comment after the declaration of a generated file."""
    content = path.read_text(encoding="utf-8")
    end = content.index("?>") + 2 if content.startswith("<?xml") else 0
    path.write_text(content[:end] + f"\n<!-- {text} -->" + content[end:], encoding="utf-8")


def stage_tool_inputs(stage: Path) -> None:
    """Copy SUMO's OSM type maps and this folder's type maps and netconvert options into `stage`."""
    for typemap in SUMO_TYPEMAPS:
        shutil.copyfile(Path(sumo.SUMO_HOME) / "data" / "typemap" / typemap, stage / typemap)
    shutil.copyfile(URBAN_SPEEDS_TYPEMAP, stage / URBAN_SPEEDS_TYPEMAP.name)
    shutil.copyfile(OCCLUDER_TYPEMAP, stage / OCCLUDER_TYPEMAP.name)
    shutil.copyfile(NETCONVERT_OPTIONS, stage / NETCONVERT_OPTIONS.name)


def _netconvert(stage: Path, osm_name: str, type_files: str, net_file: str, lefthand: bool = False) -> None:
    # --lefthand: SUMO's left-hand traffic (lane 0 still the kerb-side lane, drawn left of travel).
    _run(
        [
            sumo_binary("netconvert"),
            "-c",
            NETCONVERT_OPTIONS.name,
            "--osm-files",
            osm_name,
            "--type-files",
            type_files,
            "--output-file",
            net_file,
            *(["--lefthand"] if lefthand else []),
        ],
        stage,
        "netconvert",
    )


def _apply_patches(stage: Path, name: str, net_file: str, patches_dir: Path | None) -> list[str]:
    """netconvert over the network with the folder's patch files; the patch arguments used."""
    patch_args: list[str] = []
    if patches_dir is not None and patches_dir.is_dir():
        for kind, option in PATCH_KINDS.items():
            files = sorted(patches_dir.glob(f"*.{kind}.xml"))
            for patch in files:
                shutil.copyfile(patch, stage / patch.name)
            if files:
                patch_args += [option, ",".join(p.name for p in files)]
    if patch_args:
        patched = f"{name}.patched.net.xml"
        _run(
            [sumo_binary("netconvert"), "--sumo-net-file", net_file, *patch_args, "--output-file", patched],
            stage,
            "netconvert (patches)",
        )
        os.replace(stage / patched, stage / net_file)
    return patch_args


def convert_network(
    stage: Path, name: str, osm_name: str, net_file: str, patches_dir: Path | None, lefthand: bool = False
) -> None:
    """netconvert over the staged clip (for left-hand traffic with `lefthand`), then over the result with
    the folder's patch files (when any; netconvert keeps the network's side)."""
    _netconvert(stage, osm_name, TYPE_FILES, net_file, lefthand)
    patch_args = _apply_patches(stage, name, net_file, patches_dir)
    if patch_args:
        # SUMO's header now shows only the patch pass: say how the network was made.
        patched_with = ", ".join(
            f"{patch_args[i].lstrip('-')}={patch_args[i + 1]}" for i in range(0, len(patch_args), 2)
        )
        _add_comment(
            stage / net_file,
            f"Built by tools/build_network.py: netconvert with {NETCONVERT_OPTIONS.name}, "
            f"osm-files={osm_name}, type-files={TYPE_FILES}; then patched with "
            f"{patched_with} (from networks/{name}/patches/).",
        )


def convert_polygons(stage: Path, net_file: str, osm_name: str, poly_file: str) -> int:
    """polyconvert of the clip's occluders (buildings, trees, ...) in the network's frame, without the
    polygons OSM puts below ground; how many of those were dropped."""
    _run(
        [
            sumo_binary("polyconvert"),
            "--net-file",
            net_file,
            "--osm-files",
            osm_name,
            "--type-file",
            OCCLUDER_TYPEMAP.name,
            "--osm.keep-full-type",
            "true",
            "--all-attributes",
            "true",
            "--discard",
            "true",
            "--output-file",
            poly_file,
        ],
        stage,
        "polyconvert",
    )
    return _drop_underground(stage / poly_file)


UNDERGROUND_POLY = re.compile(
    r"[ \t]*<poly [^>]*[^/]>(?:(?!</poly>|<poly ).)*?"
    r"(?:<param key=\"layer\" value=\"-|<param key=\"location\" value=\"underground)"
    r"(?:(?!</poly>|<poly ).)*?</poly>\n",
    re.DOTALL,
)


def _drop_underground(path: Path) -> int:
    """Remove the polygons OSM puts below ground (a negative layer, location=underground: subway
    stations drawn over the road) from a polyconvert file; they hide nothing from a camera. How many."""
    text = path.read_text(encoding="utf-8")
    kept, dropped = UNDERGROUND_POLY.subn("", text)
    if dropped:
        path.write_text(kept, encoding="utf-8")
    return dropped


def lane_defaults(osm_path: Path, typemap_paths: list[Path]) -> dict[str, dict]:
    """Road classes of the clip whose ways carry no lane tag, with how many such ways and the lanes per
    direction the build gives them (the last typemap that defines the class wins, as in netconvert)."""
    lanes_by_type: dict[str, int] = {}
    for typemap in typemap_paths:
        for t in ET.parse(typemap).getroot().iter("type"):
            if t.get("numLanes"):
                lanes_by_type[t.get("id")] = int(t.get("numLanes"))
    kept = set()
    for option in ET.parse(NETCONVERT_OPTIONS).getroot().iter("keep-edges.by-type"):
        kept = set(option.get("value").split(","))
    _nodes, ways, _relations = read_osm(osm_path)
    found: dict[str, dict] = {}
    for way in ways.values():
        road_type = f"highway.{way.tags.get('highway', '')}"
        if road_type not in kept or any(k in way.tags for k in ("lanes", "lanes:forward", "lanes:backward")):
            continue
        entry = found.setdefault(road_type, {"ways": 0, "lanes_per_direction": lanes_by_type.get(road_type)})
        entry["ways"] += 1
    return dict(sorted(found.items()))
