"""left_turn stagings of the oncoming occluder, over every draw of a protocol (no SUMO): for which draws
each staging hides the pedestrian until their step-off while the ego and the oncoming vehicles stay clear of
each other, both driving on at the ego's speed.

The draws (ego speed v, conflict offset, walking speed) are those of the episode runner
(EpisodeRunner.draw_setup_sampled), as in research/left_turn_sight_line_draws.py. Times are relative to
the pedestrian's step-off (t = 0). The ego's front at t is F(t) = conflict point - v (conflict offset +
walk from the step-off point to the conflict) + v t along its turn (SUMO metres); its eye is its box centre
(the roof LiDAR, as the staging's sight line). The pedestrian stands at the step-off point from their kerb
arrival to the step-off: 1 s before it (`ped_start_delay_s`, "at_kerb" timing) or, under paper-v11's
"stop_line" timing, when the ego's front is 3 m before its stop line if that is earlier.

Hidden at t: the three sight lines from the eye to the pedestrian's body circle (its centre and its two
edges, radius 0.3 m across the line) cross the oncoming path's centreline within one oncoming body's
extent along the path (its rear to its front), so the body covers where each line crosses its lane. This
ignores the body's width (an oblique line can clip a corner of the box beyond that extent) and heights
(an SUV is 1.75 m tall, the LiDAR at 1.9 m): it is the ground-plane proxy the staging itself uses, not the
engine's perception. Every oncoming vehicle drives at v along the path; a platoon's followers are `h v`
(time headway h, front to front) behind their leader. The least gap between the ego and each oncoming
body, both driving on at v, is taken as in left_turn_sight_line_draws.py (rectangles along their paths,
the ego's front swept from 30 m before its stop line to 5 m past the junction), tabulated once per class
against the constant distance between the two fronts along their paths.

A staging places the occluder(s) either by a rule (the leader's centre on the centre sight line at a given
moment) or at the best place: any leader position for which the pedestrian is hidden at every moment of
[kerb arrival, step-off], the one with the largest least gap to the ego. Per staging: draws whose sight
line at the staged moment misses the oncoming path; draws on a collision course (least gap 0) or closer
than MARGIN_M; draws hidden at the step-off with the margin kept (feasible); of those, hidden over the
whole kerb wait; and when the occlusion around the staged moment ends, relative to the step-off.

    python research/left_turn_occlusion_design.py [--protocol protocols/paper-v11-left_turn.toml]
        [--episodes N]
"""

from __future__ import annotations

import argparse
import dataclasses
import math
from pathlib import Path

import numpy as np
import shapely

# A sibling script of this folder (run as `python research/...`, its folder is on sys.path): the sampled
# paths and vehicle rectangles of the sight-line measurement, reused unchanged.
from left_turn_sight_line_draws import boxes, sampled

from pedsafe_sumo.batch.chunks import episode_seed
from pedsafe_sumo.control.baseline import BaselineStack
from pedsafe_sumo.network.sites import resolve_site
from pedsafe_sumo.protocol import load_protocol
from pedsafe_sumo.scenarios.geometry import load_turn, path_pos_m
from pedsafe_sumo.scenarios.oncoming import load_oncoming, point_at, sight_line_pos_m
from pedsafe_sumo.scenarios.placements.turn import TURN_START_BEFORE_STOP_LINE_M, path_point
from pedsafe_sumo.scenarios.road_users import PEDESTRIAN_RADIUS_M, VEHICLE_CLASSES, VehicleSize
from pedsafe_sumo.sim.episode import EpisodeRunner

#: Least gap between the ego's body and any oncoming body, both driving on at v, for a staging a traffic
#: engineer would accept as "passing ahead of the turner" rather than a near miss (assumption, the brief's
#: example; 1 m and 0 m are printed too) [m].
MARGIN_M = 2.0
#: A 12 m city bus, 2.55 m wide (the EU's maximum width, Directive 96/53/EC; 12 m the standard solo bus).
#: Height 3 m. Not one of the scenes' VEHICLE_CLASSES: a candidate occluder only.
BUS = VehicleSize(12.0, 2.55, 3.0)
#: Time grid relative to the step-off [s]: the longest paper-v11 kerb wait is 11 s.
TIME_STEP_S = 0.05
TIME_FROM_S, TIME_TO_S = -13.0, 4.0
#: The oncoming path is cut to this window around its stop line and resampled at this step for the sight
#: line crossings (the lane runs straight through the junction: 0.5 m chords lose nothing) [m].
WINDOW_BEFORE_M, WINDOW_AFTER_M, CROSSING_STEP_M = 40.0, 80.0, 0.5
#: Step of the leader positions searched for the best placement, and of the least-gap table [m].
PLACEMENT_STEP_M, GAP_TABLE_STEP_M = 0.2, 0.1


