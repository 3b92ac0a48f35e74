"""The demand in real SUMO (the sumo binary): the shipped routes load and run cleanly, walking speeds and
desired speeds reach the simulation, and the validation command measures through SUMO's own detectors."""

from __future__ import annotations

import subprocess
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from pedsafe_sumo import NETWORKS_DIR, ROUTES_DIR
from pedsafe_sumo.demand import validate
from pedsafe_sumo.demand.generate import generate_demand, pedestrian_route_path, vehicle_route_path
from pedsafe_sumo.demand.validation_page import measured_markers
from pedsafe_sumo.sumo_binaries import sumo_binary

CROSS_NET = Path(__file__).parent / "data" / "cross.net.xml"
SITE_DIR = NETWORKS_DIR / "xueqing"


def test_shipped_routes_are_what_the_generator_makes_for_seed_1(tmp_path):
    generate_demand("xueqing", 3600.0, 1, tmp_path)
    for path in (vehicle_route_path, pedestrian_route_path):
        shipped = path(ROUTES_DIR, "xueqing")
        assert shipped.is_file(), (
            f"{shipped} missing: run python -m pedsafe_sumo.demand --site xueqing --out routes/"
        )
        assert shipped.read_bytes() == path(tmp_path, "xueqing").read_bytes(), f"{shipped} is stale"


@pytest.mark.slow
def test_sumo_runs_the_shipped_demand_without_errors_or_teleports(tmp_path):
    log = tmp_path / "sumo.log"
    routes = f"{vehicle_route_path(ROUTES_DIR, 'xueqing')},{pedestrian_route_path(ROUTES_DIR, 'xueqing')}"
    result = subprocess.run(
        [sumo_binary("sumo"), "-c", str(SITE_DIR / "xueqing.sumocfg"), "--route-files", routes,
         "--end", "300", "--no-step-log", "--duration-log.statistics", "--log", str(log),
         "--statistic-output", str(tmp_path / "stats.xml")],
        capture_output=True, text=True, check=False,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    text = log.read_text()
    assert "Error" not in text
    stats = ET.parse(tmp_path / "stats.xml").getroot()
    assert int(stats.find("vehicles").get("inserted")) > 100
    assert int(stats.find("persons").get("loaded")) > 10 and int(stats.find("persons").get("jammed")) == 0
    assert int(stats.find("teleports").get("total")) == 0
    assert int(stats.find("personTeleports").get("total")) == 0
    assert int(stats.find("safety").get("collisions")) == 0


def _straight_net(tmp_path: Path) -> Path:
    (tmp_path / "s.nod.xml").write_text(
        '<nodes><node id="A" x="0" y="0"/><node id="B" x="300" y="0"/></nodes>'
    )
    (tmp_path / "s.edg.xml").write_text(
        '<edges><edge id="AB" from="A" to="B" numLanes="1" speed="13.89" sidewalkWidth="2"/></edges>'
    )
    net = tmp_path / "s.net.xml"
    subprocess.run(
        [sumo_binary("netconvert"), "-n", str(tmp_path / "s.nod.xml"), "-e", str(tmp_path / "s.edg.xml"),
         "-o", str(net), "--no-warnings"],
        check=True, capture_output=True,
    )  # fmt: skip
    return net


@pytest.mark.slow
def test_sumo_walks_the_drawn_speed_and_drives_the_desired_speed(tmp_path):
    """The two mechanisms the generator relies on: walk `speed` and per-vehicle `speedFactor`.

    With the striping model's random dawdling switched off: its default (0.2) makes every pedestrian walk
    about 10% below their speed on average (a global SUMO option, not a per-person one)."""
    from pedsafe_sumo.demand.pedestrians import PED_VTYPE_ID
    from pedsafe_sumo.demand.vehicles import VTYPE_ID

    net = _straight_net(tmp_path)
    routes = tmp_path / "r.rou.xml"
    routes.write_text(
        f"""<routes>
    <vType id="{PED_VTYPE_ID}" vClass="pedestrian" speedDev="0"/>
    <vType id="{VTYPE_ID}" vClass="passenger" maxSpeed="55.56" speedDev="0" sigma="0"/>
    <vehicle id="car" type="{VTYPE_ID}" depart="0" departLane="1" departSpeed="desired" speedFactor="1.6"><route edges="AB"/></vehicle>
    <person id="p" type="{PED_VTYPE_ID}" depart="0" departPos="0"><walk from="AB" to="AB" arrivalPos="250" speed="0.873"/></person>
</routes>
"""  # noqa: E501
    )
    out = tmp_path / "tripinfo.xml"
    subprocess.run(
        [sumo_binary("sumo"), "-n", str(net), "-r", str(routes), "--tripinfo-output", str(out),
         "--step-length", "0.1", "--no-step-log", "--pedestrian.striping.dawdling", "0"],
        check=True, capture_output=True,
    )  # fmt: skip
    root = ET.parse(out).getroot()
    car = root.find("tripinfo[@id='car']")
    # 1.6 x 13.89 m/s = 22.2 m/s from the start (departSpeed desired, no dawdling).
    assert float(car.get("routeLength")) / float(car.get("duration")) == pytest.approx(1.6 * 13.89, rel=0.03)
    walk = root.find("personinfo[@id='p']/walk")
    assert float(walk.get("routeLength")) / float(walk.get("duration")) == pytest.approx(0.873, rel=0.02)


@pytest.mark.slow
def test_validation_pipeline_on_the_test_cross(tmp_path):
    """At a demand the cross carries, SUMO's mid-block speeds follow the non-intersection fit; the page and
    the ECDF figures are written."""
    light = tmp_path / "light.toml"
    light.write_text("[traffic]\nheadway_rate_per_s = 0.03\n[pedestrians]\narrival_rate_per_h = 100.0\n")
    docs = tmp_path / "docs"
    code = validate.main(
        ["--site", "cross", "--net", str(CROSS_NET), "--duration", "1200", "--warmup", "60",
         "--params", str(light), "--docs", str(docs)]
    )  # fmt: skip
    assert code == 0
    page = (docs / "demand_validation.md").read_text()
    assert measured_markers("cross")[0] in page and "speed, mid-block approach" in page
    figures = sorted(p.name for p in (docs / "figures").glob("*.png"))
    assert "demand_cross_configured_speed_midblock.png" in figures and len(figures) == 4
