"""pedsafe_sumo: pedestrian safety evaluation of autonomous driving on Eclipse SUMO."""

from pathlib import Path

__version__ = "0.1.0"

PACKAGE_DIR = Path(__file__).resolve().parent
#: Repository root when running from a checkout (networks/, protocols/, routes/, osm/ live there).
REPO_ROOT = PACKAGE_DIR.parent
#: Where an installed wheel keeps the shipped sites, protocols and default routes (setup.py copies the
#: checkout's networks/, protocols/ and routes/ there); absent in a checkout and an editable install.
SHIPPED_DIR = PACKAGE_DIR / "_shipped"
#: True when installed from a wheel: the shipped folders are read-only data, and what a command writes by
#: default (results/, routes/, networks/<new site>/) goes to the working folder instead of the checkout.
INSTALLED = SHIPPED_DIR.is_dir()
_DATA_ROOT = SHIPPED_DIR if INSTALLED else REPO_ROOT
#: The shipped sites (one folder per site), protocols and default demand.
NETWORKS_DIR = _DATA_ROOT / "networks"
PROTOCOLS_DIR = _DATA_ROOT / "protocols"
ROUTES_DIR = _DATA_ROOT / "routes"
#: The checkout the package runs from (it has a .git), or None when installed from a wheel.
CHECKOUT_ROOT = REPO_ROOT if not INSTALLED and (REPO_ROOT / ".git").exists() else None
#: Where a command writes when not told: the checkout's folders, or the working folder's when installed.
WRITE_ROOT = Path() if INSTALLED else REPO_ROOT

#: Attribution required by the Open Database License for everything derived from OpenStreetMap.
OSM_ATTRIBUTION = (
    "Map data (c) OpenStreetMap contributors, licensed under the Open Database License (ODbL) 1.0, "
    "https://www.openstreetmap.org/copyright"
)

#: The Python API (pedsafe_sumo.api), whose names the package also answers to: `pedsafe_sumo.load_run`.
API_NAMES = (
    "BatchError",
    "EpisodeRun",
    "FIGURES",
    "ReportError",
    "Run",
    "UsageError",
    "figure",
    "load_run",
    "paired_comparison",
    "run_batch",
    "run_episode",
    "table_one",
)


def __getattr__(name: str) -> object:
    """The API's names, imported on first use: `import pedsafe_sumo` stays cheap (no pandas, no SUMO)."""
    if name in API_NAMES:
        from pedsafe_sumo import api  # here, not at the top: it imports pandas, SUMO and matplotlib

        return getattr(api, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
