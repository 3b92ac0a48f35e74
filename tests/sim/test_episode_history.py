"""An episode's rows are a function of its seed, not of the episodes its worker ran before.

Found on the dual-ring site: right_turn on the W approach, seed 1641411168, run after that episode's SV
run in the same process with the state restore (sim/connection.py) gave the turning leader a speed factor
SUMO drew from generators left where the previous episode put them (0.9932; every load with that seed
gives 0.9602), and its V2I run failed ("SUMO did not insert vehicle 'leader_0'"). The engine loads every
episode; these tests run the same episodes in one process and one by one in fresh runners.
"""

from __future__ import annotations

import pandas as pd
import pytest

from pedsafe_sumo.control.reference import ReferenceStack
from pedsafe_sumo.network.sites import get_site
from pedsafe_sumo.params import load_params
from pedsafe_sumo.scenarios.specs import get_scenario
from pedsafe_sumo.sim import staging
from pedsafe_sumo.sim.episode import EpisodeRunner

SEED = 1641411168
#: (approach, condition) in the order `batch --scenario right_turn --approach all` runs them.
EPISODES = (("S", "sv"), ("W", "sv"), ("W", "v2i"))


def _leader_speed_factor(mp: pytest.MonkeyPatch, seen: list[float]) -> None:
    """Record the leader's speed factor as staged, right before the staging moves vehicles onto the
    junction (after SUMO's inserting step)."""
    real_place = staging.place_on_junction

    def place(api, setup):
        seen.append(api.vehicle.getSpeedFactor("leader_0") if "leader_0" in api.vehicle.getIDList() else -1.0)
        return real_place(api, setup)

    mp.setattr(staging, "place_on_junction", place)


def _run(episodes, restore: bool | None = None):
    runner = EpisodeRunner(get_site("xueqing_dual_ring"), load_params(), ReferenceStack)
    if restore is not None:
        runner.session.restore_state = restore
    factors: list[float] = []
    spec = get_scenario("right_turn")
    try:
        with pytest.MonkeyPatch.context() as mp:
            _leader_speed_factor(mp, factors)
            results = [
                runner.run(spec.with_overrides({"approach": arm}), cond, SEED) for arm, cond in episodes
            ]
    finally:
        runner.close()
    return results, factors


@pytest.mark.slow
def test_episodes_in_one_process_equal_each_run_alone():
    together, factors_together = _run(EPISODES)
    for (arm, condition), result, factor in zip(EPISODES, together, factors_together, strict=True):
        alone, factors_alone = _run([(arm, condition)])
        pd.testing.assert_frame_equal(result.log, alone[0].log, check_exact=True)
        assert result.end_reason == alone[0].end_reason
        assert factor == factors_alone[0]
    # SUMO draws the leader's speed factor from the episode's --seed: the same seed, the same factor.
    assert len(set(factors_together)) == 1 and factors_together[0] > 0


@pytest.mark.slow
def test_the_state_restore_carries_sumos_draws_from_one_episode_to_the_next():
    """Why the restore is off: with it the same seed gives the leader another speed factor after an
    episode has run (the test above, with the restore, fails)."""
    try:
        _, factors = _run(EPISODES, restore=True)
    except RuntimeError as exc:  # the V2I run's leader is not inserted at all
        assert "did not insert vehicle 'leader_0'" in str(exc)
        return
    assert len(set(factors)) > 1, factors
