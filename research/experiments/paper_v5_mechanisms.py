"""Mechanisms behind paper-v5's Table I, from the run's own rows and case logs (read-only).

Run: PAPER_V5_RUN=RUN_DIR python research/experiments/paper_v5_mechanisms.py build build_all report \
    blending_pairs
Reads RUN_DIR/{episodes.parquet,cases/} (the paper-v5 full run, research/EXPERIMENTS.md); writes
$PAPER_V5_ANALYSIS/features.parquet (default: paper_v5_mechanisms in the system temporary folder; one row
per case log of a collision episode, plus the conflict-only logs with build_all) and prints every number
quoted in research/EXPERIMENTS.md's "Why the paper-v5 numbers are what they are". A one-off analysis.
"""

from __future__ import annotations

import json
import os
import sys
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd

RUN = Path(os.environ.get("PAPER_V5_RUN", "results/paper-v5"))
OUT = Path(os.environ.get("PAPER_V5_ANALYSIS", Path(tempfile.gettempdir()) / "paper_v5_mechanisms"))
OUT.mkdir(parents=True, exist_ok=True)
DT = 0.05
REACTION_S, DECEL = 0.4, 6.0  # the reference stack's settings in run.json [algorithm]

pd.set_option("display.width", 250)
pd.set_option("display.max_columns", 60)


def stop_dist(v):
    """Distance the reference stack needs to stop from speed v, reaction included [m]."""
    return v * REACTION_S + v * v / (2 * DECEL)


def episodes() -> pd.DataFrame:
    d = pd.read_parquet(RUN / "episodes.parquet")
    inp = d.sampler_inputs.map(lambda s: json.loads(s)["inputs"])
    d["clothing_idx"] = inp.map(lambda i: i.get("waiting_0.colour", np.nan))
    d["waiting_class"] = inp.map(lambda i: i.get("waiting_0.class", np.nan))
    d["conflict_offset_s"] = inp.map(lambda i: i.get("conflict_offset_s", np.nan))
    return d


