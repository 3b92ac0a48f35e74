"""The impact speeds of a run's collisions, and how much of eq. 4's injury comes from its intercept.

Eq. 4 (saade2020) is not 0 at an impact speed of 0: sigmoid(-2.9893 + 0.0286 A) is 0.068 at age 13 and
0.364 at age 85, so a touch at walking pace scores nearly as high as a real impact. The report therefore
shows the impact-speed distribution beside the injury columns and states the share of the summed eq. 4
P_I that eq. 4 would give those same pedestrians at 0 km/h.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
from matplotlib.figure import Figure

from pedsafe_sumo.report.figures import _conditions, _new_figure, _save, colour
from pedsafe_sumo.report.summaries import MPS_TO_KMH
from pedsafe_sumo.report.tables import condition_label
from pedsafe_sumo.safety.injury import injury_probability

FIGURE_FILE = "impact_speed.png"
#: Histogram bins of 5 km/h: the resolution at which the published risk curves are read.
BIN_KMH = 5.0
#: Ages at which the report states eq. 4 at rest: the youngest and oldest of the paper's age groups.
AGES_AT_REST = (13.0, 85.0)


@dataclass(frozen=True)
class InterceptShare:
    n_collisions: int
    #: sum of injury_probability over the collisions
    eq4_sum: float
    #: sum over the same collisions of eq. 4 at 0 km/h for the pedestrian's age
    eq4_at_rest_sum: float

    @property
    def share(self) -> float:
        return self.eq4_at_rest_sum / self.eq4_sum if self.eq4_sum > 0 else float("nan")


def eq4_at_rest() -> tuple[float, float]:
    """Eq. 4 at 0 km/h at the youngest and oldest age of AGES_AT_REST."""
    young, old = (float(injury_probability(0.0, age, "saade2020")) for age in AGES_AT_REST)
    return young, old


def intercept_share(episodes: pd.DataFrame) -> InterceptShare:
    """How much of the summed eq. 4 P_I of the collisions eq. 4 gives at 0 km/h (its age-only part)."""
    hits = episodes[episodes["collision"].astype(bool)]
    at_rest = injury_probability(np.zeros(len(hits)), hits["ped_age"].to_numpy(dtype=float), "saade2020")
    return InterceptShare(
        len(hits),
        float(np.nansum(hits["injury_probability"].to_numpy(dtype=float))),
        float(np.sum(at_rest)),
    )


def intercept_note(episodes: pd.DataFrame) -> str:
    """One plain line: eq. 4 at 0 km/h, and the share of the run's summed P_I it accounts for."""
    young, old = eq4_at_rest()
    line = (
        f"eq. 4 (injury_probability) at an impact speed of 0 km/h: {young:.3f} at age "
        f"{AGES_AT_REST[0]:.0f} to {old:.3f} at age {AGES_AT_REST[1]:.0f}"
    )
    share = intercept_share(episodes)
    if share.n_collisions == 0:
        return line + "; no collision in this run"
    return (
        f"{line}; over the {share.n_collisions} collision{'s' if share.n_collisions != 1 else ''} of the "
        f"run, eq. 4 at 0 km/h makes {share.share:.0%} of the summed P_I "
        f"({share.eq4_at_rest_sum:.2f} of {share.eq4_sum:.2f})"
    )


def impact_speed_histogram(episodes: pd.DataFrame, path: Path | None = None) -> Figure:
    """Histogram of the collisions' impact speeds [km/h], one step line per condition, 5 km/h bins."""
    hits = episodes[episodes["collision"].astype(bool)]
    speeds_kmh = hits["impact_speed_mps"].to_numpy(dtype=float) * MPS_TO_KMH
    top = max(BIN_KMH, float(np.nanmax(speeds_kmh, initial=0.0)))
    edges = np.arange(0.0, top + BIN_KMH, BIN_KMH)
    figure = _new_figure(6.4, 4.2)
    ax = figure.subplots()
    for condition in _conditions(hits) if len(hits) else []:
        mask = (hits["condition"] == condition).to_numpy()
        counts, _ = np.histogram(speeds_kmh[mask], bins=edges)
        ax.stairs(
            counts,
            edges,
            color=colour(condition),
            linewidth=2,
            label=f"{condition_label(condition)} (n={mask.sum()})",
        )
    young, old = eq4_at_rest()
    ax.set_title(
        f"Impact speeds of the collisions\n"
        f"eq. 4 at 0 km/h: {young:.3f} (age {AGES_AT_REST[0]:.0f}) to {old:.3f} (age {AGES_AT_REST[1]:.0f})",
        fontsize=10,
    )
    ax.set_xlabel("impact speed [km/h]")
    ax.set_ylabel("collisions per 5 km/h [-]")
    ax.grid(alpha=0.3)
    if len(hits):
        ax.legend(loc="upper right", fontsize=8)
    else:
        ax.text(0.5, 0.5, "no collision in this run", transform=ax.transAxes, ha="center")
    return _save(figure, path)
