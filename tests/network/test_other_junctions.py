"""Junctions other than Xueqing, built from OpenStreetMap clips (tests/network/data/osm, ODbL): each builds
into a site folder that passes its checks, says which scenarios it can host and why not, and runs the
ones it hosts with roadside detections under V2I."""

from __future__ import annotations

import json
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pandas as pd
import pytest

from pedsafe_sumo import REPO_ROOT
from pedsafe_sumo.network.sites import resolve_site

DATA = Path(__file__).parent / "data" / "osm"
TOOL = REPO_ROOT / "tools" / "build_network.py"
CENTRES = {
    "zhixin": "40.00001,116.35857",
    "xueyuan": "39.99968,116.34651",
    "g6_link": "40.00832,116.35601",
    "qinghua_link": "39.99991,116.35549",
}


def _run(*args: str, timeout: float = 300) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, *args], capture_output=True, text=True, cwd=REPO_ROOT, timeout=timeout
    )


@pytest.fixture(scope="module")
def built(tmp_path_factory) -> dict[str, tuple[Path, str]]:
    """Every clip built into its own site folder: name -> (folder, build output)."""
    root = tmp_path_factory.mktemp("sites")
    out = {}
    for name, centre in CENTRES.items():
        folder = root / name
        proc = _run(
            str(TOOL), "--osm", str(DATA / f"{name}.osm"), "--no-clip", "--center", centre,
            "--radius", "130", "--name", name, "--out", str(folder),
        )  # fmt: skip
        assert proc.returncode == 0, (name, proc.stderr)
        out[name] = (folder, proc.stdout)
    return out


def _hosting(stdout: str) -> dict[str, str]:
    lines = [line.strip() for line in stdout.splitlines() if line.startswith("  ") and ": " in line]
    return {
        line.split(":")[0]: line.split(": ", 1)[1]
        for line in lines
        if line.split(":")[0] in ("crossing", "jaywalking", "background_blending")
    }


def _osm_ways(name: str, highway: str) -> list[ET.Element]:
    root = ET.parse(DATA / f"{name}.osm").getroot()
    return [
        w
        for w in root.iter("way")
        if any(t.get("k") == "highway" and t.get("v") == highway for t in w.iter("tag"))
    ]


@pytest.mark.slow
def test_every_clip_builds_into_a_site_that_passes_its_checks(built):
    for name, (folder, _) in built.items():
        site = resolve_site(str(folder))  # verify: derived files made from this network
        info = json.loads(site.file("site.json").read_text())
        assert info["name"] == name and info["net_sha256"]


@pytest.mark.slow
def test_roads_without_lane_tags_get_the_road_class_default_and_the_summary_says_so(built):
    folder, stdout = built["zhixin"]
    secondary = _osm_ways("zhixin", "secondary")
    untagged = [w for w in secondary if not any(t.get("k", "").startswith("lanes") for t in w.iter("tag"))]
    assert secondary and len(untagged) == len(secondary)  # the clip has no lane tags at all
    assert (
        f"lane default: {len(untagged)} highway.secondary way(s) without a lane tag get 2 lane(s)" in stdout
    )
    # In the network: every two-way secondary edge has 2 vehicle lanes, every tertiary one 1 (one-lane
    # approaches), as the typemaps say (urban_speeds.typ.xml: secondary 2; SUMO's: tertiary 1).
    net = ET.parse(folder / "zhixin.net.xml").getroot()
    lanes_by_type: dict[str, set[int]] = {}
    for edge in net.iter("edge"):
        if edge.get("function") or edge.get("type") not in ("highway.secondary", "highway.tertiary"):
            continue
        vehicle = [lane for lane in edge.iter("lane") if lane.get("allow") != "pedestrian"]
        lanes_by_type.setdefault(edge.get("type"), set()).add(len(vehicle))
    assert lanes_by_type == {"highway.secondary": {2}, "highway.tertiary": {1}}
    assert set(_hosting(stdout).values()) == {"hosted (its roadside poles see its staging area)"}