def features(scenario: str, condition: str, seed: int) -> dict:
    """What happened in one case log: step-out, detection, braking, impact, geometry."""
    stem = RUN / "cases" / f"{scenario}_{condition}_{seed}"
    log = pd.read_parquet(stem.with_suffix(".parquet"))
    setup = json.loads(stem.with_suffix(".json").read_text())["setup"]
    t = log.time_s.to_numpy()
    v = log.ego_speed_mps.to_numpy()
    x, y, yaw = log.ego_x_m.to_numpy(), log.ego_y_m.to_numpy(), log.ego_yaw_rad.to_numpy()
    px, py = log.ped_x_m.to_numpy(), log.ped_y_m.to_numpy()
    length_m = log.ego_length_m.iloc[0]
    width_m = log.ego_width_m.iloc[0]
    # Ped in the ego frame (lon from the ego centre, lat to the left).
    dx, dy = px - x, py - y
    lon = dx * np.cos(yaw) + dy * np.sin(yaw)
    lat = -dx * np.sin(yaw) + dy * np.cos(yaw)
    travelled = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(x), np.diff(y)))])
    moving = log.ped_state.to_numpy() != "waiting"
    i_out = int(np.argmax(moving)) if moving.any() else None
    perc = log.perceived.to_numpy()
    i_det = int(np.argmax(perc)) if perc.any() else None
    br = log.braking.to_numpy()
    i_br = int(np.argmax(br)) if br.any() else None
    contact = (log.clearance_m.to_numpy() <= 0) & (v >= 0.1)
    i_imp = int(np.argmax(contact)) if contact.any() else None
    f = dict(
        scenario=scenario,
        condition=condition,
        seed=seed,
        n_steps=len(log),
        L=length_m,
        W=width_m,
        clothing=tuple(setup["pedestrian"]["clothing_rgb"]),
        start_delay_s=setup["pedestrian"]["start_delay_s"],
        conflict_time_s=setup["conflict_time_s"],
        v0=v[0],
        lat0=lat[0],
        lon0=lon[0],
    )
    if i_out is not None:
        f.update(t_out=t[i_out], v_out=v[i_out], front_gap_out=lon[i_out] - length_m / 2, lat_out=lat[i_out])
    if i_det is not None:
        f.update(
            t_det=t[i_det],
            v_det=v[i_det],
            front_gap_det=lon[i_det] - length_m / 2,
            lat_det=lat[i_det],
            ped_state_det=log.ped_state.iloc[i_det],
            cam_det=bool(log.detected_onboard_camera.iloc[i_det]),
            lidar_det=bool(log.detected_onboard_lidar.iloc[i_det]),
            rsu_det=bool(log.detected_roadside.iloc[i_det]),
        )
    if i_br is not None:
        f.update(
            t_brake=t[i_br], v_brake=v[i_br], front_gap_brake=lon[i_br] - length_m / 2, lat_brake=lat[i_br]
        )
        # deceleration the stack commanded while braking
        cmd = log.command_speed_mps.to_numpy()
        dec = (v - cmd) / DT
        f["max_cmd_decel"] = float(np.nanmax(np.where(br, dec, np.nan)))
        f["cmd_decel_first"] = float(dec[i_br])
    # ego front (centre + L/2 along the heading) in the world frame: past the stop line of Xueqing's N
    # approach (lane 177353854#0_*, which ends at y = 219.11 / 218.54) or not
    fy = y + length_m / 2 * np.sin(yaw)
    # first perception at or after the step-out, and which sources
    if i_out is not None:
        after = np.flatnonzero(perc & (np.arange(len(t)) >= i_out))
        if len(after):
            k = after[0]
            f.update(
                t_perc_out=t[k],
                rsu_perc_out=bool(log.detected_roadside.iloc[k]),
                lidar_perc_out=bool(log.detected_onboard_lidar.iloc[k]),
                cam_perc_out=bool(log.detected_onboard_camera.iloc[k]),
            )
        end = i_imp if i_imp is not None else min(len(t) - 1, i_out + 40)
        win = slice(i_out, end + 1)
        f["rsu_share_out"] = float(log.detected_roadside.iloc[win].mean())
        f["onboard_share_out"] = float(
            (log.detected_onboard_lidar | log.detected_onboard_camera).iloc[win].mean()
        )
    # close pass: first step with clearance < 1.5 m at ego speed > 1 m/s, before any contact
    clr = log.clearance_m.to_numpy()
    lim = i_imp if i_imp is not None else len(t)
    cp = np.flatnonzero((clr[:lim] < 1.5) & (v[:lim] > 1.0))
    if len(cp):
        k = cp[0]
        f.update(
            cp_state=log.ped_state.iloc[k],
            cp_clear=clr[k],
            cp_v=v[k],
            cp_lat=lat[k],
            cp_lon=lon[k],
            cp_ped_speed=float(np.hypot(log.ped_vx_mps.iloc[k], log.ped_vy_mps.iloc[k])),
        )
    kmin = int(np.argmin(np.where(v[:lim] > 1.0, clr[:lim], np.inf))) if lim else 0
    f.update(minclr_state=log.ped_state.iloc[kmin], minclr=clr[kmin], minclr_lat=lat[kmin])
    if i_imp is not None:
        f["front_y_imp"] = fy[i_imp]
        if "blocked" in set(log.ped_state.iloc[: i_imp + 1]):
            f["t_blocked_first"] = t[int(np.argmax(log.ped_state.to_numpy()[: i_imp + 1] == "blocked"))]
        f.update(
            t_imp=t[i_imp],
            v_imp=v[i_imp],
            lon_imp=lon[i_imp],
            lat_imp=lat[i_imp],
            ped_state_imp=log.ped_state.iloc[i_imp],
            ped_speed_imp=float(np.hypot(log.ped_vx_mps.iloc[i_imp], log.ped_vy_mps.iloc[i_imp])),
            sumo_flag_any=bool(log.sumo_collision.any()),
            braking_imp=bool(br[i_imp]),
        )
        # where on the ego the contact is: front face if the ped centre is ahead of the front face
        f["impact_face"] = (
            "front" if lon[i_imp] >= length_m / 2 else ("rear" if lon[i_imp] <= -length_m / 2 else "side")
        )
        # ego travel from detection / step-out / braking to the impact
        if i_det is not None:
            f["travel_det_imp"] = travelled[i_imp] - travelled[i_det]
        if i_out is not None:
            f["travel_out_imp"] = travelled[i_imp] - travelled[i_out]
        if i_br is not None:
            f["travel_brake_imp"] = travelled[i_imp] - travelled[i_br]
    return f


def build(all_logs: bool = False) -> pd.DataFrame:
    d = episodes()
    if all_logs:  # every kept case log: the pairs with a collision or a conflict under either condition
        have = {p.stem for p in (RUN / "cases").glob("*.parquet")}
        sel = d[[f"{s}_{c}_{e}" in have for s, c, e in zip(d.scenario, d.condition, d.seed)]]
    else:
        sel = d[d.collision]
    rows = [features(r.scenario, r.condition, int(r.seed)) for r in sel.itertuples()]
    f = pd.DataFrame(rows)
    f = f.merge(d.drop(columns=["sampler_inputs"]), on=["scenario", "condition", "seed"], how="left")
    f.to_parquet(OUT / ("features_all.parquet" if all_logs else "features.parquet"))
    return f


