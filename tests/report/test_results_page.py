"""tools/results_page.py: a study's page from its runs, on a hand-made run with known answers."""

from __future__ import annotations

import math
import subprocess
import sys

import pytest
from report_runs import write_standard_run

from pedsafe_sumo import REPO_ROOT

TOOL = REPO_ROOT / "tools" / "results_page.py"
sys.path.insert(0, str(TOOL.parent))
from results_page import meets_target  # noqa: E402


def _wilson(successes: int, n: int, z: float = 1.959964) -> tuple[float, float]:
    p = successes / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z / (1 + z * z / n) * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n))
    return centre - half, centre + half


@pytest.mark.parametrize(
    ("collisions", "n", "met"),
    [
        (48, 2400, True),  # 2.0%: half-width 0.00565 < 0.02 / 3
        (36, 2400, True),  # 1.5%: half-width 0.00492 < 0.005
        (24, 1000, False),  # 2.4% of 1,000: half-width 0.0095, above 0.008 and 0.005
        (0, 2400, True),  # none: half-width 0.0008
        (0, 300, False),  # none of 300: half-width 0.0064
    ],
)
def test_the_precision_target_is_a_third_of_the_rate_or_half_a_percent(collisions, n, met):
    low, high = _wilson(collisions, n)
    assert meets_target(collisions / n, low, high) is met


def test_the_page_holds_the_runs_numbers_beside_the_papers(tmp_path):
    run = write_standard_run(tmp_path / "run")
    page = tmp_path / "page" / "results.md"
    proc = subprocess.run(
        [sys.executable, str(TOOL), "--run", f"Standard={run}", "--out", str(page),
         "--figures", str(tmp_path / "page" / "figures")],
        capture_output=True, text=True, cwd=REPO_ROOT, timeout=300,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    text = page.read_text()
    low, high = _wilson(3, 10)
    # crossing SV: 3 collisions of 10, the paper's 0.23 beside it, the target not met at n = 10
    assert f"| crossing | SV | 10 | 0.3000 [{low:.4f}, {high:.4f}] | 0.23 | no |" in text
    # the paired test: 3 SV-only collisions, none V2I-only -> p = 2 / 2^3
    assert "| crossing | collision | 10 | 3 | 0 | 0.25 |" in text
    # jaywalking's pair with a V2I error is dropped: 5 SV-only of 10 pairs -> p = 2 / 2^5
    assert "| jaywalking | collision | 10 | 5 | 0 | 0.0625 |" in text
    assert "](figures/standard_first_detection_distance.png)" in text
    assert (tmp_path / "page" / "figures" / "standard_first_detection_distance.png").stat().st_size > 10_000


def test_a_missing_run_directory_is_one_line_exit_2(tmp_path):
    proc = subprocess.run(
        [sys.executable, str(TOOL), "--run", f"X={tmp_path / 'none'}", "--out", str(tmp_path / "p.md"),
         "--figures", str(tmp_path / "f")],
        capture_output=True, text=True, cwd=REPO_ROOT, timeout=300,
    )  # fmt: skip
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1
    assert not (tmp_path / "p.md").exists()
