"""One implementation of the indexes: an episode exported to FCD by the replay tool and read by
`python -m pedsafe_sumo.conflicts` gives back the indexes of its row of episodes.parquet.

The conflicts tool knows nothing of the episode: it reads SUMO's front-bumper positions and angles, the
person's position, angle and speed, and takes the sizes from a vType file (the ego's footprint and the
pedestrian's circle, as the run recorded them). The radius is wide enough for the whole episode to be one
interaction. Two runs: the replay fixture's (an AD stack that never brakes: every episode a collision) and
a crossing batch with the reference stack (episodes without a collision, where PET and the conflict
measures come from the whole encounter).
"""

from __future__ import annotations

import math
import os

import pandas as pd
import pytest
from replay_runs import episode_row, run_cli

from pedsafe_sumo.replay.rundir import load_logged_episode
from pedsafe_sumo.sim.episode import EpisodeRunner
from pedsafe_sumo.sim.staging import EGO_ID, PED_ID

#: Index columns compared; both sides NaN counts as equal.
COMPARED = ("md_m", "tmd_s", "cs_mps", "conflict_probability", "pet_s", "min_clearance_m", "drac_mps2")
#: FCD positions and angles carry 6 decimals: measures agree to well below a millimetre / millisecond.
TOLERANCE = 1e-4
#: ... and relatively for DRAC = v / (2 TTC), which magnifies a microsecond of TTC when TTC is tiny
#: (205.864 m/s2 at TTC 0.03 s differs in the 7th digit).
RELATIVE_TOLERANCE = 1e-5


@pytest.fixture(scope="module")
def crossing_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("crossing") / "run"
    # The conflicts tool measures the minimum clearance over every step of an interaction (proximity scope
    # "episode"); the batch is asked for the same.
    params = out.parent / "episode_scope.toml"
    params.write_text('[safety]\nproximity_scope = "episode"\n', encoding="utf-8")
    proc = run_cli(
        "pedsafe_sumo.batch",
        *("--scenario", "crossing", "--episodes", "3", "--seed", "11", "--workers", "1", "--out", str(out)),
        *("--params", str(params)),
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    return out


def roundtrip(run_dir, episode: int, condition: str, tmp_path) -> tuple[dict, pd.Series]:
    row = episode_row(run_dir, episode, condition)
    logged = load_logged_episode(run_dir, episode, condition, None)
    fcd = tmp_path / f"e{episode}{condition}.fcd.xml"
    proc = run_cli(
        "pedsafe_sumo.replay",
        str(run_dir),
        *("--episode", str(episode), "--condition", condition, "--export-fcd", str(fcd)),
        env={k: v for k, v in os.environ.items() if k != "DISPLAY"},
    )
    assert proc.returncode == 0, proc.stderr
    # The sizes the episode had: the ego's vType and the pedestrian's circle (the engine's person type is
    # 2 radii wide), from the world the run recorded, else the one its seed draws.
    setup = logged.case_meta["setup"] if logged.case_meta else None
    if setup is None:
        runner = EpisodeRunner(
            logged.site, logged.params, logged.agent_class, step_length_s=logged.step_length_s
        )
        try:
            setup = runner.draw_setup(logged.spec, logged.seed)
        finally:
            runner.close()
    types = tmp_path / "types.xml"
    types.write_text(
        f'<routes><vType id="type_{EGO_ID}" length="{setup.ego.size.length_m!r}" '
        f'width="{setup.ego.size.width_m!r}"/>'
        f'<vType id="ped_type" vClass="pedestrian" width="{2 * setup.pedestrian.radius_m!r}"/></routes>'
    )
    out = tmp_path / f"e{episode}{condition}.csv"
    proc = run_cli(
        "pedsafe_sumo.conflicts", str(fcd), "--out", str(out), "--types", str(types), "--radius", "1000"
    )
    assert proc.returncode == 0, proc.stderr
    table = pd.read_csv(out)
    mine = table[(table["vehicle_id"] == EGO_ID) & (table["person_id"] == PED_ID)]
    assert len(mine) == 1, table[["vehicle_id", "person_id", "begin_s", "end_s"]]
    return row, mine.iloc[0]


def assert_same_indexes(row: dict, got: pd.Series) -> None:
    assert bool(got["collision"]) == bool(row["collision"])
    assert bool(got["conflict"]) == bool(row["conflict"])
    for name in COMPARED:
        want, have = float(row[name]), float(got[name])
        close = have == pytest.approx(want, abs=TOLERANCE, rel=RELATIVE_TOLERANCE)
        assert (math.isnan(want) and math.isnan(have)) or close, name
    want, have = float(row["min_ttc_s"]), float(got["ttc_s"])
    assert (math.isnan(want) and math.isnan(have)) or have == pytest.approx(want, abs=TOLERANCE)


@pytest.mark.slow
def test_collision_episode_gives_back_its_row(replay_run, tmp_path):
    row, got = roundtrip(replay_run, 0, "sv", tmp_path)
    assert row["collision"]
    assert_same_indexes(row, got)


@pytest.mark.slow
@pytest.mark.parametrize("condition", ["sv", "v2i"])
def test_crossing_episode_gives_back_its_row(crossing_run, condition, tmp_path):
    row, got = roundtrip(crossing_run, 2, condition, tmp_path)  # episode 2: a conflict under sv
    assert not row["collision"] and math.isfinite(row["md_m"])
    assert_same_indexes(row, got)