@pytest.mark.slow
def test_a_junction_netconvert_splits_into_several_signal_nodes(built):
    folder, stdout = built["xueyuan"]
    info = json.loads((folder / "xueyuan.site.json").read_text())
    net = ET.parse(folder / "xueyuan.net.xml").getroot()
    signal_nodes = {
        j.get("id") for j in net.iter("junction") if j.get("type", "").startswith("traffic_light")
    }
    assert len(info["signal_nodes"]) > 1 and set(info["signal_nodes"]) <= signal_nodes
    assert info["main_junction"] in info["signal_nodes"]
    assert f"the intersection has {len(info['signal_nodes'])} signal nodes" in stdout
    assert set(_hosting(stdout).values()) == {"hosted (its roadside poles see its staging area)"}


@pytest.mark.slow
def test_polygons_below_ground_are_not_occluders(built):
    """Liudaokou subway station is mapped as a 160 m building with layer=-1 over Xueyuan Road's
    crosswalks; kept, it hid every staging point from every pole placement."""
    folder, _ = built["xueyuan"]
    osm = ET.parse(DATA / "xueyuan.osm").getroot()
    underground = {
        w.get("id")
        for w in osm.iter("way")
        if any(t.get("k") == "building" for t in w.iter("tag"))
        and any(t.get("k") == "layer" and float(t.get("v")) < 0 for t in w.iter("tag"))
    }
    kept = {p.get("id") for p in ET.parse(folder / "xueyuan.poly.xml").getroot().iter("poly")}
    assert underground and not (underground & kept)
    assert json.loads((folder / "xueyuan.site.json").read_text())["underground_polygons_dropped"] == len(
        underground
    )


@pytest.mark.slow
def test_a_t_junction_of_one_way_roads_builds_and_says_why_it_hosts_nothing(built, tmp_path):
    folder, stdout = built["g6_link"]
    summary = _run("-m", "pedsafe_sumo.site", "--site", str(folder), "--no-build")
    assert summary.returncode == 0, summary.stderr
    arms = [line for line in summary.stdout.splitlines() if line.startswith("    ") and " lane(s) in" in line]
    assert len(arms) == 3  # a T
    assert all(v.startswith("NOT hosted: cannot be staged: ") for v in _hosting(stdout).values())
    proc = _run(
        "-m", "pedsafe_sumo.batch", "--scenario", "crossing", "--episodes", "1", "--site", str(folder),
        "--out", str(tmp_path / "run"),
    )  # fmt: skip
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1 and "no crosswalk over" in proc.stderr
    assert not (tmp_path / "run").exists()


@pytest.mark.slow
def test_a_pole_that_cannot_see_the_crosswalk_is_refused_at_batch_start(built, tmp_path):
    folder, stdout = built["qinghua_link"]
    assert _hosting(stdout)["crossing"].startswith("NOT hosted: not seen under V2I")
    proc = _run(
        "-m", "pedsafe_sumo.batch", "--scenario", "crossing", "--episodes", "1", "--site", str(folder),
        "--out", str(tmp_path / "run"),
    )  # fmt: skip
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1, proc.stderr
    assert "cannot host scenario 'crossing': not seen under V2I" in proc.stderr
    assert not (tmp_path / "run").exists()