def load_features() -> pd.DataFrame:
    p = OUT / "features.parquet"
    return pd.read_parquet(p) if p.exists() else build()


if __name__ == "__main__":
    if "build" in sys.argv:
        build()
    if "build_all" in sys.argv:
        build(all_logs=True)


def report() -> None:
    """Every number quoted in mechanisms.md (features*.parquet must exist: run `build` and `build_all`)."""
    d = episodes()
    f = load_features()  # collision episodes only
    a = pd.read_parquet(OUT / "features_all.parquet")  # every kept case log (collision/conflict pairs)
    for x in (f, a):
        x["det_after_out"] = x.t_det - x.t_out
        x["imp_after_det"] = x.t_imp - x.t_det
        x["imp_after_out"] = x.t_imp - x.t_out
        x["brake_after_det"] = x.t_brake - x.t_det
        x["brake_after_out"] = x.t_brake - x.t_out
        x["unavoid_det"] = stop_dist(x.v_det) >= x.travel_det_imp
        x["unavoid_out"] = stop_dist(x.v_out) >= x.travel_out_imp
        x["brake_before_out"] = x.t_brake < x.t_out
    g = f.groupby(["scenario", "condition"])
    print("## A. collisions: timing and kinematics (medians; counts)")
    print(
        g[
            [
                "v0",
                "v_det",
                "det_after_out",
                "imp_after_det",
                "brake_after_det",
                "brake_after_out",
                "imp_after_out",
                "travel_det_imp",
                "v_imp",
            ]
        ]
        .median()
        .round(2)
        .to_string()
    )
    print(g[["unavoid_det", "unavoid_out", "braking_imp"]].agg(["sum", "size"]).to_string())
    print(g.impact_face.value_counts().unstack().fillna(0).astype(int).to_string())
    print(g.ped_state_det.value_counts().unstack().fillna(0).astype(int).to_string())
    print("## B. start geometry: ped lateral offset from the ego's centre line at t=0 (all kept logs)")
    print(a.groupby("scenario").lat0.median().round(2).to_string())
    print("step-out to the staged conflict time [s], median over kept logs (SV):")
    print(
        (a.conflict_time_s - a.t_out)[a.condition == "sv"].groupby(a.scenario).median().round(2).to_string()
    )
    print("collisions: ego front to the pedestrian at first detection [m] (median):")
    print(g.front_gap_det.median().round(2).to_string())
    print("## C. collision rate by initial ego speed, walking speed, risk, age (all rows)")
    d["vbin"] = pd.cut(d.ego_initial_speed_mps, [0, 3, 5, 7, 8, 8.34, 10, 12, 20.1])
    d["pbin"] = pd.cut(d.ped_speed_mps, [0, 1.2, 1.4, 1.6, 1.8, 3])
    d["over60"] = d.ped_age > 60
    for by in ("vbin", "pbin", "ped_risk", "over60", "waiting_class", "clothing_idx"):
        t = d.groupby(["scenario", "condition", by], observed=True).collision.agg(["sum", "size"])
        t = (t["sum"].astype(str) + "/" + t["size"].astype(str)).unstack([0, 1])
        print(t.to_string())
    print(
        "collisions with conflict_offset_s < 0:",
        d[d.collision]
        .groupby(["scenario", "condition"])
        .apply(lambda x: f"{(x.conflict_offset_s < 0).sum()}/{len(x)}")
        .to_string(),
    )
    print("## D. blending: detection delay after step-out by waiting vehicle class (all kept SV logs)")
    bb = a[(a.scenario == "background_blending") & (a.condition == "sv")]
    print(bb.groupby("waiting_class").det_after_out.median().to_string())
    print("## E. blending pairs, grey clothing (car colour 110,110,110 vs road 105,105,105)")
    p = d[d.scenario == "background_blending"].pivot_table(
        index="episode", columns="condition", values="collision"
    )
    grey = (
        d[(d.scenario == "background_blending") & (d.condition == "sv")]
        .set_index("episode")
        .clothing_idx.eq(3)
    )
    for name, m in (("grey", grey), ("other", ~grey)):
        q = p[m]
        print(
            name,
            "pairs",
            len(q),
            "both",
            int(((q.sv == 1) & (q.v2i == 1)).sum()),
            "SV only",
            int(((q.sv == 1) & (q.v2i == 0)).sum()),
            "V2I only",
            int(((q.sv == 0) & (q.v2i == 1)).sum()),
        )
    fb = f[f.scenario == "background_blending"].assign(grey=lambda x: x.clothing_idx.eq(3))
    print(
        fb.groupby(["condition", "grey"])[["det_after_out", "brake_after_out", "rsu_share_out"]]
        .median()
        .round(2)
        .to_string()
    )
    print("## F. braking before the step-out (pedestrian still standing), kept logs")
    print(a.groupby(["scenario", "condition"]).brake_before_out.agg(["sum", "size"]).to_string())
    pa = a.pivot_table(
        index=["scenario", "episode"], columns="condition", values=["collision", "brake_before_out"]
    )
    q = pa.loc["background_blending"]
    so = q[(q.collision.sv == 1) & (q.collision.v2i == 0)]
    print(
        "blending SV-only pairs",
        len(so),
        "of which V2I braked before step-out",
        int(so.brake_before_out.v2i.sum()),
    )
    print("## G. right_turn collisions")
    r = f[f.scenario == "right_turn"]
    print(
        r.groupby("condition")[
            [
                "t_det",
                "first_detection_distance_m",
                "t_out",
                "brake_after_out",
                "imp_after_out",
                "v_out",
                "travel_out_imp",
                "v_imp",
            ]
        ]
        .describe()
        .loc[:, (slice(None), ["min", "50%", "max"])]
        .round(2)
        .T.to_string()
    )
    print(
        "blocked only at the last step(s):",
        (r.t_imp - r.t_blocked_first).describe()[["count", "max"]].to_dict(),
    )
    print("## H. SUMO agreement")
    for s in ("background_blending",):
        x = f[f.scenario == s]
        print(
            s,
            x.groupby("condition")
            .apply(
                lambda y: (
                    f"front before stop line (y>219.11) {(y.front_y_imp > 219.11).sum()}/{len(y)}, "
                    f"front y median {y.front_y_imp.median():.2f}"
                )
            )
            .to_string(),
        )
    for s in ("crossing", "right_turn"):
        for c in ("sv", "v2i"):
            x = d[(d.scenario == s) & (d.condition == c)]
            so = x[(x.sumo_collision == True) & ~x.collision]  # noqa: E712
            print(
                s,
                c,
                "SUMO-only",
                len(so),
                "our min clearance there",
                so.min_clearance_m.agg(["min", "max"]).round(3).to_dict(),
            )
    print("## I. close passes")
    print(
        d.groupby(["scenario", "condition"])
        .apply(
            lambda x: pd.Series(
                {
                    "no_collision": int((~x.collision).sum()),
                    "close_pass_no_collision": int((x.close_pass & ~x.collision).sum()),
                    "min_clearance_1.40": int(((x.min_clearance_m - 1.4022).abs() < 0.01).sum()),
                    "min_clearance_lt_1.5": int((x.min_clearance_m < 1.5).sum()),
                }
            )
        )
        .to_string()
    )
    nc = a[~a.collision]
    print(
        nc.groupby(["scenario", "condition"])
        .cp_state.value_counts()
        .unstack()
        .fillna(0)
        .astype(int)
        .to_string()
    )
    print("## J. end reasons")
    print(
        d.groupby(["scenario", "condition"])
        .end_reason.value_counts()
        .unstack()
        .fillna(0)
        .astype(int)
        .to_string()
    )


