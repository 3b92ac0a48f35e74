"""left_turn's oncoming vehicle under approach staging, over every draw of a protocol (no SUMO): where the
ego is at the moment the oncoming vehicle is staged across the line of sight from the ego's box centre to
the pedestrian at their step-off point, whether that line crosses the oncoming path at all, and whether
the oncoming vehicle, driving on at the ego's speed as staged, then passes in front of the ego or into it.

Both values of ScenarioSpec.oncoming_moment on the protocol's own draws (its seed rule, its spec):
"at_kerb" (the moment the pedestrian reaches the kerb, wherever the ego then is) and "stop_line" (no
later than the ego's front 3 m before its stop line, the pedestrian waiting the longer on the kerb).
The draws (ego speed, conflict offset, walking speed) are those of the episode runner
(EpisodeRunner.draw_setup_sampled); the ego's front at the moment is computed from them by hand:
conflict point - v (conflict offset + walk from the step-off point to the conflict + ped_start_delay_s),
SUMO metres along the turn. Clearance: both vehicles as rectangles (length x width of their class) along
the chord from the rear to the front on their paths, the ego's front swept from 30 m before its stop
line to 5 m past the junction with the oncoming vehicle's front at the same offset along its path as
at the staged moment (both drive at v); the least gap between the rectangles. Then the batch's own
staging check (batch/staging_check.staging_problem) over every seed under each value.

    python research/left_turn_sight_line_draws.py [--protocol protocols/paper-v10-left_turn.toml]
        [--episodes N]
"""

from __future__ import annotations

import argparse
import collections
import dataclasses
import math
from pathlib import Path

import numpy as np
import shapely

from pedsafe_sumo.batch.chunks import episode_seed
from pedsafe_sumo.batch.staging_check import staging_problem
from pedsafe_sumo.control.baseline import BaselineStack
from pedsafe_sumo.network.sites import resolve_site
from pedsafe_sumo.protocol import load_protocol
from pedsafe_sumo.scenarios.geometry import load_turn, path_pos_m
from pedsafe_sumo.scenarios.oncoming import load_oncoming, point_at, sight_line_pos_m
from pedsafe_sumo.scenarios.placements.turn import TURN_START_BEFORE_STOP_LINE_M, path_point
from pedsafe_sumo.scenarios.road_users import VEHICLE_CLASSES
from pedsafe_sumo.sim.episode import EpisodeRunner
from pedsafe_sumo.sumo_net import read_net

#: Sampling step of the paths (SUMO metres) and of the ego's sweep [m].
STEP_M = 0.1
SWEEP_STEP_M = 0.25


def sampled(point, length_m: float) -> tuple[np.ndarray, np.ndarray]:
    """(positions, xy) of a path every STEP_M, for np.interp."""
    pos = np.arange(0.0, length_m, STEP_M)
    return pos, np.array([point(p) for p in pos])


