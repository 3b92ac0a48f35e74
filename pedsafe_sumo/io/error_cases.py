"""The case log of an episode that ended in an error or a timeout: its traceback, as text.

    <dir>/<scenario>_<condition>_<seed>.error.txt   the row's one-line error, then the full traceback

(the stem of pedsafe_sumo.io.cases). Such an episode has no per-step log to keep; the traceback says
where the AD stack (or SUMO) failed. Written to a temporary name and renamed, like every case file.
"""

from __future__ import annotations

import os
from pathlib import Path

ERROR_CASE_SUFFIX = ".error.txt"


def write_error_case(directory: Path, stem: str, text: str) -> Path:
    """Write the traceback `text` of the failed episode `stem`; returns its path."""
    directory.mkdir(parents=True, exist_ok=True)
    path = directory / f"{stem}{ERROR_CASE_SUFFIX}"
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, path)
    return path
