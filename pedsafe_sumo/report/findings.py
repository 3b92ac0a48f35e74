"""The paper's qualitative findings, checked on a run's episodes, and where they hold across a sweep.

Sensitivity as a primary result: for each combination of a sweep the four findings
of the paper are evaluated on the point estimates of its episodes.parquet (with small runs, say so):

- `v2i_safer_everywhere`: in every scenario of the run, V2I's collision rate is below SV's, or equal
  to it with a conflict rate no higher (the paper: V2I is safer in every scenario);
- `jaywalking_most_dangerous`: jaywalking's SV collision rate is the highest of the paper's three
  scenarios (crossing, jaywalking, background_blending) present;
- `blending_safest`: background blending's SV collision rate is the lowest of them (ties hold);
- `v2i_beyond_13m_in_90pct`: at least 90 % of the V2I episodes (all scenarios; never detected counts
  as not beyond) first detect the pedestrian farther than 13 m away (the paper's conflict figure).

A finding that cannot be evaluated on a run (its scenarios or conditions are missing) is NaN.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd

FINDINGS = (
    "v2i_safer_everywhere",
    "jaywalking_most_dangerous",
    "blending_safest",
    "v2i_beyond_13m_in_90pct",
)
PAPER_SCENARIOS = ("crossing", "jaywalking", "background_blending")
DETECTION_DISTANCE_M = 13.0
DETECTION_SHARE = 0.9


def _rates(episodes: pd.DataFrame) -> pd.DataFrame:
    ok = episodes[episodes["status"] == "ok"]
    grouped = ok.groupby(["scenario", "condition"])
    return pd.DataFrame(
        {
            "collision": grouped["collision"].mean(),
            # The paper's conflict rate: a conflict without a collision.
            "conflict": grouped.apply(lambda g: float((g["conflict"] & ~g["collision"]).mean())),
        }
    )


def paper_findings(episodes: pd.DataFrame) -> dict[str, float]:
    """1.0 (holds), 0.0 (fails) or NaN (cannot be evaluated) for each of FINDINGS."""
    rates = _rates(episodes)
    out: dict[str, float] = dict.fromkeys(FINDINGS, math.nan)
    scenarios = sorted({s for s, _ in rates.index})
    paired = [s for s in scenarios if (s, "sv") in rates.index and (s, "v2i") in rates.index]
    if paired:
        held = True
        for s in paired:
            sv, v2i = rates.loc[(s, "sv")], rates.loc[(s, "v2i")]
            held &= bool(
                v2i["collision"] < sv["collision"]
                or (v2i["collision"] == sv["collision"] and v2i["conflict"] <= sv["conflict"])
            )
        out["v2i_safer_everywhere"] = float(held)
    sv_collision = {s: rates.loc[(s, "sv"), "collision"] for s in PAPER_SCENARIOS if (s, "sv") in rates.index}
    if "jaywalking" in sv_collision and len(sv_collision) > 1:
        others = [v for s, v in sv_collision.items() if s != "jaywalking"]
        out["jaywalking_most_dangerous"] = float(sv_collision["jaywalking"] > max(others))
    if "background_blending" in sv_collision and len(sv_collision) > 1:
        others = [v for s, v in sv_collision.items() if s != "background_blending"]
        out["blending_safest"] = float(sv_collision["background_blending"] <= min(others))
    v2i = episodes[(episodes["condition"] == "v2i") & (episodes["status"] == "ok")]
    if len(v2i):
        distance = v2i["first_detection_distance_m"].to_numpy(dtype=float)
        beyond = np.nan_to_num(distance, nan=-1.0) > DETECTION_DISTANCE_M
        out["v2i_beyond_13m_in_90pct"] = float(beyond.mean() >= DETECTION_SHARE)
    return out


def findings_table(run_dirs: dict[str, Path]) -> pd.DataFrame:
    """One row per labelled run (a sweep's combinations), one column per finding."""
    rows = []
    for name, run_dir in run_dirs.items():
        episodes = pd.read_parquet(run_dir / "episodes.parquet", partitioning=None)
        rows.append({"run": name, **paper_findings(episodes)})
    return pd.DataFrame(rows, columns=["run", *FINDINGS])


def findings_figure(table: pd.DataFrame, path: Path, title: str = "") -> Path:
    """A grid: findings (rows) against runs (columns); green holds, red fails, grey not evaluated."""
    import matplotlib  # here, not at the top: Agg is a process-wide choice, made only when a figure is drawn

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # after matplotlib.use
    from matplotlib.colors import ListedColormap  # with pyplot, above

    values = table[list(FINDINGS)].to_numpy(dtype=float).T
    coded = np.where(np.isnan(values), 0, np.where(values > 0.5, 2, 1))
    cmap = ListedColormap(["#d0d0d0", "#d9534f", "#5cb85c"])
    labels = [str(run) for run in table["run"]]
    keys = {label.split("=", 1)[0] for label in labels if "=" in label and "," not in label}
    xlabel = ""
    if len(keys) == 1 and all("=" in label and "," not in label for label in labels):
        # One swept key: its values on the axis, its name below.
        xlabel = keys.pop()
        labels = [label.split("=", 1)[1] for label in labels]
    fig, ax = plt.subplots(figsize=(max(5.0, 2.6 + 0.8 * len(table)), 3.0), constrained_layout=True)
    ax.imshow(coded, cmap=cmap, vmin=0, vmax=2, aspect="auto")
    ax.set_yticks(range(len(FINDINGS)), [f.replace("_", " ") for f in FINDINGS], fontsize=8)
    ax.set_xticks(range(len(table)), labels, rotation=0 if xlabel else 45, ha="center" if xlabel else "right",
                  fontsize=7)  # fmt: skip
    if xlabel:
        ax.set_xlabel(xlabel, fontsize=8)
    for (i, j), code in np.ndenumerate(coded):
        ax.text(j, i, {0: "n/a", 1: "fails", 2: "holds"}[int(code)], ha="center", va="center", fontsize=7)
    if title:
        ax.set_title(title, fontsize=9)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def findings_across_sweeps(sweep_dirs: list[Path]) -> pd.DataFrame:
    """The findings.csv of several one-key sweeps in one table: sweep (the swept key), value, and the
    findings, in the order of the directories and of each sweep's combinations."""
    frames = []
    for sweep_dir in sweep_dirs:
        table = pd.read_csv(sweep_dir / "findings.csv")
        keys = {str(run).split("=", 1)[0] for run in table["run"]}
        if len(keys) != 1 or any("=" not in str(run) or "," in str(run) for run in table["run"]):
            raise ValueError(
                f"{sweep_dir}: not a sweep of one key (runs {', '.join(map(str, table['run']))})"
            )
        values = [str(run).split("=", 1)[1] for run in table["run"]]
        frames.append(table.drop(columns="run").assign(sweep=keys.pop(), value=values))
    combined = pd.concat(frames, ignore_index=True)
    return combined[["sweep", "value", *FINDINGS]]


def findings_across_sweeps_figure(table: pd.DataFrame, path: Path, title: str = "") -> Path:
    """One panel per sweep, side by side: findings (rows) against the swept values (columns); green
    holds, red fails, grey not evaluated (the layout of findings_figure)."""
    import matplotlib  # here, not at the top: Agg is a process-wide choice, made only when a figure is drawn

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # after matplotlib.use
    from matplotlib.colors import ListedColormap  # with pyplot, above

    sweeps = list(dict.fromkeys(table["sweep"]))
    widths = [max(2, int((table["sweep"] == s).sum())) for s in sweeps]
    fig, axes = plt.subplots(
        1, len(sweeps), figsize=(2.6 + 0.75 * sum(widths), 3.2), squeeze=False, constrained_layout=True,
        gridspec_kw={"width_ratios": widths},
    )  # fmt: skip
    cmap = ListedColormap(["#d0d0d0", "#d9534f", "#5cb85c"])
    for col, (ax, sweep) in enumerate(zip(axes[0], sweeps)):
        rows = table[table["sweep"] == sweep]
        values = rows[list(FINDINGS)].to_numpy(dtype=float).T
        coded = np.where(np.isnan(values), 0, np.where(values > 0.5, 2, 1))
        ax.imshow(coded, cmap=cmap, vmin=0, vmax=2, aspect="auto")
        ax.set_yticks(range(len(FINDINGS)), [f.replace("_", " ") for f in FINDINGS] if col == 0 else [],
                      fontsize=8)  # fmt: skip
        ax.set_xticks(range(len(rows)), list(rows["value"]), fontsize=7)
        ax.set_xlabel(sweep, fontsize=7)
        for (i, j), code in np.ndenumerate(coded):
            ax.text(j, i, {0: "n/a", 1: "fails", 2: "holds"}[int(code)], ha="center", va="center", fontsize=6)
    if title:
        fig.suptitle(title, fontsize=9)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path
