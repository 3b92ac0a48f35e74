"""Hand-made run directories with known answers for the report tests.

The standard run (`write_standard_run`), paired episodes seeded 100 + episode:

crossing, episodes 0-9:
  SV  collisions {0, 1, 2} (3 of 10), P_I 0.2, 0.4, 0.6 -> mean 0.12; raw conflicts {2, 3, 4}
      -> Table I conflicts {3, 4} (2 of 10)
  V2I no collision; conflicts {5} (1 of 10)
  paired collisions: both 0, b 3, c 0 -> p = 2 / 2^3 = 0.25
  paired conflicts:  both 0, b 2, c 1 -> p = min(1, 2 (1 + 3) / 8) = 1
jaywalking, episodes 0-10 (V2I episode 10 has status "error" and missing values for its indexes):
  SV  collisions {0..5} (6 of 11)
  V2I collision {0} (1 of 10, 1 error)
  paired collisions (episode 10 dropped): both 1, b 5, c 0 -> p = 2 / 2^5 = 0.0625
First detection distances (m): SV 1, 2, ..., 10 in episode order (episode 10: never), V2I 10 * that.
First detection times (s): SV 3.0, V2I 1.0, except jaywalking episode 3: SV 5.0, V2I 0.5 (the
largest gap among the jaywalking pairs with case files).
Case files: jaywalking episodes 0 and 3 (both conditions), jaywalking episode 4 (SV only),
crossing episode 1 (both conditions).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pandas as pd

from pedsafe_sumo.io.episodes import EPISODE_COLUMNS

STEP_S = 0.05  # [s]


def episode_row(scenario: str, condition: str, episode: int, **values) -> dict:
    """One episodes.parquet row with plausible defaults (no collision, no conflict, seen at 20 m)."""
    rng = np.random.default_rng(episode * 7919 + len(scenario))
    row = {
        "scenario": scenario,
        "condition": condition,
        "episode": episode,
        "seed": 100 + episode,
        "ped_age": float(rng.integers(13, 85)),
        "ped_gender": "f" if episode % 2 else "m",
        "ped_risk": "unaware",
        "ped_speed_mps": 1.4,
        "ego_initial_speed_mps": float(rng.lognormal(1.83, 0.49)),
        "collision": False,
        "impact_speed_mps": math.nan,
        "injury_probability": 0.0,
        "conflict": False,
        "md_m": 3.0,
        "tmd_s": 1.0,
        "cs_mps": 5.0,
        "conflict_probability": 0.1,
        "min_ttc_s": 3.0,
        "pet_s": 2.0,
        "first_detection_distance_m": 20.0,
        "first_detection_time_s": 1.0,
        "detected_by": "onboard_camera",
        "sumo_collision": False,
        "status": "ok",
        "error": "",
    }
    unknown = set(values) - set(row)
    assert not unknown, f"unknown columns {unknown}"
    row.update(values)
    return row


def standard_episodes() -> pd.DataFrame:
    rows = []
    for episode in range(10):
        sv_hit = episode in (0, 1, 2)
        rows.append(
            episode_row(
                "crossing",
                "sv",
                episode,
                collision=sv_hit,
                impact_speed_mps=8.0 if sv_hit else math.nan,
                injury_probability=(0.2, 0.4, 0.6)[episode] if sv_hit else 0.0,
                conflict=episode in (2, 3, 4),
                first_detection_distance_m=float(episode + 1),
                first_detection_time_s=3.0,
            )
        )
        rows.append(
            episode_row(
                "crossing",
                "v2i",
                episode,
                conflict=episode == 5,
                first_detection_distance_m=10.0 * (episode + 1),
                first_detection_time_s=1.0,
            )
        )
    for episode in range(11):
        sv_hit, v2i_hit = episode <= 5, episode == 0
        never = episode == 10
        rows.append(
            episode_row(
                "jaywalking",
                "sv",
                episode,
                collision=sv_hit,
                impact_speed_mps=6.0 + episode if sv_hit else math.nan,
                injury_probability=0.1 + 0.1 * episode if sv_hit else 0.0,
                first_detection_distance_m=math.nan if never else float(episode + 1),
                first_detection_time_s=math.nan if never else (5.0 if episode == 3 else 3.0),
                detected_by="" if never else "onboard_camera",
            )
        )
        rows.append(
            episode_row(
                "jaywalking",
                "v2i",
                episode,
                collision=v2i_hit,
                impact_speed_mps=4.0 if v2i_hit else math.nan,
                injury_probability=0.05 if v2i_hit else 0.0,
                first_detection_distance_m=10.0 * (episode + 1),
                first_detection_time_s=0.5 if episode == 3 else 1.0,
                detected_by="roadside",
                status="error" if episode == 10 else "ok",
                error="SimulatorError: lost" if episode == 10 else "",
            )
        )
    # An errored episode has no outcome: its indexes are missing values (nullable booleans on disk).
    errored = rows[-1]
    errored.update(collision=None, conflict=None, injury_probability=math.nan, sumo_collision=None)
    errored.update(first_detection_distance_m=math.nan, first_detection_time_s=math.nan, detected_by="")
    return pd.DataFrame(rows, columns=list(EPISODE_COLUMNS))


def case_log(
    n_steps: int,
    first_onboard_step: int | None,
    first_roadside_step: int | None,
    speed_mps: float = 10.0,
    brake_step: int | None = None,
) -> pd.DataFrame:
    """A per-step log starting at t = STEP_S (frame 1): constant speed, then -5 m/s^2 from brake_step.

    Onboard camera flags are set from `first_onboard_step` on, roadside flags from
    `first_roadside_step` on (row indices; the frame is the row index + 1).
    """
    step = np.arange(n_steps)
    speed = np.full(n_steps, speed_mps)
    if brake_step is not None:
        speed = np.maximum(0.0, speed - 5.0 * STEP_S * np.clip(step - brake_step, 0, None))
    onboard = step >= first_onboard_step if first_onboard_step is not None else np.zeros(n_steps, bool)
    roadside = step >= first_roadside_step if first_roadside_step is not None else np.zeros(n_steps, bool)
    return pd.DataFrame(
        {
            "time_s": STEP_S * (step + 1),
            "ego_x_m": np.cumsum(speed) * STEP_S,
            "ego_y_m": 0.0,
            "ego_yaw_rad": 0.0,
            "ego_speed_mps": speed,
            "ego_length_m": 4.5,
            "ego_width_m": 1.8,
            "ped_x_m": 40.0,
            "ped_y_m": -3.0,
            "ped_vx_mps": 0.0,
            "ped_vy_mps": 1.4,
            "ped_radius_m": 0.3,
            "detected_onboard_camera": onboard,
            "detected_onboard_lidar": False,
            "detected_roadside": roadside,
            "perceived": onboard | roadside,
            "braking": False,
            "command_speed_mps": speed,
        }
    )


def write_case(cases_dir: Path, scenario: str, condition: str, seed: int, log: pd.DataFrame) -> None:
    cases_dir.mkdir(parents=True, exist_ok=True)
    stem = f"{scenario}_{condition}_{seed}"
    log.to_parquet(cases_dir / f"{stem}.parquet", index=False)
    (cases_dir / f"{stem}.json").write_text(json.dumps({"condition": condition, "outcome": {}}))


#: SV: onboard from row 99 (frame 100); V2I: roadside from row 34 (frame 35), onboard from row 79.
STANDARD_SV_CASE = {"n_steps": 140, "first_onboard_step": 99, "first_roadside_step": None, "brake_step": 105}
STANDARD_V2I_CASE = {"n_steps": 160, "first_onboard_step": 79, "first_roadside_step": 34, "brake_step": 60}

RUN_INFO = {
    "episodes_per_scenario": 10,
    "run_seed": 100,
    "workers": 2,
    "versions": {"pedsafe_sumo": "0.1.0", "sumo": "1.28.0"},
    "wall_time_s": 12.34,
}


def write_run(directory: Path, episodes: pd.DataFrame, run_info: dict | None = RUN_INFO) -> Path:
    directory.mkdir(parents=True, exist_ok=True)
    episodes.to_parquet(directory / "episodes.parquet", index=False)
    if run_info is not None:
        (directory / "run.json").write_text(json.dumps(run_info))
    return directory


def write_standard_run(directory: Path) -> Path:
    write_run(directory, standard_episodes())
    cases = directory / "cases"
    for scenario, episode in (("jaywalking", 0), ("jaywalking", 3), ("crossing", 1)):
        write_case(cases, scenario, "sv", 100 + episode, case_log(**STANDARD_SV_CASE))
        write_case(cases, scenario, "v2i", 100 + episode, case_log(**STANDARD_V2I_CASE))
    write_case(cases, "jaywalking", "sv", 104, case_log(**STANDARD_SV_CASE))
    return directory
