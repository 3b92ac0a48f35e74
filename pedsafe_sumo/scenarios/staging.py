"""From a scenario spec and a seed to one episode's initial world: `draw_episode` places the road users
(through the spec's placement, scenarios/placements/), `stage_signals` places the episode in the
junction's signal program."""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from pedsafe_sumo.network.traffic_side import KEEP_RIGHT, near_turn_letter
from pedsafe_sumo.sampling.draws import Draws, as_draws
from pedsafe_sumo.scenarios.chained import land_scene
from pedsafe_sumo.scenarios.episode_setup import EpisodeSetup, PedestrianSetup, SignalStaging
from pedsafe_sumo.scenarios.geometry import Approach, Turn
from pedsafe_sumo.scenarios.oncoming import OncomingPath
from pedsafe_sumo.scenarios.placements import placement_of
from pedsafe_sumo.scenarios.placements.base import StagingInputs
from pedsafe_sumo.scenarios.road_users import CLOTHING_COLOURS_RGB, PEDESTRIAN_RADIUS_M, pedestrian_height_m
from pedsafe_sumo.scenarios.signals import (
    NO_LINK,
    JunctionSignals,
    SignalStagingError,
    cycle_start_windows,
    draw_cycle_start_s,
)
from pedsafe_sumo.scenarios.specs import ScenarioSpec
from pedsafe_sumo.scenarios.walkways import polyline_length_m, shape_between

#: Approach staging: when the scene from the pedestrian's appearance to after the conflict is longer than
#: the ego's signal run, they appear this much later than the run's start would allow at the earliest,
#: so that the window of start times is an interval, not an instant (a thousandth of a step) [s].
SIGNAL_FIT_MARGIN_S = 1e-3
#: Approach staging, ped_signal_hold "step_off": how long after the planned step-off the pedestrian's
#: signal still shows `ped_signal` [s]. Measured: SUMO's step-off lags the plan by 0.05-0.15 s (1-3
#: steps); without the hold, 4 of 100 right_turn episodes of protocol approach-v2 stepped off on red just
#: after their walk ended. 0.5 s covers that lag several times over.
STEP_OFF_HOLD_S = 0.5
#: Approach staging: when no point of the cycle fits even with the pedestrian appearing as late as the
#: ego's longest signal run allows, later appearances along the same walk-in are tried in these steps [s]
#: (the walk signal inside the ego's green can be the tighter bound: a step-off held past the walk's end).
APPEAR_LATER_STEP_S = 0.25


def draw_episode(
    spec: ScenarioSpec,
    approach: Approach,
    seed: int,
    pedestrian_traits: dict,
    ego_speed_mps: float,
    rng: np.random.Generator | Draws,
    turn: Turn | None = None,
    oncoming: OncomingPath | None = None,
) -> EpisodeSetup:
    """Place one episode of `spec` on the approach (for a turning scenario, on `turn`; with an oncoming
    vehicle, on the `oncoming` path).

    `pedestrian_traits` (age_years, gender, risk, walking_speed_mps) and `ego_speed_mps` come from the
    demand model's samplers, drawn from the same seeded `rng` before this is called; the draws here
    (offsets, gaps, colours) follow in a fixed order so the world is a function of the seed alone: the
    conflict offset, the clothing, then the placement's own. `rng` may be a Draws (sampling/draws.py):
    the named draws then go through it, recorded (and under importance sampling drawn from its
    proposal); a bare Generator draws them all nominally.
    """
    draws = as_draws(rng)
    conflict_offset_s = draws.uniform(
        "conflict_offset_s", spec.conflict_offset_min_s, spec.conflict_offset_max_s
    )
    clothing = CLOTHING_COLOURS_RGB[draws.index("clothing", len(CLOTHING_COLOURS_RGB))]
    scene = placement_of(spec).stage(
        StagingInputs(
            spec=spec,
            approach=approach,
            traits=pedestrian_traits,
            ego_speed_mps=float(np.clip(ego_speed_mps, spec.ego_speed_min_mps, spec.ego_speed_max_mps)),
            conflict_offset_s=conflict_offset_s,
            clothing_rgb=clothing,
            draws=draws,
            turn=turn,
            oncoming=oncoming,
        )
    )
    # Where the approach is a chain of edges, on the lanes SUMO knows (scenarios/chained.py).
    scene = land_scene(approach, scene)
    return EpisodeSetup(
        scenario=spec.name,
        seed=seed,
        ego=scene.ego,
        ego_route=scene.ego_route,
        pedestrian=dataclasses.replace(
            pedestrian(pedestrian_traits, scene.clothing_rgb, scene.start_delay_s, scene.path),
            appear_time_s=float(scene.appear_time_s),
            kerb_index=scene.kerb_index,
            leaves_scene=scene.leaves_scene,
        ),
        parked=scene.parked,
        conflict_xy=(float(scene.conflict_xy[0]), float(scene.conflict_xy[1])),
        conflict_offset_s=conflict_offset_s,
        # Under approach staging the episode lasts the approach until the pedestrian appears, then the
        # scene (in the fixed staging they are there from the start: appear_time_s is 0).
        time_limit_s=float(scene.appear_time_s) + spec.time_limit_s
        if spec.staging == "approach"
        else spec.time_limit_s,
        conflict_time_s=float(scene.conflict_time_s),
        ped_crossing_id=scene.ped_crossing_id,
        ego_start_distance_m=float(scene.ego_start_distance_m),
    )


