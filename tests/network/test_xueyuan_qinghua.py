"""networks/xueyuan_qinghua: the second study junction, built from the repository's OpenStreetMap extract.

Checked against the OSM data and SUMO's own view of the built network: the build reproduces the committed
network from the extract; its junction lies where OSM puts the junction's signal nodes; one traffic light
controls every link of the junction; and the approach-staged scenarios of a study are hosted.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
import xml.etree.ElementTree as ET

import pytest

from pedsafe_sumo import NETWORKS_DIR, REPO_ROOT

NAME = "xueyuan_qinghua"
FOLDER = NETWORKS_DIR / NAME
NET = FOLDER / f"{NAME}.net.xml"
TOOL = REPO_ROOT / "tools" / "build_network.py"
SOURCE = REPO_ROOT / "osm" / "haidian_xueqing.osm"
CENTRE = (39.99962, 116.34655)
#: OSM nodes tagged highway=traffic_signals at this junction (read from the source extract).
SIGNAL_NODES = (
    "9284656878",
    "9284656879",
    "9284656880",
    "9284656881",
    "9284656882",
    "9284656883",
    "9284656884",
)


def _edges(net: ET.Element) -> dict[str, tuple[str, str, int]]:
    return {
        e.get("id"): (e.get("from"), e.get("to"), len(e.findall("lane")))
        for e in net.iter("edge")
        if e.get("function") != "internal"
    }


def test_the_build_from_the_extract_gives_the_committed_network(tmp_path):
    out = tmp_path / NAME
    proc = subprocess.run(
        [sys.executable, str(TOOL), "--osm", str(SOURCE), f"--center={CENTRE[0]},{CENTRE[1]}",
         "--radius", "220", "--name", NAME, "--out", str(out), "--osm-out", str(tmp_path / f"{NAME}.osm")],
        capture_output=True, text=True, cwd=REPO_ROOT, timeout=300,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    built = ET.parse(out / f"{NAME}.net.xml").getroot()
    committed = ET.parse(NET).getroot()
    assert _edges(built) == _edges(committed)
    assert {j.get("id") for j in built.iter("junction")} == {j.get("id") for j in committed.iter("junction")}


def test_the_junction_is_where_osm_puts_its_signals_and_one_light_controls_its_links():
    import libsumo

    # the OSM signal nodes' centroid, projected by the network's own projection
    root = ET.parse(SOURCE).getroot()
    signals = [n for n in root.iter("node") if n.get("id") in SIGNAL_NODES]
    assert len(signals) == len(SIGNAL_NODES)
    lat = sum(float(n.get("lat")) for n in signals) / len(signals)
    lon = sum(float(n.get("lon")) for n in signals) / len(signals)
    libsumo.start(["sumo", "-n", str(NET), "--no-step-log", "--no-warnings"])
    try:
        x, y = libsumo.simulation.convertGeo(lon, lat, fromGeo=True)
        lights = libsumo.trafficlight.getIDList()
        controlling = {
            tls
            for tls in lights
            for group in libsumo.trafficlight.getControlledLinks(tls)
            for (from_lane, _, _) in group
        }
        junctions = {
            j: libsumo.junction.getPosition(j) for j in libsumo.junction.getIDList() if not j.startswith(":")
        }
    finally:
        libsumo.close()
    main = min(junctions, key=lambda j: math.dist(junctions[j], (x, y)))
    # the signal nodes span a divided-road junction ~60 m across: its cluster is within 20 m of their centre
    assert math.dist(junctions[main], (x, y)) < 20.0
    assert main == json.loads((FOLDER / f"{NAME}.site.json").read_text())["main_junction"]
    assert len(controlling) == 1


def test_a_study_s_approach_staged_scenarios_are_hosted():
    proc = subprocess.run(
        [sys.executable, "-m", "pedsafe_sumo.site", "--site", NAME, "--no-build"],
        capture_output=True, text=True, cwd=REPO_ROOT, timeout=300,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.splitlines()
    for scenario in ("crossing", "jaywalking", "background_blending", "right_turn"):
        (line,) = [s for s in lines if s.strip().startswith(f"{scenario} under approach staging:")]
        assert ": hosted" in line, line
    (left,) = [s for s in lines if s.strip().startswith("left_turn under approach staging:")]
    assert "NOT hosted" in left and "oncoming" in left


@pytest.mark.slow
def test_one_pair_of_each_scenario_runs_with_its_signals_staged(tmp_path):
    import pandas as pd

    out = tmp_path / "run"
    proc = subprocess.run(
        [sys.executable, "-m", "pedsafe_sumo.batch", "--site", NAME, "--scenario",
         "crossing,jaywalking,background_blending,right_turn", "--set", "staging=approach",
         "--episodes", "1", "--workers", "1", "--out", str(out)],
        capture_output=True, text=True, cwd=REPO_ROOT, timeout=900,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    episodes = pd.read_parquet(out / "episodes.parquet")
    assert len(episodes) == 8
    assert not episodes["error"].fillna("").astype(bool).any()
    assert set(episodes["ego_signal"]) == {"green"}
