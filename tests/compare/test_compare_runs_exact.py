"""tools/compare_runs_exact.py: the bit-for-bit check of runs (that a change keeps the rows) must see a
difference of one unit in the last place, a changed dtype, a missing step, and must treat NaN as equal to
NaN."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

REPO_ROOT = Path(__file__).resolve().parents[2]
_spec = importlib.util.spec_from_file_location(
    "compare_runs_exact", REPO_ROOT / "tools" / "compare_runs_exact.py"
)
assert _spec is not None and _spec.loader is not None
tool = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(tool)


def _episodes() -> pd.DataFrame:
    return pd.DataFrame(
        {
            "scenario": ["crossing", "crossing"],
            "condition": ["sv", "v2i"],
            "md_m": [1.25, np.nan],
            "collision": [True, False],
            "sumo_collision": pd.array([None, True], dtype="boolean"),
        }
    )


def _steps() -> pd.DataFrame:
    return pd.DataFrame({"episode": [0, 0, 0], "time_s": [0.0, 0.05, 0.1], "ped_state": ["waiting"] * 3})


def _write_run(path: Path, episodes: pd.DataFrame, steps: pd.DataFrame | None = None) -> Path:
    path.mkdir()
    episodes.to_parquet(path / "episodes.parquet")
    if steps is not None:
        (path / "steplogs").mkdir()
        steps.to_parquet(path / "steplogs" / "crossing-000000-000000.parquet")
    return path


def test_identical_runs_pass_nan_included(tmp_path, capsys):
    a = _write_run(tmp_path / "a", _episodes(), _steps())
    b = _write_run(tmp_path / "b", _episodes(), _steps())
    assert tool.main([str(a), str(b)]) == 0
    assert "IDENTICAL: 2 episode rows and 3 logged steps compared" in capsys.readouterr().out


def test_one_ulp_is_a_difference(tmp_path, capsys):
    changed = _episodes()
    changed.loc[0, "md_m"] = np.nextafter(1.25, 2.0)
    a = _write_run(tmp_path / "a", _episodes())
    b = _write_run(tmp_path / "b", changed)
    assert tool.main([str(a), str(b)]) == 1
    out = capsys.readouterr().out
    assert "episodes.md_m: 1 of 2 rows differ (first row 0" in out
    assert "DIFFERENT" in out


def test_nullable_flag_and_dtype_and_steps(tmp_path, capsys):
    changed = _episodes()
    changed["sumo_collision"] = pd.array([False, True], dtype="boolean")  # NA -> False is a change
    steps = _steps()
    steps.loc[2, "time_s"] = 0.1000001
    a = _write_run(tmp_path / "a", _episodes(), _steps())
    b = _write_run(tmp_path / "b", changed.astype({"collision": "int64"}), steps)
    assert tool.main([str(a), str(b)]) == 1
    out = capsys.readouterr().out
    assert "episodes.sumo_collision: 1 of 2 rows differ (first row 0" in out
    assert "episodes.collision: dtype bool against int64" in out
    assert "steplogs.time_s: 1 of 3 rows differ (first row 2" in out


def test_missing_run_is_refused_in_one_line(tmp_path, capsys):
    a = _write_run(tmp_path / "a", _episodes())
    assert tool.main([str(a), str(tmp_path / "nothing")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "holds no episodes.parquet" in err[0]


@pytest.mark.parametrize("rows_b", [1, 3])
def test_row_count_differs(tmp_path, capsys, rows_b):
    b_table = pd.concat([_episodes()] * 2, ignore_index=True).iloc[:rows_b]
    a = _write_run(tmp_path / "a", _episodes())
    b = _write_run(tmp_path / "b", b_table)
    assert tool.main([str(a), str(b)]) == 1
    assert f"episodes: 2 rows against {rows_b}" in capsys.readouterr().out