def ego_exit_edge(setup: EpisodeSetup) -> str:
    """The edge the ego's route takes beyond the junction: the one after its approach lane's edge (the
    route may start on the road before the approach)."""
    route = setup.ego_route
    approach_edge = setup.ego.stop_line_lane_id.rsplit("_", 1)[0]
    return route[route.index(approach_edge) + 1] if approach_edge in route[:-1] else route[1]


def pedestrian(traits: dict, clothing, start_delay_s: float, path) -> PedestrianSetup:
    """The pedestrian of an episode: its traits, its body (road_users), where it walks and when."""
    return PedestrianSetup(
        path_xy=tuple((float(p[0]), float(p[1])) for p in path),
        start_delay_s=start_delay_s,
        age_years=float(traits["age_years"]),
        gender=str(traits["gender"]),
        risk=str(traits["risk"]),
        walking_speed_mps=float(traits["walking_speed_mps"]),
        clothing_rgb=(int(clothing[0]), int(clothing[1]), int(clothing[2])),
        radius_m=PEDESTRIAN_RADIUS_M,
        height_m=pedestrian_height_m(traits["gender"], traits["age_years"]),
    )


def stage_signals(
    spec: ScenarioSpec,
    setup: EpisodeSetup,
    junction: JunctionSignals | None,
    rng: np.random.Generator | Draws,
    side: float = KEEP_RIGHT,
) -> EpisodeSetup:
    """Place the episode in the junction's signal program: a start time in the cycle, drawn uniformly
    (one draw from `rng`) among those at which the ego's signal shows what `spec` requires from the
    start (under approach staging from the pedestrian's appearance, or from the stop line of a vehicle
    turning ahead of it on its lane, whichever is earlier), the pedestrian's from the moment they step
    off, and an oncoming vehicle's green from its stop line (VehicleSetup.green_from_s), until
    `signal_hold_after_s` after the staged conflict. Under approach staging, when that is longer than any
    run of the ego's signal, the pedestrian appears later, part of the way along their walk-in
    (appear_later; _fit_approach). SignalStagingError when the program has no such time (the message says
    which). `side`: the site's traffic side (network.traffic_side): the kerb lane's occluder turns by
    its near-side turn."""
    if junction is None:
        # An unsignalised junction (another site): nobody has a signal, and episodes.parquet says so
        # (ego_signal and ped_signal "none").
        return setup
    ego_link = junction.vehicle_link(setup.ego.stop_line_lane_id, ego_exit_edge(setup))
    ped_link = junction.crossing_link(setup.ped_crossing_id) if setup.ped_crossing_id else NO_LINK
    if (ped_link == NO_LINK) != (spec.ped_signal == "none"):
        where = f"crossing {setup.ped_crossing_id}" if setup.ped_crossing_id else "a mid-block crossing"
        raise SignalStagingError(
            f"scenario '{spec.name}': ped_signal {spec.ped_signal} does not fit {where} "
            f"({'signalised' if ped_link != NO_LINK else 'no signal'})"
        )
    until_s = setup.conflict_time_s + spec.signal_hold_after_s
    required = _required_signals(spec, setup, junction, ego_link, ped_link, until_s)
    if spec.staging == "approach" and not cycle_start_windows(junction.program, required, until_s):
        setup, required = _fit_approach(spec, setup, junction, ego_link, ped_link, until_s)
    oncoming_links = _oncoming_links(setup, junction)
    # The point in the cycle is one uniform draw on [0, 1), recorded (never proposed) as signal_cycle_u.
    source = as_draws(rng).uniform_source("signal_cycle_u")
    cycle_start_s = draw_cycle_start_s(junction.program, required, until_s, source)  # type: ignore[arg-type]
    staging = SignalStaging(
        tls_id=junction.program.tls_id,
        program_id=junction.program.program_id,
        cycle_start_s=round(cycle_start_s, 6),
        ego_link_index=ego_link,
        ped_link_index=ped_link,
        occluder_link_index=(
            oncoming_links[0]
            if oncoming_links
            else junction.turn_link(setup.parked[0].stop_line_lane_id, near_turn_letter(side))
            if setup.parked
            else NO_LINK
        ),
    )
    return dataclasses.replace(setup, signals=staging)


