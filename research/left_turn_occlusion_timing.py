"""When the turning ego first perceives the left_turn pedestrian, against their step-off, from step logs.

Reads a batch run made with `--keep-logs all` (its steplogs/*.parquet, every step of every episode) and
prints, per condition and episode: how long the pedestrian waited on the kerb (first `waiting` step to
the first step they move on the road), the share of waiting steps at which the ego perceived them, how
long before the step-off the last unperceived waiting step was (when the oncoming vehicle's occlusion
ended, or the pedestrian came into range), whether they were perceived at the step-off, the distance from
the ego's reference point to them then, and the episode's minimum clearance; then the medians.

    python -m pedsafe_sumo.batch --protocol protocols/paper-v11-left_turn.toml --episodes 20 --workers 1 \\
        --keep-logs all --out /tmp/left_turn_logs
    python research/left_turn_occlusion_timing.py /tmp/left_turn_logs
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import pandas as pd

#: Pedestrian states (safety/log.py) once they have left the kerb for the road.
ON_THE_ROAD = ("walking", "reacting", "hastening", "blocked")


def episode_timing(steps: pd.DataFrame) -> dict[str, float]:
    """One episode's kerb wait and perception around the step-off (its steps in time order)."""
    time_s = steps["time_s"].to_numpy()
    state = steps["ped_state"].to_numpy()
    perceived = steps["perceived"].to_numpy().astype(bool)
    waiting = state == "waiting"
    on_road = np.isin(state, ON_THE_ROAD)
    if not waiting.any() or not on_road.any():
        return {"kerb_wait_s": np.nan}
    step_off = int(np.argmax(on_road))
    unseen_waiting = time_s[waiting & ~perceived]
    distance_m = np.hypot(
        steps["ego_x_m"].to_numpy() - steps["ped_x_m"].to_numpy(),
        steps["ego_y_m"].to_numpy() - steps["ped_y_m"].to_numpy(),
    )
    return {
        "kerb_wait_s": time_s[step_off] - time_s[waiting].min(),
        "perceived_share_waiting": float(perceived[waiting].mean()),
        "last_unperceived_before_step_off_s": (
            time_s[step_off] - unseen_waiting.max() if len(unseen_waiting) else np.nan
        ),
        "perceived_at_step_off": float(perceived[step_off]),
        "distance_at_step_off_m": float(distance_m[step_off]),
        "min_clearance_m": float(np.nanmin(steps["clearance_m"].to_numpy())),
    }


def timing_table(run_dir: Path) -> pd.DataFrame:
    logs = sorted((run_dir / "steplogs").glob("*.parquet"))
    if not logs:
        raise SystemExit(f"error: no steplogs/*.parquet in {run_dir} (run the batch with --keep-logs all)")
    steps = pd.concat([pd.read_parquet(path) for path in logs], ignore_index=True)
    rows = []
    for (condition, episode), group in steps.groupby(["condition", "episode"], sort=True):
        timing = episode_timing(group.sort_values("time_s"))
        rows.append({"condition": condition, "episode": episode, **timing})
    return pd.DataFrame(rows)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run_dir", type=Path, help="a batch run directory made with --keep-logs all")
    args = parser.parse_args(argv)
    table = timing_table(args.run_dir)
    with pd.option_context("display.width", 200, "display.max_rows", 500):
        print(table.round(2).to_string(index=False))
        print("\nmedians per condition:")
        print(table.drop(columns="episode").groupby("condition").median().round(2).to_string())
    return 0


if __name__ == "__main__":
    sys.exit(main())
