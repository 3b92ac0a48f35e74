"""The build tool: a rebuild equals the committed files; bad input ends in one clear line and a non-zero
exit and leaves the committed network untouched."""

from __future__ import annotations

import hashlib
import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

from pedsafe_sumo import REPO_ROOT
from pedsafe_sumo.network.sites import get_site

SITE = get_site("xueqing")
TOOL = REPO_ROOT / "tools" / "build_network.py"
PRODUCTS = ["net.xml", "poly.xml", "rsu.add.xml", "view.xml", "sumocfg", "site.json"]
# The only part of a SUMO output that may differ between two builds.
GENERATED_ON = re.compile(r"generated on \S+ by")


def _digest(paths: list[Path]) -> dict[str, str]:
    return {str(p): hashlib.sha256(p.read_bytes()).hexdigest() for p in paths}


def _committed_files() -> list[Path]:
    return [SITE.file(s) for s in PRODUCTS] + [SITE.clip_osm]


def _run_tool(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(TOOL), *args], capture_output=True, text=True, cwd=REPO_ROOT)


def _same_apart_from_generation_time(a: Path, b: Path) -> bool:
    """Same text apart from SUMO's generation time; in the site file, apart from where the OSM files are
    (recorded relative to the site folder, which differs)."""
    if a.name.endswith(".site.json"):
        located = ("source_osm", "clip_osm")
        drop = lambda p: {k: v for k, v in json.loads(p.read_text()).items() if k not in located}  # noqa: E731
        return drop(a) == drop(b)
    strip = lambda p: GENERATED_ON.sub("generated on <time> by", p.read_text(encoding="utf-8"))  # noqa: E731
    return strip(a) == strip(b)


@pytest.mark.slow
def test_rebuild_from_the_committed_clip_equals_the_committed_network(tmp_path):
    out = tmp_path / "xueqing"
    result = _run_tool(
        "--no-clip",
        "--osm",
        str(SITE.clip_osm),
        "--out-dir",
        str(out),
        "--osm-out",
        str(tmp_path / "unused.osm"),
    )
    assert result.returncode == 0, result.stderr
    for suffix in PRODUCTS:
        assert _same_apart_from_generation_time(out / f"xueqing.{suffix}", SITE.file(suffix)), suffix


@pytest.mark.slow
@pytest.mark.skipif(not SITE.source_osm.exists(), reason="the shared OSM export is not beside this checkout")
def test_clip_and_build_from_the_source_extract_equals_the_committed_files(tmp_path):
    out = tmp_path / "xueqing"
    clip = tmp_path / "xueqing.osm"
    result = _run_tool("--osm", str(SITE.source_osm), "--out-dir", str(out), "--osm-out", str(clip))
    assert result.returncode == 0, result.stderr
    assert clip.read_bytes() == SITE.clip_osm.read_bytes()
    for suffix in PRODUCTS:
        assert _same_apart_from_generation_time(out / f"xueqing.{suffix}", SITE.file(suffix)), suffix


def _not_osm(tmp_path: Path) -> Path:
    path = tmp_path / "routes.xml"
    path.write_text('<?xml version="1.0"?>\n<routes><vehicle id="a" depart="0"/></routes>\n')
    return path


def _garbage(tmp_path: Path) -> Path:
    path = tmp_path / "broken.osm"
    path.write_text('<?xml version="1.0"?>\n<osm version="0.6"><node id="1" lat="40" lon="116"><tag k=\n')
    return path


@pytest.mark.parametrize(
    ("make_args", "expected"),
    [
        (lambda tmp: ["--osm", str(tmp / "missing.osm")], "not found"),
        (lambda tmp: ["--osm", str(_not_osm(tmp))], "not an OpenStreetMap"),
        (lambda tmp: ["--osm", str(_garbage(tmp))], "could not be read"),
        (lambda tmp: ["--osm", str(SITE.clip_osm), "--center", "39.9,116.4"], "outside the data"),
        (lambda tmp: ["--osm", str(SITE.clip_osm), "--center", "north"], "LAT,LON"),
        (lambda tmp: ["--site", "atlantis"], "unknown site"),
        (lambda tmp: ["--radius", "-5", "--osm", str(SITE.clip_osm)], "radius must be positive"),
    ],
    ids=[
        "missing-file",
        "not-osm",
        "malformed-xml",
        "centre-outside",
        "centre-not-a-number",
        "unknown-site",
        "negative-radius",
    ],
)
def test_bad_input_is_one_clear_line_and_leaves_the_network_untouched(tmp_path, make_args, expected):
    before = _digest(_committed_files())
    result = _run_tool(*make_args(tmp_path))  # default output: the committed networks/xueqing and osm/
    assert result.returncode != 0
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 or lines[0].startswith("usage:"), result.stderr
    assert expected in result.stderr
    assert "Traceback" not in result.stderr
    assert _digest(_committed_files()) == before
