"""The onboard camera's night model (pedsafe_sumo.ncap.night): its detection range by hand, and a night
cell in real SUMO whose camera first sees the dummy inside that range while the day camera sees it farther."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))
from agents import NeverBrakes  # noqa: E402

from pedsafe_sumo.ncap.night import camera_range_m, night_params  # noqa: E402
from pedsafe_sumo.ncap.protocol import Cell, load_protocol, select_cells  # noqa: E402
from pedsafe_sumo.ncap.scoring import points_of_test  # noqa: E402
from pedsafe_sumo.ncap.staging import spec_for, stage_cell  # noqa: E402
from pedsafe_sumo.ncap.suite import NcapRunner  # noqa: E402
from pedsafe_sumo.network.sites import get_site  # noqa: E402
from pedsafe_sumo.params import load_params  # noqa: E402

PROTOCOL = load_protocol()
DAY = load_params()
NIGHT = night_params(DAY, PROTOCOL)


def test_night_camera_range_by_hand():
    # Default camera: 1280 px wide, 90 degrees: f = 640 px. Adult 1.80 m, 20 px by day: 57.6 m; the night
    # share 0.5 doubles the threshold to 40 px: 28.8 m. The miss probability is the night one.
    assert camera_range_m(DAY["perception"]["camera"], 1.8) == pytest.approx(640 * 1.8 / 20) == 57.6
    assert NIGHT["perception"]["camera"]["min_height_px"] == 40.0
    assert camera_range_m(NIGHT["perception"]["camera"], 1.8) == pytest.approx(28.8)
    assert NIGHT["perception"]["camera"]["miss_probability"] == 0.2
    # The day parameters are untouched; LiDAR and the roadside camera are the day ones.
    assert DAY["perception"]["camera"]["min_height_px"] == 20.0
    assert NIGHT["perception"]["lidar"] == DAY["perception"]["lidar"]
    assert NIGHT["perception"]["roadside_camera"] == DAY["perception"]["roadside_camera"]


def test_night_load_cases_are_the_calculators():
    from euroncap_rating_2026.crash_avoidance import data_model  # the reference, only in tests

    for name, test in PROTOCOL.tests.items():
        night = f"{name} night" in data_model.TOTAL_SCORES
        assert ("night" in test.lightings) == night
        if night:
            totals = data_model.TOTAL_SCORES[f"{name} night"]
            assert (totals["Standard"], totals["Extended"]) == (test.points_standard, test.points_extended)
            assert (
                data_model.EXTENDED_RANGE_CELLS[f"{name} night"]
                == data_model.EXTENDED_RANGE_CELLS[f"{name} day"]
            )
    cells = select_cells(PROTOCOL, "CPNA-50,CPTAsame-50", (10.0,), lightings=("night",))
    # CPTA has no night load case: only CPNA's night cell.
    assert [c.cell_id for c in cells] == ["CPNA-50_10kmh_night"]
    assert points_of_test(0.5, 0.0625, [("standard", 1.0)])["points"] == 0.5


def _first_camera_depth_m(runner, cell: Cell) -> float:
    """The distance along the ego's heading from its camera to the dummy at the first camera detection."""
    staged = stage_cell(PROTOCOL, runner.approach, runner.site.file("net.xml"), cell, 0, runner.step_length_s)
    spec = spec_for(cell, tuple(runner.roadside_units), staged.setup.time_limit_s)
    log = runner.run(spec, "sv", 0, setup=staged.setup).log
    row = log[log["detected_onboard_camera"]].iloc[0]
    forward_m = DAY["perception"]["camera"]["forward_offset_m"]
    cos_yaw, sin_yaw = math.cos(row["ego_yaw_rad"]), math.sin(row["ego_yaw_rad"])
    camera_x, camera_y = row["ego_x_m"] + forward_m * cos_yaw, row["ego_y_m"] + forward_m * sin_yaw
    return (row["ped_x_m"] - camera_x) * cos_yaw + (row["ped_y_m"] - camera_y) * sin_yaw


@pytest.mark.slow
def test_a_night_cell_is_seen_inside_the_night_range():
    # CPLA-50 at 60 km/h: the adult walks ahead in the lane, in view from the start (61 m ahead).
    test = PROTOCOL.tests["CPLA"]
    site = get_site("xueqing")
    depths = {}
    for lighting, params in (("day", DAY), ("night", NIGHT)):
        runner = NcapRunner(site, params, NeverBrakes)
        try:
            depths[lighting] = _first_camera_depth_m(runner, Cell(test, 60.0, 50.0, lighting=lighting))
        finally:
            runner.close()
    # Night: no farther than 28.8 m (+ one step of closing, 55 km/h x 0.05 s = 0.76 m, and the sample
    # height's share of the dummy); day: beyond the night range, within 57.6 m.
    assert depths["night"] <= 28.8 + 0.8
    # ... and not much nearer: a frame missed at night (p = 0.2) costs 0.76 m; six in a row, 4.6 m, have
    # a chance of 0.2**6 = 6e-5 (the seed is fixed: the run is the same every time).
    assert depths["night"] > 28.8 - 4.6
    assert 28.8 < depths["day"] <= 57.6 + 0.8
