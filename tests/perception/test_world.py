"""Loading static occluders from a polyconvert .poly.xml and roadside units from an additional file."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from pedsafe_sumo.perception import load_roadside_units, load_static_occluders

POLY_XML = """<?xml version="1.0" encoding="UTF-8"?>
<additional>
    <poly id="b_height" type="building" color="255,230,230" fill="1" layer="-1.00"
          shape="0.00,0.00 10.00,0.00 10.00,8.00 0.00,8.00 0.00,0.00">
        <param key="height" value="21.5 m"/>
    </poly>
    <poly id="b_levels" type="building.residential" color="200,100,100" fill="1"
          shape="20.00,0.00 30.00,0.00 30.00,8.00 20.00,8.00">
        <param key="building:levels" value="6"/>
    </poly>
    <poly id="b_bare" type="building.yes" color="0.5,0.5,0.5" fill="1" shape="40,0 50,0 50,8 40,8 40,0"/>
    <poly id="park" type="leisure.park" color="0,255,0" fill="1" shape="0,20 50,20 50,40 0,40 0,20"/>
    <poly id="wood" type="natural.wood" color="0,128,0" fill="1" shape="60,0 80,0 80,20 60,20 60,0"/>
    <poly id="row" type="natural.tree_row" fill="0" shape="0,50 16,50"/>
    <poi id="t1" type="natural.tree" color="0,100,0" layer="1" x="100.0" y="5.0"/>
    <poi id="t2" type="natural.tree" x="110.0" y="5.0"><param key="height" value="12"/></poi>
    <poi id="bench" type="amenity.bench" x="120.0" y="5.0"/>
</additional>
"""


@pytest.fixture
def occluder_params(params):
    return params["perception"]["occluders"]


def test_poly_loader_heights_kinds_and_trees(tmp_path, occluder_params):
    path = tmp_path / "site.poly.xml"
    path.write_text(POLY_XML)
    st = load_static_occluders(path, occluder_params)
    assert st.poly_ids == ("b_height", "b_levels", "b_bare", "wood")
    assert st.poly_kinds == ("building", "building", "building", "canopy")
    tops = {pid: float(st.z_top_m[st.edge_poly == i][0]) for i, pid in enumerate(st.poly_ids)}
    # height param 21.5 m; 6 levels x 3 m = 18 m; default 12 m; canopy block 2.5..8 m.
    assert tops == {"b_height": 21.5, "b_levels": 18.0, "b_bare": 12.0, "wood": 8.0}
    assert float(st.z_base_m[st.edge_poly == 3][0]) == 2.5
    # Four walls each (closing point dropped, open ring closed).
    assert np.bincount(st.edge_poly).tolist() == [4, 4, 4, 4]
    # Colours: "255,230,230" as is; "0.5,0.5,0.5" read as fractions.
    assert st.poly_rgb[0] == pytest.approx([255, 230, 230])
    assert st.poly_rgb[2] == pytest.approx([127.5, 127.5, 127.5])
    # Trees: a 16 m row at 8 m spacing gives 3 trees, plus 2 POIs; each is trunk + crown.
    assert st.n_cylinders == 2 * 5
    crowns = st.cyl_radius_m == occluder_params["tree_crown_radius_m"]
    assert sorted(st.cyl_z1_m[crowns].tolist()) == [8.0, 8.0, 8.0, 8.0, 12.0]


def test_edge_grid_query_returns_exactly_the_overlapping_edges(tmp_path, occluder_params):
    path = tmp_path / "site.poly.xml"
    path.write_text(POLY_XML)
    st = load_static_occluders(path, occluder_params)
    got = set(st.edges_in_box(9.0, -1.0, 21.0, 1.0).tolist())
    xmin, xmax = np.minimum(st.ax, st.bx), np.maximum(st.ax, st.bx)
    ymin, ymax = np.minimum(st.ay, st.by), np.maximum(st.ay, st.by)
    brute = set(np.nonzero((xmin <= 21) & (xmax >= 9) & (ymin <= 1) & (ymax >= -1))[0].tolist())
    assert (
        got == brute and len(got) == 4
    )  # right wall and bottom of b_height, left wall and bottom of b_levels


def test_poly_loader_rejects_lon_lat_and_broken_files(tmp_path, occluder_params):
    bad = tmp_path / "geo.poly.xml"
    bad.write_text('<additional><poly id="g" type="building" geo="1" shape="116,39 117,40"/></additional>')
    with pytest.raises(ValueError, match="lon/lat"):
        load_static_occluders(bad, occluder_params)
    broken = tmp_path / "broken.poly.xml"
    broken.write_text("<additional><poly")
    with pytest.raises(ValueError, match="cannot read"):
        load_static_occluders(broken, occluder_params)


def test_roadside_unit_loader(tmp_path):
    path = tmp_path / "site.rsu.add.xml"
    path.write_text(
        """<additional>
        <poi id="rsu_camera_0" type="roadside_camera" x="12.5" y="-3.0" color="blue">
            <param key="height_m" value="6.5"/><param key="yaw_deg" value="90"/>
            <param key="pitch_deg" value="25"/>
        </poi>
        <poi id="rsu_camera_1" type="roadside_camera" x="0" y="0" angle="180"/>
        <poi id="other" type="bench" x="1" y="1"/>
        </additional>"""
    )
    units = load_roadside_units(path, default_height_m=6.0, default_pitch_down_deg=20.0)
    assert [u.id for u in units] == ["rsu_camera_0", "rsu_camera_1"]
    u0, u1 = units
    assert (u0.x_m, u0.y_m, u0.height_m) == (12.5, -3.0, 6.5)
    assert u0.yaw_rad == pytest.approx(0.0)  # SUMO 90 deg = east
    assert u0.pitch_down_rad == pytest.approx(math.radians(25))
    assert u1.yaw_rad == pytest.approx(-math.pi / 2)  # angle 180 = south
    assert (u1.height_m, u1.pitch_down_rad) == (6.0, pytest.approx(math.radians(20)))


def test_xueqing_site_occluders_and_roadside_unit(params):
    from pedsafe_sumo import NETWORKS_DIR

    site = NETWORKS_DIR / "xueqing"
    if not (site / "xueqing.poly.xml").exists():
        pytest.skip("Xueqing network not built")
    p = params["perception"]
    st = load_static_occluders(site / "xueqing.poly.xml", p["occluders"])
    assert len(st.poly_ids) >= 20 and set(st.poly_kinds) == {"building"}
    assert np.all(st.z_top_m > 0)
    units = load_roadside_units(site / "xueqing.rsu.add.xml", 6.0, 20.0)
    all_facts = json.loads((site / "xueqing.site.json").read_text())["roadside_units"]
    # The site's own approach keeps rsu_camera_0/1; every other approach has its pair named after its arm.
    other_arms = ("E", "S", "W")
    expected = ["rsu_camera_0", "rsu_camera_1"] + [
        f"rsu_camera_{k}_{arm}" for arm in other_arms for k in (0, 1)
    ]
    assert [u.id for u in units] == [f["id"] for f in all_facts] == expected
    for unit, facts in zip(units, all_facts):
        assert unit.height_m == facts["height_m"]
        assert (unit.x_m, unit.y_m) == (facts["x"], facts["y"])
        # yaw_deg is SUMO's (clockwise from north): yaw = 90 - yaw_deg counter-clockwise from east.
        assert math.degrees(unit.yaw_rad) == pytest.approx(90.0 - facts["yaw_deg"])
        assert math.degrees(unit.pitch_down_rad) == pytest.approx(facts["pitch_deg"])
