"""sumo-gui (under Xvfb) renders the site: roads, buildings and the roadside camera are in the picture."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys

import cv2
import numpy as np
import pytest

from pedsafe_sumo import REPO_ROOT

HAVE_DISPLAY = bool(os.environ.get("DISPLAY")) or shutil.which("xvfb-run") is not None


@pytest.mark.gui
@pytest.mark.skipif(not HAVE_DISPLAY and not os.environ.get("CI"), reason="needs Xvfb (apt-get install xvfb)")
def test_sumo_gui_screenshot_shows_the_junction(tmp_path):
    out = tmp_path / "junction.png"
    proc = subprocess.run(
        [
            sys.executable,
            str(REPO_ROOT / "tools" / "screenshot_site.py"),
            "--out",
            str(out),
            "--zoom",
            "300",
            "--size",
            "1000,800",
        ],
        capture_output=True,
        text=True,
        timeout=180,
    )
    assert proc.returncode == 0, proc.stderr
    image = cv2.imread(str(out))[:, :, ::-1].astype(int)  # RGB
    height, width, _ = image.shape
    # The tool refuses a snapshot taken before the window had its size (a 1x1 picture, once in CI).
    assert width >= 500 and height >= 400, image.shape
    centre = image[height // 4 : 3 * height // 4, width // 4 : 3 * width // 4]

    def share(pixels, rgb, tol=12):
        return float(np.mean(np.all(np.abs(pixels - np.array(rgb)) <= tol, axis=-1)))

    # The junction area (asphalt, drawn black in the "real world" scheme) fills much of the centre.
    assert share(centre, (0, 0, 0), tol=30) > 0.25
    # Sidewalks (grey) and the roadside camera POI (its colour in xueqing.rsu.add.xml: 0,90,255).
    assert share(image, (128, 128, 128), tol=20) > 0.01
    assert share(image, (0, 90, 255), tol=40) > 0.00005


def _load_tool():
    import importlib.util

    spec = importlib.util.spec_from_file_location(
        "screenshot_site", REPO_ROOT / "tools" / "screenshot_site.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_png_size_is_read_from_the_header(tmp_path):
    tool = _load_tool()
    picture = tmp_path / "p.png"
    cv2.imwrite(str(picture), np.zeros((37, 211, 3), dtype=np.uint8))  # height 37, width 211
    assert tool.png_size_px(picture) == (211, 37)
    not_png = tmp_path / "n.png"
    not_png.write_bytes(b"GIF89a" + bytes(40))
    assert tool.png_size_px(not_png) is None
    assert tool.png_size_px(tmp_path / "missing.png") is None


def test_a_bad_window_size_is_one_line_and_exit_2(tmp_path):
    proc = subprocess.run(
        [
            sys.executable,
            str(REPO_ROOT / "tools" / "screenshot_site.py"),
            "--out",
            str(tmp_path / "x.png"),
            "--size",
            "wide",
        ],
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 2
    assert proc.stderr.strip().splitlines()[-1] == (
        "screenshot_site: error: argument --size: give WIDTH,HEIGHT in pixels, got 'wide'"
    )
    assert not (tmp_path / "x.png").exists()
