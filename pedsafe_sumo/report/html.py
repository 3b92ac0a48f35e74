"""DIR/report.html: the run's report as one self-contained page (every image embedded as base64).

Sections: the run line, Table I and the paired SV-vs-V2I tests (the same rows as the text report), the
collision witness and the staging diagnostics (report/audit.py),
every figure under the report's figures/ folder, a gallery of the logged cases (a picture of each,
its outcome, and the commands that replay and export it) and the run's configuration (run.json).

A case's picture is the replay tool's screenshot when one was saved beside the case log
(`cases/<case>.png`, the gallery prints the command); else a plot of the logged trajectories drawn
here from the case log, which costs no simulation.
"""

from __future__ import annotations

import base64
import html
import io
import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import pandas as pd  # noqa: E402

from pedsafe_sumo.report.audit import Section  # noqa: E402
from pedsafe_sumo.report.rundir import RunDirectory, run_header  # noqa: E402
from pedsafe_sumo.report.tables import (  # noqa: E402
    TABLE_ONE_TITLE,
    condition_label,
    paired_rows,
    paired_title,
    table_one_rows,
)

HTML_FILE = "report.html"
#: Cases shown in the gallery (collisions first, then conflicts); the page says how many more there are.
MAX_GALLERY_CASES = 24

STYLE = """
body { font-family: system-ui, sans-serif; margin: 2em auto; max-width: 1200px; color: #222; }
h1 { font-size: 1.6em; } h2 { border-bottom: 1px solid #ccc; padding-bottom: .2em; margin-top: 1.6em; }
table.data { border-collapse: collapse; margin: .6em 0; font-size: .92em; }
table.data th, table.data td { border: 1px solid #bbb; padding: .3em .6em; text-align: right; }
table.data th { background: #e8eef6; }
table.data td:first-child, table.data td:nth-child(2) { text-align: left; }
.figures img { max-width: 100%; border: 1px solid #ddd; margin: .4em 0; }
.gallery { display: grid; grid-template-columns: repeat(auto-fill, minmax(340px, 1fr)); gap: 1em; }
.case { border: 1px solid #ccc; border-radius: 6px; padding: .6em; background: #fafafa; }
.case img { width: 100%; } .case code { font-size: .78em; word-break: break-all; display: block; }
.collision { color: #b00020; font-weight: bold; } .conflict { color: #b06000; font-weight: bold; }
pre { background: #f4f4f4; padding: .8em; overflow-x: auto; font-size: .8em; }
.banner { background: #ffe08a; padding: .6em; font-weight: bold; }
"""


def _png_data_uri(data: bytes) -> str:
    return "data:image/png;base64," + base64.b64encode(data).decode("ascii")


