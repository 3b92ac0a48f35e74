"""python -m pedsafe_sumo.conflicts on hand-built FCD files whose measures are worked out by hand.

The encounters (tests/conflicts/fcd_files.py): a 4 m x 2 m car drives east along y = 0 at 10 m/s, centre
x = 10 t. People have radius 0.25 m.

The walker, at x = 20 m, walks north at 1 m/s from y = -2.5 m at t = 0, stands at y = -2 m while the car
passes (t = 0.5 to 2.0 s) and walks on from t = 2.5 s, reaching y = 0 at t = 4.5 s. By hand:
- TTC at t = 0: relative position (20, -2.5), relative velocity (-10, 1). The circle's centre reaches the
  grown box's front face x = 2 + 0.25 after (20 - 2.25) / 10 = 1.775 s, when y = -2.5 + 1.775 = -0.725,
  inside |y| <= 1: TTC = 1.775 s. At every later step the walker stands off the car's lane or is behind
  it: no collision course. So min TTC = 1.775 s at t = 0, and DRAC = 10 / (2 * 1.775) = 2.8169 m/s2.
- Minimum clearance: at t = 2.0 s the car's centre is at x = 20, the walker 2 m to its right: 2 - 1 (half
  width) - 0.25 = 0.75 m, at the walker's position (20, -2).
- PET: the paths cross at (20, 0). The car covers the point while its centre is within 2 m of it, until
  t = 2.2 s; the walker's circle reaches it at y = -0.25, t = 4.25 s: PET = 4.25 - 2.2 = 2.05 s.
- Amini at t = 0: the paths cross at (20, 0), 2.0 s ahead for the car and 2.5 s for the walker
  (difference 0.5 <= 3 s: a candidate). MD = |dp x dv| / |dv| = |20 * 1 - 2.5 * 10| / sqrt(101) = 0.49752,
  TMD = -(dp.dv) / |dv|^2 = 202.5 / 101 = 2.00495 s, CS = 10 m/s,
  p = sigmoid(4.327 - 2.898 MD - 3.067 TMD + 0.376 * 10) = 0.62152 >= 0.425: a conflict at t = 0.
- SSM fields: the only step with a TTC is t = 0, so minTTC and maxDRAC are both at t = 0, at the walker's
  position (20, -2.5), car speed 10 m/s. The car's centre is nearest the path crossing (20, 0) at t = 2.0 s,
  the walker at t = 4.5 s: the car is first, SUMO's type 10 (CROSSING_LEADER). The PET's time is the
  step the second one (the walker) is there, t = 4.5 s, car speed 10 m/s, type 17 (BOTH_LEFT_CONFLICT_AREA).

The stander stands at (40, 0) on the car's path: contact when the front face reaches 39.75 m (centre
37.75 m, t = 3.775 s), first logged at t = 4.0 s (clearance -1 - 0.25 = -1.25 m). TTC at t = 3.5 s is
(5 - 2.25) / 10 = 0.275 s, so DRAC = 10 / 0.55 = 18.18 m/s2 (its largest, at t = 3.5 s, the stander at
(40, 0)); TTC 0 at the contact step; PET 0 at the contact, t = 4.0 s, at (40, 0); no conflict (a standing
pedestrian has no path). The paths never cross (the stander does not move): type 2 (FOLLOWING_FOLLOWER).
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET

import pandas as pd
import pytest
import sumolib.xml
from fcd_files import TYPES_XML, stander, walker, write_fcd

from pedsafe_sumo.conflicts.__main__ import main
from pedsafe_sumo.conflicts.row import ROW_COLUMNS


def sigmoid(z: float) -> float:
    return 1.0 / (1.0 + math.exp(-z))


@pytest.fixture
def scene(tmp_path):
    fcd = write_fcd(tmp_path / "scene.fcd.xml", 11, [("walker", walker), ("stander", stander)])
    types = tmp_path / "types.xml"
    types.write_text(TYPES_XML)
    return fcd, types


def run(*args) -> int:
    return main([str(a) for a in (*args, "--quiet")])


def test_crossing_walker_by_hand(scene, tmp_path):
    fcd, types = scene
    out = tmp_path / "out.csv"
    assert run(fcd, "--out", out, "--types", types) == 0
    table = pd.read_csv(out, keep_default_na=False, na_values=[""])
    assert list(table.columns) == list(ROW_COLUMNS)
    row = table.set_index("person_id").loc["walker"]
    assert row["vehicle_id"] == "car" and row["begin_s"] == 0.0 and row["end_s"] == 5.0
    assert row["ttc_s"] == pytest.approx(1.775, abs=1e-9) and row["ttc_time_s"] == 0.0
    assert row["drac_mps2"] == pytest.approx(10 / (2 * 1.775), abs=1e-9)
    assert row["min_clearance_m"] == pytest.approx(0.75, abs=1e-9)
    assert (row["time_s"], row["x_m"], row["y_m"]) == (2.0, 20.0, -2.0)
    assert row["vehicle_speed_mps"] == 10.0 and row["person_speed_mps"] == 0.0
    assert row["pet_s"] == pytest.approx(2.05, abs=1e-9)
    assert (row["pet_x_m"], row["pet_y_m"]) == pytest.approx((20.0, 0.0), abs=1e-9)
    md, tmd = 5 / math.sqrt(101), 202.5 / 101
    assert row["md_m"] == pytest.approx(md, abs=1e-9) and row["tmd_s"] == pytest.approx(tmd, abs=1e-9)
    assert row["cs_mps"] == 10.0
    p = sigmoid(4.327 - 2.898 * md - 3.067 * tmd + 0.376 * 10)
    assert row["conflict_probability"] == pytest.approx(p, abs=1e-9) and p == pytest.approx(0.6215, abs=1e-4)
    assert bool(row["conflict"]) and row["conflict_time_s"] == 0.0 and not bool(row["collision"])
    assert (row["vehicle_lane"], row["person_edge"]) == ("road_0", "walk")


def test_standing_pedestrian_hit_by_hand(scene, tmp_path):
    fcd, types = scene
    out = tmp_path / "out.parquet"
    assert run(fcd, "--out", out, "--types", types) == 0
    row = pd.read_parquet(out).set_index("person_id").loc["stander"]
    assert bool(row["collision"]) and row["contact_time_s"] == 4.0
    assert row["min_clearance_m"] == pytest.approx(-1.25, abs=1e-9)
    assert row["ttc_s"] == 0.0 and row["ttc_time_s"] == 4.0
    assert row["drac_mps2"] == pytest.approx(10 / (2 * 0.275), abs=1e-9)
    assert row["pet_s"] == 0.0
    assert not bool(row["conflict"]) and math.isnan(row["md_m"])


def test_ssm_xml_holds_the_same_measures(scene, tmp_path):
    fcd, types = scene
    ssm = tmp_path / "out.ssm.xml"
    assert run(fcd, "--out", tmp_path / "out.csv", "--types", types, "--ssm", ssm) == 0
    conflicts = {c.get("foe"): c for c in ET.parse(ssm).getroot().iter("conflict")}
    walker_c = conflicts["walker"]
    assert walker_c.get("ego") == "car" and walker_c.get("begin") == "0.00" and walker_c.get("end") == "5.00"
    assert walker_c.find("minTTC").get("value") == "1.77"  # 1.775 written with two decimals, as SUMO does
    assert walker_c.find("minTTC").get("position") == "20.00,-2.50"
    assert walker_c.find("PET").get("value") == "2.05"
    assert walker_c.find("PET").get("position") == "20.00,0.00"
    assert walker_c.find("maxDRAC").get("value") == "2.82"
    assert walker_c.find("amini").get("conflict") == "true"
    assert conflicts["stander"].find("minClearance").get("collision") == "true"


#: The attributes SUMO's SSM device documents on each measure element of a <conflict>.
SSM_MEASURE_ATTRIBUTES = ("time", "position", "type", "value", "speed")


def test_ssm_xml_reads_as_sumos_ssm_output(scene, tmp_path):
    """Read the way a script written for SUMO's SSM device reads its output: sumolib.xml.parse on
    'conflict', every documented attribute of minTTC, maxDRAC and PET, values worked out above."""
    fcd, types = scene
    ssm = tmp_path / "out.ssm.xml"
    assert run(fcd, "--out", tmp_path / "out.csv", "--types", types, "--ssm", ssm) == 0
    read = {}
    for conflict in sumolib.xml.parse(str(ssm), "conflict"):
        measures = {}
        for tag in ("minTTC", "maxDRAC", "PET"):
            element = getattr(conflict, tag)[0]
            measures[tag] = {name: element.getAttribute(name) for name in SSM_MEASURE_ATTRIBUTES}
        read[conflict.foe] = (conflict.begin, conflict.end, conflict.ego, measures)
    begin, end, ego, walker_m = read["walker"]
    assert (begin, end, ego) == ("0.00", "5.00", "car")
    assert walker_m["minTTC"] == {
        "time": "0.00",
        "position": "20.00,-2.50",
        "type": "10",
        "value": "1.77",
        "speed": "10.00",
    }
    assert walker_m["maxDRAC"] == {
        "time": "0.00",
        "position": "20.00,-2.50",
        "type": "10",
        "value": f"{10 / 3.55:.2f}",
        "speed": "10.00",
    }
    assert walker_m["PET"] == {
        "time": "4.50",
        "position": "20.00,0.00",
        "type": "17",
        "value": "2.05",
        "speed": "10.00",
    }
    _, _, _, stander_m = read["stander"]
    assert stander_m["minTTC"] == {
        "time": "4.00",
        "position": "40.00,0.00",
        "type": "2",
        "value": "0.00",
        "speed": "10.00",
    }
    assert stander_m["maxDRAC"] == {
        "time": "3.50",
        "position": "40.00,0.00",
        "type": "2",
        "value": f"{10 / 0.55:.2f}",
        "speed": "10.00",
    }
    assert stander_m["PET"] == {
        "time": "4.00",
        "position": "40.00,0.00",
        "type": "17",
        "value": "0.00",
        "speed": "10.00",
    }
    # the numbers as a script would convert them
    assert float(walker_m["maxDRAC"]["value"]) == pytest.approx(2.82, abs=1e-9)
    assert int(stander_m["PET"]["type"]) == 17


def test_sizes_from_element_attributes_and_defaults(tmp_path):
    """Without types the car is SUMO's default passenger car (5 m x 1.8 m) and the walker 0.48 m wide: the
    centre is 2.5 m behind the FCD position, at x = 19.5 m at t = 2 s, and the clearance to the walker at
    (20, -2) is 2 - 0.9 - 0.24 = 0.86 m (TTC at t = 0: (20.5 - 2.5 - 0.24) / 10 = 1.776 s). `length` and
    `width` attributes on the car's element (--fcd-output.params) make it 4 m x 2 m: centre at x = 20 m at
    t = 2 s, clearance 2 - 1 - 0.24 = 0.76 m."""
    fcd = write_fcd(tmp_path / "a.fcd.xml", 11, [("walker", walker)])
    out = tmp_path / "a.csv"
    assert run(fcd, "--out", out) == 0
    row = pd.read_csv(out).iloc[0]
    assert row["min_clearance_m"] == pytest.approx(0.86, abs=1e-9) and row["time_s"] == 2.0
    assert row["ttc_s"] == pytest.approx(1.776, abs=1e-9)
    fcd = write_fcd(tmp_path / "b.fcd.xml", 11, [("walker", walker)], car_attrs=' length="4" width="2"')
    assert run(fcd, "--out", out) == 0
    assert pd.read_csv(out)["min_clearance_m"].iloc[0] == pytest.approx(0.76, abs=1e-9)


def test_an_interaction_ends_when_the_pair_parts(tmp_path):
    """With a 20 m radius, a person near the car, then 60 m away, then near again: two interactions."""

    def leaper(t):
        if t <= 1.0:
            return 5.0, -2.0, 0.0, 0.0
        if t <= 2.0:
            return 5.0, -60.0, 0.0, 0.0
        return 30.0, -2.0, 0.0, 0.0

    fcd = write_fcd(
        tmp_path / "l.fcd.xml", 11, [("leaper", leaper), ("far", lambda t: (20.0, 100.0, 0.0, 0.0))]
    )
    out = tmp_path / "l.csv"
    assert run(fcd, "--out", out, "--radius", "20") == 0
    table = pd.read_csv(out)
    assert list(table["person_id"]) == ["leaper", "leaper"]
    assert list(zip(table["begin_s"], table["end_s"])) == [(0.0, 1.0), (2.5, 5.0)]


def test_bad_input_one_line_exit_2_and_earlier_output_kept(scene, tmp_path, capsys):
    fcd, types = scene
    out = tmp_path / "keep.csv"
    out.write_text("earlier result\n")
    broken = tmp_path / "broken.fcd.xml"
    broken.write_text(fcd.read_text()[:-200])  # cut inside the last timesteps
    not_fcd = tmp_path / "routes.xml"
    not_fcd.write_text(TYPES_XML)
    no_xy = tmp_path / "geo.fcd.xml"
    no_xy.write_text(
        '<fcd-export><timestep time="0"><vehicle id="v" lon="1" lat="2" angle="0"/></timestep></fcd-export>'
    )
    negative = tmp_path / "negative.toml"
    negative.write_text("[conflicts]\nvehicle_length_m = -1\n")
    typo = tmp_path / "typo.toml"
    typo.write_text("[conflicts]\nvehicle_lenth_m = 5\n")
    cases = [
        ([tmp_path / "missing.xml", "--out", out], "not found"),
        ([fcd, "--out", out, "--params", negative], "conflicts.vehicle_length_m must be a positive number"),
        ([fcd, "--out", out, "--params", typo], "unknown parameter 'conflicts.vehicle_lenth_m'"),
        ([broken, "--out", out], "not well-formed"),
        ([not_fcd, "--out", out], "not SUMO FCD"),
        ([no_xy, "--out", out], "no 'x' attribute"),
        ([fcd, "--out", tmp_path / "x.txt"], ".csv or .parquet"),
        ([fcd, "--out", out, "--radius", "-1"], "--radius"),
        ([fcd, "--out", out, "--types", tmp_path / "nope.xml"], "types file not found"),
        ([fcd, "--out", out, "--net", tmp_path / "nope.net.xml"], "network file not found"),
        ([fcd, "--out", out, "--site", tmp_path / "nosite"], "nosite"),
        ([fcd, "--out", out, "--site", "xueqing", "--net", tmp_path / "a.net.xml"], "not both"),
    ]
    for args, words in cases:
        assert run(*args) == 2, args
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and err.startswith("error: ") and words in err, err
        assert out.read_text() == "earlier result\n"
        assert not out.with_name(out.name + ".tmp").exists()