def _fit_approach(
    spec: ScenarioSpec,
    setup: EpisodeSetup,
    junction: JunctionSignals,
    ego_link: int,
    ped_link: int,
    until_s: float,
) -> tuple[EpisodeSetup, dict]:
    """Approach staging, when no point of the cycle gives every road user their signal: (the setup, the
    signals required of it). From the pedestrian's appearance to after the conflict is longer than any
    run of the ego's signal (Xueqing's through green lasts 16 s of its 90 s cycle): they enter the scene
    later, part of the way along their walk-in, so that the scene fits in one run (appear_later). A
    vehicle turning ahead of the ego (right_turn's leader) whose stop line comes too long before the
    conflict for one green (a slow ego) is then no longer required to cross it on green (it crossed it on
    the end of the previous phase), so that the ego, the pedestrian and the oncoming vehicle keep theirs."""
    longest_s = max((hi - lo for lo, hi in junction.program.runs(ego_link, spec.ego_signal)), default=0.0)
    later = appear_later(spec, setup, until_s - longest_s + SIGNAL_FIT_MARGIN_S)
    for leaders in (True, False):
        if leaders is False and not _leaders(setup):
            break
        required = _required_signals(spec, setup, junction, ego_link, ped_link, until_s, leaders)
        if cycle_start_windows(junction.program, required, until_s):
            return setup, required
        if later is not None:
            required = _required_signals(spec, later, junction, ego_link, ped_link, until_s, leaders)
            if cycle_start_windows(junction.program, required, until_s):
                return later, required
    # Later still, along the same walk-in, until a point of the cycle fits or the walk-in is used up.
    base = later if later is not None else setup
    appear_s = base.pedestrian.appear_time_s + APPEAR_LATER_STEP_S
    while (later_still := appear_later(spec, base, appear_s)) is not None:
        for leaders in (True, False) if _leaders(setup) else (True,):
            required = _required_signals(spec, later_still, junction, ego_link, ped_link, until_s, leaders)
            if cycle_start_windows(junction.program, required, until_s):
                return later_still, required
        appear_s += APPEAR_LATER_STEP_S
    if later is not None:
        setup = later
    return setup, _required_signals(spec, setup, junction, ego_link, ped_link, until_s)


def _leaders(setup: EpisodeSetup) -> list:
    """The vehicles that come down the ego's lane ahead of it to turn on its green (approach staging's
    right_turn leader)."""
    lane_id = setup.ego.stop_line_lane_id
    return [v for v in setup.parked if v.vehicle_id.startswith("leader_") and v.stop_line_lane_id == lane_id]


def step_off_time_s(ped: PedestrianSetup) -> float:
    """When the pedestrian steps off the kerb [s]: their appearance, the walk-in (the points of their path
    before `kerb_index`, at their walking speed), then the wait at the kerb."""
    if ped.kerb_index == 0:
        return ped.appear_time_s + ped.start_delay_s if ped.appear_time_s else ped.start_delay_s
    walk_in = ped.path_xy[: ped.kerb_index + 1]
    walk_in_m = sum(math.dist(p, q) for p, q in zip(walk_in[:-1], walk_in[1:]))
    return ped.appear_time_s + walk_in_m / ped.walking_speed_mps + ped.start_delay_s


