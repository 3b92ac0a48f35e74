"""The report's figures, drawn with matplotlib's Agg canvas (no pyplot, no display, no global state).

Every figure has labelled axes (units in brackets), a title and a legend; SV is always orange-red and
V2I always blue. Each function returns the matplotlib Figure, and writes it as a PNG at 150 dpi when given
a path. The numbers come from `summaries`; nothing is computed
here beyond laying them out.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from pedsafe_sumo.report.summaries import (
    MPS_TO_KMH,
    CasePair,
    CaseTrace,
    DetectionSummary,
    binned_mean,
    quantile_edges,
)
from pedsafe_sumo.report.tables import condition_label

DPI = 150
COLOURS = {"sv": "orangered", "v2i": "tab:blue"}
OTHER_COLOUR = "tab:gray"
FIGURE_FILES = {
    "injury_vs_age": "injury_vs_age.png",
    "injury_vs_speed": "injury_vs_speed.png",
    "first_detection_distance": "first_detection_distance.png",
    "case_speed_vs_frame": "case_speed_vs_frame.png",
}
#: Case figure: long dashes mark the first onboard detection, short dashes the first roadside one.
ONBOARD_DASHES = (0, (7, 3))
ROADSIDE_DASHES = (0, (2, 2))
AGE_BINS = 8
SPEED_BINS = 8
#: Panels per row of a figure with a panel per scenario: two keep each panel about 750 px wide at 150 dpi,
#: so the page (about 1000 px of text width) shows the figure at two thirds, legends still legible.
PANEL_COLUMNS = 2
#: Legend text in points: at 150 dpi shown at two thirds, about 13 px on the page.
LEGEND_FONT_PT = 10
#: A bin's mean is drawn on the curve only when it rests on this many episodes or more.
MIN_BIN_EPISODES = 2


def colour(condition: str) -> str:
    return COLOURS.get(condition, OTHER_COLOUR)


def _new_figure(width_in: float, height_in: float) -> Figure:
    figure = Figure(figsize=(width_in, height_in), layout="constrained")
    FigureCanvasAgg(figure)
    return figure


def _save(figure: Figure, path: Path | None) -> Figure:
    """The figure, also written as a PNG at `path` when given."""
    if path is None:
        return figure
    path.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(path, dpi=DPI, format="png")
    return figure


def _conditions(episodes: pd.DataFrame) -> list[str]:
    present = list(pd.unique(episodes["condition"]))
    return [c for c in COLOURS if c in present] + [c for c in present if c not in COLOURS]


def _grid(figure: Figure, n_panels: int) -> list:
    """`n_panels` axes in rows of at most PANEL_COLUMNS, the unused cells of the last row hidden."""
    columns = min(PANEL_COLUMNS, max(n_panels, 1))
    rows = max(1, math.ceil(n_panels / columns))
    axes = list(np.ravel(figure.subplots(rows, columns, squeeze=False)))
    for ax in axes[n_panels:]:
        ax.set_visible(False)
    return axes[:n_panels]


def _panel_figure(n_panels: int, panel_width_in: float, panel_height_in: float) -> Figure:
    columns = min(PANEL_COLUMNS, max(n_panels, 1))
    rows = max(1, math.ceil(n_panels / columns))
    return _new_figure(panel_width_in * columns, panel_height_in * rows)


def collision_scenarios(episodes: pd.DataFrame) -> list[str]:
    """The scenarios with at least one collision, in the order of the rows (the injury figures' panels)."""
    collided = episodes["collision"].astype("boolean").fillna(False).to_numpy(dtype=bool)
    return [str(s) for s in pd.unique(episodes.loc[collided, "scenario"])]


def _binned_means(ax, means: pd.DataFrame, condition: str, label: str) -> None:
    """The mean per bin: a line through the bins of at least MIN_BIN_EPISODES episodes (when there are
    two or more of them), a hollow marker alone where a bin holds fewer (a mean of one point is no curve)."""
    solid = means[means["n"] >= MIN_BIN_EPISODES]
    sparse = means[means["n"] < MIN_BIN_EPISODES]
    if len(solid) >= 2:
        ax.plot(
            solid["x_mean"],
            solid["mean"],
            "-o",
            color=colour(condition),
            linewidth=2,
            markersize=4,
            label=f"{label}: mean per bin",
        )
    elif len(solid):
        ax.plot(
            solid["x_mean"], solid["mean"], "o", color=colour(condition), markersize=5, label=f"{label}: mean"
        )
    if len(sparse):
        ax.plot(
            sparse["x_mean"],
            sparse["mean"],
            "o",
            markerfacecolor="none",
            color=colour(condition),
            markersize=6,
            label=f"{label}: bin of fewer than {MIN_BIN_EPISODES} episodes",
        )


def _injury_figure(
    episodes: pd.DataFrame, x_of, n_bins: int, xlabel: str, what: str, path: Path | None
) -> Figure:
    """One panel per scenario with a collision: P_I of each episode against x (scatter) and its mean over
    equal-count bins of x (drawn at each bin's mean x); the bins are shared by SV and V2I."""
    scenarios = collision_scenarios(episodes)
    figure = _panel_figure(len(scenarios), 5.2, 4.0)
    for ax, scenario in zip(_grid(figure, len(scenarios)), scenarios):
        rows = episodes[episodes["scenario"] == scenario]
        x = x_of(rows)
        edges = quantile_edges(x, n_bins)
        for condition in _conditions(rows):
            mask = (rows["condition"] == condition).to_numpy()
            y = rows["injury_probability"].to_numpy(dtype=float)[mask]
            xs = x[mask]
            label = condition_label(condition)
            ax.scatter(
                xs, y, s=10, alpha=0.35, color=colour(condition), label=f"{label}: episodes (n={mask.sum()})"
            )
            _binned_means(ax, binned_mean(xs, y, edges), condition, label)
        ax.set_xlabel(xlabel)
        ax.set_ylabel("injury probability P_I [-]")
        top = float(np.nanmax(rows["injury_probability"].to_numpy(dtype=float), initial=0.0))
        ax.set_ylim(bottom=-0.02 * max(top, 0.05), top=1.1 * max(top, 0.05))
        ax.set_title(f"{scenario}: {what}")
        ax.grid(alpha=0.3)
        ax.legend(loc="upper left", fontsize=LEGEND_FONT_PT)
    return _save(figure, path)


def injury_vs_age(episodes: pd.DataFrame, path: Path | None = None) -> Figure:
    """P_I against pedestrian age, SV and V2I, a panel per scenario with a collision (the paper's
    S-curve figure, age panel)."""
    return _injury_figure(
        episodes,
        lambda rows: rows["ped_age"].to_numpy(dtype=float),
        AGE_BINS,
        "pedestrian age [years]",
        "injury probability against pedestrian age",
        path,
    )


def injury_vs_speed(episodes: pd.DataFrame, path: Path | None = None) -> Figure:
    """P_I against the ego's initial speed in km/h, SV and V2I, a panel per scenario with a collision
    (the S-curve figure, speed panel)."""
    return _injury_figure(
        episodes,
        lambda rows: rows["ego_initial_speed_mps"].to_numpy(dtype=float) * MPS_TO_KMH,
        SPEED_BINS,
        "initial vehicle speed [km/h]",
        "injury probability against initial speed",
        path,
    )


def first_detection_distance(summaries: list[DetectionSummary], path: Path | None = None) -> Figure:
    """Histogram of the first-detection distance, one panel per scenario, SV and V2I overlaid.

    Per-scenario panels rather than one pooled distribution: where the pedestrian can first be seen
    (at a crosswalk, mid-block, behind parked cars) is set by the scenario's geometry, so a pooled
    histogram mixes different distributions and its 90% line would move with the mix of scenarios in
    the run. Each panel marks, per condition, the distance X that at least 90% of that condition's
    episodes detect at or beyond (never-detected episodes counted against it, and in the legend).
    """
    scenarios = list(dict.fromkeys(s.scenario for s in summaries))
    figure = _panel_figure(len(scenarios), 5.2, 4.6)
    for ax, scenario in zip(_grid(figure, len(scenarios)), scenarios):
        panel = [s for s in summaries if s.scenario == scenario]
        pooled = np.concatenate([s.distances_m for s in panel])
        edges = (
            np.histogram_bin_edges(pooled, bins=min(30, max(5, int(math.sqrt(max(pooled.size, 1))))))
            if pooled.size
            else np.array([0.0, 1.0])
        )
        for s in panel:
            label = condition_label(s.condition)
            ax.hist(
                s.distances_m,
                bins=edges,
                histtype="stepfilled",
                alpha=0.35,
                color=colour(s.condition),
                edgecolor=colour(s.condition),
                label=f"{label} (n={s.n}, never detected: {s.n_never})",
            )
            if math.isfinite(s.distance_90_m):
                ax.axvline(
                    s.distance_90_m,
                    color=colour(s.condition),
                    linestyle="--",
                    linewidth=1.8,
                    label=f"{label}: 90% of episodes detect beyond {s.distance_90_m:.1f} m",
                )
            elif s.n:
                ax.plot([], [], " ", label=f"{label}: fewer than 90% of episodes ever detect")
        ax.set_xlabel("ego-pedestrian distance at first detection [m]")
        ax.set_ylabel("episodes")
        ax.set_title(f"{scenario}: first-detection distance")
        ax.grid(alpha=0.3)
        # below the panel: over the bars it would hide them
        ax.legend(fontsize=LEGEND_FONT_PT, loc="upper center", bbox_to_anchor=(0.5, -0.2), ncols=1)
    return _save(figure, path)


def case_speed_vs_frame(pair: CasePair, traces: list[CaseTrace], path: Path | None = None) -> Figure:
    """Speed against simulation time of one paired episode, SV and V2I, with the first onboard detection
    and the first roadside (V2I) detection as vertical dashed lines (the paper's case figure, whose axis
    counts frames; here seconds)."""
    figure = _new_figure(7.0, 4.2)
    ax = figure.subplots()
    for trace in traces:
        label = condition_label(trace.condition)
        # V2I wide underneath, SV narrow on top: where the two runs drive alike, both stay visible.
        ax.plot(
            trace.time_s,
            trace.speed_kmh,
            color=colour(trace.condition),
            linewidth=1.6 if trace.condition == "sv" else 3.2,
            zorder=3 if trace.condition == "sv" else 2,
            label=f"{label}: speed",
        )
        if trace.collision and trace.time_s.size:
            ax.plot(
                trace.time_s[-1],
                trace.speed_kmh[-1],
                "X",
                color=colour(trace.condition),
                markersize=10,
                markeredgecolor="black",
                label=f"{label}: collision",
            )
        for frame, dashes, what in (
            (trace.first_onboard_frame, ONBOARD_DASHES, "onboard"),
            (trace.first_roadside_frame, ROADSIDE_DASHES, "roadside"),
        ):
            time_s = trace.time_of_frame(frame)
            if time_s is not None:
                ax.axvline(
                    time_s,
                    color=colour(trace.condition),
                    linestyle=dashes,
                    linewidth=1.4,
                    label=f"{label}: first {what} detection ({time_s:.2f} s)",
                )
    ax.set_xlabel("simulation time [s]")
    ax.set_ylabel("ego speed [km/h]")
    ax.set_ylim(bottom=0)
    ax.set_title(f"{pair.scenario}, episode {pair.episode} (seed {pair.seed}): speed, SV and V2I")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="best")
    return _save(figure, path)
