"""Fixtures shared by the network tests."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from pedsafe_sumo import REPO_ROOT

OSM_CLIPS = Path(__file__).parent / "data" / "osm"
BUILD_TOOL = REPO_ROOT / "tools" / "build_network.py"


@pytest.fixture(scope="session")
def zhixin(tmp_path_factory) -> Path:
    """The zhixin clip (one-lane approaches N and S; tests/network/data/osm/README.md) built as a site
    folder by tools/build_network.py, once per test session."""
    folder = tmp_path_factory.mktemp("sites") / "zhixin"
    proc = subprocess.run(
        [sys.executable, str(BUILD_TOOL), "--osm", str(OSM_CLIPS / "zhixin.osm"), "--no-clip", "--center",
         "40.00001,116.35857", "--radius", "130", "--name", "zhixin", "--out", str(folder)],
        capture_output=True, text=True, cwd=REPO_ROOT, timeout=300,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    return folder
