"""Re-run a protocol run's collision episodes with the reference stack's tracks recorded, and count the steps
at which an onboard sensor measured the pedestrian walking (true speed above 0.5 m/s) while the track's
standing model was the more probable (standing probability above 0.5): the tracker holding a walker as
standing (docs/decisions/2026-11-27-tracker-validation-gate.md).

    python research/experiments/tracker_lock_scan.py PROTOCOL.toml RUN_DIR SCENARIO CONDITION [EPISODES]

RUN_DIR is the protocol's run (its finished chunks are read); EPISODES a comma-separated list, by default
every episode of SCENARIO x CONDITION with a collision. Each episode is run again in this process from
its seed, with the protocol's values (the rows are the run's own: the same seed gives the same episode).
"""

from __future__ import annotations

import glob
import json
import sys
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd

from pedsafe_sumo.batch.__main__ import parse_args, plan_batch
from pedsafe_sumo.batch.chunks import Task, episode_seed
from pedsafe_sumo.batch.runner import _run_pair
from pedsafe_sumo.control import baseline

RECORDED: list[tuple[float, str, float]] = []
_run_step = baseline.BaselineStack.run_step


def recording_run_step(self, observation, time_s):
    """The stack's own step, with (time, sources measured, standing probability) of its track kept."""
    update = self.tracker.update

    def recorded_update(pedestrians, at_s):
        tracks = update(pedestrians, at_s)
        sources = ",".join(sorted({p.source for p in pedestrians}))
        RECORDED.append((time_s, sources, tracks[0].standing_probability if tracks else np.nan))
        return tracks

    self.tracker.update = recorded_update
    try:
        return _run_step(self, observation, time_s)
    finally:
        del self.tracker.update


def main() -> None:
    protocol, run_dir, scenario, condition = sys.argv[1:5]
    baseline.BaselineStack.run_step = recording_run_step
    with tempfile.TemporaryDirectory() as unused:
        plan, _ = plan_batch(parse_args(["--protocol", protocol, "--out", str(Path(unused) / "run")]))
    run_seed = json.loads((Path(run_dir) / "run.json").read_text())["run_seed"]
    rows = pd.concat(pd.read_parquet(f) for f in glob.glob(f"{run_dir}/parts/{scenario}-*.parquet"))
    rows = rows[rows.condition == condition]
    collided = sorted(rows[rows.collision].episode)
    episodes = [int(e) for e in sys.argv[5].split(",")] if len(sys.argv) > 5 else collided
    found = []
    for episode in episodes:
        RECORDED.clear()
        task = Task(scenario, episode, episode_seed(run_seed, episode), (condition,))
        pair_rows, _, results = _run_pair(plan.config, task)
        steps = results[0].log.merge(
            pd.DataFrame(RECORDED, columns=["time_s", "sources", "standing_probability"]).drop_duplicates(
                "time_s"
            ),
            on="time_s",
            how="left",
        )
        walking_seen = steps.sources.fillna("").str.contains("onboard") & (
            np.hypot(steps.ped_vx_mps, steps.ped_vy_mps) > 0.5
        )
        held = walking_seen & (steps.standing_probability > 0.5)
        found.append(
            {
                "episode": episode,
                "collision": bool(pair_rows[0]["collision"]),
                "walking_seen_steps": int(walking_seen.sum()),
                "held_standing_steps": int(held.sum()),
            }
        )
        print(found[-1], flush=True)
    table = pd.DataFrame(found)
    held = int((table.held_standing_steps > 0).sum())
    print(
        f"{scenario} {condition}: {held} of {len(table)} episodes had steps "
        "with a walker measured onboard and held standing"
    )


if __name__ == "__main__":
    main()
