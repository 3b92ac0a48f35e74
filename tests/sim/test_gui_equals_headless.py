"""The same episode in sumo-gui (traci) and headless (libsumo) gives the same per-step log: the
connection module's promise that the loop never knows which SUMO it drives (replay rests on it)."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys

import pandas as pd
import pytest

from pedsafe_sumo import REPO_ROOT

HAVE_DISPLAY = bool(os.environ.get("DISPLAY")) or shutil.which("xvfb-run") is not None


@pytest.mark.gui
@pytest.mark.skipif(not HAVE_DISPLAY and not os.environ.get("CI"), reason="needs Xvfb (apt-get install xvfb)")
def test_gui_episode_log_equals_headless(tmp_path):
    base = [
        sys.executable,
        "-m",
        "pedsafe_sumo.episode",
        "--scenario",
        "crossing",
        "--condition",
        "sv",
        "--seed",
        "3",
    ]
    headless = subprocess.run(
        [*base, "--log", str(tmp_path / "headless.csv")],
        capture_output=True,
        text=True,
        cwd=REPO_ROOT,
        timeout=120,
    )
    assert headless.returncode == 0, headless.stderr
    gui_cmd = [*base, "--gui", "--log", str(tmp_path / "gui.csv")]
    if not os.environ.get("DISPLAY"):
        gui_cmd = ["xvfb-run", "-a", "-s", "-screen 0 1400x1000x24", *gui_cmd]
    gui = subprocess.run(
        gui_cmd,
        capture_output=True,
        text=True,
        cwd=REPO_ROOT,
        timeout=180,
        env={**os.environ, "LIBGL_ALWAYS_SOFTWARE": "1"},
    )
    assert gui.returncode == 0, gui.stderr[-2000:]
    a = pd.read_csv(tmp_path / "gui.csv")
    b = pd.read_csv(tmp_path / "headless.csv")
    pd.testing.assert_frame_equal(a, b)
