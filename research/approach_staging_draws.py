"""Approach staging's worlds on a site, drawn as the episode runner draws them (EpisodeRunner.
draw_setup_sampled: the world stream of each seed, the pedestrian's traits, the ego's speed, then
draw_episode and stage_signals), without running SUMO. Per straight-through scenario: the ego's speed, its
start distance and the pedestrian's appearance time (min, quartiles, max), how often each fallback of the
timing fired (placements/approach.py), how many scenes were longer than any run of the ego's signal (the
pedestrian then appears later on their walk-in: staging.appear_later) and how many could still not be
placed in the signal program.

    python research/approach_staging_draws.py [--site xueqing] [--seeds 20]
"""

from __future__ import annotations

import argparse
import collections

import numpy as np

from pedsafe_sumo.demand.sampling import traffic_distributions
from pedsafe_sumo.demand.vehicles import speed_limit_scale
from pedsafe_sumo.network.sites import get_site
from pedsafe_sumo.params import load_params
from pedsafe_sumo.sampling.draws import Draws, draw_lognormal, draw_pedestrian_traits
from pedsafe_sumo.scenarios.geometry import load_approach
from pedsafe_sumo.scenarios.placements import placement_of
from pedsafe_sumo.scenarios.placements.base import StagingInputs
from pedsafe_sumo.scenarios.road_users import CLOTHING_COLOURS_RGB
from pedsafe_sumo.scenarios.signals import SignalStagingError, load_junction_signals
from pedsafe_sumo.scenarios.specs import get_scenario
from pedsafe_sumo.scenarios.staging import draw_episode, stage_signals

STRAIGHT = ("crossing", "jaywalking", "background_blending")


def runner_draws(spec, approach, params, seed: int):
    """(Draws, traits, ego speed) as the runner makes them before draw_episode."""
    world_seq, _, _ = np.random.SeedSequence(seed).spawn(3)
    draws = Draws(np.random.default_rng(world_seq))
    traits = draw_pedestrian_traits(draws, params["pedestrians"])
    _, non_intersection, intersection = traffic_distributions(params["traffic"])
    fit = intersection if spec.ego_speed_fit == "intersection" else non_intersection
    scale = speed_limit_scale(approach.speed_limit_mps, params["traffic"])
    return draws, traits, draw_lognormal(draws, "ego_speed_log", fit.log_mu, fit.log_sigma) * scale


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--site", default="xueqing")
    parser.add_argument("--seeds", type=int, default=20)
    args = parser.parse_args()
    params = load_params(None)
    site = get_site(args.site)
    approach = load_approach(site)
    signals = load_junction_signals(site.file("net.xml"), approach.junction_id)
    for name in STRAIGHT:
        spec = get_scenario(name).with_overrides({"staging": "approach"})
        speeds, starts, appears = [], [], []
        fired: collections.Counter[str] = collections.Counter()
        unstaged = 0
        for seed in range(args.seeds):
            draws, traits, speed = runner_draws(spec, approach, params, seed)
            drawn = draw_episode(spec, approach, seed, traits, speed, draws)
            try:
                setup = stage_signals(spec, drawn, signals, draws)
            except SignalStagingError:
                unstaged += 1
                setup = drawn
            if setup.pedestrian.appear_time_s != drawn.pedestrian.appear_time_s:
                fired["appear_later (signal)"] += 1
            # The placement's scene again from the same draws, for the fallbacks it names.
            draws, traits, speed = runner_draws(spec, approach, params, seed)
            low_s, high_s = spec.conflict_offset_min_s, spec.conflict_offset_max_s
            offset_s = draws.uniform("conflict_offset_s", low_s, high_s)
            clothing = CLOTHING_COLOURS_RGB[draws.index("clothing", len(CLOTHING_COLOURS_RGB))]
            speed = float(np.clip(speed, spec.ego_speed_min_mps, spec.ego_speed_max_mps))
            inputs = StagingInputs(spec, approach, traits, speed, offset_s, clothing, draws)
            fired.update(placement_of(spec).stage(inputs).approach_fallbacks)
            speeds.append(setup.ego.speed_mps)
            starts.append(setup.ego_start_distance_m)
            appears.append(setup.pedestrian.appear_time_s)

        def spread(values) -> str:
            return " ".join(f"{v:.1f}" for v in np.percentile(values, [0, 25, 50, 75, 100]))

        print(f"{name} ({args.seeds} seeds; min q1 median q3 max)")
        print(f"  ego speed [m/s]          {spread(speeds)}")
        print(f"  ego_start_distance_m     {spread(starts)}")
        print(f"  ped_appear_time_s        {spread(appears)}")
        print(f"  fallbacks fired          {dict(fired) or 'none'}")
        print(f"  signal staging failed    {unstaged}")


if __name__ == "__main__":
    main()
