"""What produced a result: the package's version and, when it runs from a git checkout, its commit."""

from __future__ import annotations

import subprocess

from pedsafe_sumo import CHECKOUT_ROOT


def git_commit() -> str:
    """The checkout's commit, with "-dirty" when its work tree has changes; "" when the package is not
    run from a git checkout (installed from a wheel) or git cannot tell."""
    if CHECKOUT_ROOT is None:
        return ""
    try:
        out = subprocess.run(
            ["git", "rev-parse", "HEAD"], cwd=CHECKOUT_ROOT, capture_output=True, text=True, timeout=5
        )
        dirty = subprocess.run(
            ["git", "status", "--porcelain"], cwd=CHECKOUT_ROOT, capture_output=True, text=True, timeout=5
        )
        return out.stdout.strip() + ("-dirty" if dirty.stdout.strip() else "") if out.returncode == 0 else ""
    except (OSError, subprocess.SubprocessError):
        return ""
