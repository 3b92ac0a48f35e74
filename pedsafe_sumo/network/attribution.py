"""The ODbL attribution carried by every file derived from OpenStreetMap."""

from __future__ import annotations

from pathlib import Path

from pedsafe_sumo import OSM_ATTRIBUTION


def add_attribution_comment(path: Path) -> None:
    """Insert the attribution as an XML comment after the declaration (once)."""
    text = path.read_text(encoding="utf-8")
    comment = f"<!-- {OSM_ATTRIBUTION} -->\n"
    if comment in text:
        return
    if text.startswith("<?xml"):
        end = text.index("?>") + 2
        text = text[:end] + "\n" + comment + text[end:].lstrip("\n")
    else:
        text = comment + text
    path.write_text(text, encoding="utf-8")