def _table_html(header: list[str], rows: list[list[str]], table_id: str) -> str:
    head = "".join(f"<th>{html.escape(h)}</th>" for h in header)
    body = "".join("<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in row) + "</tr>" for row in rows)
    return f'<table class="data" id="{table_id}"><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>'


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


def _case_card(run: RunDirectory, row: pd.Series) -> str:
    scenario, condition, episode, seed = (
        row["scenario"],
        row["condition"],
        int(row["episode"]),
        int(row["seed"]),
    )
    log_path = run.case_path(scenario, condition, seed)
    screenshot = log_path.with_suffix(".png")
    label = f"{scenario} episode {episode}, {condition_label(condition)} (seed {seed})"
    if screenshot.is_file():
        picture, caption = screenshot.read_bytes(), "replay screenshot"
    else:
        try:
            log = pd.read_parquet(log_path, partitioning=None)
            picture, caption = _case_plot(log, label), "logged trajectories"
        except Exception as exc:  # a broken case file costs its picture, not the page
            picture, caption = None, f"case log unreadable: {exc}"
    if bool(row.get("collision", False)):
        outcome = f'<span class="collision">collision at {_fmt(row.get("impact_speed_mps"), "m/s")}</span>'
    elif bool(row.get("conflict", False)):
        outcome = '<span class="conflict">conflict</span>'
    else:
        outcome = "no collision, no conflict"
    commands = replay_commands(run, row)
    image = f'<img alt="{html.escape(label)}" src="{_png_data_uri(picture)}">' if picture else ""
    sensors = html.escape(str(row.get("detected_by", "")) or "never")
    details = (
        f"min TTC {_fmt(row.get('min_ttc_s'), 's')}, first detection "
        f"{_fmt(row.get('first_detection_distance_m'), 'm', 1)} ({sensors})"
    )
    return (
        f'<div class="case"><b>{html.escape(label)}</b><br>{image}<small>{html.escape(caption)}</small><br>'
        f"{outcome}; {details}" + "".join(f"<code>{html.escape(c)}</code>" for c in commands) + "</div>"
    )


def replay_commands(run: RunDirectory, row: pd.Series) -> list[str]:
    """The commands that replay a case, render its picture (beside its case log, where the gallery
    looks) and export it as FCD. A case of a batch run with --approach (its log named after the arm)
    is picked with --approach: the run holds the same episode on every approach."""
    scenario, condition = row["scenario"], row["condition"]
    episode, seed = int(row["episode"]), int(row["seed"])
    log_path = run.case_path(scenario, condition, seed)
    arm = run.approach if run.approach and log_path.stem.endswith(f"_{run.approach}") else ""
    base = (
        f"python -m pedsafe_sumo.replay {run.path} --episode {episode} --condition {condition} "
        f"--scenario {scenario}" + (f" --approach {arm}" if arm else "")
    )
    return [
        base,
        f"{base} --screenshot {log_path.with_suffix('.png')}",
        f"{base} --export-fcd {log_path.stem}.fcd.xml",
    ]


def gallery_rows(run: RunDirectory) -> tuple[pd.DataFrame, int]:
    """The episode rows with a case log, collisions first then conflicts; (shown, how many in all)."""
    episodes = run.episodes
    has_case = [
        run.case_path(s, c, int(seed)).is_file()
        for s, c, seed in zip(episodes["scenario"], episodes["condition"], episodes["seed"])
    ]
    cases = episodes[has_case]
    order = cases.assign(
        _collision=~cases["collision"].astype(bool), _conflict=~cases["conflict"].astype(bool)
    ).sort_values(["_collision", "_conflict", "scenario", "episode", "condition"])
    return order.head(MAX_GALLERY_CASES), len(cases)


def write_html_report(
    run: RunDirectory,
    table: pd.DataFrame,
    paired: pd.DataFrame,
    figures_dir: Path,
    out_path: Path,
    sections: Sequence[Section] = (),
) -> Path:
    """Write the page to `out_path` (through a temporary file) and return its path. `sections` (the
    collision witness and the staging diagnostics, report/audit.py) follow the paired tests."""
    parts = [
        "<!DOCTYPE html>",
        '<html lang="en"><head><meta charset="utf-8">',
        f"<title>pedsafe_sumo report: {html.escape(run.path.name)}</title>",
        f"<style>{STYLE}</style></head><body>",
        f"<h1>Pedestrian safety report: {html.escape(run.path.name)}</h1>",
    ]
    if run.incomplete:
        parts.append(f'<p class="banner">{html.escape(run.incomplete)}</p>')
    parts.append(f"<p>{html.escape(run_header(run))}</p>")
    parts.append(f"<h2>{html.escape(TABLE_ONE_TITLE)}</h2>")
    parts.append(_table_html(*table_one_rows(table), "table-one"))
    parts.append(f"<h2>{html.escape(paired_title(paired))}</h2>")
    parts.append(_table_html(*paired_rows(paired), "paired-tests"))
    for section in sections:
        heading, _, note = section.title.partition("\n")
        parts.append(f"<h2>{html.escape(heading)}</h2>")
        if note:
            parts.append(f"<p>{html.escape(note)}</p>")
        parts.append(_table_html(section.header, section.rows, section.table_id))
    parts.append('<h2>Figures</h2><div class="figures">')
    pictures = sorted(figures_dir.glob("*.png")) if figures_dir.is_dir() else []
    for picture in pictures:
        parts.append(
            f'<figure><img alt="{html.escape(picture.stem)}" src="{_png_data_uri(picture.read_bytes())}">'
            f"<figcaption>{html.escape(picture.name)}</figcaption></figure>"
        )
    if not pictures:
        parts.append("<p>No figures for this run.</p>")
    parts.append("</div>")
    shown, total = gallery_rows(run)
    parts.append(f"<h2>Logged cases ({total})</h2>")
    if total == 0:
        parts.append(
            "<p>The batch kept no case log (cases are kept for pairs with a collision or a conflict).</p>"
        )
    else:
        parts.append('<div class="gallery">')
        parts.extend(_case_card(run, row) for _, row in shown.iterrows())
        parts.append("</div>")
        if total > len(shown):
            parts.append(f"<p>{total - len(shown)} more cases in {html.escape(str(run.cases_dir))}.</p>")
    parts.append("<h2>Configuration</h2>")
    if run.run_info is None:
        parts.append(
            f"<p>No run.json{': ' + html.escape(run.run_info_problem) if run.run_info_problem else ''}.</p>"
        )
    else:
        config = json.dumps(run.run_info, indent=1, sort_keys=True, default=str)
        parts.append(f"<details open><summary>run.json</summary><pre>{html.escape(config)}</pre></details>")
    parts.append("</body></html>")
    out_path.parent.mkdir(parents=True, exist_ok=True)
    tmp = out_path.with_name(out_path.name + ".tmp")
    tmp.write_text("\n".join(parts) + "\n", encoding="utf-8")
    tmp.replace(out_path)
    return out_path
