"""An episode judged: what the loop recorded (EpisodeTrace) turned into its row of episodes.parquet.

The indexes come from the per-step log (pedsafe_sumo.safety.episode); SUMO's own collision check is
read during the loop (`sumo_collision_record`) and counts only where SUMO looks; the signals are those
SUMO showed at the staged conflict (`conflict_step`, `signals_at_conflict`); who struck whom in a
collision from the logged geometry at its first step (`collision_type`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd

from pedsafe_sumo.safety.collision import STATIONARY_SPEED_MPS
from pedsafe_sumo.safety.episode import episode_indexes
from pedsafe_sumo.safety.proximity import ProximityModel
from pedsafe_sumo.safety.witness import witness_collision
from pedsafe_sumo.scenarios.episode_setup import EpisodeSetup
from pedsafe_sumo.scenarios.signals import colour_of_link
from pedsafe_sumo.sim.staging import EGO_ID, PED_ID

#: The per-step log's columns, in order (pedsafe_sumo.safety.log's contract plus the command and
#: diagnostics): the loop appends one tuple of these per step.
LOG_COLUMNS = (
    "time_s",
    "ego_x_m",
    "ego_y_m",
    "ego_yaw_rad",
    "ego_speed_mps",
    "ego_length_m",
    "ego_width_m",
    "ped_x_m",
    "ped_y_m",
    "ped_vx_mps",
    "ped_vy_mps",
    "ped_radius_m",
    "detected_onboard_camera",
    "detected_onboard_lidar",
    "detected_roadside",
    "perceived",
    "roadside_raw",
    "clearance_m",
    "command_speed_mps",
    "braking",
    "ped_state",
    "sumo_collision",
    "command_refused",
)


@dataclass
class EpisodeResult:
    setup: EpisodeSetup
    condition: str
    #: One row per step (columns of pedsafe_sumo.safety.log plus the command and diagnostics).
    log: pd.DataFrame
    #: The columns of this episode (one row of episodes.parquet, docs/design.md, 'Contracts').
    outcome: dict[str, Any]
    end_reason: str
    timings_s: dict[str, float] = field(default_factory=dict)
    #: SUMO's own record of the ego-pedestrian collision: {"time_s", "ego_speed_mps", "type"}, or {}.
    sumo_collision: dict[str, Any] = field(default_factory=dict)
    #: SUMO's link-state string of the junction's traffic light at every logged step ("" without one).
    signal_states: list[str] = field(default_factory=list)


@dataclass
class EpisodeTrace:
    """What the loop recorded of one episode, for judging."""

    #: One row per step (LOG_COLUMNS); empty when no step was logged.
    log: pd.DataFrame
    #: Why the episode ended: "collision", "both_cleared", "ego_left_network" or "time_limit".
    end_reason: str
    #: SUMO's link-state string of the junction's traffic light at every logged step ("" without one).
    signal_states: list[str]
    #: SUMO's own record of the ego-pedestrian collision (sumo_collision_record), or {}.
    sumo_record: dict[str, Any]
    #: The pedestrian's SUMO edge at the closest approach ("" when no step was logged).
    closest_edge: str
    #: Seconds spent in each part of the loop: sumo_s, snapshot_s, perception_s, agent_s, logging_s.
    timings_s: dict[str, float]


def sumo_collision_record(api, time_s: float) -> dict[str, Any]:
    """SUMO's collision between the moving ego and the pedestrian in the last step, if it saw one.

    Same definition as ours: a contact while the ego is slower than STATIONARY_SPEED_MPS is none.
    """
    for collision in api.simulation.getCollisions():
        if {collision.collider, collision.victim} == {EGO_ID, PED_ID}:
            speed = collision.colliderSpeed if collision.collider == EGO_ID else collision.victimSpeed
            if speed >= STATIONARY_SPEED_MPS:
                return {"time_s": time_s, "ego_speed_mps": float(speed), "type": collision.type}
    return {}


def is_crossing_or_walkingarea(edge_id: str) -> bool:
    """SUMO's netconvert names crossings ':<junction>_c<k>' and walking areas ':<junction>_w<k>'."""
    if not edge_id.startswith(":"):
        return False
    tail = edge_id.rsplit("_", 1)[-1]
    return len(tail) > 1 and tail[0] in "cw" and tail[1:].isdigit()


def conflict_step(log: pd.DataFrame, setup: EpisodeSetup) -> int:
    """Row of the log at the staged conflict: the first step at or after `setup.conflict_time_s` (the
    ego's front at the conflict point had nobody reacted), or the last step when the episode ended
    before it (a collision just before it). Not the closest approach: once an ego has stopped for the
    pedestrian their closest approach can come many seconds later, under the next phase."""
    times = log["time_s"].to_numpy()
    index = int(np.searchsorted(times, setup.conflict_time_s - 1e-9))
    return min(index, len(times) - 1)


def signals_at_conflict(log: pd.DataFrame, states: Sequence[str], setup: EpisodeSetup) -> tuple[str, str]:
    """(ego_signal, ped_signal) that SUMO showed at the staged conflict (conflict_step). `states` holds
    SUMO's link-state string of every logged step."""
    staging = setup.signals
    if staging is None or not len(log):
        return "none", "none"
    state = states[conflict_step(log, setup)]
    return colour_of_link(state, staging.ego_link_index), colour_of_link(state, staging.ped_link_index)


