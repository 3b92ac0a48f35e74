"""Checks of the files a batch reads, made before anything is written.

A batch reads, besides its parameter file (pedsafe_sumo.params checks that one), the site's files
listed in pedsafe_sumo.sim.staging.SITE_FILES_READ: the network, the buildings, the roadside unit and
the site facts. Each must exist and parse, and the episode loop must be able to derive its world from
them; otherwise the batch ends in one line naming the file, before its run directory exists.
"""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from typing import Any

from pedsafe_sumo.network.sites import Site
from pedsafe_sumo.sim.staging import SITE_FILES_READ, load_site_data


class InputFileError(ValueError):
    """A file the batch needs is missing or broken; the message names it, in one line."""


def _one_line(exc: BaseException) -> str:
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__


def check_site(site: Site, params: dict[str, Any]) -> None:
    """Raise InputFileError unless every site file exists, parses, and yields the episode's world."""
    for suffix in SITE_FILES_READ:
        path = site.file(suffix)
        if not path.is_file():
            raise InputFileError(f"site {site.name}: {path} is missing")
        try:
            if suffix.endswith(".json"):
                json.loads(path.read_text(encoding="utf-8"))
            else:
                ET.parse(path)
        except (OSError, UnicodeDecodeError, ValueError, ET.ParseError) as exc:
            raise InputFileError(f"site {site.name}: cannot parse {path}: {_one_line(exc)}") from None
    try:
        load_site_data(site, params)
    except Exception as exc:  # sumolib and the loaders raise many types on a well-formed but wrong file
        # The loaders' ValueErrors explain themselves; anything else (a KeyError from sumolib on a
        # network without its attributes) needs the type and where to look.
        detail = _one_line(exc) if type(exc) is ValueError else f"{type(exc).__name__}: {_one_line(exc)}"
        raise InputFileError(
            f"site {site.name}: the files in {site.network_dir} do not make a usable site: {detail}"
        ) from None
