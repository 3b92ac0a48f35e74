"""Report of a batch run: Table I with 95% intervals, the paired SV-vs-V2I tests, and the figures.

    python -m pedsafe_sumo.report DIR
    python -m pedsafe_sumo.report DIR --partial     # a batch that has not finished yet

Prints the tables and writes DIR/tables/{table1,paired}.{csv,md}, the checks of the indexes, the collision
witness and the staging diagnostics (DIR/tables/*.csv, indexes.md, audit.md) and DIR/figures/*.png (see
docs/report.md). Bad input (no DIR, no episodes.parquet, missing columns) ends in one line on stderr
and exit code 2; so does a batch that has not finished, unless --partial: then the report covers the
chunks finished so far, says INCOMPLETE RUN in its first and last lines and in its Markdown tables,
and writes under DIR/partial/ so that nothing is taken for the final report.
All of it also goes into one self-contained page, DIR/report.html (pedsafe_sumo/report/html.py).
"""

from __future__ import annotations

import argparse
import math
import os
import sys
from pathlib import Path
from typing import Any

import pandas as pd
from matplotlib.figure import Figure

from pedsafe_sumo.confine import ConfinementError, check_tree
from pedsafe_sumo.io.outputs import check_output_dir, check_output_file
from pedsafe_sumo.network.approaches import leg_argument
from pedsafe_sumo.report import figures, impact
from pedsafe_sumo.report import indexes as idx
from pedsafe_sumo.report.audit import Section, audit
from pedsafe_sumo.report.html import (
    HTML_FILE,
    ApproachTable,
    PageTable,
    page_context,
    write_html_report,
    write_page,
)
from pedsafe_sumo.report.rundir import (
    ReportError,
    RunDirectory,
    approaches_of,
    load_pooled,
    load_run,
    load_run_per_approach,
    run_header,
)
from pedsafe_sumo.report.staging_checks import collision_type_columns
from pedsafe_sumo.report.summaries import (
    choose_case_pair,
    detection_summaries,
    load_case_traces,
    ok_episodes,
)
from pedsafe_sumo.report.tables import (
    TABLE_ONE_TITLE,
    condition_label,
    estimator_note,
    markdown_table,
    paired_of_run,
    paired_rows,
    paired_title,
    table_one_of_run,
    table_one_rows,
    text_table,
    v2i_only_note,
    write_tables,
)
from pedsafe_sumo.sampling.pooling import first_estimated_stage

TABLES_DIR = "tables"
FIGURES_DIR = "figures"
#: Where the report of an unfinished batch goes (--partial), away from the final report's files.
PARTIAL_DIR = "partial"


def _fmt_time(value: float) -> str:
    return "never" if math.isnan(value) else f"{value:.2f} s"


#: The report's figures, in the order it draws them, and their files under DIR/figures/.
FIGURE_FILES = {
    "injury_vs_age": figures.FIGURE_FILES["injury_vs_age"],
    "injury_vs_speed": figures.FIGURE_FILES["injury_vs_speed"],
    "impact_speed": impact.FIGURE_FILE,
    "first_detection_distance": figures.FIGURE_FILES["first_detection_distance"],
    "case_speed_vs_frame": figures.FIGURE_FILES["case_speed_vs_frame"],
}


def _quiet(line: str) -> None:
    """A `say` that says nothing."""


def draw_figure(run: RunDirectory, name: str, path: Path | None = None, say=_quiet) -> Figure | None:
    """One of the report's figures (a key of FIGURE_FILES), written as a PNG at `path` when given; None
    when the run's data do not allow it, `say` getting the line that says why (and the figure's notes)."""
    if name not in FIGURE_FILES:
        raise ReportError(f"unknown figure '{name}' (known: {', '.join(FIGURE_FILES)})")
    ok = ok_episodes(run.episodes)
    if name in ("injury_vs_age", "injury_vs_speed"):
        if not figures.collision_scenarios(ok):
            say("note: no collision (status ok) in this run: injury figures skipped")
            return None
        draw = figures.injury_vs_age if name == "injury_vs_age" else figures.injury_vs_speed
        return draw(ok, path)
    if name == "impact_speed":
        say(impact.intercept_note(ok))
        return impact.impact_speed_histogram(ok, path)
    if name == "first_detection_distance":
        summaries = detection_summaries(run.episodes)
        if not summaries:
            say("note: no episode with status ok: first-detection figure skipped")
            return None
        for s in summaries:
            where = (
                f"90% of episodes detect beyond {s.distance_90_m:.1f} m"
                if math.isfinite(s.distance_90_m)
                else "fewer than 90% of episodes ever detect the pedestrian"
            )
            say(
                f"first detection, {s.scenario} {condition_label(s.condition)}: {where} "
                f"({s.n_never} of {s.n} never)"
            )
        return figures.first_detection_distance(summaries, path)
    pair = choose_case_pair(run)
    if pair is None:
        say(
            f"note: no case pair (SV and V2I case logs of the same seed) in {run.cases_dir}: "
            "case figure skipped"
        )
        return None
    try:
        traces = load_case_traces(run, pair)
    except Exception as exc:  # a broken case file should not cost the rest of the report
        say(
            f"note: cannot read the case logs of {pair.scenario} seed {pair.seed} ({exc}): "
            "case figure skipped"
        )
        return None
    say(
        f"case figure: {pair.scenario} episode {pair.episode} (seed {pair.seed}), first perceived "
        f"SV {_fmt_time(pair.sv_first_detection_s)}, V2I {_fmt_time(pair.v2i_first_detection_s)}"
    )
    return figures.case_speed_vs_frame(pair, traces, path)