def first_collision_step(log: pd.DataFrame) -> int | None:
    """Row of the first contact with the moving ego (the collision of safety.collision), or None."""
    if not len(log):
        return None
    clearance = log["clearance_m"].to_numpy(dtype=float)
    moving = log["ego_speed_mps"].to_numpy(dtype=float) >= STATIONARY_SPEED_MPS
    strikes = np.flatnonzero((clearance <= 0.0) & moving)
    return int(strikes[0]) if strikes.size else None


def collision_type(log: pd.DataFrame, step: int | None) -> str:
    """Who struck whom at the collision's first contact row `step` (None: no collision): one of
    io.episodes.COLLISION_TYPES, from the logged geometry (docs/engine.md, "Collisions").

    In the ego's frame (x forward along its heading, y to its left) the pedestrian's centre is at (lon,
    lat). The ego's front face moved speed x step length in the step that ended in contact: a centre
    within that distance of the front face's line, or ahead of it, is where the front (or a front corner)
    came onto them: "ego_strikes_pedestrian". A centre farther back lies beside the box (or behind its
    front corners, from which a forward-moving box moves away); it is "pedestrian_strikes_side" if the
    pedestrian moved towards the box's centreline faster than the box's side moved towards them (the
    side point at lon moves sideways at yaw rate x lon while the ego turns), else the ego drove into
    them: "ego_strikes_pedestrian"."""
    if step is None:
        return "none"
    row = log.iloc[step]
    times = log["time_s"].to_numpy(dtype=float)
    yaws = log["ego_yaw_rad"].to_numpy(dtype=float)
    step_s = times[step] - times[step - 1] if step > 0 else (times[1] - times[0] if len(times) > 1 else 0.05)
    cos, sin = math.cos(row["ego_yaw_rad"]), math.sin(row["ego_yaw_rad"])
    dx, dy = row["ped_x_m"] - row["ego_x_m"], row["ped_y_m"] - row["ego_y_m"]
    lon, lat = cos * dx + sin * dy, -sin * dx + cos * dy
    front_travel_m = row["ego_speed_mps"] * step_s
    if lon >= row["ego_length_m"] / 2 - front_travel_m:
        return "ego_strikes_pedestrian"
    side = math.copysign(1.0, lat)  # +1: the pedestrian is on the ego's left
    ped_towards_mps = -side * (-sin * row["ped_vx_mps"] + cos * row["ped_vy_mps"])
    yaw_rate = 0.0
    if step > 0:
        turned = (yaws[step] - yaws[step - 1] + math.pi) % (2 * math.pi) - math.pi
        yaw_rate = turned / step_s
    side_towards_mps = side * yaw_rate * lon
    if ped_towards_mps > 0.0 and ped_towards_mps > side_towards_mps:
        return "pedestrian_strikes_side"
    return "ego_strikes_pedestrian"


def judge_episode(
    setup: EpisodeSetup,
    condition: str,
    seed: int,
    trace: EpisodeTrace,
    arm: str,
    injury_model: str = "saade2020",
    proximity_model: ProximityModel | None = None,
) -> EpisodeResult:
    """The episode's result: its outcome row (the drawn pedestrian and ego, the indexes of the log,
    SUMO's verdict, the signals at the conflict, the approach `arm`) beside what the loop recorded."""
    log, ped = trace.log, setup.pedestrian
    # SUMO checks vehicle-person contact only on crossings and walking areas: its verdict counts where
    # it looks, a pedestrian on a crossing or walking area at the closest approach. Elsewhere
    # (mid-block: a person moved across the road stays logically on its sidewalk lane, where SUMO
    # never checks against vehicles) it is unknown, not False.
    sumo_collision = bool(trace.sumo_record)
    sumo_witness = sumo_collision if is_crossing_or_walkingarea(trace.closest_edge) else None
    indexes = episode_indexes(log, ped.age_years, injury_model=injury_model, proximity_model=proximity_model)
    ego_signal, ped_signal = signals_at_conflict(log, trace.signal_states, setup)
    witness = witness_collision(log)  # a second opinion on `collision`, by other geometry code
    outcome = {
        "scenario": setup.scenario,
        "condition": condition,
        "seed": seed,
        "ped_age": ped.age_years,
        "ped_gender": ped.gender,
        "ped_risk": ped.risk,
        "ped_speed_mps": ped.walking_speed_mps,
        "ego_initial_speed_mps": setup.ego.speed_mps,
        **indexes,
        "sumo_collision": sumo_witness,
        "end_reason": trace.end_reason,
        "ego_signal": ego_signal,
        "ped_signal": ped_signal,
        "approach": arm,
        "ego_start_distance_m": setup.ego_start_distance_m,
        "ped_appear_time_s": ped.appear_time_s,
        "collision_type": collision_type(log, first_collision_step(log)) if indexes["collision"] else "none",
        "witness_collision": witness.collided,
        "witness_collision_time_s": witness.time_s,
        "status": "ok",
        "error": "",
    }
    return EpisodeResult(
        setup,
        condition,
        log,
        outcome,
        trace.end_reason,
        trace.timings_s,
        trace.sumo_record,
        trace.signal_states,
    )
