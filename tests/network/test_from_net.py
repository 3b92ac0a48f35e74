"""A site from a plain SUMO network (tools/build_network.py --net): SUMO's own RiLSA example and an
Ingolstadt network of the SUMO game (tests/network/data/sumo_nets/README.md), no OSM data and no
geo-projection; bad input in one line, exit 2."""

from __future__ import annotations

import gzip
import json
import os
import re
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pandas as pd
import pytest

from pedsafe_sumo import REPO_ROOT
from pedsafe_sumo.network.sites import resolve_site, verify_site
from pedsafe_sumo.params import load_params
from pedsafe_sumo.perception.world import load_static_occluders
from pedsafe_sumo.sumo_binaries import sumo_binary

NETS = Path(__file__).parent / "data" / "sumo_nets"
RILSA = NETS / "rilsa1.net.xml"
INGOLSTADT = NETS / "ingolstadt.net.xml.gz"
BUILD_TOOL = REPO_ROOT / "tools" / "build_network.py"
#: The Ingolstadt junction of the batch and where its node lies in the shipped file (read from it below).
JUNCTION = "gneJ21"


def _run(*args: str, timeout: float = 600) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, *args], capture_output=True, text=True, cwd=REPO_ROOT, timeout=timeout,
        env={**os.environ, "PYTHONPATH": str(REPO_ROOT)},
    )  # fmt: skip


def _netconvert(*args: str, cwd: Path) -> None:
    env = {**os.environ, "SUMO_HOME": str(Path(sumo_binary("netconvert")).parent.parent)}
    subprocess.run([sumo_binary("netconvert"), *args], cwd=cwd, check=True, capture_output=True, env=env)


def _build(*args: str) -> subprocess.CompletedProcess:
    return _run(str(BUILD_TOOL), *args)


def _node_xy(net_text: str, node: str) -> tuple[float, float]:
    element = next(j for j in ET.fromstring(net_text.encode()).iter("junction") if j.get("id") == node)
    return float(element.get("x")), float(element.get("y"))


def _one_line_exit_2(proc: subprocess.CompletedProcess) -> str:
    assert proc.returncode == 2, (proc.stdout, proc.stderr)
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    assert "Traceback" not in proc.stderr
    return lines[0]


@pytest.fixture(scope="module")
def plain_ingolstadt(tmp_path_factory) -> Path:
    """The Ingolstadt network with its geo-projection taken out (projParameter "!", as netconvert writes
    a network built without one): nothing of the site may need it."""
    text = gzip.decompress(INGOLSTADT.read_bytes()).decode("utf-8")
    plain, n = re.subn(r'projParameter="[^"]*"', 'projParameter="!"', text)
    assert n == 1
    path = tmp_path_factory.mktemp("nets") / "ingolstadt.net.xml"
    path.write_text(plain, encoding="utf-8")
    return path