def write_figures(run: RunDirectory, out_dir: Path, say) -> list[Path]:
    """Every figure the run's data allow; `say` gets one line per figure written or skipped."""
    written: list[Path] = []
    said: list[str] = [""]

    def say_once(line: str) -> None:  # the two injury figures share their note: said once
        if line != said[-1]:
            said.append(line)
            say(line)

    for name, file_name in FIGURE_FILES.items():
        if draw_figure(run, name, out_dir / file_name, say_once) is not None:
            written.append(out_dir / file_name)
    return written


CONTACTS_TITLE = (
    "Stationary contacts: the pedestrian touched the ego while it stood (speed below 0.1 m/s);\n"
    "neither a collision nor an injury in Table I"
)
AGREEMENT_TITLE = (
    "Our collision against SUMO's own collision check (sumo_collision), on the episodes where SUMO can see\n"
    "(not null); SUMO null = episodes where SUMO cannot see the pedestrian (mid-block: no crossing lane)"
)
PET_TITLE = (
    "Post-encroachment time: episodes where it is defined (both passed the crossing point of their paths);\n"
    "the others by why not, read from the kept logs (cases/, or steplogs/ with --keep-logs all)"
)


def _proximity_title(model) -> str:
    return (
        f"Proximity ({model.scope} steps): close passes over the episodes with an interaction and no "
        f"collision; close pass = clearance between the bodies below {model.close_pass_clearance_m:g} m\n"
        f"at an ego speed above {model.close_pass_min_speed_mps:g} m/s; "
        f"DRAC over {model.drac_threshold_mps2:g} m/s2 = harder than a comfortable stop "
        "(params [safety], docs/safety_indexes.md)"
    )


def index_checks(run: RunDirectory, tables_dir: Path, say) -> tuple[list[Path], list[Section]]:
    """Stationary contacts, our collision against SUMO's, where PET is defined, the proximity measure:
    printed, and written to tables_dir (indexes.md and one CSV each); returns the files and the page's
    sections. Columns a run lacks are a note."""
    episodes = run.episodes
    sections: list[tuple[str, str, Any, Any]] = []  # (title, csv name, table, rows function)
    contacts = idx.stationary_contacts(episodes)
    if contacts is None:
        say(idx.missing_note(episodes, ("contact_stationary",), "the stationary-contact count"))
    else:
        sections.append((CONTACTS_TITLE, "contacts.csv", contacts, idx.contacts_rows))
    agreement = idx.collision_agreement(episodes)
    if agreement is None:
        say(idx.missing_note(episodes, ("sumo_collision",), "the agreement with SUMO"))
    else:
        title = AGREEMENT_TITLE
        if not idx.sumo_collision_is_nullable(episodes):
            title += (
                "\nnote: this run's sumo_collision is a plain boolean (it cannot say 'SUMO cannot see'): "
                "False also where SUMO could not see, so those episodes are compared too"
            )
        sections.append((title, "agreement.csv", agreement, idx.agreement_rows))
    if "pet_s" in episodes.columns:
        pet = idx.pet_coverage(episodes, idx.KeptLogs(run))
        sections.append((PET_TITLE, "pet.csv", pet, idx.pet_rows))
    else:
        say(idx.missing_note(episodes, ("pet_s",), "the PET summary"))
    model = idx.proximity_model_of_run(run.run_info)
    proximity = idx.proximity_summary(episodes, model.drac_threshold_mps2)
    if proximity is None:
        say(idx.missing_note(episodes, idx.PROXIMITY_COLUMNS, "the proximity summary"))
    else:
        sections.append((_proximity_title(model), "proximity.csv", proximity, idx.proximity_rows))

    tables_dir.mkdir(parents=True, exist_ok=True)
    written: list[Path] = []
    markdown = [f"**{run.incomplete}**\n"] if run.incomplete else []
    page_sections = []
    for title, csv_name, table, rows_of in sections:
        header, rows = rows_of(table)
        page_sections.append(
            Section(title, header, rows, csv_name.removesuffix(".csv"), SHORT_HEADINGS.get(csv_name, ""))
        )
        say(title)
        say(text_table(header, rows))
        say("")
        path = tables_dir / csv_name
        table.to_csv(path, index=False)
        written.append(path)
        first, _, rest = title.partition("\n")
        markdown.append(
            f"**{first}**\n\n{rest}\n\n{markdown_table(header, rows)}\n"
            if rest
            else f"**{first}**\n\n{markdown_table(header, rows)}\n"
        )
    if sections:
        path = tables_dir / "indexes.md"
        path.write_text("\n".join(markdown), encoding="utf-8")
        written.append(path)
    return written, page_sections