if __name__ == "__main__" and "report" in sys.argv:
    report()


def blending_threat_after_step_out() -> pd.DataFrame:
    """Blending pairs with an SV collision: first braking step at or after the step-out, SV against V2I."""
    d = episodes()
    sv = d[(d.scenario == "background_blending") & (d.condition == "sv") & d.collision]
    v2i = d[(d.scenario == "background_blending") & (d.condition == "v2i")].set_index("episode").collision
    rows = []
    for e, seed in zip(sv.episode, sv.seed):
        r = {"episode": e, "v2i_collision": bool(v2i[e])}
        for c in ("sv", "v2i"):
            log = pd.read_parquet(RUN / "cases" / f"background_blending_{c}_{seed}.parquet")
            out = log.ped_state.ne("waiting").to_numpy()
            i_out = int(np.argmax(out))
            after = np.flatnonzero(log.braking.to_numpy() & (np.arange(len(log)) >= i_out))
            r[f"{c}_brake_after_out"] = (
                log.time_s.iloc[after[0]] - log.time_s.iloc[i_out] if len(after) else np.nan
            )
            r[f"{c}_v_at_out"] = log.ego_speed_mps.iloc[i_out]
        rows.append(r)
    t = pd.DataFrame(rows)
    print(
        t.groupby("v2i_collision")[
            ["sv_brake_after_out", "v2i_brake_after_out", "sv_v_at_out", "v2i_v_at_out"]
        ]
        .median()
        .round(2)
        .to_string()
    )
    print(t.groupby("v2i_collision").size().to_string())
    return t


if __name__ == "__main__" and "blending_pairs" in sys.argv:
    blending_threat_after_step_out()
