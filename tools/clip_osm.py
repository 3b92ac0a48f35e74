#!/usr/bin/env python3
"""Clip an OSM file to a circle: python tools/clip_osm.py SOURCE TARGET --center LAT,LON --radius M."""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from pedsafe_sumo.network.clip import main  # noqa: E402

if __name__ == "__main__":
    raise SystemExit(main())
