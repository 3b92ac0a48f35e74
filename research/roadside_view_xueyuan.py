#!/usr/bin/env python3
"""Why the roadside camera does not see the jaywalker waiting at the kerb on one site and does on another:
the pole's place against the waiting point, and what stands on the line of sight between them.

    PYTHONPATH=. nice -n 10 python research/roadside_view_xueyuan.py RUN_DIR [RUN_DIR ...] [--rerun N]

Each RUN_DIR is a complete batch run of an approach-staged protocol with jaywalking under V2I
(episodes.parquet, run.json, cases/). Two parts per run:

1. From the run's files only (episodes.parquet and the step logs of the kept V2I jaywalking cases): the
   share of V2I jaywalking episodes whose first detector was the roadside camera alone; per kept case the
   waiting point (the pedestrian's position at their last `waiting` step, the step-off), its distance from
   the scenario's roadside pole (from the site's rsu.add.xml) and its bearing off the pole's optical axis,
   the pedestrian's projected height in the pole's image there, whether the pole saw them (`roadside_raw`,
   at the pole, before the link) at any waiting step, and when it first saw them after the step-off.
   With `--kerb-corner-pole`: how many scenarios the build's hosting check (static occluders only) lets
   the site host with its corner pole, and with the corner pole placed by the build's own rule on the
   site's kerb corner (the corner the build tries first) at each setback it tries.
2. `--rerun N`: the run's first N collision episodes of jaywalking under V2I and its first N without a
   collision, in episode order, run again in this process from their seeds with the
   protocol's values (the same seed gives the same episode; each re-run's collision flag is checked
   against the run's row). The world snapshot the sensors saw at the step-off is kept, and the pole's
   camera rays to the pedestrian's 30 sample points are cast again with the package's numpy reference
   (`perception.sensors.plan_camera`, `perception.raycast.cast_rays_numpy`, `finish_camera`): the share of
   samples in sight, what each blocked ray hits first (the queued vehicle just downstream or upstream of
   the gap the pedestrian steps out of, another queued vehicle, the ego, a background vehicle, a
   building, a tree), and the visible share with the vehicles taken away (static occluders only), with
   only the kerb-lane queue, and with everything but the queue; with `--kerb-corner-pole` also what the
   kerb-corner pole (2 m setback) sees of the pedestrian in the same snapshot.

Prints one table per part (markdown).
"""

from __future__ import annotations

import argparse
import glob
import hashlib
import json
import math
import sys
import tempfile
from collections import Counter
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
import sumolib

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import pedsafe_sumo.sim.loop as sim_loop  # noqa: E402
from pedsafe_sumo.batch.__main__ import parse_args, plan_batch  # noqa: E402
from pedsafe_sumo.batch.chunks import Task, episode_seed  # noqa: E402
from pedsafe_sumo.batch.runner import _close_runner, _run_pair  # noqa: E402
from pedsafe_sumo.network.poles import place_roadside_unit  # noqa: E402
from pedsafe_sumo.network.sites import get_site  # noqa: E402
from pedsafe_sumo.perception.pipeline import SensorSuite  # noqa: E402
from pedsafe_sumo.perception.raycast import cast_rays_numpy  # noqa: E402
from pedsafe_sumo.perception.sensors import finish_camera, plan_camera  # noqa: E402
from pedsafe_sumo.perception.surfaces import (  # noqa: E402
    KIND_CYLINDER,
    KIND_PEDESTRIAN,
    KIND_PRISM,
    KIND_VEHICLE,
)
from pedsafe_sumo.perception.world import (  # noqa: E402
    Pedestrians,
    RoadsideUnit,
    VehicleBoxes,
    WorldSnapshot,
    load_roadside_units,
)
from pedsafe_sumo.scenarios.hosting import hosted_count  # noqa: E402

SCENARIO = "jaywalking"
CONDITION = "v2i"
#: Heights of the queue's vehicle classes (scenarios/road_users.py VEHICLE_CLASSES) [m].
CLASS_BY_HEIGHT_M = {1.5: "car", 1.75: "suv", 2.0: "van"}

_perceive = sim_loop.perceive
SNAPSHOTS: dict[float, tuple] = {}


