#!/usr/bin/env python3
"""Build a site folder from OpenStreetMap (python tools/build_network.py --site xueqing) or from any SUMO
network (python tools/build_network.py --net my.net.xml --junction ID --out DIR); --help lists the options."""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from pedsafe_sumo.site.build_command import main  # noqa: E402

if __name__ == "__main__":
    raise SystemExit(main())
