"""Exact comparison of two run directories: every column of episodes.parquet, and with `--keep-logs all`
every step of steplogs/, must be bit-identical (NaN equal to NaN, same dtypes).

    .venv/bin/python tools/compare_runs_exact.py RUN_A RUN_B

For changes that must not change results (optimisations, restructuring): run the same batch on the code
before and after and compare. episodes.parquet has no wall-clock column; run.json (timings, paths) is not
compared. Prints one line per difference and exits 1 if there is any, 0 when identical, 2 on bad input.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import pandas as pd


def _read_steplogs(run: Path) -> pd.DataFrame | None:
    folder = run / "steplogs"
    files = sorted(folder.glob("*.parquet")) if folder.is_dir() else []
    if not files:
        return None
    return pd.concat([pd.read_parquet(f) for f in files], ignore_index=True)


def table_differences(name: str, a: pd.DataFrame, b: pd.DataFrame) -> list[str]:
    """One line per column that differs between `a` and `b` (order, dtype, values; NaN == NaN)."""
    out = []
    if list(a.columns) != list(b.columns):
        out.append(f"{name}: columns differ: {sorted(set(a.columns) ^ set(b.columns))} or their order")
    if len(a) != len(b):
        return [*out, f"{name}: {len(a)} rows against {len(b)}"]
    for column in [c for c in a.columns if c in b.columns]:
        ca, cb = a[column].reset_index(drop=True), b[column].reset_index(drop=True)
        if ca.dtype != cb.dtype:
            out.append(f"{name}.{column}: dtype {ca.dtype} against {cb.dtype}")
        elif not ca.equals(cb):
            differ = ~((ca == cb) | (ca.isna() & cb.isna())).fillna(False).to_numpy(dtype=bool)
            first = int(differ.argmax())
            out.append(
                f"{name}.{column}: {int(differ.sum())} of {len(ca)} rows differ "
                f"(first row {first}: {ca.iloc[first]!r} against {cb.iloc[first]!r})"
            )
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run_a", type=Path)
    parser.add_argument("run_b", type=Path)
    parser.add_argument(
        "--new-columns",
        action="store_true",
        help="RUN_B may have columns RUN_A lacks (a newer contract): compare the columns of RUN_A only, "
        "and list the new ones",
    )
    args = parser.parse_args(argv)
    for run in (args.run_a, args.run_b):
        if not (run / "episodes.parquet").is_file():
            print(f"error: {run} holds no episodes.parquet", file=sys.stderr)
            return 2
    table_a = pd.read_parquet(args.run_a / "episodes.parquet")
    table_b = pd.read_parquet(args.run_b / "episodes.parquet")
    if args.new_columns:
        new = [c for c in table_b.columns if c not in table_a.columns]
        if new:
            print(f"new columns in {args.run_b} (not compared): {', '.join(new)}")
        table_b = table_b[[c for c in table_b.columns if c in table_a.columns]]
    differences = table_differences("episodes", table_a, table_b)
    logs_a, logs_b = _read_steplogs(args.run_a), _read_steplogs(args.run_b)
    if (logs_a is None) != (logs_b is None):
        differences.append("steplogs: only one of the runs has them")
    elif logs_a is not None and logs_b is not None:
        differences += table_differences("steplogs", logs_a, logs_b)
    for line in differences:
        print(line)
    n = len(pd.read_parquet(args.run_a / "episodes.parquet"))
    steps = "" if logs_a is None else f" and {len(logs_a)} logged steps"
    print(f"{'IDENTICAL' if not differences else 'DIFFERENT'}: {n} episode rows{steps} compared")
    return 1 if differences else 0


if __name__ == "__main__":
    sys.exit(main())
