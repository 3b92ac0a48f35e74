"""Where numba keeps the compiled kernels: ``$NUMBA_CACHE_DIR`` when it is set, else ``numba/`` in the
user's cache folder (``$XDG_CACHE_HOME/pedsafe_sumo`` or ``~/.cache/pedsafe_sumo`` on Linux,
``~/Library/Caches/pedsafe_sumo`` on macOS, ``%LOCALAPPDATA%\\pedsafe_sumo`` on Windows).

A folder the user can write wherever the package is installed (numba's default, ``__pycache__`` beside the
source, is not writable in a system-wide install), shared by every process of a batch; numba keeps the
code of each source folder apart, so two checkouts or installs do not mix. Where that folder cannot be
written either, numba falls back to its own choices (``__pycache__``, then its user-wide folder).
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import numba.core.config

CACHE_DIR_ENV = "NUMBA_CACHE_DIR"


def user_cache_dir() -> Path:
    """The package's folder in the user's cache folder (the platform's usual place)."""
    home = Path.home()
    if sys.platform == "win32":
        base = Path(os.environ.get("LOCALAPPDATA") or home / "AppData" / "Local")
    elif sys.platform == "darwin":
        base = home / "Library" / "Caches"
    else:
        base = Path(os.environ.get("XDG_CACHE_HOME") or home / ".cache")
    return base / "pedsafe_sumo"


def use_kernel_cache() -> str:
    """Set $NUMBA_CACHE_DIR (unless set) and have numba read it again; returns the folder. Must run
    before the kernels are decorated: numba picks a function's cache folder then. The variable is
    inherited by the batch's worker processes."""
    os.environ.setdefault(CACHE_DIR_ENV, str(user_cache_dir() / "numba"))
    numba.core.config.reload_config()
    return os.environ[CACHE_DIR_ENV]
