"""Which steps the minimum clearance and the close pass count (`proximity_scope`), on hand-built logs.

Throughout: the ego is 4 m x 2 m (half length 2, half width 1), drives along +x on y = 0, the pedestrian
is a circle of radius 0.3 m; the corridor reaches 0.5 m beyond each side of the ego (half width 1.5 m),
so a pedestrian's body is in it while |y_ped| <= 1.5 + 0.3 = 1.8 m; the horizon is 4 s. Close pass:
clearance < 1.5 m while the ego moves faster than 1 m/s.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from safety_logs import make_log

from pedsafe_sumo import REPO_ROOT
from pedsafe_sumo.params import ParameterError, load_params, with_overrides
from pedsafe_sumo.protocol import VALUES_BEFORE, load_protocol
from pedsafe_sumo.safety import episode_indexes, proximity
from pedsafe_sumo.safety.proximity import ProximityModel, episode_proximity, interaction_steps

INTERACTION = ProximityModel(
    close_pass_clearance_m=1.5,
    close_pass_min_speed_mps=1.0,
    drac_threshold_mps2=3.4,
    interaction_margin_m=0.5,
    interaction_horizon_s=4.0,
    scope="interaction",
)
EPISODE = replace(INTERACTION, scope="episode")


def standing_log(ped_y_m: float, speed_mps: float = 5.0):
    """Ego from x = -20 m at `speed_mps` for 8 s (steps of 0.1 s); the pedestrian stands at (0, ped_y_m)."""
    t = np.arange(81) * 0.1
    return make_log(t, ego_x_m=-20.0 + speed_mps * t, ego_speed_mps=speed_mps, ped_x_m=0.0, ped_y_m=ped_y_m)


@pytest.mark.parametrize(
    ("ped_y_m", "episode_clearance_m"),
    [
        # centre 1.2 m beyond the ego's side: 2.2 - 1.0 (ego half width) - 0.3 (radius) = 0.9 m
        (2.2, 0.9),
        # the far-kerb pedestrian of the fixed crossing staging: 1.4975 m from the ego's side
        (1.0 + 0.3 + 1.4975, 1.4975),
    ],
)
def test_pedestrian_standing_on_the_far_kerb_is_no_interaction(ped_y_m, episode_clearance_m):
    log = standing_log(ped_y_m)
    # The body's nearest edge, ped_y_m - 0.3 >= 1.9 m, is beyond the corridor (1.5 m); standing, never
    # entering it: no step in scope.
    assert not interaction_steps(log, INTERACTION).any()
    result = episode_proximity(log, INTERACTION)
    assert math.isnan(result.min_clearance_m) and math.isnan(result.ego_speed_at_min_clearance_mps)
    assert not result.close_pass and result.step == -1 and result.steps_in_scope == 0
    # Every step: the pass beside the car at 5 m/s, the clearance below 1.5 m, so a close pass.
    everything = episode_proximity(log, EPISODE)
    assert everything.min_clearance_m == pytest.approx(episode_clearance_m)
    assert everything.ego_speed_at_min_clearance_mps == 5.0
    assert everything.close_pass


def test_row_of_a_far_kerb_pass_has_nan_clearance_and_no_close_pass():
    row = episode_indexes(standing_log(2.2), ped_age_years=30, proximity_model=INTERACTION)
    assert math.isnan(row["min_clearance_m"]) and math.isnan(row["ego_speed_at_min_clearance_mps"])
    assert row["close_pass"] is False and not row["collision"]


def crossing_log():
    """The pedestrian crosses on x = 0 along +y at 1.5 m/s; the ego passes behind them at 5 m/s. At step 30
    (t = 3 s) the pedestrian's centre is 1.04 m ahead of the ego's front (x_front = -1.04, so x_ego = -3.04)
    and 0.78 m beyond its left side (y = 1.78): 1.3 m from the front-left corner (0.26 x (4, 3, 5)), a
    clearance of 1.3 - 0.3 = 1.0 m."""
    t = np.arange(51) * 0.1
    return make_log(
        t,
        ego_x_m=-3.04 + 5.0 * (t - 3.0),
        ego_speed_mps=5.0,
        ped_x_m=0.0,
        ped_y_m=1.78 + 1.5 * (t - 3.0),
        ped_vy_mps=1.5,
    )


def test_pedestrian_crossing_in_front_at_1_m():
    log = crossing_log()
    steps = interaction_steps(log, INTERACTION)
    # Step 0: y = -2.72, entering the corridor (|y| <= 1.8) after 0.92 / 1.5 = 0.61 s, long before the ego's
    # rear passes x = 0 (x_ego = -18.04: after (18.04 + 0.3 + 2) / 5 = 4.07 s).
    # Step 30: body edge at 1.48 m, inside the 1.5 m corridor; step 31: y = 1.93, edge 1.63 m, out, and
    # walking away from it.
    assert steps[:31].all() and not steps[31:].any()
    result = episode_proximity(log, INTERACTION)
    # Step 29 is farther: corner offsets (1.54, 0.63) -> sqrt(2.3716 + 0.3969) - 0.3 = 1.364 m.
    assert result.step == 30
    assert result.min_clearance_m == pytest.approx(1.0)
    assert result.ego_speed_at_min_clearance_mps == 5.0
    assert result.close_pass  # 1.0 m < 1.5 m at 5 m/s
    # Every step: the ego's corner passes closer once the pedestrian has left the corridor: at step 31 the
    # offsets are (0.54, 0.93): sqrt(0.2916 + 0.8649) - 0.3 = 0.7754 m (step 32: (0.04, 1.08) -> 0.7807 m;
    # step 33 beside the car: 1.23 - 0.3 = 0.93 m).
    everything = episode_proximity(log, EPISODE)
    assert everything.step == 31
    assert everything.min_clearance_m == pytest.approx(math.sqrt(1.1565) - 0.3)


def one_step(ped_x_m: float, ped_y_m: float, ped_vy_mps: float) -> bool:
    """Whether a one-step log is an interaction step: ego centre at the origin, 5 m/s along +x."""
    log = make_log([0.0], ego_speed_mps=5.0, ped_x_m=ped_x_m, ped_y_m=ped_y_m, ped_vy_mps=ped_vy_mps)
    return bool(interaction_steps(log, INTERACTION)[0])


def test_walking_into_the_corridor_within_the_horizon_counts():
    # 20 m ahead, 3 m to the right, walking left at 1.5 m/s: in the corridor after (3 - 1.8) / 1.5 = 0.8 s;
    # the ego's rear passes x = 20 after (20 + 0.3 + 2) / 5 = 4.46 s.
    assert one_step(20.0, -3.0, 1.5)
    # 2 m ahead: the rear passes after (2 + 0.3 + 2) / 5 = 0.86 s > 0.8 s: walking into the ego's side counts.
    assert one_step(2.0, -3.0, 1.5)


def test_walking_away_late_or_too_far_does_not_count():
    assert not one_step(20.0, -3.0, -1.5)  # walking away from the corridor
    assert not one_step(20.0, -3.0, 0.0)  # standing outside it
    # 1 m ahead: the rear has passed after (1 + 0.3 + 2) / 5 = 0.66 s, before they arrive at 0.8 s
    assert not one_step(1.0, -3.0, 1.5)
    # 9 m to the right: in the corridor after (9 - 1.8) / 1.5 = 4.8 s, beyond the 4 s horizon
    assert not one_step(40.0, -9.0, 1.5)
    # already passed: beside the ego's rear (y = 1.5, 0.5 m beyond its side, in the corridor's width),
    # body 0.01 m behind the rear (x = -2.31) ...
    assert not one_step(-2.0 - 0.3 - 0.01, 1.5, 1.5)
    # ... and 0.01 m into the strip beside the body (x = -2.29; no contact: 0.578 - 0.3 m from the corner)
    assert one_step(-2.0 - 0.3 + 0.01, 1.5, 1.5)


def test_walking_towards_the_lane_into_a_close_pass():
    # The ego from x = -12 m at 10 m/s; the pedestrian from (0, -3) walking left at 1 m/s. At step 14
    # (x_ego = 2, rear on x = 0) the pedestrian is at y = -1.6, 0.6 m from the rear-right corner: 0.3 m.
    t = np.arange(31) * 0.1
    log = make_log(
        t, ego_x_m=-12.0 + 10.0 * t, ego_speed_mps=10.0, ped_x_m=0.0, ped_y_m=-3.0 + t, ped_vy_mps=1.0
    )
    # Step 0: in the corridor after 1.2 s, the rear passes x = 0 after (12 + 0.3 + 2) / 10 = 1.43 s.
    assert interaction_steps(log, INTERACTION)[0]
    result = episode_proximity(log, INTERACTION)
    assert result.step == 14 and result.min_clearance_m == pytest.approx(0.3)
    assert result.ego_speed_at_min_clearance_mps == 10.0 and result.close_pass


def test_stepping_back_from_the_lane_is_no_interaction():
    # The pedestrian at (0, -1.9), body edge 1.6 m from the centre line (outside the 1.5 m corridor), walks
    # away at 0.5 m/s; the ego from x = -12 m at 10 m/s reaches them at step 10 (front on x = 0) when they are
    # at y = -2.4: 1.4 m from the front-right corner (0, -1), clearance 1.1 m.
    t = np.arange(31) * 0.1
    log = make_log(
        t, ego_x_m=-12.0 + 10.0 * t, ego_speed_mps=10.0, ped_x_m=0.0, ped_y_m=-1.9 - 0.5 * t, ped_vy_mps=-0.5
    )
    assert math.isnan(episode_proximity(log, INTERACTION).min_clearance_m)
    assert not episode_proximity(log, INTERACTION).close_pass
    everything = episode_proximity(log, EPISODE)
    assert everything.step == 10 and everything.min_clearance_m == pytest.approx(1.1)
    assert everything.close_pass


def test_contact_is_always_in_scope():
    # The pedestrian's centre 1.2 m left of the centre line, beside a standing ego: the body overlaps the
    # ego's side (clearance 1.2 - 1.0 - 0.3 = -0.1 m). In scope, but no close pass (0 m/s is not above 1).
    log = make_log([0.0], ego_speed_mps=0.0, ped_x_m=0.0, ped_y_m=1.2)
    result = episode_proximity(log, INTERACTION)
    assert result.min_clearance_m == pytest.approx(-0.1) and not result.close_pass


def test_steps_without_the_pedestrian_are_skipped():
    # NaN positions (before the pedestrian appears) count under neither scope. The log contract refuses
    # NaN, so the arrays go in as already validated ones would.
    log = crossing_log()
    arrays = {name: log[name].to_numpy() for name in log.columns}
    for name in ("ped_x_m", "ped_y_m"):
        arrays[name] = arrays[name].copy()
        arrays[name][:10] = np.nan
    clearance = proximity._clearance(arrays)
    for model in (INTERACTION, EPISODE):
        counted = proximity._steps_in_scope(arrays, clearance, model)
        assert not counted[:10].any() and counted[10:31].all()


def test_scope_and_corridor_come_from_the_parameter_file():
    params = load_params()
    assert ProximityModel.from_params(params) == INTERACTION
    assert (
        ProximityModel.from_params(with_overrides(params, {"safety.proximity_scope": "episode"})) == EPISODE
    )
    with pytest.raises(ParameterError, match="proximity_scope"):
        with_overrides(params, {"safety.proximity_scope": "everything"})
    with pytest.raises(ParameterError, match="interaction_margin_m"):
        with_overrides(params, {"safety.interaction_margin_m": -0.5})


def test_a_protocol_that_names_no_scope_takes_every_step():
    # protocols written before the scope existed measured every step
    assert VALUES_BEFORE["parameters"]["safety.proximity_scope"] == "episode"
    section = {k: v for k, v in load_params()["safety"].items() if k != "proximity_scope"}
    assert ProximityModel.from_params({"safety": section}).scope == "episode"


def test_protocols_written_before_the_scope_keep_every_step():
    # paper-v7 names none of the values of VALUES_BEFORE; approach-v1 names the [pedestrians] ones (its own
    # values, kept) and none of [safety]'s: both measure every step, as when they were written.
    v7 = load_protocol(REPO_ROOT / "protocols" / "paper-v7.toml").params()
    assert ProximityModel.from_params(v7).scope == "episode" and v7["pedestrians"]["yield_at_kerb"] is False
    approach = load_protocol(REPO_ROOT / "protocols" / "approach-v1.toml").params()
    assert ProximityModel.from_params(approach).scope == "episode"
    assert approach["pedestrians"]["yield_at_kerb"] is True
