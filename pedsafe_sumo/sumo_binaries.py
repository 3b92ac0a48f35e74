"""Paths of the SUMO programs of the eclipse-sumo wheel (one SUMO version for the whole package)."""

from __future__ import annotations

import shutil
from pathlib import Path

import sumo


def sumo_binary(name: str) -> str:
    """Path of a SUMO program (sumo, sumo-gui, netconvert, ...) from the eclipse-sumo wheel; another
    SUMO on the PATH is used only when the wheel lacks the program."""
    path = Path(sumo.SUMO_HOME) / "bin" / name
    if path.exists():
        return str(path)
    found = shutil.which(name)
    if found is None:
        raise FileNotFoundError(f"{name} not found (is eclipse-sumo installed?)")
    return found
