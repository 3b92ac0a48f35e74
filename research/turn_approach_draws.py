"""The turning scenarios' worlds under approach staging, drawn as the episode runner draws them
(EpisodeRunner.draw_setup_sampled: the world stream of each seed, the pedestrian's traits, the ego's speed,
then draw_episode and stage_signals), without running SUMO: right_turn on Xueqing, left_turn on its
two-phase plan. Per scenario: the ego's speed, its start distance, the pedestrian's appearance time
(min, quartiles, max), the fallbacks of the timing (placements/approach.py, FALLBACKS), how often the
pedestrian appears later to fit the ego's green (staging.appear_later), how often the leader crosses the
stop line before the ego's green (staging._fit_approach), where the oncoming vehicle starts, and how
many worlds could not be placed in the signal program.

    python research/turn_approach_draws.py [--seeds 20]
"""

from __future__ import annotations

import argparse
import collections

import numpy as np
from approach_staging_draws import runner_draws

from pedsafe_sumo.network.sites import get_site
from pedsafe_sumo.params import load_params
from pedsafe_sumo.scenarios.geometry import load_approach, load_turn
from pedsafe_sumo.scenarios.oncoming import load_oncoming
from pedsafe_sumo.scenarios.placements import placement_of
from pedsafe_sumo.scenarios.placements.base import StagingInputs
from pedsafe_sumo.scenarios.road_users import CLOTHING_COLOURS_RGB
from pedsafe_sumo.scenarios.signals import SignalStagingError, load_junction_signals
from pedsafe_sumo.scenarios.specs import get_scenario
from pedsafe_sumo.scenarios.staging import draw_episode, stage_signals

TURNS = (("right_turn", "xueqing"), ("left_turn", "xueqing_two_phase"))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=20)
    args = parser.parse_args()
    params = load_params(None)
    for name, site_name in TURNS:
        site = get_site(site_name)
        approach = load_approach(site)
        junction = load_junction_signals(site.file("net.xml"), approach.junction_id)
        program = junction.program
        spec = get_scenario(name).with_overrides({"staging": "approach"})
        turn = load_turn(site, spec.turn)
        oncoming = load_oncoming(site) if spec.oncoming_vehicle else None
        speeds, starts, appears = [], [], []
        fired: collections.Counter[str] = collections.Counter()
        where: collections.Counter[str] = collections.Counter()
        unstaged = 0
        for seed in range(args.seeds):
            draws, traits, speed = runner_draws(spec, approach, params, seed)
            drawn = draw_episode(spec, approach, seed, traits, speed, draws, turn, oncoming)
            try:
                setup = stage_signals(spec, drawn, junction, draws)
            except SignalStagingError:
                unstaged += 1
                continue
            if setup.pedestrian.appear_time_s != drawn.pedestrian.appear_time_s:
                fired["appear_later (signal)"] += 1
            other = setup.parked[0]
            where[other.internal_lane_id or other.lane_id] += 1
            if other.vehicle_id == "leader_0":
                cycle_s = (setup.signals.cycle_start_s + other.green_from_s + 1e-6) % program.cycle_s
                if program.colour(setup.signals.ego_link_index, cycle_s) != "green":
                    fired["leader before the green (signal)"] += 1
            # The placement's scene again from the same draws, for the fallbacks it names.
            draws, traits, speed = runner_draws(spec, approach, params, seed)
            offset_s = draws.uniform(
                "conflict_offset_s", spec.conflict_offset_min_s, spec.conflict_offset_max_s
            )
            clothing = CLOTHING_COLOURS_RGB[draws.index("clothing", len(CLOTHING_COLOURS_RGB))]
            speed = float(np.clip(speed, spec.ego_speed_min_mps, spec.ego_speed_max_mps))
            inputs = StagingInputs(spec, approach, traits, speed, offset_s, clothing, draws, turn, oncoming)
            fired.update(placement_of(spec).stage(inputs).approach_fallbacks)
            speeds.append(setup.ego.speed_mps)
            starts.append(setup.ego_start_distance_m)
            appears.append(setup.pedestrian.appear_time_s)

        def spread(values) -> str:
            return " ".join(f"{v:.1f}" for v in np.percentile(values, [0, 25, 50, 75, 100]))

        print(f"{name} on {site_name} ({args.seeds} seeds; min q1 median q3 max)")
        print(f"  ego speed [m/s]          {spread(speeds)}")
        print(f"  ego_start_distance_m     {spread(starts)}")
        print(f"  ped_appear_time_s        {spread(appears)}")
        print(f"  fallbacks fired          {dict(fired) or 'none'}")
        print(f"  {setup.parked[0].vehicle_id} starts on {dict(where)}")
        print(f"  signal staging failed    {unstaged}")


if __name__ == "__main__":
    main()
