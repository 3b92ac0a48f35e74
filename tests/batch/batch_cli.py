"""Helpers of the batch tests: the batch CLI run as a user runs it, file-tree digests."""

from __future__ import annotations

import hashlib
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