def _required_signals(
    spec, setup, junction, ego_link: int, ped_link: int, until_s: float, leaders: bool = True
) -> dict:
    """Link -> (colour, from, until) each road user's signal must show (signals.cycle_start_windows)."""
    # The ego from the start (it sees its signal all the way to the stop line; under approach staging
    # from the pedestrian's appearance: before it the ego is on its approach and nothing is staged), the
    # pedestrian from stepping off the kerb, both until after the conflict.
    ego_from_s = min(setup.pedestrian.appear_time_s, until_s) if spec.staging == "approach" else 0.0
    if spec.staging == "approach" and leaders:
        # A vehicle ahead of the ego on its lane turns on the same green from its stop line on.
        ego_from_s = min([ego_from_s, *(v.green_from_s for v in _leaders(setup))])
    required: dict[int, str | tuple[str, float, float]] = {ego_link: (spec.ego_signal, ego_from_s, until_s)}
    if ped_link != NO_LINK:
        step_off_s = min(step_off_time_s(setup.pedestrian), until_s)
        ped_until_s = until_s if spec.ped_signal_hold == "conflict" else step_off_s
        if spec.ped_signal_hold == "step_off" and spec.staging == "approach":
            # SUMO's pedestrian steps off up to 3 steps after the planned moment: their signal holds a
            # little past it, so that they really step off on it. (The fixed staging, which protocol
            # paper-v7 runs, holds it at the planned moment only.)
            ped_until_s = min(step_off_s + STEP_OFF_HOLD_S, until_s)
        required[ped_link] = (spec.ped_signal, step_off_s, ped_until_s)
    # A vehicle coming the other way through the junction (left_turn's oncoming vehicle) has green too,
    # from its stop line on (from the start in the fixed staging, which starts it on the junction).
    for link, from_s in _oncoming_links_from(setup, junction):
        required[link] = ("green", min(from_s, until_s), until_s)
    return required


def _oncoming_links(setup: EpisodeSetup, junction: JunctionSignals) -> list[int]:
    return [link for link, _ in _oncoming_links_from(setup, junction)]


def _oncoming_links_from(setup: EpisodeSetup, junction: JunctionSignals) -> list[tuple[int, float]]:
    """(link, from when its green must show) of each oncoming vehicle that has yet to leave the junction:
    the link from the last edge of its route before the junction (under approach staging it may start on
    the road before its approach: that edge's lane with the same index)."""
    links = []
    for v in setup.parked:
        if not v.vehicle_id.startswith("oncoming_") or len(v.route) < 2:
            continue
        lane_id = v.lane_id
        if len(v.route) > 2:
            lane_id = f"{v.route[-2]}_{v.lane_id.rsplit('_', 1)[1]}"
        links.append((junction.vehicle_link(lane_id, v.route[-1]), v.green_from_s))
    return links


def appear_later(spec: ScenarioSpec, setup: EpisodeSetup, appear_s: float) -> EpisodeSetup | None:
    """The approach-staged `setup` with the pedestrian entering the scene at `appear_s` instead, where
    their walk-in would have brought them by then (the step-off and everything after it unchanged), and
    the episode's time limit moved with it; None when their walk-in is shorter than the delay."""
    ped = setup.pedestrian
    if appear_s <= ped.appear_time_s:
        return setup
    walk = ped.path_xy[: ped.kerb_index + 1]
    walk_m = polyline_length_m(walk)
    cut_m = (appear_s - ped.appear_time_s) * ped.walking_speed_mps
    if cut_m >= walk_m:
        return None
    rest = shape_between(walk, cut_m, walk_m)[:-1]
    later = dataclasses.replace(
        ped, path_xy=(*rest, *ped.path_xy[ped.kerb_index :]), kerb_index=len(rest), appear_time_s=appear_s
    )
    return dataclasses.replace(setup, pedestrian=later, time_limit_s=appear_s + spec.time_limit_s)