def first_crossing_pos(eyes: np.ndarray, targets: np.ndarray, path_pos: np.ndarray, path_xy: np.ndarray):
    """Where each segment eyes[i]-targets[i] first crosses the polyline path_xy, as the path position
    (path_pos interpolated linearly along the crossed chord); NaN where it does not cross.
    eyes, targets: (T, 2); path_pos: (S,); path_xy: (S, 2)."""
    a, d1 = eyes[:, None, :], (targets - eyes)[:, None, :]
    p, d2 = path_xy[None, :-1, :], (path_xy[1:] - path_xy[:-1])[None, :, :]
    denom = d1[..., 0] * d2[..., 1] - d1[..., 1] * d2[..., 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = ((p[..., 0] - a[..., 0]) * d2[..., 1] - (p[..., 1] - a[..., 1]) * d2[..., 0]) / denom
        u = ((p[..., 0] - a[..., 0]) * d1[..., 1] - (p[..., 1] - a[..., 1]) * d1[..., 0]) / denom
    valid = (np.abs(denom) > 1e-12) & (t >= 0.0) & (t <= 1.0) & (u >= 0.0) & (u <= 1.0)
    first = np.argmax(valid, axis=1)
    rows = np.arange(len(eyes))
    pos = path_pos[first] + u[rows, first] * (path_pos[first + 1] - path_pos[first])
    return np.where(valid.any(axis=1), pos, np.nan)


def pedestrian_track(times: np.ndarray, step_off_xy, next_xy, walking_speed_mps: float) -> np.ndarray:
    """(T, 2): the pedestrian at the step-off point until t = 0, then walking towards next_xy."""
    start, ahead = np.asarray(step_off_xy, dtype=float), np.asarray(next_xy, dtype=float)
    heading = (ahead - start) / np.linalg.norm(ahead - start)
    return start[None, :] + np.clip(times, 0.0, None)[:, None] * walking_speed_mps * heading[None, :]


def body_edge_targets(eyes: np.ndarray, targets: np.ndarray, radius_m: float) -> np.ndarray:
    """(3, T, 2): the body circle's centre targets[i] and its two edges across the sight line from eyes[i]."""
    direction = targets - eyes
    direction = direction / np.linalg.norm(direction, axis=1, keepdims=True)
    across = np.stack([-direction[:, 1], direction[:, 0]], axis=1) * radius_m
    return np.stack([targets, targets + across, targets - across])


def covered(front_m, length_m: float, lo_m, hi_m):
    """Whether a body from front_m - length_m to front_m along the path covers [lo_m, hi_m] (NaN: no)."""
    with np.errstate(invalid="ignore"):
        return (front_m - length_m <= lo_m) & (front_m >= hi_m) & np.isfinite(lo_m) & np.isfinite(hi_m)


def last_run_end(times: np.ndarray, hidden: np.ndarray, start_s: float, end_s: float) -> float:
    """The last time of the last run of hidden steps that overlaps [start_s, end_s] (the run may go on
    past end_s); NaN when no step of [start_s, end_s] is hidden."""
    inside = np.flatnonzero(hidden & (times >= start_s - 1e-9) & (times <= end_s + 1e-9))
    if not len(inside):
        return math.nan
    i = int(inside[-1])
    while i < len(hidden) - 1 and hidden[i + 1]:
        i += 1
    return float(times[i])


@dataclasses.dataclass(frozen=True)
class Staging:
    label: str
    size: VehicleSize
    #: Oncoming vehicles in the platoon, and their time headway front to front [s].
    vehicles: int = 1
    headway_s: float = 0.0
    #: Kerb arrival: "stop_line" (paper-v11's wait) or "at_kerb" (ped_start_delay_s before the step-off).
    wait: str = "stop_line"
    #: The leader's centre on the centre sight line at this moment: "kerb" (the kerb arrival) or a time
    #: relative to the step-off [s]; None: the best placement.
    moment: str | float | None = "kerb"
    #: What the best placement maximises among those that hide the pedestrian at the step-off with the
    #: margin kept: "gap" the least gap to the ego, "late" how long after the step-off the occlusion lasts.
    objective: str = "gap"


@dataclasses.dataclass(frozen=True)
class DrawGeometry:
    """One draw's ego and sight lines on the time grid."""

    speed_mps: float
    #: The ego's front at the step-off, SUMO metres along its turn.
    front_step_off_m: float
    #: Kerb arrival, relative to the step-off, under each timing [s].
    kerb_s: dict
    #: Where the sight line to the pedestrian's centre, and the least and greatest of the three sight
    #: lines to their body, cross the oncoming path (its SUMO metres; NaN: a line misses it), per time.
    centre_m: np.ndarray
    lo_m: np.ndarray
    hi_m: np.ndarray


def evaluate(staging: Staging, draw: DrawGeometry, times: np.ndarray, least_gap) -> dict:
    """One staging on one draw: whether its sight line crosses the oncoming path, the least gap to the ego
    (both at v), whether the pedestrian is hidden at the step-off and over their whole kerb wait, and the
    hidden run around the staged moment (first, last time relative to the step-off)."""
    v, size, n = draw.speed_mps, staging.size, staging.vehicles
    spacing_m = staging.headway_s * v
    arrive_s = draw.kerb_s[staging.wait]
    wait = (times >= arrive_s - 1e-9) & (times <= 1e-9)
    step_off = int(np.argmin(np.abs(times)))
    behind_m = spacing_m * np.arange(n)

    def hidden_for(leader_m: np.ndarray) -> np.ndarray:
        """(P, T): hidden at each time, for each front of the leader at the step-off."""
        fronts = leader_m[:, None, None] - behind_m[None, :, None] + v * times[None, None, :]
        return covered(fronts, size.length_m, draw.lo_m[None, None, :], draw.hi_m[None, None, :]).any(axis=1)

    def gap_for(leader_m: np.ndarray) -> np.ndarray:
        ahead_m = leader_m[:, None] - behind_m[None, :] - draw.front_step_off_m
        return least_gap(size, ahead_m).min(axis=1)

    row: dict = {"kerb_s": arrive_s}
    if staging.moment is None:
        if not np.all(np.isfinite(draw.lo_m[wait])):
            # Some sight line of the wait misses the path: no placement hides the whole wait.
            return dict(row, crosses=False)
        # Every leader front (at the step-off) that hides them at some moment of the wait.
        low = np.min(draw.hi_m[wait] - v * times[wait]) - behind_m[-1] - 1.0
        high = np.max(draw.lo_m[wait] - v * times[wait]) + size.length_m + 1.0
        leaders = np.arange(low, high + PLACEMENT_STEP_M, PLACEMENT_STEP_M)
        hidden, gap = hidden_for(leaders), gap_for(leaders)
        whole, at_step_off, clear = hidden[:, wait].all(axis=1), hidden[:, step_off], gap >= MARGIN_M
        # The first kind of placement that exists, then the largest gap among them: hidden over the whole
        # wait and clear; hidden at the step-off and clear; hidden over the whole wait; at the step-off.
        for keep in (whole & clear, at_step_off & clear, whole, at_step_off, np.ones(len(gap), bool)):
            if keep.any():
                break
        score = gap
        if staging.objective == "late" and (at_step_off & clear).any():
            # How many steps past the step-off the occlusion lasts (the whole grid when it never ends).
            after = ~hidden[:, step_off:]
            score = np.where(after.any(axis=1), np.argmax(after, axis=1), after.shape[1]).astype(float)
            keep = at_step_off & clear
        best = int(np.argmax(np.where(keep, score, -np.inf)))
        gap_m, hidden_t = float(gap[best]), hidden[best]
    else:
        moment_s = arrive_s if staging.moment == "kerb" else float(staging.moment)
        i = int(np.argmin(np.abs(times - moment_s)))
        if not np.isfinite(draw.centre_m[i]):
            return dict(row, crosses=False)
        leader = np.array([draw.centre_m[i] + size.length_m / 2 - v * times[i]])
        gap_m, hidden_t = float(gap_for(leader)[0]), hidden_for(leader)[0]
    return dict(
        row,
        crosses=True,
        gap=gap_m,
        at_step_off=bool(hidden_t[step_off]),
        whole_wait=bool(hidden_t[wait].all()),
        ends_s=last_run_end(times, hidden_t, arrive_s, 0.0),
        hidden_share=float(hidden_t[wait].mean()),
    )


def gap_table(ego_table, oncoming_table, sweep_m, size, ahead_m: np.ndarray) -> np.ndarray:
    """Least gap between the ego (car) and one `size` body whose front runs `ahead_m` ahead of the ego's
    along its own path, both at one speed, for each ahead_m."""
    ego_sweep = boxes(ego_table, sweep_m, VEHICLE_CLASSES["car"])
    return np.array(
        [float(shapely.distance(ego_sweep, boxes(oncoming_table, sweep_m + a, size)).min()) for a in ahead_m]
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--protocol", default="protocols/paper-v11-left_turn.toml")
    parser.add_argument("--episodes", type=int, default=None, help="the protocol's number by default")
    args = parser.parse_args()
    protocol = load_protocol(Path(args.protocol))
    site = resolve_site(protocol.header["site"])
    spec = dataclasses.replace(protocol.specs()["left_turn"], background_traffic=0)
    episodes = args.episodes or protocol.header["episodes"]
    seeds = [episode_seed(protocol.header["seed"], k) for k in range(episodes)]
    runner = EpisodeRunner(site, protocol.params(), BaselineStack)
    turn = load_turn(site, spec.turn, spec.approach or None)
    path = load_oncoming(site, spec.approach or None)
    oncoming = path.extended()
    car = VEHICLE_CLASSES["car"]
    latest_m = turn.approach_length_m - TURN_START_BEFORE_STOP_LINE_M
    ego_table = sampled(lambda p: path_point(turn.lanes, p), sum(length for _, length in turn.lanes))
    oncoming_length_m = sum(lane.length_m for lane in oncoming.lanes)
    oncoming_table = sampled(lambda p: point_at(oncoming, p), oncoming_length_m)
    stop_m = path.stop_line_m()
    window = np.arange(
        stop_m - WINDOW_BEFORE_M, min(stop_m + WINDOW_AFTER_M, oncoming_length_m), CROSSING_STEP_M
    )
    window_xy = np.stack(
        [np.interp(window, oncoming_table[0], oncoming_table[1][:, k]) for k in (0, 1)], axis=1
    )
    sweep_m = np.arange(turn.approach_length_m - 30.0, turn.exit_start_m + 5.0, 0.25)
    ahead_lo = max(-sweep_m[0] + BUS.length_m + 1.0, -80.0)
    ahead_grid = np.arange(ahead_lo, oncoming_length_m - sweep_m[-1] - 1.0, GAP_TABLE_STEP_M)
    sizes = {"suv": VEHICLE_CLASSES["suv"], "van": VEHICLE_CLASSES["van"], "bus": BUS}
    gaps = {
        name: gap_table(ego_table, oncoming_table, sweep_m, size, ahead_grid) for name, size in sizes.items()
    }

    def least_gap(size, ahead_m):
        name = next(n for n, s in sizes.items() if s == size)
        return np.interp(ahead_m, ahead_grid, gaps[name], left=np.inf, right=np.inf)

    suv = sizes["suv"]
    stagings = [
        Staging("paper-v11: SUV centred on the line at kerb arrival (stop_line wait)", suv),
        Staging("paper-v10: SUV centred on the line at kerb arrival (1 s wait)", suv, wait="at_kerb"),
        Staging("(a) SUV centred on the line at the step-off (1 s wait)", suv, wait="at_kerb", moment=0.0),
        Staging(
            "(a) SUV centred on the line 0.5 s after the step-off (1 s wait)", suv, wait="at_kerb", moment=0.5
        ),
        Staging("(a) SUV centred on the line at the step-off (stop_line wait)", suv, moment=0.0),
        Staging("(b) van centred at kerb arrival (stop_line wait)", sizes["van"]),
        Staging("(b) 12 m bus centred at kerb arrival (stop_line wait)", BUS),
        Staging("(b) 12 m bus, best placement (stop_line wait)", BUS, moment=None),
    ]
    for headway_s in (1.5, 2.0, 3.0):
        stagings.append(
            Staging(f"(b) 2 SUVs {headway_s} s apart, leader centred at kerb arrival", suv, 2, headway_s)
        )
    for headway_s in (1.5, 2.0, 3.0):
        stagings.append(
            Staging(f"(b) 2 SUVs {headway_s} s apart, best placement", suv, 2, headway_s, moment=None)
        )
    stagings.append(Staging("(b) 3 SUVs 1.5 s apart, best placement", suv, 3, 1.5, moment=None))
    stagings.append(Staging("(c) SUV, best placement (1 s wait)", suv, wait="at_kerb", moment=None))
    stagings.append(
        Staging(
            "(c) SUV, placement hiding the longest after the step-off (1 s wait)",
            suv,
            wait="at_kerb",
            moment=None,
            objective="late",
        )
    )
    stagings.append(Staging("(c) 12 m bus, best placement (1 s wait)", BUS, wait="at_kerb", moment=None))
    for headway_s in (1.5, 2.0):
        stagings.append(
            Staging(
                f"(c) 2 SUVs {headway_s} s apart, best placement (1 s wait)",
                suv,
                2,
                headway_s,
                wait="at_kerb",
                moment=None,
            )
        )

    ego_line = shapely.LineString(ego_table[1])
    meet = shapely.intersection(ego_line, shapely.LineString(window_xy))
    meet_m = path_pos_m(turn.lanes, (meet.x, meet.y)) if isinstance(meet, shapely.Point) else math.nan
    print(
        f"the ego's path: stop line {turn.approach_length_m:.1f} m, crosses the oncoming centreline at "
        f"{meet_m:.1f} m, leaves the junction at {turn.exit_start_m:.1f} m (SUMO metres along it)"
    )
    times = np.round(np.arange(TIME_FROM_S, TIME_TO_S + TIME_STEP_S / 2, TIME_STEP_S), 6)
    results: dict[str, list[dict]] = {s.label: [] for s in stagings}
    check_m: list[float] = []
    for seed in seeds:
        setup, _ = runner.draw_setup_sampled(dataclasses.replace(spec, oncoming_moment="stop_line"), seed)
        ped = setup.pedestrian
        step_off = ped.path_xy[ped.kerb_index]
        conflict_m = path_pos_m(turn.lanes, setup.conflict_xy)
        walk_s = math.dist(step_off, setup.conflict_xy) / ped.walking_speed_mps
        v = setup.ego.speed_mps
        front_step_off_m = conflict_m - v * (setup.conflict_offset_s + walk_s)
        kerb_s = {
            "at_kerb": -spec.ped_start_delay_s,
            "stop_line": -spec.ped_start_delay_s
            - max(front_step_off_m - v * spec.ped_start_delay_s - latest_m, 0.0) / v,
        }
        front_m = front_step_off_m + v * times
        eyes = np.stack(
            [np.interp(front_m - car.length_m / 2, ego_table[0], ego_table[1][:, k]) for k in (0, 1)], axis=1
        )
        track = pedestrian_track(times, step_off, ped.path_xy[ped.kerb_index + 1], ped.walking_speed_mps)
        lines = body_edge_targets(eyes, track, PEDESTRIAN_RADIUS_M)
        crossings = np.stack([first_crossing_pos(eyes, targets, window, window_xy) for targets in lines])
        centre_m = crossings[0]
        with np.errstate(invalid="ignore"):
            lo_m = np.where(np.isnan(crossings).any(axis=0), np.nan, crossings.min(axis=0))
            hi_m = np.where(np.isnan(crossings).any(axis=0), np.nan, crossings.max(axis=0))
        base = {
            "speed": v,
            "offset": setup.conflict_offset_s,
            "walk": ped.walking_speed_mps,
            "front_m": front_step_off_m,
            "conflict_m": conflict_m,
            "walk_m": math.dist(step_off, setup.conflict_xy),
        }
        # The staging's own sight-line crossing at the stop_line kerb arrival, against this grid's.
        i = int(np.argmin(np.abs(times - kerb_s["stop_line"])))
        own_m = sight_line_pos_m(oncoming, tuple(eyes[i]), step_off)
        check_m.append(abs(own_m - centre_m[i]) if own_m is not None else math.inf)
        draw = DrawGeometry(v, front_step_off_m, kerb_s, centre_m, lo_m, hi_m)
        for staging in stagings:
            row = evaluate(staging, draw, times, least_gap)
            results[staging.label].append(dict(base, **row))
    runner.close()
    print(
        "the grid's centre sight-line crossing at the stop_line kerb arrival against "
        f"scenarios.oncoming.sight_line_pos_m: largest difference {max(check_m):.3f} m"
    )
    report(args.protocol, site.name, protocol.header["seed"], stagings, results, turn, latest_m)


def report(protocol_path, site_name, seed, stagings, results, turn, latest_m) -> None:
    n = len(next(iter(results.values())))
    print(f"{protocol_path}: {n:,} draws of left_turn on {site_name} (seed {seed}); margin {MARGIN_M} m")
    print(
        f"the ego's stop line at {turn.approach_length_m:.1f} m along its turn, "
        f"its latest front at kerb arrival under stop_line {latest_m:.1f} m"
    )
    header = (
        "| staging | line misses | collision course | gap < 2 m | feasible | hidden whole wait "
        "| occlusion ends vs step-off min / median / max [s] | share of the wait hidden, median |"
    )
    print("\n" + header)
    print("|" + "---|" * 8)
    for staging in stagings:
        rows = results[staging.label]
        misses = sum(not r["crosses"] for r in rows)
        crossing = [r for r in rows if r["crosses"]]
        course = sum(r["gap"] <= 0.0 for r in crossing)
        close = sum(r["gap"] < MARGIN_M for r in crossing)
        clear = [r for r in crossing if r["gap"] >= MARGIN_M]
        feasible = [r for r in clear if r["at_step_off"]]
        whole = sum(r["whole_wait"] for r in feasible)
        ends = np.array([r["ends_s"] for r in clear if np.isfinite(r["ends_s"])])
        ends_text = f"{ends.min():+.2f} / {np.median(ends):+.2f} / {ends.max():+.2f}" if len(ends) else "-"
        share = np.median([r["hidden_share"] for r in clear]) if clear else math.nan
        print(
            f"| {staging.label} | {misses} | {course} | {close} | {len(feasible)} | {whole} | {ends_text} "
            f"| {share:.2f} |"
        )
    every = next(iter(results.values()))
    for key in ("conflict_m", "walk_m"):
        print(f"{key}: {min(r[key] for r in every):.2f}-{max(r[key] for r in every):.2f}")
    print(
        "\nfeasible draws by ego speed, walking speed and conflict offset (min-max), and the infeasible ones:"
    )
    for staging in stagings:
        rows = results[staging.label]
        ok = [r for r in rows if r["crosses"] and r["gap"] >= MARGIN_M and r["at_step_off"]]
        bad = [r for r in rows if r not in ok]
        print(f"  {staging.label}")
        for name, group in (("feasible", ok), ("not", bad)):
            if group:
                text = ", ".join(
                    f"{key} {min(r[key] for r in group):.2f}-{max(r[key] for r in group):.2f}"
                    for key in ("speed", "walk", "offset", "front_m")
                )
                print(f"    {name} ({len(group)}): {text}")
        if bad and ok:
            slow = max(r["speed"] for r in bad)
            kept = sum(r["speed"] > slow for r in rows)
            print(f"    every draw faster than {slow:.2f} m/s is feasible: {kept} of {n:,} draws")
            geometry = [r for r in bad if not r["crosses"] or r["gap"] < MARGIN_M]
            if geometry:
                nearest = min(r["front_m"] for r in geometry)
                kept = sum(r["front_m"] < nearest for r in rows)
                feasible_below = sum(r["front_m"] < nearest for r in ok)
                print(
                    f"    the ego's front at the step-off before {nearest:.1f} m (the first draw missing the "
                    f"path or closer than {MARGIN_M} m): {kept} draws, {feasible_below} of them feasible"
                )


if __name__ == "__main__":
    main()
