"""DIR/report.html: the run's report as one self-contained page (every image embedded as base64), rendered
from the Jinja2 templates of pedsafe_sumo/report/templates/ with autoescaping on.

From the top: the verdict (per scenario and condition the rates with their 95% intervals, per scenario the
paired SV-vs-V2I test in words, the stack under test); Table I per approach where the run has several;
Table I and the paired tests (the same rows as the text report); every diagnostic table (the index checks,
the first detection, the collision witness, the staging diagnostics); every figure under the report's
figures/ folder; every logged case (a picture, its outcome, the commands that replay and export it),
filterable by scenario, condition and outcome; the configuration as a table, with the raw run.json folded.

A case's picture is the replay tool's screenshot when one was saved beside the case log
(`cases/<case>.png`, the page prints the command); else a plot of the logged trajectories drawn here from
the case log, which costs no simulation.
"""

from __future__ import annotations

import base64
import io
import json
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import jinja2
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import pandas as pd  # noqa: E402

from pedsafe_sumo.report.audit import Section  # noqa: E402
from pedsafe_sumo.report.rundir import RunDirectory, run_header  # noqa: E402
from pedsafe_sumo.report.tables import (  # noqa: E402
    TABLE_ONE_TITLE,
    condition_label,
    estimator_note,
    is_weighted,
    paired_rows,
    paired_title,
    table_one_rows,
)
from pedsafe_sumo.report.verdict import config_rows, paired_readings, rate_rows  # noqa: E402

HTML_FILE = "report.html"
TEMPLATE = "report.html.j2"
#: Headings of the titles whose first words do not make one (the rest of the title is the caption).
PAIRED_HEADING = "Paired SV vs V2I"
#: A title's words before its first ": " make its heading when they are at most this long.
MAX_HEADING_CHARS = 40


@dataclass(frozen=True)
class PageTable:
    """A table as the page shows it: a short heading, a caption paragraph, the cells."""

    heading: str
    caption: str
    header: list[str]
    rows: list[list[str]]
    table_id: str
    notes: list[str] = field(default_factory=list)


@dataclass(frozen=True)
class ApproachTable:
    """Table I of one approach of a run with several (report of a batch --approach all)."""

    approach: str
    table: PageTable
    #: the approach's own page, relative to the pooled one
    link: str


def split_title(title: str, heading: str = "") -> tuple[str, str]:
    """(heading, caption) of a table title: `heading` when given (the caption is the rest of the title), else
    the title's words before its first ": " when they are short, else the whole title. A title's lines are
    joined with "; " where the line ends without punctuation."""
    lines = [line.strip() for line in title.splitlines() if line.strip()]
    text = "".join(
        line + ("" if k == len(lines) - 1 else " " if line[-1] in ";:.," else "; ")
        for k, line in enumerate(lines)
    )
    if heading:
        rest = text[len(heading) :].lstrip(" :") if text.startswith(heading) else text
        inner, close, after = rest[1:].partition("): ")
        if rest.startswith("(") and close:  # "Heading (qualifier): the rest" -> "Qualifier: the rest"
            rest = f"{inner}: {after}"
        return heading, _capitalised(rest)
    first, sep, rest = text.partition(": ")
    if sep and len(first) <= MAX_HEADING_CHARS:
        return first, _capitalised(rest)
    return text, ""


def _capitalised(text: str) -> str:
    return text[:1].upper() + text[1:]


def page_table(
    title: str, header: list[str], rows: list[list[str]], table_id: str, heading: str = ""
) -> PageTable:
    short, caption = split_title(title, heading)
    return PageTable(short, caption, header, rows, table_id)


def section_table(section: Section) -> PageTable:
    return page_table(section.title, section.header, section.rows, section.table_id, section.heading)


def _png_data_uri(data: bytes) -> str:
    return "data:image/png;base64," + base64.b64encode(data).decode("ascii")


def _case_plot(log: pd.DataFrame, title: str) -> bytes:
    """The logged centre paths of the ego and the pedestrian, with the first contact marked."""
    fig, ax = plt.subplots(figsize=(4.2, 3.2), dpi=90)
    ax.plot(log["ego_x_m"], log["ego_y_m"], color="#c0208a", lw=2, label="ego (centre)")
    ax.plot(log["ped_x_m"], log["ped_y_m"], color="#e08000", lw=2, label="pedestrian")
    ax.plot(log["ego_x_m"].iloc[0], log["ego_y_m"].iloc[0], "o", color="#c0208a")
    ax.plot(log["ped_x_m"].iloc[0], log["ped_y_m"].iloc[0], "o", color="#e08000")
    if "clearance_m" in log.columns and (log["clearance_m"] <= 0).any():
        k = int((log["clearance_m"] <= 0).to_numpy().nonzero()[0][0])
        ax.plot(
            log["ped_x_m"].iloc[k],
            log["ped_y_m"].iloc[k],
            "x",
            color="#0050d0",
            ms=10,
            mew=2,
            label="contact",
        )
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_title(title, fontsize=9)
    ax.set_xlabel("x [m]", fontsize=8)
    ax.set_ylabel("y [m]", fontsize=8)
    ax.tick_params(labelsize=7)
    ax.legend(fontsize=7, loc="best")
    fig.tight_layout()
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png")
    plt.close(fig)
    return buffer.getvalue()