def recording_perceive(snapshot, ego, sensors, rng, time_s, link=None):
    """The loop's own perception call, with the snapshot and the sensor suite of each step kept."""
    SNAPSHOTS[round(time_s, 6)] = (snapshot, sensors)
    return _perceive(snapshot, ego, sensors, rng, time_s, link)


def run_info(run_dir: Path) -> dict:
    info = json.loads((run_dir / "run.json").read_text())
    return info


def roadside_pole(run_dir: Path, info: dict):
    """The scenario's first roadside unit of the run's site (the protocol's `roadside_units`)."""
    # The repository's copy of the site, checked against the run's record of the file.
    name = f"{info['site']}.rsu.add.xml"
    rsu_file = Path(__file__).resolve().parents[1] / "networks" / info["site"] / name
    recorded = info.get("site_files_sha256", {}).get(name)
    if recorded and hashlib.sha256(rsu_file.read_bytes()).hexdigest() != recorded:
        sys.exit(f"{rsu_file} is not the file run {run_dir} ran with")
    wanted = info["scenarios"][SCENARIO]["roadside_units"].split(",")[0]
    params = info["parameters"]["perception"]["roadside_camera"]
    units = load_roadside_units(rsu_file, params["default_height_m"], params["default_pitch_down_deg"])
    return next(u for u in units if u.id == wanted)


def corner_poles(info: dict, corner: str) -> list[tuple[dict, int]]:
    """The watched arm's corner pole placed by the site build's own rule (network.poles.place_roadside_unit)
    on `corner` at each setback the build tries, with the number of scenarios the build's hosting check
    (scenarios.hosting.hosted_count, static occluders only) lets the site host with it and the far-side
    pole; the build keeps the best of all corners, the kerb corner first."""
    site = get_site(info["site"])
    site_file = json.loads((site.directory / f"{site.name}.site.json").read_text())
    net = sumolib.net.readNet(str(site.directory / f"{site.name}.net.xml"), withInternal=True)
    junction = net.getNode(site_file["main_junction"])
    arm = site_file["roadside_unit"]["watched_arm"]
    across = next(u for u in site_file["roadside_units"] if u["id"] == "rsu_camera_1")
    found = []
    for setback_m in (2.0, 4.0, 6.0):  # network.poles.RSU_SETBACKS_TRIED_M
        pole = {"id": "rsu_camera_0", **place_roadside_unit(net, junction, corner, arm, setback_m=setback_m)}
        found.append((pole, hosted_count(site, [pole, across], f"{site.name}.poly.xml")))
    return found


def unit_of(pole: dict) -> RoadsideUnit:
    return RoadsideUnit.from_pole(pole)


def projected_height_px(suite: SensorSuite, x_m: float, y_m: float, height_m: float) -> float:
    """The pedestrian's axis in the pole's image, bottom to top [px] (perception.sensors.plan_camera)."""
    peds = Pedestrians.build(["ped"], [x_m], [y_m], [0.3], [height_m], [[0, 0, 0]])
    return float(plan_camera(suite.roadside, suite.roadside_poses[0], peds).extra["height_px"][0])


