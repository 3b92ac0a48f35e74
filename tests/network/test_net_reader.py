"""pedsafe_sumo.sumo_net.read_net: nets read the same whether or not lxml is installed.

With lxml importable, sumolib 1.28's readNet parses through lxml and never links crossings to the edges
they cross (its endDocument() is not called on that path): every scenario that looks for a crosswalk
over its approach then finds none. lxml is installed here (scenariogeneration depends on it), so these
tests run the case that matters.
"""

from __future__ import annotations

import importlib.util
import re
import xml.etree.ElementTree as ET

from pedsafe_sumo import REPO_ROOT
from pedsafe_sumo.network.sites import get_site
from pedsafe_sumo.sumo_net import read_net


def test_lxml_is_installed_so_the_reader_choice_matters():
    assert importlib.util.find_spec("lxml") is not None


def test_every_crossing_knows_the_edges_it_crosses():
    net_file = get_site("xueqing").file("net.xml")
    # The net file's own record, read without sumolib.
    expected = {
        edge.get("id"): edge.get("crossingEdges").split()
        for edge in ET.parse(net_file).getroot().iter("edge")
        if edge.get("function") == "crossing"
    }
    assert expected, "the site has crosswalks"
    net = read_net(net_file, withInternal=True)
    got = {
        edge.getID(): [crossed.getID() for crossed in edge.getCrossingEdges()]
        for edge in net.getEdges(withInternal=True)
        if edge.getFunction() == "crossing"
    }
    assert got == expected


def test_no_module_or_test_reads_a_net_around_the_helper():
    """A new sumolib.net.readNet call would bring the lxml path back: they all go through read_net."""
    allowed = {REPO_ROOT / "pedsafe_sumo" / "sumo_net.py"}
    offenders = []
    for folder in ("pedsafe_sumo", "tests", "tools", "benchmarks", "examples"):
        for path in sorted((REPO_ROOT / folder).rglob("*.py")):
            if path in allowed:
                continue
            for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
                if re.search(r"\breadNet\(", line) and "re.search" not in line:
                    offenders.append(f"{path.relative_to(REPO_ROOT)}:{number}")
    assert offenders == []
