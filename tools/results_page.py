"""Write a study's results page (Markdown, with figures) from its protocol runs and sensitivity sweeps.

    python tools/results_page.py --run "Xueqing, reference=results/paper-v10-xueqing" \\
        --run "Xueqing, human driver=results/paper-v10-xueqing-human" \\
        --sweep results/paper-v10-xueqing-reaction --sweep results/paper-v10-xueqing-deceleration \\
        --out docs/results.md --figures docs/figures/results

For each run (LABEL=DIR, a batch run directory, finished or not: a run still going is read from its
finished chunks and the page says how far it is): Table I beside the paper's (the paper's three
scenarios), whether each collision interval meets the study's precision target (half-width under a third
of the rate, or under 0.005), the paired SV/V2I tests, the first-detection and impact-speed figures, the
injury curves, why each collision happened (from its case log: perceived too late to stop, perceived in
time, never perceived), and the paper's four qualitative findings on its point estimates. For each sweep
(python -m pedsafe_sumo.sweep's --out): per combination both collision rates and the paired test, the
findings in each combination, and one table of each finding across every finished sweep (holds at every
value, or the values where it fails; where V2I's fewer collisions are significant), so that every
verdict on the page shows the settings under which it holds. Nothing on the page is typed by hand but
the --notes file (the mechanisms behind the numbers, with their commands): rerun the tool when the runs
have grown.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from pedsafe_sumo.report.__main__ import draw_figure  # noqa: E402
from pedsafe_sumo.report.findings import FINDINGS, paper_findings  # noqa: E402
from pedsafe_sumo.report.impact import AGES_AT_REST, eq4_at_rest  # noqa: E402
from pedsafe_sumo.report.rundir import ReportError, RunDirectory, load_run  # noqa: E402
from pedsafe_sumo.safety.stats import paired_mcnemar, table_one  # noqa: E402

#: The paper's Table I (collision, injury, conflict), read from its LaTeX source.
PAPER_TABLE_ONE = {
    ("crossing", "sv"): (0.23, 0.0506, 0.25),
    ("crossing", "v2i"): (0.0075, 0.00195, 0.05),
    ("jaywalking", "sv"): (0.38, 0.11, 0.28),
    ("jaywalking", "v2i"): (0.0079, 0.0028, 0.04),
    ("background_blending", "sv"): (0.062, 0.0017, 0.31),
    ("background_blending", "v2i"): (0.0, 0.0, 0.003),
}
#: The study's precision target for a collision rate's 95% interval.
RELATIVE_HALF_WIDTH = 1 / 3
ABSOLUTE_HALF_WIDTH = 0.005
FINDING_WORDS = {
    "v2i_safer_everywhere": "V2I is safer than SV in every scenario (point estimates; an equal "
    "collision rate counts when V2I's conflict rate is no higher)",
    "jaywalking_most_dangerous": "jaywalking is the most dangerous of the paper's three scenarios (SV)",
    "blending_safest": "background blending is the safest of them (SV)",
    "v2i_beyond_13m_in_90pct": "V2I first detects the pedestrian beyond 13 m in 90% of episodes",
}


def read_run(run_dir: Path) -> tuple[RunDirectory, dict]:
    """The run as the report reads it (a run still going: from its finished chunks) and its run.json."""
    info = json.loads((run_dir / "run.json").read_text(encoding="utf-8"))
    return load_run(run_dir, partial=not (run_dir / "episodes.parquet").is_file()), info


def meets_target(rate: float, low: float, high: float) -> bool:
    half = (high - low) / 2
    return half < ABSOLUTE_HALF_WIDTH or (rate > 0 and half < RELATIVE_HALF_WIDTH * rate)


def _interval(rate: float, low: float, high: float, digits: int = 4) -> str:
    return f"{rate:.{digits}f} [{low:.{digits}f}, {high:.{digits}f}]"


def table_one_markdown(episodes: pd.DataFrame) -> str:
    table = table_one(episodes)
    has_severe = "mais3f_mean" in table.columns and table["mais3f_mean"].notna().any()
    head = ["scenario", "condition", "n", "collision [95%]", "paper", "target met", "injury eq. 4", "paper"]
    head += ["MAIS3+F"] if has_severe else []
    head += ["conflict [95%]", "paper"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for _, row in table.iterrows():
        paper = PAPER_TABLE_ONE.get((row["scenario"], row["condition"]))
        cells = [
            row["scenario"], row["condition"].upper(), f"{int(row['n']):,}",
            _interval(row["collision_rate"], row["collision_low"], row["collision_high"]),
            f"{paper[0]:g}" if paper else "",
            "yes" if meets_target(row["collision_rate"], row["collision_low"], row["collision_high"])
            else "no",
            f"{row['injury_mean']:.4f}", f"{paper[1]:g}" if paper else "",
        ]  # fmt: skip
        if has_severe:
            cells.append(f"{row['mais3f_mean']:.4f}" if not math.isnan(row["mais3f_mean"]) else "")
        cells += [
            _interval(row["conflict_rate"], row["conflict_low"], row["conflict_high"], 3),
            f"{paper[2]:g}" if paper else "",
        ]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def glance_markdown(runs: dict[str, pd.DataFrame]) -> str:
    """Collision rate [95% Wilson] per scenario (rows) and run and condition (columns), and the paper's:
    every run's Table I side by side. A scenario a run does not hold is left blank."""
    columns: list[tuple[str, str]] = []
    cells: dict[tuple[str, str, str], str] = {}
    scenarios: list[str] = []
    for label, episodes in runs.items():
        table = table_one(episodes)
        for _, row in table.iterrows():
            column = (label, row["condition"])
            if column not in columns:
                columns.append(column)
            if row["scenario"] not in scenarios:
                scenarios.append(row["scenario"])
            cells[(row["scenario"], *column)] = _interval(
                row["collision_rate"], row["collision_low"], row["collision_high"]
            )
    head = ["scenario", *(f"{label}, {condition.upper()}" for label, condition in columns)]
    head += ["paper, SV", "paper, V2I"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for scenario in sorted(scenarios):
        row_cells = [cells.get((scenario, *column), "") for column in columns]
        for condition in ("sv", "v2i"):
            paper = PAPER_TABLE_ONE.get((scenario, condition))
            row_cells.append(f"{paper[0]:g}" if paper else "")
        lines.append("| " + " | ".join([scenario, *row_cells]) + " |")
    return "\n".join(lines)


def paired_markdown(episodes: pd.DataFrame) -> str:
    if set(episodes["condition"]) != {"sv", "v2i"}:
        return "One condition only: no paired test."
    lines = [
        "| scenario | outcome | pairs | SV only | V2I only | p (exact McNemar) |",
        "|---|---|---:|---:|---:|---:|",
    ]
    for outcome in ("collision", "conflict"):
        for _, row in paired_mcnemar(episodes, outcome).iterrows():
            lines.append(
                f"| {row['scenario']} | {outcome} | {int(row['n_pairs']):,} | {int(row['sv_only'])} | "
                f"{int(row['v2i_only'])} | {row['p_value']:.3g} |"
            )
    return "\n".join(lines)


#: The case log's columns the collision timing reads.
TIMING_COLUMNS = [
    "time_s", "ego_x_m", "ego_y_m", "ego_speed_mps", "perceived", "braking", "clearance_m", "ped_state",
]  # fmt: skip
#: The shipped stacks whose reaction time and hardest braking are [algorithm]'s reaction_time_s and
#: max_decel_mps2 (the careful human driver draws its own: docs/human_driver.md).
STACKS_READING_REACTION = {
    "pedsafe_sumo.control.baseline:BaselineStack",
    "pedsafe_sumo.control.reference:ReferenceStack",
}
#: Pedestrian states before the step-off (safety/log.py): not yet a threat to a vehicle on the road.
BEFORE_STEP_OFF = {"absent", "walking_in", "waiting"}


def collision_timing(log: pd.DataFrame, reaction_s: float, decel_mps2: float) -> dict[str, float | str]:
    """Why a collision's ego did not stop, from its case log. From the first step at which the pedestrian
    had stepped off and was perceived: the distance the ego then drove to the contact (along its logged
    positions) against the distance the stack's own reaction time and hardest braking need from the speed
    it had (v t + v^2 / 2a). "late": inside that distance, no stack could have stopped; "in time": with
    room to stop, the stack did not use it; "never": not perceived after the step-off before the contact."""
    log = log.reset_index(drop=True)
    contact = log.index[log["clearance_m"] <= 0]
    before = log.loc[: contact[0]] if len(contact) else log
    off = before.index[~before["ped_state"].isin(BEFORE_STEP_OFF)]
    step_off = off[0] if len(off) else 0
    seen = before.index[before["perceived"].astype(bool) & (before.index >= step_off)]
    if not len(seen):
        return {"kind": "never"}
    first = seen[0]
    path = before.loc[first:, ["ego_x_m", "ego_y_m"]].to_numpy()
    driven_m = float(np.hypot(*np.diff(path, axis=0).T).sum()) if len(path) > 1 else 0.0
    speed = float(before.at[first, "ego_speed_mps"])
    needed_m = speed * reaction_s + speed * speed / (2 * decel_mps2)
    braked = before.index[before["braking"].astype(bool) & (before.index >= first)]
    brake_after_s = (
        float(before.at[braked[0], "time_s"] - before.at[first, "time_s"]) if len(braked) else math.nan
    )
    return {
        "kind": "late" if driven_m < needed_m else "in time",
        "driven_m": driven_m,
        "needed_m": needed_m,
        "spare_s": (driven_m - needed_m) / speed if speed > 0 else math.nan,
        "brake_after_s": brake_after_s,
    }


def collision_timing_markdown(run: RunDirectory, info: dict) -> str:
    """Per scenario and condition: the collisions by collision_timing's kind, from their case logs."""
    algorithm = info.get("parameters", {}).get("algorithm", {})
    reaction_s = float(algorithm.get("reaction_time_s", math.nan))
    decel_mps2 = float(algorithm.get("max_decel_mps2", math.nan))
    if not (math.isfinite(reaction_s) and math.isfinite(decel_mps2)):
        return "The run does not record the stack's reaction time and deceleration: no collision timing."
    own = info.get("algorithm", "") in STACKS_READING_REACTION
    whose = (
        "the stack's reaction time"
        if own
        else f"the reference stack's reaction time (the run's stack, `{info.get('algorithm', '')}`, has "
        "its own: *in time* here means a stack with the reference's reaction and braking would have "
        "stopped)"
    )
    lines = [
        "Each collision's case log: the distance the ego drove from the first step at which the pedestrian "
        f"had stepped off the kerb and was perceived to the contact, against what {whose} "
        f"({reaction_s:g} s) and hardest braking ({decel_mps2:g} m/s²) need from the speed it then had. "
        "*Late*: perceived inside that distance, no stack with them could have stopped; *in time*: "
        "perceived with room to stop, the stack did not use it; *never*: not perceived between the "
        "step-off and the contact. For the *in time* ones, the median time to spare (the room beyond "
        "what was needed, at the speed then) and the median time from that step to the first braking step.",
        "",
        "| scenario | condition | collisions | never | late | in time | no case log "
        "| in time: time to spare | in time: braking began after |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    episodes = run.episodes
    hits = episodes[episodes["collision"].astype(bool)]
    for (scenario, condition), group in hits.groupby(["scenario", "condition"], sort=False):
        counts = {"never": 0, "late": 0, "in time": 0, "missing": 0}
        delays, spares = [], []
        for _, row in group.iterrows():
            approach = row["approach"] if "approach" in row and isinstance(row["approach"], str) else ""
            path = run.case_path(scenario, condition, int(row["seed"]), approach)
            if not path.is_file():
                counts["missing"] += 1
                continue
            timing = collision_timing(pd.read_parquet(path, columns=TIMING_COLUMNS), reaction_s, decel_mps2)
            counts[str(timing["kind"])] += 1
            if timing["kind"] == "in time":
                spares.append(float(timing["spare_s"]))
                if math.isfinite(float(timing["brake_after_s"])):
                    delays.append(float(timing["brake_after_s"]))
        delay = f"{float(np.median(delays)):.2f} s" if delays else ""
        spare = f"{float(np.nanmedian(spares)):.2f} s" if spares else ""
        lines.append(
            f"| {scenario} | {condition.upper()} | {len(group)} | {counts['never']} | {counts['late']} | "
            f"{counts['in time']} | {counts['missing']} | {spare} | {delay} |"
        )
    return "\n".join(lines)


def verdict_word(value: float) -> str:
    """A finding's value (1 holds, 0 fails, NaN cannot be evaluated) as the page writes it."""
    return "n/a" if pd.isna(value) else ("holds" if value else "fails")


def findings_markdown(runs: dict[str, pd.DataFrame]) -> str:
    head = ["finding", *runs]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    verdicts = {label: paper_findings(episodes) for label, episodes in runs.items()}
    for finding in FINDINGS:
        cells = [FINDING_WORDS[finding]]
        for label in runs:
            value = verdicts[label][finding]
            cells.append(verdict_word(value))
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


#: A paired difference counts as significant below this exact McNemar p-value.
SIGNIFICANCE = 0.05


def sweep_combinations(sweep_dir: Path) -> dict[str, pd.DataFrame] | None:
    """Each combination's episodes by its label, in the sweep's order; None while the sweep runs (its
    findings.csv is written when every combination has finished)."""
    if not (sweep_dir / "findings.csv").is_file():
        return None
    labels = pd.read_csv(sweep_dir / "findings.csv")["run"].astype(str)
    return {label: pd.read_parquet(sweep_dir / label / "episodes.parquet") for label in labels}


def _value(label: str) -> str:
    """A one-key combination's value ("algorithm.reaction_time_s=0.4" -> "0.4"); otherwise the label."""
    return label.split("=", 1)[1] if label.count("=") == 1 else label


def sweep_markdown(sweep_dir: Path) -> str:
    """Per combination and scenario: both collision rates, the paired test; then the findings in each
    combination."""
    combinations = sweep_combinations(sweep_dir)
    if combinations is None:
        return "Still running: no combination's verdict yet."
    lines = [
        "| combination | scenario | SV collision [95%] | V2I collision [95%] | SV only | V2I only | p |",
        "|---|---|---|---|---:|---:|---:|",
    ]
    for label, episodes in combinations.items():
        table = table_one(episodes).set_index(["scenario", "condition"])
        paired = paired_mcnemar(episodes, "collision").set_index("scenario")
        for scenario in paired.index:
            rates = [
                _interval(*table.loc[(scenario, c), ["collision_rate", "collision_low", "collision_high"]])
                for c in ("sv", "v2i")
            ]
            row = paired.loc[scenario]
            lines.append(
                f"| {label} | {scenario} | {rates[0]} | {rates[1]} | {int(row['sv_only'])} | "
                f"{int(row['v2i_only'])} | {row['p_value']:.3g} |"
            )
    findings = pd.read_csv(sweep_dir / "findings.csv")
    head = ["combination", *[f for f in FINDINGS if f in findings.columns]]
    lines += ["", "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for _, row in findings.iterrows():
        cells = [str(row["run"])]
        for finding in head[1:]:
            value = row[finding]
            cells.append(verdict_word(value))
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def significant_gains(episodes: pd.DataFrame) -> tuple[list[str], list[str]]:
    """The scenarios where V2I collides significantly less than SV (paired), and those where more."""
    paired = paired_mcnemar(episodes, "collision")
    significant = paired[paired["p_value"] < SIGNIFICANCE]
    fewer = significant.loc[significant["v2i_only"] < significant["sv_only"], "scenario"]
    more = significant.loc[significant["v2i_only"] > significant["sv_only"], "scenario"]
    return list(fewer), list(more)


def sweep_verdicts_markdown(sweep_dirs: list[Path]) -> str:
    """One row per finding, one column per finished sweep: whether the finding holds at every swept
    value, or the values where it fails; and where V2I's collision gain is significant."""
    finished = {d.name: c for d in sweep_dirs if (c := sweep_combinations(d)) is not None}
    if not finished:
        return "No sweep has finished."
    head = ["finding", *finished]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    verdicts = {
        name: {label: paper_findings(episodes) for label, episodes in combinations.items()}
        for name, combinations in finished.items()
    }
    for finding in FINDINGS:
        cells = [FINDING_WORDS[finding]]
        for by_label in verdicts.values():
            values = {label: by_label[label][finding] for label in by_label}
            failing = [_value(label) for label, value in values.items() if value == 0]
            if all(math.isnan(value) for value in values.values()):
                cells.append("n/a")
            elif failing:
                cells.append("fails at " + ", ".join(failing))
            else:
                cells.append(f"holds at every value ({len(values)})")
        lines.append("| " + " | ".join(cells) + " |")
    cells = [f"V2I collides significantly less than SV (paired, p < {SIGNIFICANCE:g}) in"]
    for combinations in finished.values():
        parts = []
        for label, episodes in combinations.items():
            fewer, more = significant_gains(episodes)
            text = ", ".join(fewer) if fewer else "none"
            if more:
                text += "; significantly MORE in " + ", ".join(more)
            parts.append(f"{_value(label)}: {text}")
        cells.append("; ".join(parts))
    lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def figures_of(run: RunDirectory, slug: str, figures_dir: Path, page_dir: Path) -> list[str]:
    """The report's figures of one run, written under figures_dir; Markdown image lines."""
    lines = []
    for name in ("first_detection_distance", "impact_speed", "injury_vs_speed"):
        path = figures_dir / f"{slug}_{name}.png"
        if draw_figure(run, name, path) is not None:
            lines.append(f"![{name.replace('_', ' ')}]({Path(os.path.relpath(path, page_dir))})")
    return lines


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--run", action="append", default=[], metavar="LABEL=DIR", required=True)
    parser.add_argument("--sweep", action="append", default=[], type=Path, metavar="DIR")
    parser.add_argument("--out", type=Path, required=True, help="the Markdown page to write")
    parser.add_argument("--figures", type=Path, required=True, help="folder of the page's figures")
    parser.add_argument("--title", default="Results")
    parser.add_argument(
        "--notes",
        type=Path,
        metavar="FILE.md",
        help="Markdown written by hand (the mechanisms behind the numbers, each with its command), "
        "placed after the findings",
    )
    args = parser.parse_args(argv)
    runs: dict[str, tuple[Path, RunDirectory, dict]] = {}
    for text in args.run:
        label, sep, folder = text.partition("=")
        if not sep or not Path(folder).is_dir():
            print(
                f"error: --run needs LABEL=DIR with an existing run directory, got '{text}'", file=sys.stderr
            )
            return 2
        try:
            run, info = read_run(Path(folder))
        except (ReportError, OSError, json.JSONDecodeError) as exc:
            print(f"error: {folder}: {exc}", file=sys.stderr)
            return 2
        runs[label] = (Path(folder), run, info)
    notes = ""
    if args.notes is not None:
        try:
            notes = args.notes.read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as exc:
            print(f"error: --notes {args.notes}: {exc}", file=sys.stderr)
            return 2
    args.figures.mkdir(parents=True, exist_ok=True)
    page_dir = args.out.parent
    young, old = eq4_at_rest()
    out = [f"# {args.title}", ""]
    out += [
        "Made by `tools/results_page.py` from the run directories below: every number of the tables and "
        "figures is read from the runs" + ("; the last section is written by hand." if notes else "."),
        f"The paper's eq. 4 gives an injury probability of {young:.3f} (age {AGES_AT_REST[0]:.0f}) to "
        f"{old:.3f} (age {AGES_AT_REST[1]:.0f}) at an impact speed of 0 km/h: its column counts a touch "
        "as an injury of that probability. The MAIS3+F "
        "column is the second injury model (docs/safety_indexes.md).",
        "",
        "## At a glance: collision rate per run",
        "",
        glance_markdown({label: run.episodes for label, (_, run, _) in runs.items()}),
        "",
    ]
    for label, (folder, run, info) in runs.items():
        episodes = run.episodes
        protocol = info.get("protocol", {})
        total = info.get("episodes_total")
        done = len(episodes)
        state = (
            "complete" if (folder / "episodes.parquet").is_file() else f"running: {done:,} of {total:,} rows"
        )
        out += [f"## {label}", ""]
        out += [
            f"Protocol `{protocol.get('name', '(none)')}` (SHA-256 `{protocol.get('sha256', '')[:12]}`), "
            f"stack `{info.get('algorithm', '')}`, site `{info.get('site', '')}`: {state}.",
            "",
            table_one_markdown(episodes),
            "",
            paired_markdown(episodes),
            "",
            "### Why the collisions happened",
            "",
            collision_timing_markdown(run, info),
            "",
        ]
        slug = "_".join("".join(c if c.isalnum() else " " for c in label.lower()).split())
        out += [*figures_of(run, slug, args.figures, page_dir), ""]
    findings = findings_markdown({label: run.episodes for label, (_, run, _) in runs.items()})
    out += ["## The paper's findings", "", findings, ""]
    if args.sweep:
        out += [
            "### Each finding across the sensitivity sweeps",
            "",
            "Each sweep varies one setting of the protocol over the values named in its preset "
            "(python -m pedsafe_sumo.sweep --preset NAME; docs/report.md), every other value the "
            "protocol's own, on the same seeds; the verdicts are on point estimates, as the paper's.",
            "",
            sweep_verdicts_markdown(args.sweep),
            "",
        ]
    for sweep_dir in args.sweep:
        out += [f"### Sensitivity: `{sweep_dir.name}`", "", sweep_markdown(sweep_dir), ""]
    if notes:
        out += [notes.rstrip(), ""]
    args.out.write_text("\n".join(out), encoding="utf-8")
    print(f"written: {args.out} and {len(list(args.figures.glob('*.png')))} figure(s) in {args.figures}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
