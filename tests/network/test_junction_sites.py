"""Sites of junctions other than the study site, built through the real command line: a light netconvert
joins over two junctions, coordinates south and west of zero, a junction with two lights, left-hand
traffic.

The junction is hand-made OSM data (tests/network/synthetic_osm.py) in Buenos Aires (-34.6037,
-58.3816: both coordinates negative; right-hand traffic): a two-way road across a divided road whose
carriageways lie 40 m apart, a signal node at every stop line. The build joins the signals into one
light `joinedS_<west>_<east>` over both junctions, whose id is neither junction's. Expected light ids
and link indices are read from the .net.xml with ElementTree.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pandas as pd
import pytest
from synthetic_osm import cross_osm

from pedsafe_sumo import REPO_ROOT
from pedsafe_sumo.network.coordinates import parse_lat_lon, with_negative_values
from pedsafe_sumo.network.sites import resolve_site
from pedsafe_sumo.network.traffic_side import TRAFFIC_SIDE_NOTE
from pedsafe_sumo.scenarios.signals import load_junction_signals
from pedsafe_sumo.sumo_binaries import sumo_binary

BUILD_TOOL = REPO_ROOT / "tools" / "build_network.py"
CLIP_TOOL = REPO_ROOT / "tools" / "clip_osm.py"
CENTER = (-34.6037, -58.3816)
CENTER_TEXT = f"{CENTER[0]},{CENTER[1]}"


def _run(*args: str, timeout: float = 600) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, *args], capture_output=True, text=True, cwd=REPO_ROOT, timeout=timeout,
        env={**os.environ, "PYTHONPATH": str(REPO_ROOT)},
    )  # fmt: skip


def _build(osm: Path, out: Path, *center: str) -> subprocess.CompletedProcess:
    return _run(str(BUILD_TOOL), "--osm", str(osm), *center, "--radius", "200", "--name",
                out.name, "--out", str(out))  # fmt: skip


@pytest.fixture(scope="module")
def osm(tmp_path_factory) -> Path:
    return cross_osm(tmp_path_factory.mktemp("osm") / "split.osm", CENTER, split_m=40.0)


@pytest.fixture(scope="module")
def built(osm, tmp_path_factory) -> tuple[Path, str]:
    """The site built with `--center -34.6037,-58.3816` (the space spelling); its build summary."""
    out = tmp_path_factory.mktemp("sites") / "split"
    proc = _build(osm, out, "--center", CENTER_TEXT)
    assert proc.returncode == 0, proc.stderr
    return out, proc.stdout


def _copy(site: Path, to: Path) -> Path:
    """A copy of the site folder elsewhere (the folder name is the site's)."""
    copy = to / site.name
    shutil.copytree(site, copy)
    return copy


def _main_links(net: Path, junction: str) -> dict[tuple[str, str], tuple[str, int]]:
    """(from lane, to edge) -> (tl, linkIndex) of the controlled connections through `junction`."""
    root = ET.parse(net).getroot()
    ends_at = {e.get("id"): e.get("to") for e in root.iter("edge") if e.get("to")}
    return {
        (f"{c.get('from')}_{c.get('fromLane')}", c.get("to")): (c.get("tl"), int(c.get("linkIndex")))
        for c in root.iter("connection")
        if c.get("tl")
        and (ends_at.get(c.get("from")) == junction or c.get("from").startswith(f":{junction}_w"))
    }


# --- coordinates ------------------------------------------------------------------------------------


def test_negative_values_are_joined_to_their_option():
    import argparse

    parser = argparse.ArgumentParser()
    parser.add_argument("--center", type=parse_lat_lon)
    parser.add_argument("--radius", type=float)
    for argv in (["--center", "-33.87,151.19"], ["--center=-33.87,151.19"], ["--cent", "-33.87,151.19"]):
        assert parser.parse_args(with_negative_values(parser, argv, ["--center"])).center == (-33.87, 151.19)
    # Another option's negative value and a value after "--" are left to argparse.
    assert with_negative_values(parser, ["--radius", "-5"], ["--center"]) == ["--radius", "-5"]
    assert with_negative_values(parser, ["--", "--center", "-1,2"], ["--center"]) == [
        "--",
        "--center",
        "-1,2",
    ]
    with pytest.raises(argparse.ArgumentTypeError):
        parse_lat_lon("-95,3")
    with pytest.raises(argparse.ArgumentTypeError):
        parse_lat_lon("-3,nan")


@pytest.mark.parametrize("spelling", [["--center", CENTER_TEXT], [f"--center={CENTER_TEXT}"]])
def test_clip_osm_takes_negative_coordinates_in_both_spellings(osm, tmp_path, spelling):
    target = tmp_path / "clip.osm"
    proc = _run(str(CLIP_TOOL), str(osm), str(target), *spelling, "--radius", "100")
    assert proc.returncode == 0, proc.stderr
    # The clip kept the centre's nodes: a node within 100 m of -34.6037,-58.3816 (the west junction,
    # 20 m west of the centre, at -34.6037, -58.3816 - 20 / (111320 cos 34.6037 deg)).
    lons = [float(n.get("lon")) for n in ET.parse(target).getroot().iter("node")]
    assert any(abs(lon - (-58.3816 - 20 / (111320 * 0.823))) < 1e-5 for lon in lons)


def test_the_build_takes_negative_coordinates_in_both_spellings(built, osm, tmp_path):
    site, summary = built
    info = json.loads((site / "split.site.json").read_text())
    assert (info["center_lat"], info["center_lon"]) == CENTER
    other = _build(osm, tmp_path / "split", f"--center={CENTER_TEXT}")
    assert other.returncode == 0, other.stderr
    assert (
        json.loads((tmp_path / "split" / "split.site.json").read_text())["main_junction"]
        == info["main_junction"]
    )
    help_text = _run(str(BUILD_TOOL), "--help").stdout
    assert "south and west are negative" in " ".join(help_text.split())


# --- the junction's light ---------------------------------------------------------------------------


def test_the_joined_light_is_found_from_the_junctions_connections(built):
    site_dir, summary = built
    site = resolve_site(str(site_dir))
    junction = json.loads(site.file("site.json").read_text())["main_junction"]
    lights = {tl for tl, _ in _main_links(site.file("net.xml"), junction).values()}
    assert len(lights) == 1
    (light,) = lights
    assert light.startswith("joinedS_") and light != junction  # what made the junction look unsignalised
    signals = load_junction_signals(site.file("net.xml"), junction)
    assert signals.program.tls_id == light
    assert "NOTE: traffic side: right-hand" in summary and TRAFFIC_SIDE_NOTE in summary


@pytest.mark.slow
def test_an_episode_on_the_joined_light_has_the_scenarios_signals(built):
    from pedsafe_sumo.control.reference import ReferenceStack
    from pedsafe_sumo.params import load_params
    from pedsafe_sumo.scenarios.specs import get_scenario
    from pedsafe_sumo.sim.episode import EpisodeRunner

    site = resolve_site(str(built[0]))
    runner = EpisodeRunner(site, load_params(), ReferenceStack)
    try:
        result = runner.run(get_scenario("crossing"), "sv", 3)
    finally:
        runner.close()
    setup = result.setup
    junction = json.loads(site.file("site.json").read_text())["main_junction"]
    links = _main_links(site.file("net.xml"), junction)
    light, ego_index = links[(setup.ego.lane_id, setup.ego_route[1])]
    assert setup.signals.tls_id == light and setup.signals.ego_link_index == ego_index
    assert result.outcome["ego_signal"] == "green" and result.outcome["ped_signal"] == "red"
    # SUMO's own state of the ego's link, at the first step: green.
    assert result.signal_states[0][ego_index] in "Gg"


@pytest.mark.slow
def test_a_junction_two_lights_control_is_refused_in_one_line(built, tmp_path):
    """The junction's crosswalks moved to a pedestrian light of their own (a hand edit of the network):
    the batch and episode refuse the site in one line, before writing anything, and so does the build's
    --refresh (no rebuild makes it stageable)."""
    site = _copy(built[0], tmp_path)
    net = site / "split.net.xml"
    junction = json.loads((site / "split.site.json").read_text())["main_junction"]
    tree = ET.parse(net)
    root = tree.getroot()
    crossings = [
        c for c in root.iter("connection") if c.get("from", "").startswith(f":{junction}_w") and c.get("tl")
    ]
    vehicles = len(_main_links(net, junction)) - len(crossings)
    for index, connection in enumerate(crossings):
        connection.set("tl", "ped_light")
        connection.set("linkIndex", str(index))
    logic = ET.SubElement(root, "tlLogic", id="ped_light", type="static", programID="0", offset="0")
    ET.SubElement(logic, "phase", duration="30", state="G" * len(crossings))
    ET.SubElement(logic, "phase", duration="30", state="r" * len(crossings))
    tree.write(net)
    light = next(iter({tl for tl, _ in _main_links(built[0] / "split.net.xml", junction).values()}))
    expected = (
        f"junction {junction} of split.net.xml is controlled by 2 traffic lights ({light} {vehicles} "
        f"links, ped_light {len(crossings)} links): the scenarios stage the signals of one traffic light "
        "per junction"
    )
    out = tmp_path / "run"
    commands = {
        "batch": ["-m", "pedsafe_sumo.batch", "--site", str(site), "--scenario", "crossing",
                  "--episodes", "1", "--workers", "1", "--out", str(out)],
        "episode": ["-m", "pedsafe_sumo.episode", "--site", str(site), "--scenario", "crossing"],
        "refresh": [str(BUILD_TOOL), "--refresh", str(site)],
    }  # fmt: skip
    for name, args in commands.items():
        proc = _run(*args)
        assert proc.returncode == 2, (name, proc.stderr)
        assert len(proc.stderr.strip().splitlines()) == 1, (name, proc.stderr)
        assert expected in proc.stderr, (name, proc.stderr)
    assert not out.exists()


# --- left-hand traffic ------------------------------------------------------------------------------


def test_the_build_makes_left_hand_traffic_it_is_told_of(osm, tmp_path):
    said = _build(osm, tmp_path / "a", "--center", CENTER_TEXT, "--lefthand")
    assert said.returncode == 0, said.stderr
    assert "traffic side: left-hand (--lefthand)" in said.stdout and TRAFFIC_SIDE_NOTE not in said.stdout
    tagged = cross_osm(tmp_path / "left.osm", CENTER, split_m=40.0, tags={"driving_side": "left"})
    proc = _build(tagged, tmp_path / "b", "--center", CENTER_TEXT)
    assert proc.returncode == 0, proc.stderr
    assert "traffic side: left-hand (the OSM data says driving_side=left)" in proc.stdout
    for folder in (tmp_path / "a", tmp_path / "b"):
        net = next(folder.glob("*.net.xml"))
        assert next(ET.iterparse(net, events=("start",)))[1].get("lefthand") == "true"


@pytest.mark.slow
def test_a_network_rebuilt_for_left_hand_traffic_is_refreshed_and_staged_left_hand(built, tmp_path):
    """The right-hand site's network rebuilt by netconvert --lefthand: --refresh re-derives the site from it
    (left-hand), and the batch stages crossing on it with the joined light, no error rows."""
    site = _copy(built[0], tmp_path)
    net = site / "split.net.xml"
    env = {**os.environ, "SUMO_HOME": str(Path(sumo_binary("netconvert")).parent.parent)}
    subprocess.run([sumo_binary("netconvert"), "-s", net.name, "--lefthand", "-o", net.name], cwd=site,
                   check=True, capture_output=True, env=env)  # fmt: skip
    assert next(ET.iterparse(net, events=("start",)))[1].get("lefthand") == "true"
    refresh = _run(str(BUILD_TOOL), "--refresh", str(site))
    assert refresh.returncode == 0, refresh.stderr
    assert 'traffic side: left-hand (the network says lefthand="true")' in refresh.stdout
    run = tmp_path / "run"
    proc = _run("-m", "pedsafe_sumo.batch", "--site", str(site), "--scenario", "crossing", "--episodes", "1",
                "--workers", "1", "--condition", "sv", "--out", str(run))  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    assert "keeps left (left-hand traffic)" in proc.stdout
    rows = pd.read_parquet(run / "episodes.parquet")
    assert (rows["error"] == "").all() and set(rows["ego_signal"]) == {"green"}
