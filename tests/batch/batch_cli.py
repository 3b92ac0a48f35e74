"""Helpers of the batch tests: the batch CLI run as a user runs it, file-tree digests."""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sys
from pathlib import Path

from pedsafe_sumo import REPO_ROOT

#: The reference run: 4 crossing pairs, seed 5, one pair per chunk, on 2 pool workers (about 6 s).
SMALL_RUN_ARGS = ("--scenario", "crossing", "--episodes", "4", "--seed", "5", "--chunk-size", "1")


def batch(*args: str, timeout: float = 600, env: dict[str, str] | None = None) -> subprocess.CompletedProcess:
    """`python -m pedsafe_sumo.batch ARGS` from the repository root, as a user runs it."""
    return subprocess.run(
        [sys.executable, "-m", "pedsafe_sumo.batch", *args],
        capture_output=True,
        text=True,
        cwd=REPO_ROOT,
        timeout=timeout,
        env={**os.environ, **(env or {})},
    )


def tree_digest(path: Path) -> dict[str, str]:
    """SHA-256 of every file under `path` by relative name: equal digests, byte-identical trees."""
    return {
        str(p.relative_to(path)): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(path.rglob("*"))
        if p.is_file()
    }


def resume_after_a_stop_in_the_final_stage(
    out: Path, scenario: str
) -> tuple[dict, subprocess.CompletedProcess]:
    """A sampled run stopped in its final stage: run.json back to "running", episodes.parquet and the final
    stage's parts (chunks 2-9 of `scenario`) gone; then `batch --resume`. Returns run.json as it was before
    the stop, and the resume's process."""
    run_info = json.loads((out / "run.json").read_text())
    (out / "run.json").write_text(json.dumps({**run_info, "state": "running"}))
    (out / "episodes.parquet").unlink()
    for part in (out / "parts").glob(f"{scenario}-0000[2-9]*.parquet"):
        part.unlink()
    return run_info, batch("--resume", "--out", str(out))
