"""Route generation on a small checked-in cross (tests/demand/data/cross.net.xml): determinism, per-lane
headways, movements, pedestrian attributes, and the CLI's handling of bad input."""

from __future__ import annotations

import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

from pedsafe_sumo import REPO_ROOT
from pedsafe_sumo.demand.generate import generate_demand
from pedsafe_sumo.demand.routes_xml import ODBL_ATTRIBUTION
from pedsafe_sumo.demand.site import load_site

CROSS_NET = Path(__file__).parent / "data" / "cross.net.xml"


def _generate(out: Path, seed: int, duration_s: float = 3600.0, params: Path | None = None):
    return generate_demand("cross", duration_s, seed, out, params, net_file=CROSS_NET)


def test_same_seed_identical_files_other_seed_different(tmp_path):
    a = _generate(tmp_path / "a", seed=1, duration_s=600)
    b = _generate(tmp_path / "b", seed=1, duration_s=600)
    c = _generate(tmp_path / "c", seed=2, duration_s=600)
    for attr in ("vehicles_file", "pedestrians_file"):
        assert getattr(a, attr).read_bytes() == getattr(b, attr).read_bytes()
        assert getattr(a, attr).read_bytes() != getattr(c, attr).read_bytes()


def test_site_analysis_finds_every_entering_lane_and_movement():
    site = load_site("cross", net_file=CROSS_NET)
    # Two-lane main road N-S, one-lane side road E-W: 2 + 2 + 1 + 1 entering lanes, sidewalks excluded.
    assert sorted(lane.lane_id for lane in site.entering_lanes) == [
        "E2C_1",
        "N2C_1",
        "N2C_2",
        "S2C_1",
        "S2C_2",
        "W2C_1",
    ]
    by_lane = {lane.lane_id: lane.routes_by_movement for lane in site.entering_lanes}
    # Driving on the right, from the north: straight goes south, left goes east, right goes west.
    assert [r.edges for r in by_lane["N2C_2"]["left"]] == [("N2C", "C2E")]
    assert [r.edges for r in by_lane["N2C_1"]["right"]] == [("N2C", "C2W")]
    assert [r.edges for r in by_lane["W2C_1"]["straight"]] == [("W2C", "C2E")]
    # No lane is offered a movement it has no connection for (right from the median lane, left from the kerb).
    assert "right" not in by_lane["N2C_2"] and "left" not in by_lane["N2C_1"]
    # Pedestrian ends: every arm, both sides of the road.
    assert len({end.fringe_node for end in site.pedestrian_ends}) == 4


def _vehicles(path: Path):
    return list(ET.parse(path).getroot().iter("vehicle"))


def test_vehicle_headways_per_lane_are_exponential_and_speeds_lognormal(tmp_path):
    files = _generate(tmp_path, seed=11)
    vehicles = _vehicles(files.vehicles_file)
    routes = {
        r.get("id"): r.get("edges").split() for r in ET.parse(files.vehicles_file).getroot().iter("route")
    }
    departs_by_lane: dict[str, list[float]] = {}
    speeds = []
    for v in vehicles:
        lane = f"{routes[v.get('route')][0]}_{v.get('departLane')}"
        departs_by_lane.setdefault(lane, []).append(float(v.get("depart")))
        speed = float(v.find("param[@key='desired_speed_mps']").get("value"))
        # The desired speed reaches SUMO as speedFactor on the lane's 13.89 m/s limit.
        assert float(v.get("speedFactor")) == pytest.approx(speed / 13.89, abs=1e-4)
        speeds.append(speed)
    assert len(departs_by_lane) == 6
    headways = np.concatenate([np.diff(sorted(d)) for d in departs_by_lane.values()])
    # Departures are written with 0.01 s resolution; the KS test is insensitive to that.
    assert stats.kstest(headways, stats.expon(scale=1 / 0.1742).cdf).pvalue > 0.01
    # The fit was measured at 16.67 m/s (traffic.fit_speed_limit_mps): on 13.89 m/s lanes every draw is
    # scaled by 13.89 / 16.67 (traffic.background_speed_limit_scaled), the lognormal's
    # median with it.
    scaled = stats.lognorm(s=0.4857, scale=np.exp(1.8304) * 13.89 / 16.67)
    assert stats.kstest(speeds, scaled.cdf).pvalue > 0.01
    departs = [float(v.get("depart")) for v in vehicles]
    assert departs == sorted(departs)  # SUMO needs route files sorted by departure


