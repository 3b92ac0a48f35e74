"""The command's start-up: importing it loads none of the heavy libraries a run can do without (their
imports would cost more CPU than the measures of a short run; BENCHMARKS.md, "Pedestrian conflicts: CPU
per interaction"): scipy (the risk model's logistic function takes exp from math), pandas, pyarrow
(a .parquet output imports it), tqdm (a run longer than a few seconds imports it)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[2]


def test_importing_the_command_loads_no_heavy_library():
    heavy = ("scipy", "pandas", "pyarrow", "tqdm")
    code = (
        "import sys, pedsafe_sumo.conflicts.__main__; "
        f"print(*(any(m == h or m.startswith(h + '.') for m in sys.modules) for h in {heavy!r}))"
    )
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO_ROOT, check=True
    )
    assert done.stdout.split() == ["False"] * len(heavy), dict(zip(heavy, done.stdout.split()))