def _fmt(value: Any, unit: str, digits: int = 2) -> str:
    try:
        number = float(value)
    except (TypeError, ValueError):
        return "n/a"
    return "n/a" if math.isnan(number) else f"{number:.{digits}f} {unit}"


def _row_approach(run: RunDirectory, row: pd.Series) -> str:
    """The approach of an episode row: its own column where the run has one, else the run's."""
    value = row.get("approach")
    return str(value) if isinstance(value, str) and value else run.approach


def replay_commands(run: RunDirectory, row: pd.Series) -> list[str]:
    """The commands that replay a case, render its picture (beside its case log, where the page looks)
    and export it as FCD. A case of a batch run with --approach (its log named after the arm) is picked
    with --approach: the run holds the same episode on every approach."""
    scenario, condition = row["scenario"], row["condition"]
    episode, seed = int(row["episode"]), int(row["seed"])
    approach = _row_approach(run, row)
    log_path = run.case_path(scenario, condition, seed, approach)
    arm = approach if approach and log_path.stem.endswith(f"_{approach}") else ""
    base = (
        f"python -m pedsafe_sumo.replay {run.path} --episode {episode} --condition {condition} "
        f"--scenario {scenario}" + (f" --approach {arm}" if arm else "")
    )
    return [
        base,
        f"{base} --screenshot {log_path.with_suffix('.png')}",
        f"{base} --export-fcd {log_path.stem}.fcd.xml",
    ]


def case_rows(run: RunDirectory) -> pd.DataFrame:
    """The episode rows with a case log, collisions first, then conflicts, then the rest."""
    episodes = run.episodes
    has_case = [
        run.case_path(row["scenario"], row["condition"], int(row["seed"]), _row_approach(run, row)).is_file()
        for _, row in episodes.iterrows()
    ]
    cases = episodes[has_case]
    return cases.assign(
        _collision=~cases["collision"].astype("boolean").fillna(False),
        _conflict=~cases["conflict"].astype("boolean").fillna(False),
    ).sort_values(["_collision", "_conflict", "scenario", "episode", "condition"], kind="stable")


@dataclass(frozen=True)
class CaseCard:
    scenario: str
    condition: str
    approach: str
    episode: int
    seed: int
    outcome: str
    outcome_text: str
    details: str
    picture: str
    caption: str
    commands: list[str]


def case_card(run: RunDirectory, row: pd.Series) -> CaseCard:
    scenario, condition = str(row["scenario"]), str(row["condition"])
    episode, seed = int(row["episode"]), int(row["seed"])
    approach = _row_approach(run, row)
    log_path = run.case_path(scenario, condition, seed, approach)
    screenshot = log_path.with_suffix(".png")
    label = f"{scenario} episode {episode}, {condition_label(condition)} (seed {seed})"
    picture: bytes | None
    if screenshot.is_file():
        picture, caption = screenshot.read_bytes(), "replay screenshot"
    else:
        try:
            log = pd.read_parquet(log_path, partitioning=None)
            picture, caption = _case_plot(log, label), "logged trajectories"
        except Exception as exc:  # a broken case file costs its picture, not the page
            picture, caption = None, f"case log unreadable: {exc}"
    if bool(row.get("collision", False)):
        outcome, text = "collision", f"collision at {_fmt(row.get('impact_speed_mps'), 'm/s')}"
    elif bool(row.get("conflict", False)):
        outcome, text = "conflict", "conflict"
    else:
        outcome, text = "none", "no collision, no conflict"
    sensors = str(row.get("detected_by", "")) or "never"
    details = (
        f"min TTC {_fmt(row.get('min_ttc_s'), 's')}, first detection "
        f"{_fmt(row.get('first_detection_distance_m'), 'm', 1)} ({sensors})"
    )
    return CaseCard(
        scenario,
        condition_label(condition),
        approach,
        episode,
        seed,
        outcome,
        text,
        details,
        _png_data_uri(picture) if picture else "",
        caption,
        replay_commands(run, row),
    )


