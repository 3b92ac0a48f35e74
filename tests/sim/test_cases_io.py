"""A case written to disk reads back as the same log and the same initial world."""

from __future__ import annotations

import pandas as pd
import pytest

from pedsafe_sumo.control.reference import ReferenceStack
from pedsafe_sumo.io.cases import read_case, write_case
from pedsafe_sumo.network.sites import get_site
from pedsafe_sumo.params import load_params
from pedsafe_sumo.scenarios.specs import get_scenario
from pedsafe_sumo.sim.episode import EpisodeRunner


@pytest.mark.parametrize("staging", ["fixed", "approach"])
def test_case_round_trip(tmp_path, staging):
    runner = EpisodeRunner(get_site("xueqing"), load_params(), ReferenceStack)
    try:
        result = runner.run(get_scenario("jaywalking").with_overrides({"staging": staging}), "v2i", 2)
    finally:
        runner.close()
    # A folder named key=value (as a sweep names its runs) must not add a column on reading.
    path = write_case(tmp_path / "algorithm.reaction_time_s=1.0", result)
    assert path.name == "jaywalking_v2i_2.parquet"
    log, meta = read_case(path)
    pd.testing.assert_frame_equal(log, result.log)
    assert meta["setup"] == result.setup
    # Drawn, so finite: NaN would make the equality above fail too.
    assert meta["setup"].ego_start_distance_m > 0
    assert meta["end_reason"] == result.end_reason and meta["condition"] == "v2i"
    assert not list(tmp_path.rglob("*.tmp"))