@pytest.fixture(scope="module")
def ingolstadt_site(plain_ingolstadt, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("sites") / "ingolstadt"
    proc = _build("--net", str(plain_ingolstadt), "--junction", JUNCTION, "--out", str(out))
    assert proc.returncode == 0, proc.stderr
    return out


def test_the_rilsa_example_builds_into_a_site_without_osm_or_projection(tmp_path):
    assert 'projParameter="!"' in RILSA.read_text(encoding="utf-8")  # the file has no projection
    out = tmp_path / "rilsa"
    proc = _build("--net", str(RILSA), "--junction", "0", "--out", str(out))
    assert proc.returncode == 0, proc.stderr
    site = resolve_site(str(out))  # checked: digests, one light per junction, right-hand traffic
    assert site.name == "rilsa" and site.center_lat is None and site.center_lon is None
    info = json.loads(site.file("site.json").read_text())
    assert info["main_junction"] == "0" and info["center_xy"] == [500.0, 500.0]  # junction 0 of the file
    assert Path(out / info["source_net"]).resolve() == RILSA.resolve()
    # The network is kept byte for byte.
    assert site.file("net.xml").read_bytes() == RILSA.read_bytes()
    assert "no geo-reference" in proc.stdout
    # The lane next to the kerb lane of every approach turns left only (its connections in the file:
    # fromLane 2 goes left), so the straight scenarios say so, per approach, in one line each.
    assert "crossing: NOT hosted: cannot be staged: site rilsa: lane wm_2, where the ego drives, has no " \
        "straight movement onto me" in proc.stdout  # fmt: skip
    assert "right_turn: hosted" in proc.stdout


def test_refresh_of_a_network_site_needs_no_projection(tmp_path):
    """The site's network rewritten by today's netconvert (RiLSA's file is from an old one, whose junction
    shapes it recomputes), refreshed; then shifted 40 m east: refused until --refresh, after which the
    junction and every pole are exactly 40 m east."""
    out = tmp_path / "rilsa"
    assert _build("--net", str(RILSA), "--junction", "0", "--out", str(out)).returncode == 0
    net = out / "rilsa.net.xml"
    _netconvert("-s", net.name, "-o", net.name, cwd=out)
    assert _build("--refresh", str(out)).returncode == 0
    before = json.loads((out / "rilsa.site.json").read_text())
    _netconvert("-s", net.name, "--offset.x", "40", "-o", net.name, cwd=out)
    with pytest.raises(ValueError, match="changed after its site file"):
        resolve_site(str(out))
    proc = _build("--refresh", str(out))
    assert proc.returncode == 0, proc.stderr
    site = resolve_site(str(out))
    verify_site(site)
    after = json.loads(site.file("site.json").read_text())
    assert after["main_junction_xy"] == [before["main_junction_xy"][0] + 40, before["main_junction_xy"][1]]
    assert after["source_net"] == before["source_net"]  # where it came from, not the folder's copy
    assert Path(out / after["source_net"]).resolve() == RILSA.resolve()
    for old, new in zip(before["roadside_units"], after["roadside_units"], strict=True):
        assert new["x"] == pytest.approx(old["x"] + 40, abs=0.02)
        assert new["y"] == pytest.approx(old["y"], abs=0.02)


@pytest.mark.slow
def test_a_crossing_batch_on_a_plain_network_runs_with_its_signals(ingolstadt_site, tmp_path):
    run = tmp_path / "run"
    proc = _run("-m", "pedsafe_sumo.batch", "--site", str(ingolstadt_site), "--scenario", "crossing",
                "--episodes", "2", "--workers", "1", "--keep-logs", "all", "--out", str(run))  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    rows = pd.read_parquet(run / "episodes.parquet")
    assert len(rows) == 4
    assert rows["error"].isna().all() or (rows["error"].fillna("") == "").all(), rows["error"].tolist()
    assert (rows["ego_signal"] != "none").all() and (rows["ego_signal"] == "green").all()
    # The site's roadside camera, placed by the build, is what first detects the pedestrian under V2I.
    v2i = rows[rows["condition"] == "v2i"]
    assert (v2i["detected_by"] == "roadside").any(), v2i["detected_by"].tolist()
    # Every other command on the run and the site: report, replay, conflicts on the replay's FCD.
    report = _run("-m", "pedsafe_sumo.report", str(run))
    assert report.returncode == 0, report.stderr
    fcd = tmp_path / "fcd.xml"
    replay = _run("-m", "pedsafe_sumo.replay", str(run), "--episode", "0", "--condition", "sv",
                  "--scenario", "crossing", "--export-fcd", str(fcd))  # fmt: skip
    assert replay.returncode == 0, replay.stderr
    conflicts = _run("-m", "pedsafe_sumo.conflicts", str(fcd), "--site", str(ingolstadt_site), "--out",
                     str(tmp_path / "conflicts.csv"))  # fmt: skip
    assert conflicts.returncode == 0, conflicts.stderr
    episode = _run("-m", "pedsafe_sumo.episode", "--site", str(ingolstadt_site), "--scenario", "crossing")
    assert episode.returncode == 0, episode.stderr
    summary = _run("-m", "pedsafe_sumo.site", "--site", str(ingolstadt_site), "--no-build")
    assert summary.returncode == 0, summary.stderr


@pytest.mark.parametrize("spelling", ["space", "equals"])
def test_at_takes_negative_coordinates(plain_ingolstadt, tmp_path, spelling):
    """The network shifted so that the junction lies at negative x and y; --at names a point 3 m from
    it, in both spellings."""
    shifted = tmp_path / "shifted.net.xml"
    _netconvert("-s", str(plain_ingolstadt), "--offset.x", "-5800", "--offset.y", "-5700", "-o", str(shifted),
                cwd=tmp_path)  # fmt: skip
    x, y = _node_xy(shifted.read_text(encoding="utf-8"), JUNCTION)
    assert x < 0 and y < 0
    point = f"{x + 3:.2f},{y - 1:.2f}"
    at = ["--at", point] if spelling == "space" else [f"--at={point}"]
    out = tmp_path / "shifted"
    proc = _build("--net", str(shifted), *at, "--out", str(out))
    assert proc.returncode == 0, proc.stderr
    info = json.loads((out / "shifted.site.json").read_text())
    assert info["main_junction"] == JUNCTION
    assert info["center_xy"] == [round(x + 3, 2), round(y - 1, 2)]


def _bad(tmp_path, *args: str) -> str:
    out = tmp_path / "bad"
    line = _one_line_exit_2(_build(*args, "--out", str(out)))
    assert not out.exists()
    return line


def test_bad_inputs_are_one_line_exit_2(tmp_path):
    assert _bad(tmp_path, "--net", str(tmp_path / "none.net.xml"), "--junction", "0") == (
        f"build_network: error: --net {tmp_path / 'none.net.xml'}: no such file"
    )
    assert _bad(tmp_path, "--net", str(RILSA), "--junction", "J9") == (
        f"build_network: error: junction 'J9' is not in {RILSA}"
    )
    # RiLSA spans x and y from 0 to 1000 m (its convBoundary).
    line = _bad(tmp_path, "--net", str(RILSA), "--at", "-12.5,30")
    assert "--at -12.5,30 is off the network" in line and "x 0.0 to 1000.0" in line
    # Junction 'n' is the priority junction 100 m north of the signal.
    line = _bad(tmp_path, "--net", str(RILSA), "--junction", "n")
    assert (
        "junction 'n' of" in line and "is not signalised (type priority)" in line and "network's: 0" in line
    )
    # A point on the network, 400 m from the one signal.
    line = _bad(tmp_path, "--net", str(RILSA), "--at", "900,500")
    assert "no signalised junction within 60 m" in line
    assert "--net needs the junction" in _bad(tmp_path, "--net", str(RILSA))
    assert "belong to a build from OpenStreetMap" in _bad(tmp_path, "--net", str(RILSA), "--junction", "0",
                                                          "--center", "40,116")  # fmt: skip
    assert "need --net" in _bad(tmp_path, "--junction", "0")
    assert "--at: a point must be X,Y" in _bad(tmp_path, "--net", str(RILSA), "--at", "1,2,3")


def test_a_network_without_walkways_is_refused_and_netconverts_options_add_them(tmp_path):
    """A signalised cross of 2-lane roads from plain node and edge files, no sidewalks: refused in one
    line naming what is missing and the netconvert options that add them; with those options the same
    network builds."""
    (tmp_path / "x.nod.xml").write_text(
        '<nodes><node id="C" x="0" y="0" type="traffic_light"/><node id="N" x="0" y="200"/>'
        '<node id="E" x="200" y="0"/><node id="S" x="0" y="-200"/><node id="W" x="-200" y="0"/></nodes>'
    )
    edges = "".join(
        f'<edge id="{a}C" from="{a}" to="C" numLanes="2" speed="13.89"/>'
        f'<edge id="C{a}" from="C" to="{a}" numLanes="2" speed="13.89"/>'
        for a in "NESW"
    )
    (tmp_path / "x.edg.xml").write_text(f"<edges>{edges}</edges>")
    _netconvert("-n", "x.nod.xml", "-e", "x.edg.xml", "-o", "bare.net.xml", cwd=tmp_path)
    line = _bad(tmp_path, "--net", str(tmp_path / "bare.net.xml"), "--junction", "C")
    assert "junction C of" in line and "has no sidewalks and no crosswalks" in line
    assert "netconvert -s IN.net.xml --sidewalks.guess true --crossings.guess true -o OUT.net.xml" in line
    _netconvert("-s", "bare.net.xml", "--sidewalks.guess", "true", "--crossings.guess", "true", "-o",
                "walk.net.xml", cwd=tmp_path)  # fmt: skip
    proc = _build("--net", str(tmp_path / "walk.net.xml"), "--junction", "C", "--out", str(tmp_path / "walk"))
    assert proc.returncode == 0, proc.stderr
    assert "crossing: hosted" in proc.stdout


def test_a_lefthand_attribute_the_lanes_contradict_is_refused(tmp_path):
    """RiLSA (right-hand) marked lefthand="true" by hand: its lanes are drawn for right-hand traffic, so the
    scenarios could be staged on neither side; a network netconvert built with --lefthand is taken."""
    left = tmp_path / "left.net.xml"
    left.write_text(RILSA.read_text(encoding="utf-8").replace("<net ", '<net lefthand="true" ', 1))
    line = _bad(tmp_path, "--net", str(left), "--junction", "0")
    assert 'says lefthand="true" but draws the kerb-side lane of its roads on the right of travel' in line


def test_polygons_given_are_the_sites_occluders_and_a_refresh_keeps_them(tmp_path):
    """A 10 m square building north-west of RiLSA's junction: copied into the site's poly.xml (read by the
    perception layer as one occluder), kept by --refresh; without --polygons the site has none."""
    poly = tmp_path / "houses.poly.xml"
    poly.write_text(
        '<?xml version="1.0" encoding="UTF-8"?>\n<additional>\n'
        '    <poly id="house" type="building" color="200,0,0" fill="1" layer="-1"\n'
        '          shape="460.00,540.00 470.00,540.00 470.00,550.00 460.00,550.00 460.00,540.00"/>\n'
        "</additional>\n"
    )
    out = tmp_path / "rilsa"
    proc = _build("--net", str(RILSA), "--junction", "0", "--polygons", str(poly), "--out", str(out))
    assert proc.returncode == 0, proc.stderr
    occluders = load_params(None)["perception"]["occluders"]
    shapes = [p.get("shape") for p in ET.parse(out / "rilsa.poly.xml").getroot().iter("poly")]
    assert shapes == ["460.00,540.00 470.00,540.00 470.00,550.00 460.00,550.00 460.00,540.00"]
    assert load_static_occluders(out / "rilsa.poly.xml", occluders).poly_ids == ("house",)
    assert json.loads((out / "rilsa.site.json").read_text())["polygons"] == 1
    assert _build("--refresh", str(out)).returncode == 0
    assert [p.get("shape") for p in ET.parse(out / "rilsa.poly.xml").getroot().iter("poly")] == shapes
    resolve_site(str(out))
    bare = tmp_path / "bare"
    assert _build("--net", str(RILSA), "--junction", "0", "--out", str(bare)).returncode == 0
    assert not list(ET.parse(bare / "bare.poly.xml").getroot().iter("poly"))
    assert json.loads((bare / "bare.site.json").read_text())["polygons"] == 0
