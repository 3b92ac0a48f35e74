"""V2I link: latency in steps, packet loss and noise statistics, eqs. 5-6 on delivered messages."""

from __future__ import annotations

import math

import numpy as np
import pytest
from perception_scenes import EGO, RED, ego_box, make_suite, pole, world

from pedsafe_sumo.perception import PerceptionSystem, V2ILink, V2ISpec
from pedsafe_sumo.perception.geometry import world_to_camera_transform

STEP_S = 0.05


def _hidden(params, overrides):
    van = ("van", 15.0, -3.0, 0.0, 5.0, 2.0, 2.6, (240, 240, 240))
    suite = make_suite(params, overrides, units=[pole(22.0, -12.0, 6.0, 0.0, 30.0)])
    return suite, lambda t: world([ego_box(), van], [("p", 22.0, -4.5, 0.25, 1.75, RED)], time_s=t)


def test_100ms_latency_at_50ms_step_delays_v2i_detection_by_two_steps(params):
    suite, snap = _hidden(
        params, {"perception.v2i.packet_loss_probability": 0.0, "perception.v2i.position_noise_sigma_m": 0.0}
    )
    system = PerceptionSystem(suite)
    rng = np.random.default_rng(0)
    seen_sv, seen_v2i, seen_rsu = [], [], []
    for step in range(5):
        t = step * STEP_S  # 0.0, 0.05, 0.1 (= 0.05 + 0.05 in floats), ...
        det = system.perceive(snap(t), EGO, rng, t)
        seen_sv.append("p" in det.sv)
        seen_rsu.append("p" in det.roadside)
        seen_v2i.append("p" in det.v2i)
    assert seen_sv == [False] * 5
    assert seen_rsu == [True] * 5
    # Sent at step 0 (t = 0), due at 0.1 s: first used at step 2.
    assert seen_v2i == [False, False, True, True, True]
    # Without noise the delivered ground point is the true one, through P_V = R_V R_I^-1 P_I.
    assert det.v2i_received.xy_m[0] == pytest.approx([22.0, -4.5], abs=1e-9)
    assert det.v2i.distance_m[0] == pytest.approx(math.hypot(22.0, 4.5))
    # ... and its ego-camera pixel is eq. 6 of the ego camera at (1.5, 0, 1.6) looking east:
    # depth 20.5 m, 4.5 m to the right, 1.6 m below: u = 640 + 640 * 4.5 / 20.5, v = 360 + 640 * 1.6 / 20.5.
    assert det.ego_camera_px[0] == pytest.approx([640 + 640 * 4.5 / 20.5, 360 + 640 * 1.6 / 20.5])


@pytest.mark.parametrize(("latency_s", "delay_steps"), [(0.0, 0), (0.05, 1), (0.07, 2), (0.1, 2), (0.15, 3)])
def test_delay_is_ceil_latency_over_step(latency_s, delay_steps):
    link = V2ILink(V2ISpec(latency_s, 0.0, 0.0))
    rng = np.random.default_rng(0)
    t_i = world_to_camera_transform([0.0, 0.0, 6.0], 0.0, 0.5)
    first_seen = None
    for step in range(6):
        t = step * STEP_S
        if step == 0:
            link.send(t, "rsu", t_i, ("p",), np.array([[10.0, 0.0]]), rng)
        if link.receive(t) and first_seen is None:
            first_seen = step
    assert first_seen == delay_steps


def test_packet_loss_and_noise_statistics_at_fixed_seed():
    link = V2ILink(V2ISpec(0.0, 0.01, 0.2))
    rng = np.random.default_rng(20240601)
    t_i = world_to_camera_transform([0.0, 0.0, 6.0], 0.0, 0.5)
    truth = np.array([[10.0, -2.0]])
    n = 20000
    errors = []
    for k in range(n):
        msg = link.send(k * STEP_S, "rsu", t_i, ("p",), truth, rng)
        if msg is not None:
            (got,) = link.receive(k * STEP_S)
            from pedsafe_sumo.perception.v2i import message_to_vehicle

            _, _, _, w = message_to_vehicle(got, t_i, np.eye(3))
            errors.append(w[0, :2] - truth[0])
    # Binomial(20000, 0.01): mean 200, sd 14.1; 5 sd band.
    assert 130 <= link.lost <= 270
    assert link.sent == n and len(errors) == n - link.lost
    err = np.asarray(errors)
    # Sample sd of ~19800 normals: 0.2 +- 0.2 / sqrt(2 * 19800) = 0.001 per sd; mean 0 +- 0.0014.
    assert err.std(axis=0) == pytest.approx([0.2, 0.2], abs=0.006)
    assert np.abs(err.mean(axis=0)).max() < 0.008
    # Same seed, same draws.
    again = V2ILink(V2ISpec(0.0, 0.01, 0.2))
    rng2 = np.random.default_rng(20240601)
    for k in range(n):
        again.send(k * STEP_S, "rsu", t_i, ("p",), truth, rng2)
    assert again.lost == link.lost


def test_lost_message_leaves_a_gap_in_v2i(params):
    suite, snap = _hidden(params, {"perception.v2i.packet_loss_probability": 1.0})
    system = PerceptionSystem(suite)
    rng = np.random.default_rng(0)
    for step in range(4):
        det = system.perceive(snap(step * STEP_S), EGO, rng, step * STEP_S)
        assert det.v2i.ids == ()
    assert system.link.lost == 4


def test_link_with_its_own_generator_leaves_onboard_draws_paired(params):
    # With per-frame misses on, the onboard draws must not depend on whether a link exists (SV vs V2I).
    suite, snap = _hidden(params, {"perception.lidar.miss_probability": 0.5})
    sv_rng, v2i_rng = np.random.default_rng(5), np.random.default_rng(5)
    with_link = PerceptionSystem(suite, link_rng=np.random.default_rng(99))
    from pedsafe_sumo.perception import perceive

    for step in range(20):
        t = step * STEP_S
        open_snap = world([ego_box()], [("p", 31.5, 0.0, 0.25, 1.75, RED)], time_s=t)
        a = perceive(open_snap, EGO, suite, sv_rng, t)  # SV: no link
        b = with_link.perceive(open_snap, EGO, v2i_rng, t)
        assert a.lidar.ids == b.lidar.ids
    assert sv_rng.random() == v2i_rng.random()
    assert with_link.link.sent == 20
