"""DIR/report.html: one self-contained page, checked as text and in a real headless Chromium.

The run is the hand-made standard run of report_runs.py (known Table I, 7 case logs). The browser test
opens the page from disk with networking off, takes a screenshot of the whole page and checks its
pixels: the table header colour of the page's style is there, and every embedded figure shows (a
distinctive colour of each figure's PNG is found in the screenshot). Chromium is the Debian package
`chromium` (.ci/run installs it).
"""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
from pathlib import Path

import matplotlib.image
import numpy as np
import pandas as pd
import pytest
from report_runs import write_standard_run

from pedsafe_sumo import REPO_ROOT
from pedsafe_sumo.report.html import MAX_GALLERY_CASES

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
#: The table header background of the page's style (#e8eef6).
TABLE_HEADER_RGB = (0xE8, 0xEE, 0xF6)
#: The ego's path colour of the gallery's trajectory plots (#c0208a).
EGO_PATH_RGB = (0xC0, 0x20, 0x8A)


@pytest.fixture(scope="module")
def reported(tmp_path_factory) -> Path:
    run = write_standard_run(tmp_path_factory.mktemp("html") / "run")
    proc = subprocess.run(
        [sys.executable, "-m", "pedsafe_sumo.report", str(run)],
        capture_output=True,
        text=True,
        cwd=REPO_ROOT,
        timeout=300,
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "report.html" in proc.stdout
    return run


def test_page_is_self_contained_and_holds_tables_figures_cases_config(reported):
    page = (reported / "report.html").read_text(encoding="utf-8")
    # nothing is fetched: every image inline, no external scripts, links or styles
    sources = re.findall(r'src="([^"]*)"', page)
    assert sources and all(s.startswith("data:image/png;base64,") for s in sources)
    assert not re.search(r"<(script|link)\b", page) and "http://" not in page.split("<pre>")[0]
    # Table I as the CSV the report wrote: the collision cell of crossing SV
    table = pd.read_csv(reported / "tables" / "table1.csv")
    assert len(table) == 4
    assert "0.3000 [" in page  # crossing SV: 3 of 10 collisions
    assert 'id="paired-tests"' in page and "0.2500" in page  # crossing collisions, p = 0.25
    figures = sorted((reported / "figures").glob("*.png"))
    assert figures and page.count("<figure>") == len(figures)
    # the gallery: 7 case logs, each card with its replay and export commands
    assert page.count('class="case"') == min(7, MAX_GALLERY_CASES)
    assert page.count("--export-fcd") == 7 and page.count("--screenshot") == 7
    assert "Logged cases (7)" in page
    assert "run.json" in page and "wall_time_s" in page


def distinctive_rgb(png: Path) -> tuple[int, int, int]:
    """The most frequent saturated colour of an image (a line or bar colour of the figure)."""
    pixels = (matplotlib.image.imread(png)[..., :3] * 255).round().astype(int).reshape(-1, 3)
    saturation = pixels.max(axis=1) - pixels.min(axis=1)
    colours, counts = np.unique(pixels[saturation > 100], axis=0, return_counts=True)
    return tuple(int(v) for v in colours[np.argmax(counts)])


def has_colour(shot: np.ndarray, rgb: tuple[int, int, int], tolerance: int = 6, minimum: int = 30) -> bool:
    return int((np.abs(shot - np.array(rgb)).max(axis=-1) <= tolerance).sum()) >= minimum


@pytest.mark.slow
@pytest.mark.skipif(CHROMIUM is None, reason="needs the Debian package chromium (installed by .ci/run)")
def test_page_renders_in_headless_chromium(reported, tmp_path):
    shot_path = tmp_path / "page.png"
    proc = subprocess.run(
        [
            CHROMIUM,
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-quic",
            "--no-first-run",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            f"--user-data-dir={tmp_path / 'profile'}",
            "--hide-scrollbars",
            "--window-size=1200,9000",
            f"--screenshot={shot_path}",
            (reported / "report.html").as_uri(),
        ],
        capture_output=True,
        text=True,
        timeout=180,
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    # errors of the page itself (not Chromium's own D-Bus complaints on a machine without a session bus)
    page_errors = [line for line in proc.stderr.splitlines() if "CONSOLE" in line or "net::ERR" in line]
    assert not page_errors, page_errors
    shot = (matplotlib.image.imread(shot_path)[..., :3] * 255).round().astype(int)
    assert (shot < 250).any(axis=-1).mean() > 0.05  # not blank
    assert has_colour(shot, TABLE_HEADER_RGB, tolerance=2, minimum=2000)  # the tables' headers
    assert has_colour(shot, EGO_PATH_RGB)  # the gallery's plots
    for figure in sorted((reported / "figures").glob("*.png")):
        assert has_colour(shot, distinctive_rgb(figure)), figure.name
