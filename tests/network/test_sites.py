"""A site is a folder: found by name or path, checked against the network its derived files were made
from, re-derived after an edit."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from pedsafe_sumo import NETWORKS_DIR, REPO_ROOT
from pedsafe_sumo.network.sites import NETWORKS_DIR_ENV, SiteError, resolve_site
from pedsafe_sumo.replay.rundir import ReplayError, run_site
from pedsafe_sumo.sumo_binaries import sumo_binary

TOOL = REPO_ROOT / "tools" / "build_network.py"


def copy_site(tmp_path: Path, name: str = "mysite") -> Path:
    """networks/xueqing copied to tmp_path/name (a folder anywhere, under another folder name)."""
    folder = tmp_path / name
    shutil.copytree(NETWORKS_DIR / "xueqing", folder)
    return folder


def test_a_name_is_a_folder_of_networks():
    site = resolve_site("xueqing")
    assert site.directory == NETWORKS_DIR / "xueqing"
    assert site.file("net.xml") == NETWORKS_DIR / "xueqing" / "xueqing.net.xml"
    info = json.loads(site.file("site.json").read_text())
    assert (site.center_lat, site.center_lon, site.radius_m) == (
        info["center_lat"],
        info["center_lon"],
        info["radius_m"],
    )
    assert site.clip_osm.resolve() == (REPO_ROOT / "osm" / "xueqing.osm").resolve()


def test_a_path_is_the_folder_itself(tmp_path):
    folder = copy_site(tmp_path)
    site = resolve_site(str(folder))
    assert site.name == "xueqing" and site.directory == folder


def test_the_networks_variable_replaces_networks(tmp_path, monkeypatch):
    copy_site(tmp_path, "xueqing")
    monkeypatch.setenv(NETWORKS_DIR_ENV, str(tmp_path))
    assert resolve_site("xueqing").directory == tmp_path / "xueqing"


@pytest.mark.parametrize(
    ("value", "message"),
    [
        ("atlantis", "unknown site 'atlantis' (known: xueqing"),
        ("./nowhere", "site folder nowhere does not exist"),
    ],
)
def test_unknown_sites_are_one_line(value, message):
    with pytest.raises(SiteError) as info:
        resolve_site(value)
    assert message in str(info.value) and "\n" not in str(info.value)


def test_a_folder_without_a_site_file_says_how_to_make_one(tmp_path):
    (tmp_path / "empty").mkdir()
    with pytest.raises(SiteError, match=r"not a site folder .*pedsafe-sumo site build .*--out"):
        resolve_site(str(tmp_path / "empty"))


def _refused(folder: Path, message: str) -> str:
    with pytest.raises(SiteError) as info:
        resolve_site(str(folder))
    text = str(info.value)
    assert message in text and "\n" not in text, text
    return text


def test_an_edited_network_is_refused_with_the_rebuild_command(tmp_path):
    folder = copy_site(tmp_path)
    net = folder / "xueqing.net.xml"
    text = net.read_text()
    # A speed limit changed by hand (the first lane's speed attribute).
    start = text.index('speed="', text.index("<lane "))
    end = text.index('"', start + 7)
    net.write_text(text[:start] + 'speed="8.33' + text[end:])
    message = _refused(folder, "xueqing.net.xml changed after its site file, poles and polygons were made")
    assert f"pedsafe-sumo site build --refresh {folder}" in message


@pytest.mark.parametrize("suffix", ["rsu.add.xml", "poly.xml"])
def test_a_derived_file_changed_by_hand_is_refused(tmp_path, suffix):
    folder = copy_site(tmp_path)
    path = folder / f"xueqing.{suffix}"
    root_tag = "</additional>"
    text = path.read_text()
    if suffix == "rsu.add.xml":
        # The corner pole moved 5 m east by hand.
        poi = ET.parse(path).getroot().find("poi")
        old = f'x="{float(poi.get("x")):.2f}"'
        assert old in text
        path.write_text(text.replace(old, f'x="{float(poi.get("x")) + 5.0:.2f}"', 1))
    else:
        path.write_text(text.replace(root_tag, '    <poly id="mine" shape="0,0 1,0 1,1"/>\n' + root_tag))
    _refused(folder, f"xueqing.{suffix} was changed by hand after the build")


def test_a_pole_moved_in_the_site_file_is_refused(tmp_path):
    folder = copy_site(tmp_path)
    info = json.loads((folder / "xueqing.site.json").read_text())
    info["roadside_units"][1]["y"] += 3.0
    (folder / "xueqing.site.json").write_text(json.dumps(info))
    _refused(folder, "pole rsu_camera_1 of xueqing.site.json is not where xueqing.rsu.add.xml puts it")


def test_derived_files_of_another_network_are_refused(tmp_path):
    folder = copy_site(tmp_path)
    path = folder / "xueqing.rsu.add.xml"
    text = path.read_text()
    digest = json.loads((folder / "xueqing.site.json").read_text())["net_sha256"]
    path.write_text(text.replace(digest, "0" * 64))
    _refused(folder, "xueqing.rsu.add.xml was not made from this xueqing.net.xml")


def test_a_site_file_without_hashes_is_refused(tmp_path):
    folder = copy_site(tmp_path)
    info = json.loads((folder / "xueqing.site.json").read_text())
    del info["net_sha256"]
    (folder / "xueqing.site.json").write_text(json.dumps(info))
    _refused(folder, "records no hash of the network it was made from")


def _pois(folder: Path) -> dict[str, tuple[float, float]]:
    root = ET.parse(folder / "xueqing.rsu.add.xml").getroot()
    return {p.get("id"): (float(p.get("x")), float(p.get("y"))) for p in root.iter("poi")}


def _first_building(folder: Path) -> list[tuple[float, float]]:
    poly = next(
        p
        for p in ET.parse(folder / "xueqing.poly.xml").getroot().iter("poly")
        if p.get("type", "").startswith("building")
    )
    return [tuple(map(float, xy.split(","))) for xy in poly.get("shape").split()]


@pytest.mark.slow
def test_a_shifted_network_is_refused_then_refresh_moves_poles_and_buildings_with_it(tmp_path):
    """netconvert --offset.x 40 moves every coordinate of the network 40 m east (and its geo-reference
    with it): the old poles and buildings are refused; --refresh re-derives them, 40 m east."""
    folder = copy_site(tmp_path)
    before_poles, before_building = _pois(folder), _first_building(folder)
    net = folder / "xueqing.net.xml"
    shifted = tmp_path / "shifted.net.xml"
    subprocess.run(
        [sumo_binary("netconvert"), "-s", str(net), "--offset.x", "40", "-o", str(shifted)],
        check=True,
        capture_output=True,
    )
    shutil.copyfile(shifted, net)
    message = _refused(folder, "changed after its site file")
    # The clip the site file names lives in the checkout (osm/xueqing.osm), reached relative to the
    # copied folder: give the copy its own clip, as a site folder built with --out has.
    shutil.copyfile(REPO_ROOT / "osm" / "xueqing.osm", folder / "xueqing.osm")
    info = json.loads((folder / "xueqing.site.json").read_text())
    info["clip_osm"] = "xueqing.osm"
    (folder / "xueqing.site.json").write_text(json.dumps(info))
    proc = subprocess.run(
        [sys.executable, str(TOOL), "--refresh", str(folder)], capture_output=True, text=True, cwd=REPO_ROOT
    )
    assert proc.returncode == 0, proc.stderr
    assert "--refresh" in message
    site = resolve_site(str(folder))  # accepted again
    after_poles, after_building = _pois(folder), _first_building(folder)
    assert set(after_poles) == set(before_poles)
    for pole, (x, y) in before_poles.items():
        assert after_poles[pole] == pytest.approx((x + 40.0, y), abs=0.02), pole
    for (x0, y0), (x1, y1) in zip(before_building, after_building, strict=True):
        assert (x1, y1) == pytest.approx((x0 + 40.0, y0), abs=0.02)
    junction_x = json.loads(site.file("site.json").read_text())["main_junction_xy"][0]
    original = json.loads((NETWORKS_DIR / "xueqing" / "xueqing.site.json").read_text())
    assert junction_x == pytest.approx(original["main_junction_xy"][0] + 40.0, abs=0.02)


def test_replay_refuses_a_site_whose_files_differ_from_the_run(tmp_path):
    folder = copy_site(tmp_path)
    from pedsafe_sumo.batch.runner import site_file_digests

    digests = site_file_digests(str(folder))
    run_info = {"site": "xueqing", "site_path": str(folder), "site_files_sha256": digests}
    assert run_site(run_info).directory == folder  # the recorded folder, not networks/xueqing
    changed = {**digests, "xueqing.net.xml": "0" * 64}
    with pytest.raises(ReplayError, match=r"xueqing.net.xml differ\(s\) from the file\(s\) the run read"):
        run_site({**run_info, "site_files_sha256": changed})
    # A run made on a folder that is gone: the name is looked up, and its files must match.
    assert run_site({**run_info, "site_path": str(tmp_path / "gone")}).directory == NETWORKS_DIR / "xueqing"
