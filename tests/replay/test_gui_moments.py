"""Screenshots of chosen moments (under Xvfb): the step `--at closest-approach` names, worked out from the
case log here; the pedestrian's ring at least 20 px across whatever the zoom; the stamp in the top-left
corner (black text on white, pedsafe_sumo/replay/annotate.py); a pedestrian who appears after the
first step (the approach staging), before they appear and once there.
"""

from __future__ import annotations

import os
import shutil

import cv2
import numpy as np
import pandas as pd
import pytest
from replay_runs import case_files, run_cli

HAVE_DISPLAY = bool(os.environ.get("DISPLAY")) or shutil.which("xvfb-run") is not None
GUI_ENV = {**os.environ, "LIBGL_ALWAYS_SOFTWARE": "1"}
PEDESTRIAN_ORANGE = (255, 128, 0)


def read_rgb(path) -> np.ndarray:
    image = cv2.imread(str(path))
    assert image is not None, f"{path} is not an image"
    return image[:, :, ::-1].astype(int)


def ring_size_px(image: np.ndarray) -> tuple[int, int]:
    """Width and height of the largest patch of the pedestrian's orange (the ring; the legend's swatch is
    14 px, sumo-gui's person at the default zoom about 6 px)."""
    mask = np.all(np.abs(image - np.array(PEDESTRIAN_ORANGE)) <= 40, axis=-1).astype(np.uint8)
    count, _, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
    assert count > 1, "no orange in the picture"
    largest = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    return int(stats[largest, cv2.CC_STAT_WIDTH]), int(stats[largest, cv2.CC_STAT_HEIGHT])


def assert_stamped(image: np.ndarray) -> None:
    """The stamp's box from (8, 8): white, with black text in it. sumo-gui's road, grass and vehicles
    leave no such patch in the corner."""
    box = image[10:60, 10:180]
    white = np.all(box == 255, axis=-1).mean()
    dark = np.all(box < 80, axis=-1).sum()
    assert white > 0.6, white
    assert dark > 100, dark


def shoot(run_dir, out, *args: str):
    episode = () if "--episode" in args else ("--episode", "1")
    proc = run_cli(
        "pedsafe_sumo.replay",
        str(run_dir),
        *(*episode, "--condition", "sv", "--screenshot", str(out), *args),
        env=GUI_ENV,
        timeout=240,
    )
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    return proc


@pytest.mark.gui
@pytest.mark.slow
@pytest.mark.skipif(not HAVE_DISPLAY and not os.environ.get("CI"), reason="needs Xvfb (apt-get install xvfb)")
def test_closest_approach_is_the_least_clearance_with_the_pedestrian_in_the_scene(replay_run, tmp_path):
    out = tmp_path / "closest.png"
    proc = shoot(replay_run, out, "--at", "closest-approach")
    log = pd.read_parquet(case_files(replay_run, 1, "sv")[0])
    present = log[np.isfinite(log["ped_x_m"]) & np.isfinite(log["ped_y_m"])]
    k = present["clearance_m"].idxmin()
    time_s, clearance_m = log["time_s"][k], log["clearance_m"][k]
    expected = f"screenshot at the closest approach, t = {time_s:.2f} s: clearance {clearance_m:.2f} m"
    assert expected in proc.stdout, proc.stdout
    image = read_rgb(out)
    assert image.shape == (800, 1000, 3)
    assert_stamped(image)
    width_px, height_px = ring_size_px(image)
    assert 20 <= width_px <= 60 and 20 <= height_px <= 60, (width_px, height_px)


@pytest.mark.gui
@pytest.mark.slow
@pytest.mark.skipif(not HAVE_DISPLAY and not os.environ.get("CI"), reason="needs Xvfb (apt-get install xvfb)")
def test_default_moment_of_a_collision_zoomed_out_keeps_the_ring_and_the_stamp(replay_run, tmp_path):
    out = tmp_path / "wide.png"
    # 400 m across 1000 px: sumo-gui draws the pedestrian under 2 px; the ring stays its size.
    proc = shoot(replay_run, out, "--view-width", "400")
    log = pd.read_parquet(case_files(replay_run, 1, "sv")[0])
    collision_s = log.loc[log["clearance_m"] <= 0, "time_s"].iloc[0]
    assert f"screenshot at the collision, t = {collision_s:.2f} s" in proc.stdout, proc.stdout
    image = read_rgb(out)
    assert_stamped(image)
    width_px, height_px = ring_size_px(image)
    assert 20 <= width_px <= 60 and 20 <= height_px <= 60, (width_px, height_px)


@pytest.mark.gui
@pytest.mark.slow
@pytest.mark.skipif(not HAVE_DISPLAY and not os.environ.get("CI"), reason="needs Xvfb (apt-get install xvfb)")
def test_a_pedestrian_who_appears_later_is_ringed_when_there_and_absent_before(tmp_path):
    run_dir = tmp_path / "approach"
    proc = run_cli(
        "pedsafe_sumo.batch",
        *("--scenario", "jaywalking", "--episodes", "1", "--seed", "3", "--workers", "1"),
        *("--set", "staging=approach", "--keep-logs", "all", "--out", str(run_dir)),
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    steps = pd.concat(pd.read_parquet(p) for p in sorted((run_dir / "steplogs").glob("*.parquet")))
    log = steps[steps["condition"] == "sv"].reset_index(drop=True)
    absent = ~(np.isfinite(log["ped_x_m"]) & np.isfinite(log["ped_y_m"]))
    assert absent.iloc[0], "the pedestrian of this episode is in the scene from the start"
    before_s = float(log["time_s"][int(absent.to_numpy().argmin()) - 1])  # the last step before they appear

    early = shoot(run_dir, tmp_path / "early.png", "--episode", "0", "--at", f"{before_s}")
    assert f"t = {before_s:.2f} s: the pedestrian is not in the scene" in early.stdout, early.stdout
    image = read_rgb(tmp_path / "early.png")
    assert_stamped(image)
    orange = np.all(np.abs(image - np.array(PEDESTRIAN_ORANGE)) <= 40, axis=-1)
    assert orange.sum() < 300  # the legend's swatch only: no ring

    default = shoot(run_dir, tmp_path / "default.png", "--episode", "0")
    assert "screenshot at the" in default.stdout, default.stdout
    width_px, height_px = ring_size_px(read_rgb(tmp_path / "default.png"))
    assert 20 <= width_px <= 60 and 20 <= height_px <= 60, (width_px, height_px)