#: The page's headings of the index checks whose title does not start with one.
SHORT_HEADINGS = {"agreement.csv": "Agreement with SUMO's collision check"}
DETECTION_TITLE = (
    "First detection: per scenario and condition, the distance X that 90% of the episodes first detect "
    "the pedestrian at or beyond (episodes that never detect count against it; figure "
    "first_detection_distance.png)"
)


def detection_section(run: RunDirectory) -> Section | None:
    """The first-detection distances the report prints, as a table for the page."""
    summaries = detection_summaries(run.episodes)
    if not summaries:
        return None
    rows = [
        [
            s.scenario,
            condition_label(s.condition),
            str(s.n),
            str(s.n_never),
            f"{s.distance_90_m:.1f} m" if math.isfinite(s.distance_90_m) else "fewer than 90% ever detect",
        ]
        for s in summaries
    ]
    header = ["scenario", "condition", "n", "never detected", "90% detect beyond"]
    return Section(DETECTION_TITLE, header, rows, "first-detection", "First detection")


def tables_of(
    run: RunDirectory, paired_episodes: pd.DataFrame | None = None
) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Table I (with the collisions by type) and the paired tests of a run; `paired_episodes`, the rows the
    paired tests match (the run's own by default)."""
    try:
        first_stage = first_estimated_stage(run.run_info)
        table = table_one_of_run(
            run.episodes, proposals=(run.run_info or {}).get("sampler_proposals"), first_stage=first_stage
        )
        paired = paired_of_run(run.episodes if paired_episodes is None else paired_episodes, first_stage)
        table = collision_type_columns(table, run.episodes)
    except ValueError as exc:
        raise ReportError(f"{run.path}: {exc}") from exc
    return table, paired


def _out_dir(run: RunDirectory, names: tuple[str, ...]) -> Path:
    """Where the report of `run` goes, checked: no link leads a write out of the run directory."""
    out_dir = run.path / PARTIAL_DIR if run.incomplete else run.path
    if run.selected_approach:
        out_dir = out_dir / f"approach_{run.selected_approach}"
    try:  # no link in a received run directory leads the writes below out of it (docs/trust.md)
        check_tree(run.path, [str(out_dir.relative_to(run.path) / n) for n in names], "report")
    except ConfinementError as exc:
        raise ReportError(str(exc)) from None
    for directory in (out_dir, *(out_dir / n for n in names if n != HTML_FILE)):
        check_output_dir(directory, "report into", ReportError)
    check_output_file(out_dir / HTML_FILE, "report into", ReportError, make_parents=True)
    return out_dir


def report(run: RunDirectory, say=print) -> list[Path]:
    """Print the tables, write tables and figures under the run directory; returns the files written."""
    table, paired = tables_of(run)
    if run.incomplete:
        say(run.incomplete)
    if run.run_info is not None:
        say(run_header(run))
    if run.run_info_problem:
        say(f"note: {run.run_info_problem}")
    say("")
    say(TABLE_ONE_TITLE)
    say(text_table(*table_one_rows(table)))
    if estimator_note(table):
        say(estimator_note(table))
    note = v2i_only_note(run.run_info)
    if note:
        say(note)
    if "collision_type" not in run.episodes.columns:
        say(idx.missing_note(run.episodes, ("collision_type",), "Table I's collisions by type"))
    say("")
    say(paired_title(paired))
    say(text_table(*paired_rows(paired)))
    say("")
    out_dir = _out_dir(run, (TABLES_DIR, FIGURES_DIR, HTML_FILE))
    written = write_tables(table, paired, out_dir / TABLES_DIR, banner=run.incomplete)
    index_files, sections = index_checks(run, out_dir / TABLES_DIR, say)
    written += index_files
    detection = detection_section(run)
    sections += [detection] if detection else []
    audited, audit_sections = audit(run, out_dir / TABLES_DIR, say)
    written += audited
    sections += audit_sections
    written += write_figures(run, out_dir / FIGURES_DIR, say)
    written.append(
        write_html_report(run, table, paired, out_dir / FIGURES_DIR, out_dir / HTML_FILE, sections)
    )
    say("wrote " + ", ".join(str(p.relative_to(run.path)) for p in written) + f" in {run.path}")
    if run.incomplete:
        say(run.incomplete)
    return written


def _paired_within_approach(episodes: pd.DataFrame) -> pd.DataFrame:
    """The rows with episode numbers made distinct per approach, so that the paired tests pool the
    approaches while matching SV and V2I within one (every approach runs the same episode numbers)."""
    arms = {arm: k for k, arm in enumerate(pd.unique(episodes["approach"]))}
    stride = int(episodes["episode"].max()) + 1
    return episodes.assign(episode=episodes["approach"].map(arms).astype(int) * stride + episodes["episode"])


#: The caption of an approach's Table I on the pooled page.
APPROACH_TABLE_CAPTION = "The episodes on this approach only; columns and intervals as in Table I below."


def report_every_approach(path: Path, partial: bool, say=print) -> list[Path]:
    """A run of several approaches (batch --approach all): each approach in full as `--approach` reports
    it (under DIR/approach_<arm>/), then Table I and the paired tests pooled over the approaches (SV and V2I
    matched within an approach) in DIR/tables/ and DIR/report.html, whose page also shows every approach's
    Table I and links to its page."""
    written: list[Path] = []
    approach_tables = []
    for arm, run in load_run_per_approach(path, partial).items():
        say(f"== approach {arm} ==")
        written += report(run, say)
        say("")
        table, _ = tables_of(run)
        approach_tables.append(
            ApproachTable(
                arm,
                PageTable(
                    f"Table I, approach {arm}",
                    APPROACH_TABLE_CAPTION,
                    *table_one_rows(table),
                    f"table-one-{arm}",
                ),
                f"approach_{arm}/{HTML_FILE}",
            )
        )
    pooled = load_pooled(path, partial)
    arms = ", ".join(a.approach for a in approach_tables)
    table, paired = tables_of(pooled, _paired_within_approach(pooled.episodes))
    say(f"== pooled over approaches {arms} (SV and V2I paired within an approach) ==")
    if pooled.incomplete:
        say(pooled.incomplete)
    say(TABLE_ONE_TITLE)
    say(text_table(*table_one_rows(table)))
    say("")
    say(paired_title(paired))
    say(text_table(*paired_rows(paired)))
    say("")
    out_dir = _out_dir(pooled, (TABLES_DIR, HTML_FILE))
    pooled_files = write_tables(table, paired, out_dir / TABLES_DIR, banner=pooled.incomplete)
    context = page_context(
        pooled,
        table,
        paired,
        None,
        approach_tables=approach_tables,
        title_suffix=f" (approaches {arms} pooled)",
    )
    pooled_files.append(write_page(context, out_dir / HTML_FILE))
    say("wrote " + ", ".join(str(p.relative_to(path)) for p in pooled_files) + f" in {path}")
    if pooled.incomplete:
        say(pooled.incomplete)
    return written + pooled_files


class _StdoutLines:
    """print() that stops printing, not reporting, when stdout goes away (`... | head`)."""

    def __init__(self) -> None:
        self.closed = False

    def __call__(self, line: str) -> None:
        if self.closed:
            return
        try:
            print(line, flush=True)
        except BrokenPipeError:
            self.closed = True
            # Further writes, and the interpreter's last flush, go nowhere instead of failing.
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m pedsafe_sumo.report", description=__doc__.splitlines()[0]
    )
    parser.add_argument(
        "run_dir", metavar="DIR", type=Path, help="run directory written by pedsafe_sumo.batch"
    )
    parser.add_argument(
        "--partial",
        action="store_true",
        help="report a batch that has not finished on the chunks done so far (written under DIR/partial/)",
    )
    parser.add_argument(
        "--approach",
        type=leg_argument,
        help="report the episodes on this approach only (a batch run with --approach all holds several; "
        "without this option each is reported, then all of them pooled)",
    )
    args = parser.parse_args(argv)
    say = _StdoutLines()
    try:
        if args.approach is None and len(approaches_of(args.run_dir, args.partial)) > 1:
            report_every_approach(args.run_dir, args.partial, say)
        else:
            report(load_run(args.run_dir, partial=args.partial, approach=args.approach), say=say)
    except ReportError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
