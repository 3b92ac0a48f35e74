"""With random per-frame sensor misses switched on, SV and V2I of the same seed still see the same
onboard detections (until their worlds diverge): the V2I link draws from its own stream."""

from __future__ import annotations

from pedsafe_sumo.control.agent import load_agent_class
from pedsafe_sumo.network.sites import get_site
from pedsafe_sumo.params import load_params, with_overrides
from pedsafe_sumo.scenarios.specs import get_scenario
from pedsafe_sumo.sim.episode import EpisodeRunner


def test_onboard_misses_are_paired_across_conditions():
    params = with_overrides(
        load_params(), {"perception.camera.miss_probability": 0.3, "perception.lidar.miss_probability": 0.3}
    )
    # A stack that ignores what it perceives keeps both worlds identical step by step.
    runner = EpisodeRunner(
        get_site("xueqing"), params, load_agent_class("tests.sim.plugin_agents:NeverBrakes")
    )
    try:
        sv = runner.run(get_scenario("crossing"), "sv", 6)
        v2i = runner.run(get_scenario("crossing"), "v2i", 6)
    finally:
        runner.close()
    n = min(len(sv.log), len(v2i.log))
    for column in ("detected_onboard_camera", "detected_onboard_lidar"):
        assert sv.log[column].iloc[:n].tolist() == v2i.log[column].iloc[:n].tolist()
    # The misses are real: some frames where the pedestrian is seen by one sensor are missed.
    assert sv.log["detected_onboard_camera"].any() and not sv.log["detected_onboard_camera"].all()