def test_all_movements_present_and_shares_configurable(tmp_path):
    files = _generate(tmp_path / "default", seed=3)
    movements = [v.find("param[@key='movement']").get("value") for v in _vehicles(files.vehicles_file)]
    assert set(movements) == {"left", "straight", "right"}
    only_straight = tmp_path / "straight.toml"
    only_straight.write_text(
        "[traffic]\nturn_share_left = 0.0\nturn_share_straight = 1.0\nturn_share_right = 0.0\n"
    )
    files = _generate(tmp_path / "straight", seed=3, params=only_straight)
    assert files.movement_shares["straight"] == 1.0


def test_pedestrians_carry_their_attributes_and_walk_at_their_speed(tmp_path):
    files = _generate(tmp_path, seed=5)
    persons = list(ET.parse(files.pedestrians_file).getroot().iter("person"))
    assert 200 < len(persons) < 400  # 300 per hour by default
    groups = set()
    for person in persons:
        params = {p.get("key"): p.get("value") for p in person.iter("param")}
        assert set(params) == {"ped_age_years", "ped_age_group", "ped_gender", "ped_risk", "ped_speed_mps"}
        assert 13 <= int(params["ped_age_years"]) <= 85
        assert params["ped_gender"] in {"f", "m"} and params["ped_risk"] in {"unaware", "hasten", "yield"}
        walk = person.find("walk")
        assert walk.get("speed") == params["ped_speed_mps"]
        assert walk.get("from") != walk.get("to")
        groups.add(params["ped_age_group"])
    assert groups == {"age_13_18", "age_19_30", "age_31_60", "over_60"}


def test_route_files_carry_the_odbl_attribution_and_provenance(tmp_path):
    files = _generate(tmp_path, seed=9, duration_s=60)
    for path in (files.vehicles_file, files.pedestrians_file):
        head = path.read_text(encoding="utf-8")[:600]
        assert ODBL_ATTRIBUTION in head and "seed=9" in head


def _cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "pedsafe_sumo.demand", *args], capture_output=True, text=True, cwd=REPO_ROOT
    )


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--site", "atlantis"], "unknown site 'atlantis'"),
        (["--site", "cross", "--net", "does/not/exist.net.xml"], "cannot read network"),
        (["--site", "cross", "--duration", "-5"], "duration must be > 0"),
    ],
)
def test_cli_bad_input_is_one_line_and_exit_2(tmp_path, args, message):
    if "--net" not in args and args[1] == "cross":
        args = [*args, "--net", str(CROSS_NET)]
    result = _cli(*args, "--out", str(tmp_path))
    assert result.returncode == 2
    assert message in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1 and "Traceback" not in result.stderr


def test_cli_bad_params_file_is_rejected(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("[traffic]\nheadway_rate_per_s = -1\n")
    result = _cli("--site", "cross", "--net", str(CROSS_NET), "--params", str(bad), "--out", str(tmp_path))
    assert result.returncode == 2
    assert result.stderr.strip() == (
        "pedsafe_sumo.demand: error: parameter 'traffic.headway_rate_per_s' must be > 0, got -1.0"
    )
    assert not (tmp_path / "cross.vehicles.rou.xml").exists()


def test_cli_writes_both_files_and_says_so(tmp_path):
    result = _cli(
        "--site", "cross", "--net", str(CROSS_NET), "--duration", "300", "--seed", "4", "--out", str(tmp_path)
    )
    assert result.returncode == 0, result.stderr
    assert "vehicles" in result.stdout and "pedestrians" in result.stdout
    assert (tmp_path / "cross.vehicles.rou.xml").is_file() and (
        tmp_path / "cross.pedestrians.rou.xml"
    ).is_file()