def boxes(table, front_m: np.ndarray, size) -> np.ndarray:
    """Rectangles of vehicles of class `size` whose fronts are `front_m` along a sampled path."""
    pos, xy = table
    front = np.stack([np.interp(front_m, pos, xy[:, 0]), np.interp(front_m, pos, xy[:, 1])], axis=-1)
    rear_m = front_m - size.length_m
    rear = np.stack([np.interp(rear_m, pos, xy[:, 0]), np.interp(rear_m, pos, xy[:, 1])], axis=-1)
    axis = front - rear
    axis /= np.linalg.norm(axis, axis=-1, keepdims=True)
    side = np.stack([-axis[..., 1], axis[..., 0]], axis=-1) * size.width_m / 2
    rear = front - axis * size.length_m
    corners = np.stack([front + side, front - side, rear - side, rear + side], axis=-2)
    return shapely.polygons(corners)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--protocol", default="protocols/paper-v10-left_turn.toml")
    parser.add_argument("--episodes", type=int, default=None, help="the protocol's number by default")
    args = parser.parse_args()
    protocol = load_protocol(Path(args.protocol))
    site = resolve_site(protocol.header["site"])
    params = protocol.params()
    spec = dataclasses.replace(protocol.specs()["left_turn"], background_traffic=0)
    episodes = args.episodes or protocol.header["episodes"]
    seeds = [episode_seed(protocol.header["seed"], k) for k in range(episodes)]
    runner = EpisodeRunner(site, params, BaselineStack)
    turn = load_turn(site, spec.turn, spec.approach or None)
    oncoming = load_oncoming(site, spec.approach or None).extended()
    car, occluder = VEHICLE_CLASSES["car"], VEHICLE_CLASSES[spec.occluder_class]
    latest_m = turn.approach_length_m - TURN_START_BEFORE_STOP_LINE_M
    ego_table = sampled(lambda p: path_point(turn.lanes, p), sum(length for _, length in turn.lanes))
    oncoming_table = sampled(lambda p: point_at(oncoming, p), sum(lane.length_m for lane in oncoming.lanes))
    sweep_m = np.arange(turn.approach_length_m - 30.0, turn.exit_start_m + 5.0, SWEEP_STEP_M)
    ego_sweep = boxes(ego_table, sweep_m, car)

    rows = []
    for seed in seeds:
        # The draws do not depend on oncoming_moment; "stop_line" stages every one of them.
        setup, _ = runner.draw_setup_sampled(dataclasses.replace(spec, oncoming_moment="stop_line"), seed)
        ped = setup.pedestrian
        step_off = ped.path_xy[ped.kerb_index]
        conflict_m = path_pos_m(turn.lanes, setup.conflict_xy)
        walk_s = math.dist(step_off, setup.conflict_xy) / ped.walking_speed_mps
        v = setup.ego.speed_mps
        front_at_kerb_m = conflict_m - v * (setup.conflict_offset_s + walk_s + spec.ped_start_delay_s)
        row = {"speed": v, "walk": ped.walking_speed_mps, "offset": setup.conflict_offset_s}
        for moment, front_m in (("at_kerb", front_at_kerb_m), ("stop_line", min(front_at_kerb_m, latest_m))):
            eye = path_point(turn.lanes, front_m - car.length_m / 2)
            crossing_m = sight_line_pos_m(oncoming, eye, step_off)
            row[f"{moment}.front_m"] = front_m
            row[f"{moment}.crossing"] = crossing_m is not None
            if crossing_m is None:
                row[f"{moment}.gap_now_m"] = row[f"{moment}.gap_least_m"] = math.nan
                continue
            ahead_m = crossing_m + occluder.length_m / 2 - front_m  # its front minus the ego's, constant
            row[f"{moment}.gap_now_m"] = float(
                shapely.distance(
                    boxes(ego_table, np.array([front_m]), car),
                    boxes(oncoming_table, np.array([front_m + ahead_m]), occluder),
                )[0]
            )
            row[f"{moment}.gap_least_m"] = float(
                shapely.distance(ego_sweep, boxes(oncoming_table, sweep_m + ahead_m, occluder)).min()
            )
        row["kerb_wait_s"] = spec.ped_start_delay_s + max(front_at_kerb_m - latest_m, 0.0) / v
        rows.append(row)

    n = len(rows)
    print(f"{args.protocol}: {n:,} draws of left_turn on {site.name} (seed {protocol.header['seed']})")
    print(
        f"the ego's turn: stop line at {turn.approach_length_m:.1f} m, fixed staging's latest start "
        f"{latest_m:.1f} m, junction left at {turn.exit_start_m:.1f} m (SUMO metres along its path)"
    )
    for moment in ("at_kerb", "stop_line"):
        front = np.array([r[f"{moment}.front_m"] for r in rows])
        missed = [r for r in rows if not r[f"{moment}.crossing"]]
        least = np.array([r[f"{moment}.gap_least_m"] for r in rows])
        now = np.array([r[f"{moment}.gap_now_m"] for r in rows])
        print(f"\noncoming_moment = {moment}")
        print(
            "  the ego's front at that moment: "
            + ", ".join(
                f"p{q} {v:.1f}"
                for q, v in zip((0, 25, 50, 75, 100), np.percentile(front, [0, 25, 50, 75, 100]))
            )
            + " m"
        )
        print(f"  line of sight misses the oncoming path: {len(missed)} of {n:,}")
        if missed:
            for key, unit in (("speed", "m/s"), ("walk", "m/s"), ("offset", "s"), (f"{moment}.front_m", "m")):
                values = [r[key] for r in missed]
                print(f"    {key}: {min(values):.2f}-{max(values):.2f} {unit}")
            hit = [r[f"{moment}.front_m"] for r in rows if r[f"{moment}.crossing"]]
            first_m = min(r[f"{moment}.front_m"] for r in missed)
            print(
                f"    the line crosses it for every front up to {max(hit):.2f} m, misses from {first_m:.2f} m"
            )
        print(f"  the two bodies overlap at that moment: {int(np.sum(now <= 0.0))} of {n:,}")
        print(f"  on a collision course (least gap 0, both at v): {int(np.sum(least <= 0.0))} of {n:,}")
        for gap_m in (0.5, 1.0, 2.0):
            print(f"  least gap under {gap_m} m: {int(np.sum(least < gap_m))} of {n:,}")
        finite = least[np.isfinite(least)]
        print(f"  least gap: min {finite.min():.2f} m, median {np.median(finite):.2f} m")
    changed = [r for r in rows if r["kerb_wait_s"] > spec.ped_start_delay_s]
    waits = np.array([r["kerb_wait_s"] for r in rows])
    print(
        f"\nstop_line moves the moment earlier in {len(changed)} of {n:,} draws; the kerb wait: "
        + ", ".join(
            f"p{q} {v:.1f}" for q, v in zip((0, 25, 50, 75, 100), np.percentile(waits, [0, 25, 50, 75, 100]))
        )
        + " s"
    )

    net = read_net(str(site.file("net.xml")), withInternal=True)
    lanes_m = {lane.getID(): lane.getLength() for edge in net.getEdges() for lane in edge.getLanes()}
    for moment in ("at_kerb", "stop_line"):
        moment_spec = dataclasses.replace(spec, oncoming_moment=moment)
        problems = [staging_problem(runner, moment_spec, seed, lanes_m) for seed in seeds]
        reasons = collections.Counter(p.split(": ", 1)[1] for p in problems if p is not None)
        print(
            f"\nthe batch's staging check, oncoming_moment = {moment}: "
            f"{sum(reasons.values())} of {n:,} refused"
        )
        for reason, count in reasons.most_common():
            print(f"  {count}: {reason}")
    runner.close()


if __name__ == "__main__":
    main()
