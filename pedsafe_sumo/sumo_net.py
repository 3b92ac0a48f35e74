"""Reading SUMO networks with sumolib: the one way the package reads a .net.xml.

sumolib 1.28's `readNet` picks its XML parser by what is installed: lxml's `iterparse` when lxml can be
imported (scenariogeneration, the OpenSCENARIO export's library, brings it in), else the standard
library's SAX parser. The lxml path never calls the reader's `endDocument()`, where sumolib links
each pedestrian crossing to the road edges it crosses, so with lxml installed every crossing reports
no crossed edges (`Edge.getCrossingEdges() == []`) and whatever finds a crosswalk over a road finds
none. `read_net` always takes the SAX path, which the package was written and tested on, whatever is
installed; every module (and test) reads nets through it (tests/network/test_net_reader.py checks
both the result and that no other `readNet` call is left).
"""

from __future__ import annotations

from pathlib import Path

import sumolib


def read_net(net_file: str | Path, **options) -> sumolib.net.Net:
    """`sumolib.net.readNet(net_file, **options)` through the SAX parser (see the module's docstring)."""
    options["lxml"] = False
    return sumolib.net.readNet(str(net_file), **options)
