"""Checking, step by step, that a replayed episode follows its logged trajectory.

The engine is deterministic for a seed (same SUMO, same parameters, same AD stack: same log, in
libsumo and in sumo-gui alike), so a replay must reproduce its case log to the last digit. A difference
means the run's settings were not all rebuilt, or the code or SUMO changed since the run: it is
reported at the first step where it shows (time, quantity, logged and replayed values), counted after
that, and makes the replay's exit status non-zero.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

#: The log columns compared at every step: time, the ego's and the pedestrian's positions and speeds.
CHECKED_COLUMNS = (
    "time_s",
    "ego_x_m",
    "ego_y_m",
    "ego_speed_mps",
    "ped_x_m",
    "ped_y_m",
    "ped_vx_mps",
    "ped_vy_mps",
)
#: Largest accepted difference per quantity (m, m/s or s). The engine reproduces logs exactly; the
#: margin only absorbs the last bit of a float written and read back.
TOLERANCE = 1e-6
#: Outcome columns of episodes.parquet compared at the end of a complete replay.
CHECKED_OUTCOME = (
    "collision",
    "impact_speed_mps",
    "conflict",
    "min_ttc_s",
    "first_detection_time_s",
    "first_detection_distance_m",
    "detected_by",
)


@dataclass(frozen=True)
class Mismatch:
    time_s: float
    quantity: str
    logged: Any
    replayed: Any

    def line(self) -> str:
        def show(value: Any) -> str:
            return f"{value:.6f}" if isinstance(value, float) else str(value)

        if math.isnan(self.time_s):  # an outcome value, not a step
            return (
                f"MISMATCH in the outcome: {self.quantity} recorded {show(self.logged)}, "
                f"replayed {show(self.replayed)}"
            )
        return (
            f"MISMATCH at t={self.time_s:.2f} s: {self.quantity} logged {show(self.logged)}, "
            f"replayed {show(self.replayed)}"
        )


class TrajectoryCheck:
    """A per-step hook (EpisodeRunner.run(on_step=...)) comparing each replayed step with the log.

    `report(line)` is called once, at the first mismatch; `summary()` says how it went.
    """

    def __init__(
        self, logged: pd.DataFrame, report: Callable[[str], None], reference_name: str = "the log"
    ) -> None:
        self.reference_name = reference_name
        self.logged = {column: logged[column].to_numpy(dtype=float) for column in CHECKED_COLUMNS}
        self.n_logged = len(logged)
        self.report = report
        self.steps_checked = 0
        self.steps_differing = 0
        self.first: Mismatch | None = None

    def __call__(self, api, row: dict[str, Any]) -> None:
        k = self.steps_checked
        self.steps_checked += 1
        if k >= self.n_logged:
            if k == self.n_logged:
                last_s = self.logged["time_s"][-1]
                self._found(Mismatch(row["time_s"], "episode end", f"t={last_s:.2f} s", "still running"))
            return
        for column in CHECKED_COLUMNS:
            logged, replayed = self.logged[column][k], float(row[column])
            # NaN where nobody is (the pedestrian before they appear, after they leave) matches NaN.
            if not (abs(replayed - logged) <= TOLERANCE or (math.isnan(logged) and math.isnan(replayed))):
                self._found(Mismatch(float(row["time_s"]), column, float(logged), replayed))
                return

    def finish(self, replayed_steps: int, end_reason: str, complete: bool) -> None:
        """After the episode: a replay that ended before the log did is a mismatch too (`complete`:
        the replay ran to its own end rather than being stopped early, e.g. for a screenshot)."""
        if complete and replayed_steps < self.n_logged:
            last_s = self.logged["time_s"][replayed_steps - 1] if replayed_steps else 0.0
            self._found(
                Mismatch(
                    float(last_s),
                    "episode end",
                    f"goes on to t={self.logged['time_s'][-1]:.2f} s",
                    f"ended ({end_reason.replace('_', ' ')})",
                )
            )

    @property
    def ok(self) -> bool:
        return self.first is None

    def summary(self) -> str:
        if self.first is None:
            return (
                f"trajectory matches {self.reference_name}: {self.steps_checked} of {self.n_logged} "
                f"steps checked (time, ego and pedestrian position and speed within {TOLERANCE:g})"
            )
        return (
            f"trajectory DIFFERS from {self.reference_name} from t={self.first.time_s:.2f} s on "
            f"({self.steps_differing} of {self.steps_checked} replayed steps differ)"
        )

    def _found(self, mismatch: Mismatch) -> None:
        self.steps_differing += 1
        if self.first is None:
            self.first = mismatch
            self.report(mismatch.line())


def outcome_mismatches(recorded: dict[str, Any], replayed: dict[str, Any]) -> list[Mismatch]:
    """Outcome values of a complete replay that differ from the run's episodes.parquet row."""
    found = []
    for column in CHECKED_OUTCOME:
        if column not in recorded or column not in replayed:
            continue
        a, b = recorded[column], replayed[column]
        if isinstance(a, (bool, np.bool_, str)) or isinstance(b, (bool, np.bool_, str)):
            same = a == b
        else:
            a, b = float(a), float(b)
            same = (math.isnan(a) and math.isnan(b)) or abs(a - b) <= TOLERANCE
        if not same:
            found.append(Mismatch(math.nan, column, a, b))
    return found
