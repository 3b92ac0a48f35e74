"""research/experiments/is_pilot_size.py refuses runs it cannot read in one line."""

from __future__ import annotations

import subprocess
import sys

from pedsafe_sumo import REPO_ROOT


def test_a_missing_run_is_refused_in_one_line(tmp_path):
    proc = subprocess.run(
        [sys.executable, str(REPO_ROOT / "research" / "experiments" / "is_pilot_size.py"),
         str(tmp_path / "a"), str(tmp_path / "b"), "--scenario", "jaywalking"],
        capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert proc.returncode == 2 and len(proc.stderr.strip().splitlines()) == 1, proc.stderr
