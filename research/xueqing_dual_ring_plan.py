#!/usr/bin/env python3
"""Write the Xueqing dual-ring signal plan tried as an alternative to the real one (not adopted;
docs/demand_validation.md).

    python research/xueqing_dual_ring_plan.py networks/xueqing/xueqing.net.xml dual.tll.xml
    cd networks/xueqing && sumo -c xueqing.sumocfg --end 1800 \
        -r ../../routes/xueqing.vehicles.rou.xml,../../routes/xueqing.pedestrians.rou.xml \
        -a xueqing.poly.xml,xueqing.rsu.add.xml,../../dual.tll.xml

Stages (link indices of the joined Xueqing junction's signal; each checked against the junction's foe
matrix: no two green links and no green crosswalk conflict): A1 north-south through with the crosswalks
over the east and west approaches and exits; A2 north-south through and right, lefts permissive; B north-
south protected lefts with the crosswalks over the north and south exits; C east-west, lefts permissive,
with the crosswalks over the north and south approaches. 3 s yellow, 2 s all-red, 5 s pedestrian clearance.
The programme gets id "dual", so loaded as an additional file it replaces the network's own.
"""

import sys
import xml.etree.ElementTree as ET

JUNCTION = "cluster_12817118532_12817118533_12817118534_12817118535_#15more"
N_LINKS = 37
NS_THROUGH = {2, 3, 15, 16}
NS_RIGHT = {0, 1, 13, 14}
NS_LEFT = {4, 17}
EW_MAJOR = {7, 8, 9, 20, 21, 22, 23}
EW_MINOR = {10, 11, 24, 25}
YELLOW_S, ALL_RED_S, PED_CLEARANCE_S = 3, 2, 5
# (name, duration s, green links, permissive links, green crosswalk links, yellow links)
STAGES = [
    ("A1", 10, NS_THROUGH, set(), {29, 30, 34, 35}, set()),
    ("A1 ped clearance", PED_CLEARANCE_S, NS_THROUGH, set(), {29, 34}, set()),
    ("A2", 28, NS_THROUGH | NS_RIGHT, NS_LEFT, {29, 34}, set()),
    ("A2 ped clearance", PED_CLEARANCE_S, NS_THROUGH | NS_RIGHT, NS_LEFT, set(), set()),
    ("A yellow", YELLOW_S, set(), set(), set(), NS_THROUGH | NS_RIGHT | NS_LEFT),
    ("B", 12, NS_LEFT, set(), {27, 28, 32, 33}, set()),
    ("B ped clearance", PED_CLEARANCE_S, NS_LEFT, set(), set(), set()),
    ("B yellow", YELLOW_S, set(), set(), set(), NS_LEFT),
    ("B all red", ALL_RED_S, set(), set(), set(), set()),
    ("C", 38, EW_MAJOR, EW_MINOR, {31, 36}, set()),
    ("C ped clearance", PED_CLEARANCE_S, EW_MAJOR, EW_MINOR, set(), set()),
    ("C yellow", YELLOW_S, set(), set(), set(), EW_MAJOR | EW_MINOR),
    ("C all red", ALL_RED_S, set(), set(), set(), set()),
]


def main(net_file: str, out_file: str) -> int:
    junction = next(j for j in ET.parse(net_file).getroot().iter("junction") if j.get("id") == JUNCTION)
    foes = {
        int(r.get("index")): {k for k, c in enumerate(r.get("foes")[::-1]) if c == "1"}
        for r in junction.iter("request")
    }
    lines = []
    for name, duration_s, green, permissive, crosswalks, yellow in STAGES:
        protected = green | crosswalks
        for link in protected:
            if foes[link] & protected:
                raise SystemExit(f"stage {name}: link {link} conflicts with {sorted(foes[link] & protected)}")
        for link in permissive:
            if foes[link] & crosswalks:
                raise SystemExit(f"stage {name}: permissive link {link} crosses a green crosswalk")
        state = "".join(
            "G" if i in protected else "g" if i in permissive else "y" if i in yellow else "r"
            for i in range(N_LINKS)
        )
        lines.append(f'        <phase duration="{duration_s}" state="{state}" name="{name}"/>')
    with open(out_file, "w", encoding="utf-8") as out:
        out.write('<?xml version="1.0" encoding="UTF-8"?>\n<tlLogics>\n')
        out.write(f'    <tlLogic id="{JUNCTION}" type="static" programID="dual" offset="0">\n')
        out.write("\n".join(lines) + "\n    </tlLogic>\n</tlLogics>\n")
    print(f"wrote {out_file}: cycle {sum(s[1] for s in STAGES)} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(*sys.argv[1:3]))