def case_table(run_dir: Path, unit, info: dict, episodes: pd.DataFrame) -> pd.DataFrame:
    suite = SensorSuite.from_params(info["parameters"]["perception"], [unit])
    rows = []
    yaw_deg = 90.0 - math.degrees(unit.yaw_rad)  # SUMO convention, clockwise from north
    for path in sorted(glob.glob(str(run_dir / "cases" / f"{SCENARIO}_{CONDITION}_*.parquet"))):
        seed = int(Path(path).stem.split("_")[-1])
        setup = json.loads(Path(path).with_suffix(".json").read_text())["setup"]
        log = pd.read_parquet(
            path, columns=["time_s", "ego_yaw_rad", "ped_x_m", "ped_y_m", "ped_state", "roadside_raw"]
        )
        waiting = log[log.ped_state == "waiting"]
        if waiting.empty:
            continue
        x, y, step_off_s = waiting.ped_x_m.iloc[-1], waiting.ped_y_m.iloc[-1], waiting.time_s.iloc[-1]
        bearing = math.degrees(math.atan2(x - unit.x_m, y - unit.y_m))
        # The ego's approach is straight: its heading at the start is the kerb's direction. Right of it
        # (right-hand traffic) lie the kerb lane and the sidewalk.
        heading = float(log.ego_yaw_rad.iloc[0])
        right = (math.sin(heading), -math.cos(heading))
        to_pole = (unit.x_m - x, unit.y_m - y)
        lateral = to_pole[0] * right[0] + to_pole[1] * right[1]
        along = to_pole[0] * math.cos(heading) + to_pole[1] * math.sin(heading)
        seen = log[log.roadside_raw]
        after = seen[seen.time_s > step_off_s]
        before = seen[seen.time_s <= step_off_s]
        walking_in = log[log.ped_state == "walking_in"]
        rows.append(
            {
                "seed": seed,
                "wait_x_m": x,
                "wait_y_m": y,
                "distance_m": math.hypot(x - unit.x_m, y - unit.y_m),
                "off_axis_deg": (bearing - yaw_deg + 180) % 360 - 180,
                "pole_kerb_side_m": lateral,
                "sight_to_kerb_deg": math.degrees(math.atan2(abs(lateral), abs(along))),
                "height_px": projected_height_px(suite, x, y, setup["pedestrian"]["height_m"]),
                "seen_waiting": bool(waiting.roadside_raw.any()),
                "seen_walking_in_share": float(walking_in.roadside_raw.mean()) if len(walking_in) else np.nan,
                "first_seen_after_step_off_s": after.time_s.iloc[0] - step_off_s if len(after) else np.nan,
                "last_seen_before_step_off_s": step_off_s - before.time_s.iloc[-1] if len(before) else np.nan,
            }
        )
    table = pd.DataFrame(rows)
    return table.merge(episodes[["seed", "episode", "collision", "detected_by"]], on="seed", how="left")


def role_of(vid: str, queue_roles: dict[str, str]) -> str:
    if vid == "ego":
        return "ego"
    return queue_roles.get(vid, "background vehicle")


def queue_roles_at(vehicles: VehicleBoxes, x_m: float, y_m: float) -> dict[str, str]:
    """The queued vehicles (ids queued_*) named by their place against the pedestrian's crossing line:
    the nearest one ahead of it (downstream, nearer the junction), the nearest behind, the others."""
    ahead, behind = [], []
    for i, vid in enumerate(vehicles.ids):
        if not str(vid).startswith("queued_"):
            continue
        heading = np.array([math.cos(vehicles.yaw_rad[i]), math.sin(vehicles.yaw_rad[i])])
        along = float(np.array([vehicles.x_m[i] - x_m, vehicles.y_m[i] - y_m]) @ heading)
        (ahead if along > 0 else behind).append((abs(along), vid))
    roles = {vid: "queue, other" for _, vid in ahead + behind}
    if ahead:
        roles[min(ahead)[1]] = "queue, ahead of the gap"
    if behind:
        roles[min(behind)[1]] = "queue, behind the gap"
    return roles


def subset(snapshot: WorldSnapshot, keep: np.ndarray) -> WorldSnapshot:
    v = snapshot.vehicles
    idx = np.nonzero(keep)[0]
    boxes = VehicleBoxes.build(
        [v.ids[i] for i in idx], v.x_m[idx], v.y_m[idx], v.yaw_rad[idx], v.length_m[idx], v.width_m[idx],
        v.height_m[idx], v.rgb[idx],
    )  # fmt: skip
    return replace(snapshot, vehicles=boxes)


def pole_view(snapshot: WorldSnapshot, sensors, pose, ped_index: int):
    """The pole camera on the pedestrian: (visible share, detected, per-sample first hit kind and index,
    per-sample in-image and visible flags, projected height), the package's numpy reference path."""
    plan = plan_camera(sensors.roadside, pose, snapshot.pedestrians)
    height_px = float(plan.extra["height_px"][ped_index])
    groups = np.nonzero(plan.ped == ped_index)[0]
    if groups.size == 0:
        return 0.0, False, None, None, None, None, height_px
    starts = np.concatenate([[0], np.cumsum(plan.group_count)[:-1]])
    hits = cast_rays_numpy(snapshot, plan.origin, plan.direction, plan.t_max, starts, plan.group_count,
                           plan.skip_ped, -1)  # fmt: skip
    result = finish_camera(sensors.roadside, plan, hits, snapshot, sensors.ground_rgb, sensors.sky_rgb)
    n_s = plan.extra["n_samples"]
    g = int(groups[0])
    rays = slice(g * n_s, (g + 1) * n_s)
    in_image = plan.extra["in_image"][rays]
    visible = in_image & ~(hits.t_m[rays] < plan.extra["dist"][rays] - 1e-6)
    return (
        float(result.visible_fraction[ped_index]),
        bool(result.detected[ped_index]),
        hits.kind[rays],
        hits.index[rays],
        in_image,
        visible,
        height_px,
    )


