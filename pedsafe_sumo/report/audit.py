"""The report's audit of a run: the collision witness against the loop (report/witness_check.py) and the
staging diagnostics (report/staging_checks.py), printed, written as CSV and Markdown under DIR/tables/, and
handed to the HTML page as sections."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from pedsafe_sumo.report.indexes import KeptLogs
from pedsafe_sumo.report.rundir import RunDirectory
from pedsafe_sumo.report.staging_checks import STAGING_TITLE, staging_diagnostics, staging_rows
from pedsafe_sumo.report.tables import markdown_table, text_table
from pedsafe_sumo.report.witness_check import (
    DISAGREEMENTS_TITLE,
    WITNESS_TITLE,
    disagreement_rows,
    witness_agreement,
    witness_rows,
)

WITNESS_CSV = "witness.csv"
DISAGREEMENTS_CSV = "witness_disagreements.csv"
STAGING_CSV = "staging.csv"
AUDIT_MD = "audit.md"


@dataclass(frozen=True)
class Section:
    """A titled table as the HTML page shows it (title: first line the heading, the rest its note)."""

    title: str
    header: list[str]
    rows: list[list[str]]
    table_id: str
    #: the page's short heading (the rest of the title is its caption); "" = the title's words before ": "
    heading: str = ""


def audit(run: RunDirectory, tables_dir: Path, say) -> tuple[list[Path], list[Section]]:
    """Print the witness table (and the disagreeing episodes) and the staging diagnostics; write them to
    tables_dir (witness.csv, witness_disagreements.csv, staging.csv, audit.md); return (files, sections)."""
    episodes = run.episodes
    witness, disagreements = witness_agreement(episodes, KeptLogs(run))
    sections = [Section(WITNESS_TITLE, *witness_rows(witness), "witness")]
    if len(disagreements):
        sections.append(
            Section(
                DISAGREEMENTS_TITLE,
                *disagreement_rows(disagreements),
                "witness-disagreements",
                "Witness disagreements",
            )
        )
    else:
        say("collision witness: no episode where the loop and the witness disagree")
    staging = staging_diagnostics(episodes)
    sections.append(Section(STAGING_TITLE, *staging_rows(staging), "staging", "Staging diagnostics"))

    tables_dir.mkdir(parents=True, exist_ok=True)
    written = []
    for name, table in ((WITNESS_CSV, witness), (DISAGREEMENTS_CSV, disagreements), (STAGING_CSV, staging)):
        table.to_csv(tables_dir / name, index=False)
        written.append(tables_dir / name)
    markdown = [f"**{run.incomplete}**\n"] if run.incomplete else []
    for section in sections:
        say(section.title)
        say(text_table(section.header, section.rows))
        say("")
        first, _, rest = section.title.partition("\n")
        note = f"{rest}\n\n" if rest else ""
        markdown.append(f"**{first}**\n\n{note}{markdown_table(section.header, section.rows)}\n")
    (tables_dir / AUDIT_MD).write_text("\n".join(markdown), encoding="utf-8")
    written.append(tables_dir / AUDIT_MD)
    return written, sections
