"""The SSM and FCD XML writers (ElementTree) against the files SUMO's layout prescribes, written out by
hand here: both parse to the same elements, attributes (names, order, values) and comments, and sumolib's
fast parser, which reads by regular expression, finds the same records."""

from __future__ import annotations

import math
from xml.etree import ElementTree

import sumolib.xml

from pedsafe_sumo.conflicts.output import SsmWriter
from pedsafe_sumo.conflicts.row import BOOL_COLUMNS, ROW_COLUMNS, STRING_COLUMNS
from pedsafe_sumo.replay.fcd import PersonState, Timestep, VehicleState, write_fcd

OSM = (
    "Map data (c) OpenStreetMap contributors, licensed under the Open Database License (ODbL) 1.0, "
    "https://www.openstreetmap.org/copyright"
)
EXPECTED_FCD = f"""<?xml version="1.0" encoding="UTF-8"?>
<!-- replay of - - a case -->
<!-- {OSM} -->
<fcd-export xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance" xsi:noNamespaceSchemaLocation="http://sumo.dlr.de/xsd/fcd_file.xsd">
    <timestep time="0.00">
        <vehicle id="ego" x="1.000000" y="2.500000" angle="90.000000" type="car&lt;1&gt;" speed="8.330000" pos="10.000000" lane="e_0" slope="0.000000"/>
    </timestep>
    <timestep time="0.05">
        <vehicle id="bg&amp;1" x="-3.000000" y="4.000000" angle="270.123457" type="bus" speed="0.000000" pos="1.000000" lane="f_1" slope="0.500000"/>
        <person id="ped" x="5.000000" y="6.000000" angle="180.000000" type="DEFAULT_PEDTYPE" speed="1.300000" pos="2.000000" edge=":j_w0" slope="0.000000"/>
    </timestep>
    <timestep time="0.123000">
    </timestep>
</fcd-export>
"""  # noqa: E501

EXPECTED_SSM = """<?xml version="1.0" encoding="UTF-8"?>
<!-- pedsafe_sumo.conflicts: pedestrian-vehicle interactions (docs/conflicts.md) -->
<SSMLog>
    <conflict begin="1.00" end="NA" ego="car&lt;&amp;&quot;'" foe="ped" egoType="passenger" foeType="DEFAULT_PEDTYPE">
        <minTTC time="1.50" position="10.00,-2.25" type="11" value="0.80" speed="3.00"/>
        <maxDRAC time="1.00" position="9.00,-2.50" type="11" value="5.25" speed="4.00"/>
        <PET time="NA" position="NA" type="NA" value="NA" speed="NA"/>
        <minClearance time="2.00" position="11.00,-2.00" value="0.125" collision="true" geometryArtefact="false"/>
        <amini time="NA" md="NA" tmd="0.300" cs="4.000" probability="0.1235" conflict="false" uncertain="false"/>
    </conflict>
</SSMLog>
"""  # noqa: E501


def _shape(element: ElementTree.Element) -> list:
    """Tag, attributes in order, and children, recursively (text and tails are layout only)."""
    return [str(element.tag), list(element.attrib.items()), [_shape(child) for child in element]]


def _comments(text: str) -> list[str]:
    parser = ElementTree.XMLParser(target=ElementTree.TreeBuilder(insert_comments=True))
    parser.feed(text)
    return [c.text for c in parser.close().iter() if c.tag is ElementTree.Comment] + [
        line for line in text.splitlines() if line.startswith("<!--")
    ]


def test_fcd_writer_gives_the_file_of_sumos_layout(tmp_path):
    steps = [
        Timestep(0.0, (VehicleState("ego", 1.0, 2.5, 90.0, "car<1>", 8.33, 10.0, "e_0", 0.0),), ()),
        Timestep(
            0.05,
            (VehicleState("bg&1", -3.0, 4.0, 270.123456789, "bus", 0.0, 1.0, "f_1", 0.5),),
            (PersonState("ped", 5.0, 6.0, 180.0, "DEFAULT_PEDTYPE", 1.3, 2.0, ":j_w0", 0.0),),
        ),
        Timestep(0.123, (), ()),
    ]
    path = write_fcd(tmp_path / "case.fcd.xml", steps, comment="replay of -- a case")
    written = path.read_text(encoding="utf-8")
    assert _shape(ElementTree.fromstring(written.encode())) == _shape(
        ElementTree.fromstring(EXPECTED_FCD.encode())
    )
    assert _comments(written) == _comments(EXPECTED_FCD)
    assert written.startswith('<?xml version="1.0" encoding="UTF-8"?>\n')
    expected_path = tmp_path / "expected.fcd.xml"
    expected_path.write_text(EXPECTED_FCD, encoding="utf-8")
    for element in ("vehicle", "person"):
        records = [
            (step.time, record.id, record.x)
            for step, record in sumolib.xml.parse_fast_nested(
                str(path), "timestep", ["time"], element, ["id", "x"]
            )
        ]
        assert records == [
            (step.time, record.id, record.x)
            for step, record in sumolib.xml.parse_fast_nested(
                str(expected_path), "timestep", ["time"], element, ["id", "x"]
            )
        ]
        assert records  # the comparison compared something


def _row(**values) -> dict:
    row = {
        name: ("" if name in STRING_COLUMNS else False if name in BOOL_COLUMNS else math.nan)
        for name in ROW_COLUMNS
    }
    row.update(values)
    return row


def test_ssm_writer_gives_the_file_of_sumos_layout(tmp_path):
    writer = SsmWriter(
        tmp_path / "ssm.xml", ttc_threshold_s=3.0, drac_threshold_mps2=4.0, pet_threshold_s=2.0
    )
    kept = _row(
        vehicle_id="car<&\"'",
        person_id="ped",
        vehicle_type="passenger",
        person_type="DEFAULT_PEDTYPE",
        begin_s=1.0,
        ttc_time_s=1.5,
        ttc_x_m=10.0,
        ttc_y_m=-2.25,
        ttc_s=0.8,
        ttc_speed_mps=3.0,
        drac_mps2=5.25,
        drac_time_s=1.0,
        drac_x_m=9.0,
        drac_y_m=-2.5,
        drac_speed_mps=4.0,
        encounter_type=11.0,
        time_s=2.0,
        x_m=11.0,
        y_m=-2.0,
        min_clearance_m=0.125,
        collision=True,
        tmd_s=0.3,
        cs_mps=4.0,
        conflict_probability=0.12345,
    )
    writer.write(kept)
    writer.write(_row(vehicle_id="far", ttc_s=9.0, drac_mps2=0.0, pet_s=9.0))  # meets no threshold
    writer.close()
    written = (tmp_path / "ssm.xml").read_text(encoding="utf-8")
    assert writer.kept == 1
    assert _shape(ElementTree.fromstring(written.encode())) == _shape(
        ElementTree.fromstring(EXPECTED_SSM.encode())
    )
    assert _comments(written) == _comments(EXPECTED_SSM)
    assert [
        c.ego for c in sumolib.xml.parse_fast(str(tmp_path / "ssm.xml"), "conflict", ["begin", "ego"])
    ] == ["car&lt;&amp;&quot;'"]
