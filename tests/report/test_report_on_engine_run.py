"""The report on a small run of the real episode engine (SUMO), laid out as the batch lays it out.

Until `pedsafe_sumo.batch` exists this test writes the run directory itself from `EpisodeRunner`
results (episodes.parquet rows = the engine's outcome dicts plus the episode number; every episode
kept as a case); once the batch exists it should call the batch instead.
"""

from __future__ import annotations

import json

import matplotlib.image
import pandas as pd
import pytest

from pedsafe_sumo.control.reference import ReferenceStack
from pedsafe_sumo.io.cases import write_case
from pedsafe_sumo.network.sites import get_site
from pedsafe_sumo.params import load_params
from pedsafe_sumo.report.__main__ import main
from pedsafe_sumo.report.rundir import REQUIRED_COLUMNS
from pedsafe_sumo.scenarios.registry import get_scenario
from pedsafe_sumo.sim.episode import EpisodeRunner

SEEDS = (3, 4)


@pytest.mark.slow
def test_report_on_engine_episodes_writes_every_figure(tmp_path, capsys):
    runner = EpisodeRunner(get_site("xueqing"), load_params(), ReferenceStack)
    rows = []
    try:
        for scenario in ("jaywalking", "crossing"):
            for episode, seed in enumerate(SEEDS):
                for condition in ("sv", "v2i"):
                    result = runner.run(get_scenario(scenario), condition, seed)
                    rows.append({"episode": episode, **result.outcome})
                    write_case(tmp_path / "cases", result)
    finally:
        runner.close()
    pd.DataFrame(rows).to_parquet(tmp_path / "episodes.parquet", index=False)
    (tmp_path / "run.json").write_text(json.dumps({"episodes": len(SEEDS), "seed": SEEDS[0]}))
    assert set(REQUIRED_COLUMNS) <= set(rows[0])

    assert main([str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "case figure: jaywalking episode" in out
    for name in ("injury_vs_age", "injury_vs_speed", "first_detection_distance", "case_speed_vs_frame"):
        image = matplotlib.image.imread(tmp_path / "figures" / f"{name}.png")
        assert image.shape[0] > 100 and float(image[..., :3].std()) > 0.01
    table = pd.read_csv(tmp_path / "tables" / "table1.csv")
    assert table["n"].tolist() == [len(SEEDS)] * 4 and (table["n_error"] == 0).all()