def rerun_table(
    run_dir: Path, info: dict, episodes: pd.DataFrame, n: int, other_poles: dict[str, RoadsideUnit]
) -> pd.DataFrame:
    protocol = Path(info["protocol"]["file"])
    if not protocol.is_absolute():
        protocol = Path(__file__).resolve().parents[1] / protocol
    with tempfile.TemporaryDirectory() as unused:
        plan, _ = plan_batch(parse_args(["--protocol", str(protocol), "--out", str(Path(unused) / "run")]))
    jay = episodes.sort_values("episode")
    chosen = pd.concat([jay[jay.collision].head(n), jay[~jay.collision].head(n)])
    rows = []
    sim_loop.perceive = recording_perceive
    try:
        for episode, recorded_collision in zip(chosen.episode, chosen.collision, strict=True):
            SNAPSHOTS.clear()
            task = Task(SCENARIO, int(episode), episode_seed(info["run_seed"], int(episode)), (CONDITION,))
            pair_rows, _, results = _run_pair(plan.config, task)
            log = results[0].log
            waiting = log[log.ped_state == "waiting"]
            step = waiting.iloc[-1]
            snapshot, sensors = SNAPSHOTS[round(float(step.time_s), 6)]
            pose = sensors.roadside_poses[0]
            ped_index = list(snapshot.pedestrians.ids).index("ped")
            x, y = float(step.ped_x_m), float(step.ped_y_m)
            roles = queue_roles_at(snapshot.vehicles, x, y)
            share, detected, kind, index, in_image, visible, height_px = pole_view(
                snapshot, sensors, pose, ped_index
            )
            blockers: Counter = Counter()
            if kind is not None:
                for k, i, shown, vis in zip(kind, index, in_image, visible, strict=True):
                    if vis:
                        continue
                    if not shown:
                        blockers["outside the image"] += 1
                    elif k == KIND_VEHICLE:
                        vid = snapshot.vehicles.ids[i]
                        height = round(float(snapshot.vehicles.height_m[i]), 2)
                        vehicle_class = CLASS_BY_HEIGHT_M.get(height, f"{height} m")
                        blockers[f"{role_of(vid, roles)} ({vehicle_class})"] += 1
                    elif k == KIND_PRISM:
                        blockers["building/canopy/hedge"] += 1
                    elif k == KIND_CYLINDER:
                        blockers["tree"] += 1
                    elif k == KIND_PEDESTRIAN:
                        blockers["other pedestrian"] += 1
                    else:
                        blockers[f"surface kind {k}"] += 1
            queued = np.array([str(v).startswith("queued_") for v in snapshot.vehicles.ids], dtype=bool)
            nothing = np.zeros(len(snapshot.vehicles), dtype=bool)
            counterfactual = {
                "static_only": pole_view(subset(snapshot, nothing), sensors, pose, ped_index)[0],
                "queue_only": pole_view(subset(snapshot, queued), sensors, pose, ped_index)[0],
                "all_but_queue": pole_view(subset(snapshot, ~queued), sensors, pose, ped_index)[0],
            }
            by_role = {r: v for v, r in roles.items()}
            ahead = by_role.get("queue, ahead of the gap")
            ahead_class = "none"
            if ahead is not None:
                height = round(float(snapshot.vehicles.height_m[snapshot.vehicles.ids.index(ahead)]), 2)
                ahead_class = CLASS_BY_HEIGHT_M.get(height, f"{height} m")
            other = {}
            for name, other_pole in other_poles.items():
                view = pole_view(snapshot, sensors, sensors.roadside_pose(other_pole), ped_index)
                outside = 30 if view[4] is None else int((~view[4]).sum())
                other[name] = f"{view[1]}|{view[0]:.2f}|{outside}"
            rows.append(
                {
                    "episode": int(episode),
                    "ahead_class": ahead_class,
                    "collision": bool(pair_rows[0]["collision"]),
                    "collision_in_run": bool(recorded_collision),
                    "distance_m": math.hypot(x - pose.position_m[0], y - pose.position_m[1]),
                    "height_px": height_px,
                    "visible_share": share,
                    "detected": detected,
                    "seen_waiting_rerun": bool(waiting.roadside_raw.any()),
                    **{f"visible_{k}": v for k, v in counterfactual.items()},
                    "blockers": dict(blockers),
                    **other,
                }
            )
            print(f"  episode {episode}: {rows[-1]}", file=sys.stderr, flush=True)
    finally:
        sim_loop.perceive = _perceive
        _close_runner()
    return pd.DataFrame(rows)


