"""The replay in sumo-gui (under Xvfb): a logged collision rendered to a PNG really shows the scene, and
a whole replay in the window follows the log step by step.

Colours looked for are the replay's documented role colours (docs/replay.md): the ego magenta
(255, 0, 255), the pedestrian orange (255, 128, 0).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys

import cv2
import numpy as np
import pandas as pd
import pytest
from replay_runs import case_files, run_cli

from pedsafe_sumo import REPO_ROOT

HAVE_DISPLAY = bool(os.environ.get("DISPLAY")) or shutil.which("xvfb-run") is not None
EGO_MAGENTA = (255, 0, 255)
PEDESTRIAN_ORANGE = (255, 128, 0)
GUI_ENV = {**os.environ, "LIBGL_ALWAYS_SOFTWARE": "1"}


def pixels_of(image: np.ndarray, rgb, tol: int = 40) -> np.ndarray:
    """Mask of the pixels within `tol` of `rgb` on every channel."""
    return np.all(np.abs(image - np.array(rgb)) <= tol, axis=-1)


def read_rgb(path) -> np.ndarray:
    image = cv2.imread(str(path))
    assert image is not None, f"{path} is not an image"
    return image[:, :, ::-1].astype(int)


@pytest.mark.gui
@pytest.mark.slow
@pytest.mark.skipif(not HAVE_DISPLAY and not os.environ.get("CI"), reason="needs Xvfb (apt-get install xvfb)")
def test_screenshot_of_a_logged_collision_shows_the_ego_and_the_pedestrian(replay_run, tmp_path):
    out = tmp_path / "collision.png"
    # Without a display the replay starts Xvfb itself (xvfb-run); with one it uses it.
    proc = run_cli(
        "pedsafe_sumo.replay",
        str(replay_run),
        *("--episode", "1", "--condition", "sv", "--screenshot", str(out), "--at", "collision"),
        *("--size", "800,600"),
        env=GUI_ENV,
        timeout=240,
    )
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    log = pd.read_parquet(case_files(replay_run, 1, "sv")[0])
    collision_s = log.loc[log["clearance_m"] <= 0, "time_s"].iloc[0]
    assert f"screenshot at the collision, t = {collision_s:.2f} s" in proc.stdout

    image = read_rgb(out)
    height, width, _ = image.shape
    assert (width, height) == (800, 600)
    # Not a blank canvas: several colours each cover a good part of the picture.
    colours, counts = np.unique(image.reshape(-1, 3), axis=0, return_counts=True)
    assert (counts > 0.01 * width * height).sum() >= 4
    # The ego and the pedestrian, touching, near the centre of the picture.
    centre = image[int(0.3 * height) : int(0.7 * height), int(0.3 * width) : int(0.7 * width)]
    ego = pixels_of(centre, EGO_MAGENTA)
    pedestrian = pixels_of(centre, PEDESTRIAN_ORANGE)
    assert ego.sum() > 300, ego.sum()
    assert pedestrian.sum() > 10, pedestrian.sum()
    # ... and not elsewhere: the picture is framed on them.
    assert pixels_of(image, EGO_MAGENTA).sum() < 3 * ego.sum() + 5000
    ego_yx = np.argwhere(ego).mean(axis=0)
    pedestrian_yx = np.argwhere(pedestrian).mean(axis=0)
    assert np.hypot(*(ego_yx - pedestrian_yx)) < 0.15 * width


@pytest.mark.gui
@pytest.mark.slow
@pytest.mark.skipif(not HAVE_DISPLAY and not os.environ.get("CI"), reason="needs Xvfb (apt-get install xvfb)")
def test_whole_replay_in_sumo_gui_follows_the_log(replay_run):
    command = [
        sys.executable,
        *("-m", "pedsafe_sumo.replay", str(replay_run)),
        *("--episode", "2", "--condition", "v2i", "--delay", "0"),
    ]
    if not os.environ.get("DISPLAY"):
        # Watching needs a display (the replay starts Xvfb itself only for --screenshot): a virtual one.
        command = ["xvfb-run", "-a", "-s", "-screen 0 1400x1000x24", *command]
    proc = subprocess.run(
        command,
        capture_output=True,
        text=True,
        cwd=REPO_ROOT,
        timeout=240,
        env=GUI_ENV,
        stdin=subprocess.DEVNULL,  # not a terminal: sumo-gui closes at the end without asking
    )
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    n_steps = len(pd.read_parquet(case_files(replay_run, 2, "v2i")[0]))
    assert f"trajectory matches the log: {n_steps} of {n_steps} steps checked" in proc.stdout
    assert "outcome matches episodes.parquet" in proc.stdout
    assert "first onboard detection" in proc.stdout and "roadside camera first saw them" in proc.stdout


@pytest.mark.gui
@pytest.mark.slow
@pytest.mark.skipif(not HAVE_DISPLAY and not os.environ.get("CI"), reason="needs Xvfb (apt-get install xvfb)")
def test_first_detection_of_an_episode_without_case_log_in_scene_colours(run_copy, tmp_path):
    run_dir = run_copy()
    for condition in ("sv", "v2i"):
        for path in case_files(run_dir, 0, condition):
            path.unlink()
    out = tmp_path / "first_detection.png"
    proc = run_cli(
        "pedsafe_sumo.replay",
        str(run_dir),
        *("--episode", "0", "--condition", "sv", "--screenshot", str(out), "--at", "first-detection"),
        "--scene-colours",
        env=GUI_ENV,
        timeout=240,
    )
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    assert "nothing recorded to check the trajectory against" in proc.stdout
    image = read_rgb(out)
    assert image.shape == (800, 1000, 3)
    # Scene colours: the ego in its own blue (the registry's EGO_BLUE_RGB, 30, 110, 255; the tolerance
    # leaves out the roadside camera's 0, 90, 255), not magenta.
    assert pixels_of(image, (30, 110, 255), tol=12).sum() > 300
