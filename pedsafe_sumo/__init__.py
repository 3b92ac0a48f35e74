"""pedsafe_sumo: pedestrian safety evaluation of autonomous driving on Eclipse SUMO."""

from pathlib import Path

__version__ = "0.1.0"

#: Repository root when running from a checkout (networks/, routes/, osm/ live there).
REPO_ROOT = Path(__file__).resolve().parent.parent
NETWORKS_DIR = REPO_ROOT / "networks"
ROUTES_DIR = REPO_ROOT / "routes"

#: Attribution required by the Open Database License for everything derived from OpenStreetMap.
OSM_ATTRIBUTION = (
    "Map data (c) OpenStreetMap contributors, licensed under the Open Database License (ODbL) 1.0, "
    "https://www.openstreetmap.org/copyright"
)