def markdown(columns: list[dict]) -> str:
    """One column per site, one row per quantity (no tabulate in the environment)."""
    sites = [c["site"] for c in columns]
    lines = ["| | " + " | ".join(sites) + " |", "|---|" + "---|" * len(sites)]
    keys = list(dict.fromkeys(k for c in columns for k in c if k != "site"))
    for key in keys:
        lines.append(f"| {key} | " + " | ".join(str(c.get(key, "-")) for c in columns) + " |")
    return "\n".join(lines)


def median(series: pd.Series) -> str:
    return f"{series.median():.1f}" if series.notna().any() else "-"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("runs", nargs="+", type=Path, help="run directories (batch --out)")
    parser.add_argument("--rerun", type=int, default=0, help="episodes per run to run again with snapshots")
    parser.add_argument(
        "--kerb-corner-pole",
        action="store_true",
        help="also place the corner pole on the site's kerb corner (the build's first try, 2 m setback)",
    )
    args = parser.parse_args()
    for run_dir in args.runs:
        if not (run_dir / "episodes.parquet").is_file() or not (run_dir / "run.json").is_file():
            sys.exit(f"{run_dir}: not a complete run (no episodes.parquet or run.json)")
    summary, reruns = [], []
    for run_dir in args.runs:
        info = run_info(run_dir)
        unit = roadside_pole(run_dir, info)
        all_rows = pd.read_parquet(run_dir / "episodes.parquet")
        episodes = all_rows[(all_rows.scenario == SCENARIO) & (all_rows.condition == CONDITION)]
        cases = case_table(run_dir, unit, info, episodes)
        hit = cases[cases.collision == True]  # noqa: E712 (NaN for seeds not in the run)
        summary.append(
            {
                "site": info["site"],
                "pole": f"{unit.id} ({unit.x_m:.1f}, {unit.y_m:.1f}) h {unit.height_m:.0f} m",
                "V2I episodes": len(episodes),
                "roadside first (alone)": f"{(episodes.detected_by == 'roadside').mean():.0%}",
                "kept cases": len(cases),
                "distance to waiting point m (min-median-max)": (
                    f"{cases.distance_m.min():.0f}-{cases.distance_m.median():.0f}-{cases.distance_m.max():.0f}"
                ),
                "off axis deg (median)": f"{cases.off_axis_deg.median():+.0f}",
                "pole beside the waiting point m (+ sidewalk side, - across the road; median)": (
                    f"{cases.pole_kerb_side_m.median():+.1f}"
                ),
                "sight line to the kerb deg (median)": f"{cases.sight_to_kerb_deg.median():.0f}",
                "height px (min)": f"{cases.height_px.min():.0f}",
                "seen while waiting (cases)": f"{cases.seen_waiting.sum()}/{len(cases)}",
                "seen while waiting (collisions)": f"{hit.seen_waiting.sum()}/{len(hit)}",
                "seen share of walking-in steps (median)": f"{cases.seen_walking_in_share.median():.2f}",
                "seen before the step-off (cases)": (
                    f"{cases.last_seen_before_step_off_s.notna().sum()}/{len(cases)}"
                ),
                "last seen before the step-off, s before it (median)": median(
                    cases.last_seen_before_step_off_s
                ),
                "first seen after step-off s (collisions, median)": median(hit.first_seen_after_step_off_s),
            }
        )
        other_poles: dict[str, RoadsideUnit] = {}
        if args.kerb_corner_pole:
            site = get_site(info["site"])
            actual = json.loads((site.directory / f"{site.name}.site.json").read_text())["roadside_units"]
            across = next(u for u in actual if u["id"] == "rsu_camera_1")
            pole0 = next(u for u in actual if u["id"] == unit.id)
            hosted = hosted_count(site, [pole0, across], f"{site.name}.poly.xml")
            tried = corner_poles(info, site.rsu_corner)
            kerb = tried[0][0]
            # The same pole aimed at the median waiting point (ground), pitch as the build computes it.
            aim = (cases.wait_x_m.median() - kerb["x"], cases.wait_y_m.median() - kerb["y"])
            aimed = kerb | {
                "yaw_deg": math.degrees(math.atan2(aim[0], aim[1])) % 360.0,
                "pitch_deg": math.degrees(math.atan2(kerb["height_m"], math.hypot(*aim))),
            }
            other_poles = {
                "kerb corner, the build's aim": unit_of(kerb),
                "kerb corner, aimed": unit_of(aimed),
            }
            summary[-1][f"scenarios hosted with {unit.id} (build's check)"] = hosted
            summary[-1]["kerb corner: scenarios hosted at setback 2/4/6 m"] = "/".join(
                str(count) for _, count in tried
            )
            summary[-1]["kerb-corner pole (2 m): place, yaw (deg from N)"] = (
                f"{site.rsu_corner} ({kerb['x']:.1f}, {kerb['y']:.1f}), {kerb['yaw_deg']:.0f}"
            )
            summary[-1]["kerb-corner pole aimed at the median waiting point: yaw, hosted"] = (
                f"{aimed['yaw_deg']:.0f}, {hosted_count(site, [aimed, across], f'{site.name}.poly.xml')}"
            )
            print(f"  {info['site']} hosting: {hosted}, kerb corner {tried}", file=sys.stderr, flush=True)
        if args.rerun:
            print(f"{info['site']}: running {args.rerun} episodes again", file=sys.stderr, flush=True)
            table = rerun_table(run_dir, info, episodes, args.rerun, other_poles)
            table.insert(0, "site", info["site"])
            reruns.append(table)
    print(markdown(summary))
    if reruns:
        table = pd.concat(reruns)
        print()
        agg = []
        for site, part in table.groupby("site", sort=False):
            blockers: Counter = Counter()
            for b in part.blockers:
                blockers.update(b)
            same = part.collision == part.collision_in_run
            ranked = ", ".join(f"{k} {v}" for k, v in blockers.most_common(6))
            agg.append(
                {
                    "site": site,
                    "episodes run again": len(part),
                    "collision as in the run": f"{same.sum()}/{len(part)}",
                    "detected at step-off": f"{part.detected.sum()}/{len(part)}",
                    "visible share, actual (median)": f"{part.visible_share.median():.2f}",
                    "static occluders only": f"{part.visible_static_only.median():.2f}",
                    "kerb-lane queue only": f"{part.visible_queue_only.median():.2f}",
                    "all but the queue": f"{part.visible_all_but_queue.median():.2f}",
                    "below 0.3 with the queue only": f"{(part.visible_queue_only < 0.3).sum()}/{len(part)}",
                    "below 0.3 without the queue": f"{(part.visible_all_but_queue < 0.3).sum()}/{len(part)}",
                    "blocked samples by first hit (sum)": ranked,
                    "visible share >= 0.3 yet not detected (colour contrast)": (
                        f"{((part.visible_share >= 0.3) & ~part.detected).sum()}/{len(part)}"
                    ),
                }
            )
            for name in ("kerb corner, the build's aim", "kerb corner, aimed"):
                if name in part:
                    fields = part[name].str.split("|", expand=True)
                    detected = (fields[0] == "True").sum()
                    share = fields[1].astype(float).median()
                    outside = fields[2].astype(int).median()
                    agg[-1][f"{name}: detected, median visible share, median samples outside the image"] = (
                        f"{detected}/{len(part)}, {share:.2f}, {outside:.0f}"
                    )
            for vehicle_class, group in part.groupby("ahead_class"):
                agg[-1][
                    f"a {vehicle_class} ahead of the gap: detected, median visible share (queue only)"
                ] = f"{group.detected.sum()}/{len(group)}, {group.visible_queue_only.median():.2f}"
        print(markdown(agg))


if __name__ == "__main__":
    main()
