"""Hosting decided by staging: before the first episode the batch stages, without SUMO, every episode it will
run, and a combination of scenario and approach whose staging fails for any of its seeds is skipped (with
the reason, printed and recorded in run.json) or, when the user asked for exactly it, refused.

The static hosting check (scenarios/hosting.py) reads the approach's geometry and the poles; whether an
episode can be staged also depends on its draws (the ego's speed, the gaps of the queue, the signal
timing). Staging an episode without SUMO is the episode runner's own `draw_setup` (the placement and the
signal staging: the world the worker builds from the same seed; the background traffic, drawn from a
stream of its own, is left out), then what SUMO cannot do with it: every staged vehicle (the ego, the
occluders, the queue) must stand on its lane, its front between the lane's start and its end. A vehicle
staged before the lane's start is not where the episode means it to be: on a 27 m approach lane at
Ingolstadt a jaywalking occluder staged 5.6 m before its start was inserted elsewhere and a car of the
queue behind it not at all ("SUMO did not insert vehicle 'queued_4'", tests/batch/test_hosting_staging.py).
The check covers what can be told without SUMO; an error row of a combination that passes it is a bug
(its cause belongs in this check, with a test).

Importance sampling (`--sampler is`) draws its worlds from a proposal fitted during the run: the check
stages the nominal worlds of its seeds; the worlds a proposal draws are not checked in advance.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from typing import Any

from pedsafe_sumo.batch.chunks import episode_seed
from pedsafe_sumo.control.baseline import BaselineStack
from pedsafe_sumo.scenarios.signals import SignalStagingError
from pedsafe_sumo.sim.episode import EpisodeRunner
from pedsafe_sumo.sumo_net import read_net

#: Print a progress line when the check is expected to take longer than this [s]: below it the batch
#: starts without a word.
PROGRESS_AFTER_S = 3.0
#: Then a line this often [s].
PROGRESS_EVERY_S = 15.0


def staging_problem(runner: EpisodeRunner, spec, seed: int, lane_lengths_m: dict[str, float]) -> str | None:
    """Why episode `seed` of `spec` cannot be staged (one line), or None."""
    try:
        # The background traffic is drawn from a stream of its own (after the world's draws) and SUMO
        # inserts it as it comes: it cannot make staging fail, and drawing it is 60 % of the cost.
        setup = runner.draw_setup(dataclasses.replace(spec, background_traffic=0), seed)
    except (SignalStagingError, ValueError) as exc:  # the staging's own refusals
        return f"seed {seed}: {exc}"
    except Exception as exc:  # anything else would end the episode in an error row: named, never hidden
        return f"seed {seed}: {type(exc).__name__}: {exc}"
    for vehicle in (setup.ego, *setup.parked):
        length_m = lane_lengths_m.get(vehicle.lane_id)
        if length_m is None:
            return f"seed {seed}: vehicle '{vehicle.vehicle_id}' is staged on {vehicle.lane_id}, not a lane"
        chain = getattr(runner.approach, "chain", None)
        if chain is not None and vehicle.lane_id in runner.approach.lane_ids and not vehicle.approach_lane_id:
            # Left on the stop line's lane by scenarios/chained.py: its position is along the chain.
            chain_m = chain.length_m(runner.approach.lane_ids.index(vehicle.lane_id))
            where = (
                f"{-vehicle.front_pos_m:.1f} m before the start"
                if vehicle.front_pos_m < 0.0
                else f"{vehicle.front_pos_m - chain_m:.1f} m beyond the end"
            )
            if not 0.0 <= vehicle.front_pos_m <= chain_m:
                return (
                    f"seed {seed}: vehicle '{vehicle.vehicle_id}' would stand {where} of its lane "
                    f"{vehicle.lane_id} and the chain of edges before it ({', '.join(chain.edges)}: "
                    f"{chain_m:.1f} m): SUMO cannot put it there"
                )
            continue
        if not 0.0 <= vehicle.front_pos_m <= length_m:
            where = (
                f"{-vehicle.front_pos_m:.1f} m before the start"
                if vehicle.front_pos_m < 0.0
                else f"{vehicle.front_pos_m - length_m:.1f} m beyond the end"
            )
            return (
                f"seed {seed}: vehicle '{vehicle.vehicle_id}' would stand {where} of its lane "
                f"{vehicle.lane_id} ({length_m:.1f} m long): SUMO cannot put it there"
            )
    return None


def unstageable_units(
    site,
    params: dict[str, Any],
    specs: dict[str, Any],
    run_seed: int,
    episodes: int,
    say: Callable[[str], None] = print,
) -> dict[str, str]:
    """Unit -> why one of its episodes cannot be staged (the first seed that fails), for the units of
    `specs` over episodes 0..`episodes`-1 of run `run_seed`. Says so when it is expected to take longer
    than PROGRESS_AFTER_S, then every PROGRESS_EVERY_S how far it is."""
    try:
        runner = EpisodeRunner(site, params, BaselineStack)  # no episode runs: no stack is started
    except ValueError as exc:  # the site's own approach cannot be read: no episode of it can be staged
        return {unit: str(exc) for unit in specs}
    try:
        # Internal lanes too: a turning scenario may stage a vehicle inside the junction.
        net = read_net(str(site.file("net.xml")), withInternal=True)
        lane_lengths_m = {lane.getID(): lane.getLength() for e in net.getEdges() for lane in e.getLanes()}
        seeds = [episode_seed(run_seed, episode) for episode in range(episodes)]
        started = last_said = time.perf_counter()
        announced = False
        failed: dict[str, str] = {}
        total = len(specs) * len(seeds)
        done = 0
        for unit, spec in specs.items():
            for index, seed in enumerate(seeds):
                problem = staging_problem(runner, spec, seed, lane_lengths_m)
                if problem is not None:
                    failed[unit] = problem
                    done += len(seeds) - index
                    break
                done += 1
                now = time.perf_counter()
                if not announced and (now - started) * total / done > PROGRESS_AFTER_S and done < total:
                    say(f"staging {total:,} episodes without SUMO before the first one runs ...")
                    announced, last_said = True, now
                elif announced and now - last_said > PROGRESS_EVERY_S:
                    say(f"  staged {done:,} of {total:,} ({now - started:.0f} s)")
                    last_said = now
        if announced:
            say(f"staged {total:,} episodes in {time.perf_counter() - started:.1f} s")
    finally:
        runner.close()
    return failed