def _batch(folder: Path, scenario: str, out: Path) -> pd.DataFrame:
    proc = _run(
        "-m", "pedsafe_sumo.batch", "--scenario", scenario, "--episodes", "2", "--workers", "1",
        "--site", str(folder), "--out", str(out),
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    return pd.read_parquet(out / "episodes.parquet")


@pytest.mark.slow
@pytest.mark.parametrize(
    ("name", "scenario"), [("zhixin", "crossing"), ("zhixin", "jaywalking"), ("xueyuan", "crossing")]
)
def test_hosted_scenarios_run_with_roadside_detections_under_v2i(built, tmp_path, name, scenario):
    folder, _ = built[name]
    episodes = _batch(folder, scenario, tmp_path / "run")
    assert (episodes["status"] == "ok").all(), episodes["error"].tolist()
    v2i = episodes[episodes["condition"] == "v2i"]
    assert len(v2i) == 2 and (v2i["detected_by"] == "roadside").any(), v2i["detected_by"].tolist()


@pytest.mark.slow
def test_scenario_all_runs_what_the_site_hosts_and_names_what_it_skips(built, tmp_path):
    folder, _ = built["qinghua_link"]
    out = tmp_path / "run"
    proc = _run(
        "-m", "pedsafe_sumo.batch", "--scenario", "all", "--episodes", "1", "--workers", "1",
        "--site", str(folder), "--out", str(out),
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    assert "skipping scenario 'crossing' on site qinghua_link: not seen under V2I" in proc.stdout
    episodes = pd.read_parquet(out / "episodes.parquet")
    assert set(episodes["scenario"]) == {"jaywalking", "background_blending"}
    assert list(json.loads((out / "run.json").read_text())["scenarios"]) == [
        "jaywalking",
        "background_blending",
    ]


def _hosting_by_approach(stdout: str, own: str) -> dict[tuple[str, str], str]:
    """(scenario, arm) -> the build summary's verdict, for every approach it lists."""
    found = {}
    for line in stdout.splitlines():
        if not line.startswith("  ") or ": " not in line:
            continue
        head, verdict = line.strip().split(": ", 1)
        if head.endswith(" under approach staging"):  # the batch runs each scenario's own staging
            continue
        name, _, arm = head.partition(" on approach ")
        if name in ("crossing", "jaywalking", "background_blending", "right_turn", "left_turn"):
            found[(name, arm or own)] = verdict
    return found


@pytest.mark.slow
def test_every_hosted_scenario_runs_on_every_approach_with_roadside_detections(built, tmp_path):
    """On the zhixin clip (two-lane Qinghua East Rd, one-lane tertiary side roads): what
    the build says it hosts on each approach is what `--scenario all --approach all` runs, under SV and
    V2I, each on the approach it names, with detections by the roadside camera under V2I."""
    folder, stdout = built["zhixin"]
    info = json.loads((folder / "zhixin.site.json").read_text())
    own = info["rsu_watch_arm"]
    verdicts = _hosting_by_approach(stdout, own)
    hosted = {combo for combo, verdict in verdicts.items() if verdict.startswith("hosted")}
    # N and S have one vehicle lane each: the straight scenarios are staged there with the occluders parked
    # at the kerb (tests/network/test_one_lane_straight.py), and the right turn.
    for arm in ("N", "S"):
        for name in ("crossing", "jaywalking", "background_blending", "right_turn"):
            assert (name, arm) in hosted, verdicts[(name, arm)]
        # The build's split phasing (tls.layout incoming) lets no oncoming vehicle move with the left turn.
        assert "never shows green to the oncoming through movement" in verdicts[("left_turn", arm)]
    assert {arm for _, arm in hosted} == {"N", "E", "S", "W"}
    out = tmp_path / "run"
    proc = _run(
        "-m", "pedsafe_sumo.batch", "--scenario", "all", "--approach", "all", "--episodes", "1",
        "--workers", "1", "--site", str(folder), "--out", str(out), timeout=600,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    for name, arm in set(verdicts) - hosted:
        assert f"skipping scenario '{name}' on approach {arm} of site zhixin: " in proc.stdout
    episodes = pd.read_parquet(out / "episodes.parquet")
    assert set(zip(episodes["scenario"], episodes["approach"], strict=True)) == hosted
    assert (episodes["status"] == "ok").all(), episodes["error"].tolist()
    for _, conditions in episodes.groupby(["scenario", "approach"])["condition"]:
        assert sorted(conditions) == ["sv", "v2i"]
    v2i = episodes[episodes["condition"] == "v2i"]
    assert (v2i["detected_by"] == "roadside").any(), v2i["detected_by"].tolist()
    # Each episode was staged on its approach: the ego's lane (from the kept case logs, where there are
    # any) is a lane of an edge entering the junction from that arm.
    net = ET.parse(folder / "zhixin.net.xml").getroot()
    edge_of_lane = {lane.get("id"): edge.get("id") for edge in net.iter("edge") for lane in edge.iter("lane")}
    for meta_path in (out / "cases").glob("*.json"):
        meta = json.loads(meta_path.read_text())
        arm = meta["setup"]["approach"]
        assert meta_path.stem.endswith(f"_{arm}")
        edge = edge_of_lane[meta["setup"]["ego"]["lane_id"]]
        assert info["approaches"][arm]["junction"] in {
            e.get("to") for e in net.iter("edge") if e.get("id") == edge
        }
