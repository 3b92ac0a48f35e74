"""Paths named by files from others, kept inside the directory the user named (docs/trust.md).

A run directory's manifest.json names its part files, a site file names its OSM data: such a path is
data. `confined` accepts it only as a path relative to its base directory that stays inside it once
resolved (symbolic links followed): an absolute path, a '..' part or a link pointing out is refused
with one line. `check_entries` does the same for the fixed names a command reads and writes in a
directory (a run's .lock, parts/, ...), so that a link planted in a received directory cannot send a
write or a deletion elsewhere.
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path, PurePosixPath, PureWindowsPath


class ConfinementError(ValueError):
    """A path a file names that would leave its directory; the message is one line."""


def is_inside(path: Path, base: Path) -> bool:
    """Whether `path`, resolved (links followed), is `base` resolved or lies below it."""
    resolved, root = Path(path).resolve(), Path(base).resolve()
    return resolved == root or root in resolved.parents


def confined(base: Path, relative: str, what: str) -> Path:
    """`base / relative` when `relative` is a relative path without '..' that stays inside `base`;
    ConfinementError naming `what` (e.g. "manifest.json entry parts/x") otherwise."""
    text = str(relative)
    parts = PurePosixPath(text.replace("\\", "/")).parts
    if not text or PurePosixPath(text).is_absolute() or PureWindowsPath(text).is_absolute():
        raise ConfinementError(f"{what}: '{text}' is not a path relative to {base}: refused")
    if ".." in parts:
        raise ConfinementError(f"{what}: '{text}' climbs out of {base} ('..'): refused")
    path = Path(base) / text
    if not is_inside(path, base):
        raise ConfinementError(f"{what}: '{text}' leads out of {base} (a symbolic link): refused")
    return path


def check_entries(base: Path, names: Iterable[str], what: str) -> None:
    """ConfinementError when one of the entries `names` of `base` (a file or folder to be, too) would lie
    outside it once resolved: a link leading out, at the name or at a folder on its way."""
    for name in names:
        path = Path(base) / name
        if not is_inside(path, base):
            raise ConfinementError(f"{what}: {path} leads out of {base} (a symbolic link): refused")


def check_tree(base: Path, names: Iterable[str], what: str) -> None:
    """check_entries for the entries `names` of `base` and everything below those that are folders."""
    check_entries(base, names, what)
    for name in names:
        folder = Path(base) / name
        if folder.is_dir() and not folder.is_symlink():
            check_tree(base, [str(p.relative_to(base)) for p in folder.iterdir()], what)