def _environment() -> jinja2.Environment:
    return jinja2.Environment(
        loader=jinja2.PackageLoader("pedsafe_sumo.report", "templates"),
        autoescape=True,
        undefined=jinja2.StrictUndefined,  # a name the page uses but was not given is an error, not ""
        trim_blocks=True,
        lstrip_blocks=True,
    )


def render_page(context: dict[str, Any]) -> str:
    """The page's HTML from the template and `context` (every name the template uses)."""
    return _environment().get_template(TEMPLATE).render(**context)


#: The figures in the page's order, with what each shows; a figure not named here follows, by name.
FIGURE_CAPTIONS = {
    "injury_vs_age.png": "Injury probability against pedestrian age, a panel per scenario with a collision",
    "injury_vs_speed.png": "Injury probability against initial speed, a panel per scenario with a collision",
    "impact_speed.png": "Impact speeds of the collisions",
    "first_detection_distance.png": "Distance at first detection, a panel per scenario",
    "case_speed_vs_frame.png": "One paired case: the ego's speed under SV and V2I, and the first detections",
}


@dataclass(frozen=True)
class PageFigure:
    name: str
    caption: str
    uri: str


def figure_list(figures_dir: Path) -> list[PageFigure]:
    """Every PNG of the report's figures folder, in FIGURE_CAPTIONS' order, then the others by name."""
    pictures = sorted(figures_dir.glob("*.png")) if figures_dir.is_dir() else []
    order = list(FIGURE_CAPTIONS)
    pictures.sort(key=lambda p: (order.index(p.name) if p.name in order else len(order), p.name))
    return [
        PageFigure(p.name, FIGURE_CAPTIONS.get(p.name, p.stem), _png_data_uri(p.read_bytes()))
        for p in pictures
    ]


def page_context(
    run: RunDirectory,
    table: pd.DataFrame,
    paired: pd.DataFrame,
    figures_dir: Path | None,
    sections: Sequence[Section] = (),
    approach_tables: Sequence[ApproachTable] = (),
    title_suffix: str = "",
) -> dict[str, Any]:
    """Everything the template shows."""
    info = run.run_info or {}
    cards = [case_card(run, row) for _, row in case_rows(run).iterrows()] if figures_dir is not None else []
    table_one = page_table(TABLE_ONE_TITLE, *table_one_rows(table), "table-one", heading="Table I")
    note = estimator_note(table)
    if note:
        table_one.notes.append(note)
    return {
        "run_name": run.path.name + title_suffix,
        "run_line": run_header(run),
        "incomplete": run.incomplete,
        "run_info_problem": run.run_info_problem,
        "algorithm": str(info.get("algorithm", "")),
        "rates": rate_rows(table, is_weighted(run.episodes)),
        "readings": paired_readings(paired),
        "weighted": "test" in paired.columns,
        "approach_tables": list(approach_tables),
        "table_one": table_one,
        "paired": page_table(
            paired_title(paired), *paired_rows(paired), "paired-tests", heading=PAIRED_HEADING
        ),
        "diagnostics": [section_table(s) for s in sections],
        "figures": figure_list(figures_dir) if figures_dir is not None else [],
        "show_figures_and_cases": figures_dir is not None,
        "cases": cards,
        "cases_dir": str(run.cases_dir),
        "filters": {
            "scenario": sorted({c.scenario for c in cards}),
            "condition": sorted({c.condition for c in cards}),
            "outcome": [o for o in ("collision", "conflict", "none") if any(c.outcome == o for c in cards)],
            "approach": sorted({c.approach for c in cards if c.approach}),
        },
        "config": config_rows(run.run_info),
        "run_json": json.dumps(run.run_info, indent=1, sort_keys=True, default=str)
        if run.run_info is not None
        else "",
    }


def write_page(context: dict[str, Any], out_path: Path) -> Path:
    """Render `context` to `out_path` (through a temporary file) and return its path."""
    out_path.parent.mkdir(parents=True, exist_ok=True)
    tmp = out_path.with_name(out_path.name + ".tmp")
    tmp.write_text(render_page(context), encoding="utf-8")
    tmp.replace(out_path)
    return out_path


def write_html_report(
    run: RunDirectory,
    table: pd.DataFrame,
    paired: pd.DataFrame,
    figures_dir: Path,
    out_path: Path,
    sections: Sequence[Section] = (),
) -> Path:
    """Write the page of one run (or one approach of it) to `out_path`; `sections` are the diagnostic
    tables (the index checks, the first detection, the witness, the staging diagnostics)."""
    return write_page(page_context(run, table, paired, figures_dir, sections), out_path)
