"""research/is_validation.py --markdown writes its table without tabulate (not installed): a pipe table whose
cells are the values, floats to 4 places."""

from __future__ import annotations

import subprocess
import sys

import pandas as pd

from pedsafe_sumo import REPO_ROOT

sys.path.insert(0, str(REPO_ROOT / "research"))
from is_validation import markdown_table  # noqa: E402


def test_markdown_table_by_hand():
    table = pd.DataFrame({"scenario": ["crossing"], "is_estimate": [0.0078125], "mc_n": [10000]})
    assert markdown_table(table) == (
        "| scenario | is_estimate | mc_n |\n|---|---|---|\n| crossing | 0.0078 | 10000 |"
    )


def test_the_tool_refuses_a_missing_run_in_one_line(tmp_path):
    proc = subprocess.run(
        [sys.executable, str(REPO_ROOT / "research" / "is_validation.py"), str(tmp_path / "a"),
         str(tmp_path / "b"), "--markdown"],
        capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert proc.returncode == 2 and len(proc.stderr.strip().splitlines()) == 1, proc.stderr


def test_z_of_the_difference_by_hand():
    # The last live run's crossing SV: IS 0.0059 with upper bound 0.0069, MC 20 collisions in 2,400.
    # se_is = 0.0010 / 1.959964 = 0.000510; se_mc = sqrt(0.008333 * 0.991667 / 2400) = 0.001856;
    # z = (0.0059 - 0.008333) / hypot(0.000510, 0.001856) = -0.002433 / 0.001925 = -1.264.
    from is_validation import _z_difference

    assert abs(_z_difference(0.0059, 0.0069, 20 / 2400, 2400) - (-1.264)) < 0.002
