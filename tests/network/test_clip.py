"""The OSM clip cuts ways exactly at the circle (hand-made data with known answers)."""

from __future__ import annotations

import math
from pathlib import Path

import osmium
import pytest

from pedsafe_sumo.network.clip import ClipError, clip_osm

LAT0, LON0 = 40.0, 116.0
M_PER_DEG_LAT = 111_035.0  # WGS84 meridian arc per degree at 40 N, to 0.1 %
M_PER_DEG_LON = 85_394.0  # WGS84 parallel arc per degree at 40 N


def _osm(tmp_path: Path) -> Path:
    """A 2 km east-west road through the centre (nodes at -1000, -10, +10, +1000 m), a 10 m building
    50 m north, and a 400 m x 1 km park whose west edge (100 m east of the centre) cuts the circle."""

    def node(nid, east_m, north_m, tags=""):
        lat = LAT0 + north_m / M_PER_DEG_LAT
        lon = LON0 + east_m / M_PER_DEG_LON
        return f'<node id="{nid}" lat="{lat:.7f}" lon="{lon:.7f}" version="1">{tags}</node>'

    nodes = [node(1, -1000, 0), node(2, -10, 0), node(3, 10, 0), node(4, 1000, 0)]
    nodes += [node(10 + i, x, y) for i, (x, y) in enumerate([(0, 50), (10, 50), (10, 60), (0, 60)])]
    nodes += [
        node(20 + i, x, y) for i, (x, y) in enumerate([(100, -500), (500, -500), (500, 500), (100, 500)])
    ]
    ways = [
        '<way id="100" version="1"><nd ref="1"/><nd ref="2"/><nd ref="3"/><nd ref="4"/>'
        '<tag k="highway" v="primary"/></way>',
        '<way id="200" version="1"><nd ref="10"/><nd ref="11"/><nd ref="12"/><nd ref="13"/><nd ref="10"/>'
        '<tag k="building" v="yes"/></way>',
        '<way id="300" version="1"><nd ref="20"/><nd ref="21"/><nd ref="22"/><nd ref="23"/><nd ref="20"/>'
        '<tag k="leisure" v="park"/></way>',
    ]
    path = tmp_path / "in.osm"
    path.write_text('<?xml version="1.0"?>\n<osm version="0.6">\n' + "\n".join(nodes + ways) + "\n</osm>\n")
    return path


def _read(path: Path):
    nodes, ways = {}, {}
    for obj in osmium.FileProcessor(str(path)):
        if obj.is_node():
            nodes[obj.id] = (obj.location.lon, obj.location.lat)
        elif obj.is_way():
            ways[obj.id] = ([n.ref for n in obj.nodes], dict(obj.tags))
    return nodes, ways


def test_road_is_cut_at_the_circle_and_small_areas_kept_whole(tmp_path):
    out = tmp_path / "out.osm"
    result = clip_osm(_osm(tmp_path), out, LAT0, LON0, 200.0)
    nodes, ways = _read(out)
    refs, tags = ways[100]
    assert tags["highway"] == "primary"
    # The far nodes (1 km out) are gone; the road now runs from a new node on the circle to another.
    assert 1 not in nodes and 4 not in nodes
    assert refs[1:3] == [2, 3] and refs[0] < 0 and refs[-1] < 0
    west_east_m = [(nodes[r][0] - LON0) * M_PER_DEG_LON for r in (refs[0], refs[-1])]
    assert west_east_m == pytest.approx([-200.0, 200.0], abs=0.5)
    assert all(abs(nodes[r][1] - LAT0) * M_PER_DEG_LAT < 0.5 for r in (refs[0], refs[-1]))
    # The building (50-60 m away) is kept whole and closed; the park reaches 707 m out: dropped.
    assert ways[200][0] == [10, 11, 12, 13, 10]
    assert 300 not in ways
    assert result.boundary_nodes == 2 and result.split_ways == 1 and result.dropped_areas == 1


def test_centre_outside_the_data_is_rejected(tmp_path):
    with pytest.raises(ClipError, match="outside the data"):
        clip_osm(_osm(tmp_path), tmp_path / "out.osm", LAT0 + 1.0, LON0, 200.0)


def test_circle_without_roads_is_rejected(tmp_path):
    # 400 m north of the road: only the park is near.
    with pytest.raises(ClipError, match="no road"):
        clip_osm(
            _osm(tmp_path),
            tmp_path / "out.osm",
            LAT0 + 400 / M_PER_DEG_LAT,
            LON0 + 300 / M_PER_DEG_LON,
            100.0,
        )
    assert not (tmp_path / "out.osm").exists()


def test_geodesy_constants_of_this_test():
    # Independent check of the metres-per-degree used above (WGS84, 40 N).
    a, e2 = 6378137.0, 6.69437999014e-3
    phi = math.radians(40.0)
    meridian = math.pi / 180 * a * (1 - e2) / (1 - e2 * math.sin(phi) ** 2) ** 1.5
    parallel = math.pi / 180 * a * math.cos(phi) / math.sqrt(1 - e2 * math.sin(phi) ** 2)
    assert meridian == pytest.approx(M_PER_DEG_LAT, rel=1e-3)
    assert parallel == pytest.approx(M_PER_DEG_LON, rel=1e-3)
