"""Checks of the output paths a command is given, made before any work starts.

A command that finds out only at its end that it cannot write its output has spent the work for nothing
and ends in a traceback; these checks turn the usual causes (a missing or unwritable folder, a file where
a folder is expected and back) into one line of the command's own usage error.
"""

from __future__ import annotations

import os
from pathlib import Path


class OutputPathError(ValueError):
    """An output path the command cannot write; the message is one line."""


def _existing_ancestor(path: Path) -> Path:
    """The nearest folder (or file) above `path` that exists; the current folder for a relative name."""
    candidate = path.absolute()
    while not candidate.exists() and candidate != candidate.parent:
        candidate = candidate.parent
    return candidate


def _check_creatable(path: Path, option: str, error: type[Exception]) -> None:
    """`path` does not exist yet: its nearest existing ancestor must be a folder one can write into."""
    ancestor = _existing_ancestor(path.parent)
    if not ancestor.is_dir():
        raise error(f"{option} {path}: {ancestor} is not a folder")
    if not os.access(ancestor, os.W_OK | os.X_OK):
        raise error(f"{option} {path}: cannot write into {ancestor}")


def check_output_file(
    path: Path, option: str, error: type[Exception] = OutputPathError, *, make_parents: bool = False
) -> None:
    """Raise `error` unless `path` can be written as a file (its folder exists, unless `make_parents`)."""
    path = Path(path)
    if path.is_dir():
        raise error(f"{option} {path} is a folder, not a file")
    if path.exists() or path.is_symlink():
        if not os.access(path, os.W_OK) or not os.access(path.absolute().parent, os.W_OK | os.X_OK):
            raise error(f"{option} {path}: cannot write this file")
        return
    if not make_parents and not path.absolute().parent.is_dir():
        raise error(f"{option} {path}: the folder {path.parent} does not exist")
    _check_creatable(path, option, error)


def probe_output_dir(path: Path, option: str, error: type[Exception] = OutputPathError) -> None:
    """Raise `error` unless the folder `path` exists or can be made, found by making it and removing again
    what was made. Permission bits do not tell for every user (root may write into a folder of mode 555,
    nobody into /proc or a read-only mount): the attempt does."""
    path = Path(path).absolute()
    missing = []
    candidate = path
    while not candidate.exists() and candidate != candidate.parent:
        missing.append(candidate)
        candidate = candidate.parent
    try:
        for folder in reversed(missing):
            folder.mkdir()
    except OSError as exc:
        raise error(f"{option} {path}: cannot create this folder ({exc.strerror or exc})") from None
    finally:
        for folder in missing:
            if folder.is_dir():
                folder.rmdir()


def check_output_dir(path: Path, option: str, error: type[Exception] = OutputPathError) -> None:
    """Raise `error` unless `path` is a writable folder or one that can be made."""
    path = Path(path)
    if path.exists():
        if not path.is_dir():
            raise error(f"{option} {path} is a file, not a folder")
        if not os.access(path, os.W_OK | os.X_OK):
            raise error(f"{option} {path}: cannot write into this folder")
        return
    _check_creatable(path, option, error)
