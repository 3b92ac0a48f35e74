"""The moments of a logged episode that a screenshot can show, found in the episode's step log.

- `collision`: the first step at which the ego's footprint touches the pedestrian (clearance <= 0).
- `first-detection`: the first step at which the AD stack perceives the pedestrian.
- `closest-approach`: the step of the smallest clearance among the steps with the pedestrian in the
  scene (the log holds the steps before they appear and after they leave with a NaN position).
- `least-ttc`: the step of the smallest TTC, computed per step by `pedsafe_sumo.safety.surrogates`
  over the steps the episode's `min_ttc_s` takes (with the pedestrian in the scene, up to and including
  the first collision step), so its value is the episode's `min_ttc_s`.
- a time in seconds: the first step at or after it.

Without a choice the screenshot shows the most telling moment the episode has: the collision, else the
least TTC when the two were ever on a collision course, else the closest approach.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pandas as pd

from pedsafe_sumo.replay.rundir import ReplayError
from pedsafe_sumo.safety import LogError, detect_collision
from pedsafe_sumo.safety.episode import steps_with_pedestrian
from pedsafe_sumo.safety.surrogates import ttc_steps_s

#: The moments `--at` names, in the order an error message lists what an episode has.
MOMENT_NAMES = ("collision", "least-ttc", "closest-approach", "first-detection")
#: Their phrase in the one line that says which moment a screenshot shows.
MOMENT_PHRASES = {
    "collision": "the collision",
    "first-detection": "the first detection",
    "closest-approach": "the closest approach",
    "least-ttc": "the least TTC",
    "time": "the requested time",
}


@dataclass(frozen=True)
class Moment:
    """A step of the log chosen for a screenshot."""

    name: str  # one of MOMENT_NAMES, or "time"
    step_index: int
    time_s: float
    detail: str  # what the moment measures, e.g. "clearance 0.84 m"

    @property
    def phrase(self) -> str:
        return MOMENT_PHRASES[self.name]

    def line(self) -> str:
        return f"screenshot at {self.phrase}, t = {self.time_s:.2f} s: {self.detail}"


def present_mask(log: pd.DataFrame) -> np.ndarray:
    """Steps with the pedestrian in the scene (finite position); all of them when the log has no
    position columns."""
    if "ped_x_m" not in log.columns or "ped_y_m" not in log.columns:
        return np.ones(len(log), dtype=bool)
    return np.isfinite(log["ped_x_m"].to_numpy(float)) & np.isfinite(log["ped_y_m"].to_numpy(float))


def collision_step(log: pd.DataFrame) -> int | None:
    hits = np.flatnonzero(log["clearance_m"].to_numpy(float) <= 0.0)
    return int(hits[0]) if hits.size else None


def first_detection_step(log: pd.DataFrame) -> int | None:
    seen = np.flatnonzero(log["perceived"].to_numpy(bool))
    return int(seen[0]) if seen.size else None


def closest_approach_step(log: pd.DataFrame) -> int | None:
    clearance = np.where(present_mask(log), log["clearance_m"].to_numpy(float), np.nan)
    if not np.isfinite(clearance).any():
        return None
    return int(np.nanargmin(clearance))


def least_ttc_step(log: pd.DataFrame) -> tuple[int, float] | None:
    """(step index, TTC in s) of the smallest per-step TTC over the steps the episode's `min_ttc_s` takes;
    None when the two were never on a collision course (or the log lacks the safety log's columns)."""
    present = present_mask(log)
    indexes = np.flatnonzero(present)
    if indexes.size == 0:
        return None
    rows = steps_with_pedestrian(log)
    try:
        ttc_s = ttc_steps_s(rows)
        hit = detect_collision(rows)
    except LogError:
        return None
    if hit.step is not None:
        ttc_s = ttc_s[: hit.step + 1]
    if not np.isfinite(ttc_s).any():
        return None
    k = int(np.nanargmin(ttc_s))
    return int(indexes[k]), float(ttc_s[k])


def _clearance(log: pd.DataFrame, k: int) -> str:
    value = float(log["clearance_m"].iloc[k])
    return f"clearance {value:.2f} m" if math.isfinite(value) else "the pedestrian is not in the scene"


def episode_moments(log: pd.DataFrame) -> dict[str, Moment]:
    """Every named moment the episode has, by name (MOMENT_NAMES order)."""
    times = log["time_s"].to_numpy(float)
    found: dict[str, Moment] = {}
    k = collision_step(log)
    if k is not None:
        speed = (
            f", ego at {float(log['ego_speed_mps'].iloc[k]):.2f} m/s"
            if "ego_speed_mps" in log.columns
            else ""
        )
        found["collision"] = Moment("collision", k, float(times[k]), _clearance(log, k) + speed)
    least = least_ttc_step(log)
    if least is not None:
        k, ttc_s = least
        found["least-ttc"] = Moment(
            "least-ttc", k, float(times[k]), f"TTC {ttc_s:.2f} s, {_clearance(log, k)}"
        )
    k = closest_approach_step(log)
    if k is not None:
        found["closest-approach"] = Moment("closest-approach", k, float(times[k]), _clearance(log, k))
    k = first_detection_step(log)
    if k is not None:
        found["first-detection"] = Moment("first-detection", k, float(times[k]), _clearance(log, k))
    return found


def _what_it_has(found: dict[str, Moment], times: np.ndarray) -> str:
    named = [f"{m.name} (t = {m.time_s:.2f} s)" for m in found.values()]
    return "it has " + ", ".join([*named, f"any time from 0 to {times[-1]:.2f} s"])


def find_moment(log: pd.DataFrame, at: str | None, describe: str) -> Moment:
    """The moment `--at` names (None: the most telling one the episode has). ReplayError, one line naming
    the moments the episode has, when it names one the episode does not have."""
    times = log["time_s"].to_numpy(float)
    found = episode_moments(log)
    if at is None:
        for name in ("collision", "least-ttc", "closest-approach"):
            if name in found:
                return found[name]
        # No step with the pedestrian in the scene: nothing to show but the end.
        k = len(times) - 1
        return Moment("time", k, float(times[k]), _clearance(log, k))
    if at in found:
        return found[at]
    if at in MOMENT_NAMES:
        missing = {
            "collision": f"there is no collision in {describe} (it ended at t={times[-1]:.2f} s without one)",
            "first-detection": f"the AD stack never perceived the pedestrian in {describe}",
            "least-ttc": f"the ego and the pedestrian were never on a collision course in {describe} "
            "(no finite TTC)",
            "closest-approach": f"the pedestrian is never in the scene in {describe}",
        }[at]
        raise ReplayError(f"{missing}; {_what_it_has(found, times)}")
    try:
        time_s = float(at)
    except ValueError:
        raise ReplayError(
            f"--at must be {', '.join(MOMENT_NAMES)} or a time in seconds, got '{at}'"
        ) from None
    if not math.isfinite(time_s) or time_s < 0.0 or time_s > times[-1] + 1e-9:
        raise ReplayError(f"--at {at}: the episode runs from t=0 to t={times[-1]:.2f} s")
    k = int((times >= time_s - 1e-9).nonzero()[0][0])
    return Moment("time", k, float(times[k]), _clearance(log, k))


def moment_step(reference: pd.DataFrame, moment: str | None, logged) -> tuple[int, str]:
    """Index of the reference step `--at` names, and a phrase saying which moment it is."""
    found = find_moment(reference, moment, logged.describe())
    return found.step_index, found.phrase
