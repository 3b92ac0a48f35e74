"""Build against build: Tango's interval worked by hand, refusals of runs that do not share draws, and
real batches of the same and of a deliberately worse stack."""

from __future__ import annotations

import json
import math
import os
import shutil
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest

from pedsafe_sumo import REPO_ROOT
from pedsafe_sumo.compare import CompareError, compare_runs, main, tango_interval

Z95 = 1.959963984540054


def test_tango_with_no_discordant_pair_is_the_score_bound_worked_by_hand():
    # With b = a = 0 the restricted MLE is q = 0 for d > 0 and T(d) = -sqrt(n d / (1 - d)); T = -z
    # gives d = z^2 / (n + z^2).
    n = 200
    diff = tango_interval(0, 0, n, 0.95)
    assert diff.estimate == 0.0
    assert diff.high == pytest.approx(Z95**2 / (n + Z95**2), rel=1e-6)
    assert diff.low == pytest.approx(-(Z95**2) / (n + Z95**2), rel=1e-6)


def test_tango_interval_covers_in_about_95_percent_of_simulated_paired_samples():
    rng = np.random.default_rng(12)
    p_b_only, p_a_only, n = 0.03, 0.01, 300
    truth = p_b_only - p_a_only
    covered = []
    for _ in range(400):
        counts = rng.multinomial(n, [p_b_only, p_a_only, 1 - p_b_only - p_a_only])
        diff = tango_interval(int(counts[0]), int(counts[1]), n, 0.95)
        covered.append(diff.low <= truth <= diff.high)
    # Binomial(400, 0.95) lies within [0.92, 0.975] with probability > 0.99.
    assert 0.92 <= np.mean(covered) <= 0.975


def _table(collisions, seeds=None, weights=None):
    n = len(collisions)
    table = pd.DataFrame(
        {
            "scenario": "crossing",
            "condition": "sv",
            "episode": np.arange(n),
            "seed": np.arange(n) + 100 if seeds is None else seeds,
            "collision": np.asarray(collisions, dtype=bool),
            "conflict": False,
            "injury_probability": np.asarray(collisions, dtype=float) * 0.2,
            "status": "ok",
        }
    )
    if weights is not None:
        table["weight"] = weights
    return table


def test_a_clearly_worse_build_fails_and_its_worse_episodes_are_listed():
    a = _table([0] * 400)
    b = _table([1] * 40 + [0] * 360)
    result, worse = compare_runs(a, b, {"collision": 0.01, "injury_probability": 0.01, "conflict": 0.02})
    row = result.set_index("index").loc["collision"]
    assert row["difference"] == pytest.approx(0.1)
    assert row["verdict"] == "FAIL"
    assert sorted(worse["episode"]) == list(range(40))
    # Conflicts equal (none): B is not worse there.
    assert result.set_index("index").loc["conflict", "verdict"] == "PASS"


def test_runs_of_different_draws_are_refused():
    a = _table([0] * 10)
    with pytest.raises(CompareError, match="do not share their draws"):
        compare_runs(a, _table([0] * 10, seeds=np.arange(10) + 7), {"collision": 0.01})
    with pytest.raises(CompareError, match="different proposals"):
        compare_runs(_table([0] * 10, weights=1.0), _table([0] * 10, weights=2.0), {"collision": 0.01})


def test_weighted_runs_use_the_weighted_difference():
    weights = np.array([0.5] * 10 + [1.5] * 10)
    a = _table([0] * 20, weights=weights)
    b = _table([1] + [0] * 19, weights=weights)
    result, _ = compare_runs(a, b, {"collision": 0.5})
    row = result.set_index("index").loc["collision"]
    # (1/n) sum w (B - A) = 0.5 / 20.
    assert row["difference"] == pytest.approx(0.025)
    assert row["b"] == pytest.approx(0.025)


def test_no_differing_pair_is_bounded_by_the_stages_weight_bounds():
    """Identical runs of a nominal stage 0 (50 pairs) and a joint stage 1 (300 pairs, defensive share 0.1:
    weights at most 10): the interval is +-(-ln(0.025) / (50 + 300 / 10)) given the proposals
    (docs/sampling.md, "No event"), the rule of three on the ESS without them."""
    from pedsafe_sumo.sampling.importance import Normal
    from pedsafe_sumo.sampling.joint import JointProposal

    weights = np.r_[np.ones(50), np.full(150, 0.2), np.full(150, 4.0)]
    table = _table([0] * 350, weights=weights)
    table["sampler_stage"] = np.r_[np.zeros(50, dtype=int), np.ones(300, dtype=int)]
    joint = JointProposal({"x": Normal(0.0, 1.0)}, (0.0, 0.0, 0.0), 0.5, 0.1).to_json()
    result, _ = compare_runs(table, table.copy(), {"collision": 0.5}, proposals={"crossing": ["", joint]})
    row = result.set_index("index").loc["collision"]
    assert row["difference"] == 0.0
    assert row["high"] == pytest.approx(-math.log(0.025) / 80)
    assert row["low"] == pytest.approx(math.log(0.025) / 80)
    without, _ = compare_runs(table, table.copy(), {"collision": 0.5})
    ess = weights.sum() ** 2 / (weights**2).sum()
    assert without.set_index("index").loc["collision", "high"] == pytest.approx(-math.log(0.025) / ess)


def test_bad_margin_is_one_line_and_exit_2(capsys, tmp_path):
    assert main([str(tmp_path), str(tmp_path), "--margin", "collision=-1"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--margin collision" in err


def _run_batch(*args):
    proc = subprocess.run(
        [sys.executable, "-m", "pedsafe_sumo.batch", *args],
        capture_output=True,
        text=True,
        cwd=REPO_ROOT,
        env=dict(os.environ),
        timeout=600,
    )
    assert proc.returncode == 0, proc.stderr[-2000:]


def _batch(out, *extra):
    _run_batch(
        *("--scenario", "crossing", "--episodes", "40", "--seed", "5", "--workers", "1"),
        *("--out", str(out), *extra),
    )


def _compare(a, b, *extra):
    return subprocess.run(
        [sys.executable, "-m", "pedsafe_sumo.compare", str(a), str(b), *extra],
        capture_output=True,
        text=True,
        cwd=REPO_ROOT,
        timeout=120,
    )


@pytest.mark.slow
def test_same_stack_passes_and_a_slower_reacting_stack_fails(tmp_path):
    same_a, same_b, slow = tmp_path / "a", tmp_path / "b", tmp_path / "slow"
    _batch(same_a)
    # The same stack run again: the same seed gives the same rows (a batch is deterministic, see
    # tests/batch), so a copy of the first run is the second run's folder.
    shutil.copytree(same_a, same_b)
    # A stack that reacts 2.6 s later than the reference's 0.4 s: it brakes for the pedestrian too late.
    _batch(slow, "--set", "algorithm.reaction_time_s=3.0")
    # Margins above the bound z^2 / (n + z^2) = 0.088 that 40 pairs without any difference can give.
    margins = ["--margin", "collision=0.1", "--margin", "conflict=0.1", "--margin", "injury_probability=0.1"]
    same = _compare(same_a, same_b, *margins)
    assert same.returncode == 0, same.stdout + same.stderr
    assert same.stdout.strip().splitlines()[-1].startswith("PASS")
    worse = _compare(same_a, slow, *margins)
    assert worse.returncode == 1, worse.stdout + worse.stderr
    assert worse.stdout.strip().splitlines()[-1].startswith("FAIL")
    collision_rows = [line for line in worse.stdout.splitlines() if " collision " in f" {line} "]
    assert any("FAIL" in line for line in collision_rows)
    assert f"python -m pedsafe_sumo.replay {slow} --episode" in worse.stdout


#: The cross-entropy product moving every input (not the default joint family): its stage-1 proposal
#: moves inputs even when 20 pilot pairs hold no collision.
PRODUCT_ALL_INPUTS = ("--is-family", "product", "--is-inputs", "all")


def _is_batch(out, *extra):
    """A small importance-sampled crossing run, SV only: one pilot stage of 20 pairs (every input
    proposed: 20 pairs are too few for the screen), 20 final pairs."""
    _run_batch(
        *("--scenario", "crossing", "--condition", "sv", "--episodes", "20", "--seed", "5", "--workers", "1"),
        *("--sampler", "is", "--out", str(out), *extra),
    )


@pytest.mark.slow
def test_builds_on_a_shared_proposal_compare_with_their_weights(tmp_path):
    """batch --is-proposal A: B (the same stack) draws A's episodes with A's weights, so compare pairs
    them and passes at a margin above the resolution of the weighted sample; a stack reacting 2.6 s later
    on the same proposal fails; the weighted difference is the one recomputed from the rows."""
    run_a, run_b, slow = tmp_path / "a", tmp_path / "b", tmp_path / "slow"
    _is_batch(run_a, *("--is-pilot-stages", "1", "--is-pilot-episodes", "20"), *PRODUCT_ALL_INPUTS)
    _is_batch(run_b, "--is-proposal", str(run_a))
    _is_batch(slow, "--is-proposal", str(run_a), "--set", "algorithm.reaction_time_s=3.0")
    rows_a = pd.read_parquet(run_a / "episodes.parquet")
    rows_b = pd.read_parquet(run_b / "episodes.parquet")
    info_a = json.loads((run_a / "run.json").read_text())
    info_b = json.loads((run_b / "run.json").read_text())
    assert info_b["sampler_proposals"] == info_a["sampler_proposals"]
    assert info_a["sampler_proposals"]["crossing"][1] != ""  # a proposal that moves inputs
    weights = rows_a["weight"].to_numpy(dtype=float)
    assert not np.allclose(weights[rows_a["sampler_stage"] == 1], 1.0)
    # Same draws, same weights, same outcomes: the same stack on the same episodes.
    pd.testing.assert_frame_equal(rows_a, rows_b)
    # No pair differs: the interval is the rule-of-three bound on the weights' effective size,
    # -ln(0.025) / ESS (docs/compare.md); the same stack passes at any margin above it, never below.
    bound = -math.log(0.025) / (weights.sum() ** 2 / (weights**2).sum())
    indexes = ("collision", "conflict", "injury_probability")
    same = _compare(run_a, run_b, *[f"--margin={i}={1.01 * bound}" for i in indexes])
    assert same.returncode == 0, same.stdout + same.stderr
    assert same.stdout.strip().splitlines()[-1].startswith("PASS")
    below = _compare(run_a, run_b, *[f"--margin={i}={0.99 * bound}" for i in indexes])
    assert below.returncode == 1, below.stdout + below.stderr
    rows_slow = pd.read_parquet(slow / "episodes.parquet")
    assert np.array_equal(rows_slow["weight"].to_numpy(), weights)
    # The slower stack collides more on the weighted estimate, (1/n) sum w (B - A), recomputed here.
    collided = rows_slow["collision"].astype(float) - rows_a["collision"].astype(float)
    diff = float(np.mean(weights * collided))
    assert diff > 0
    worse = _compare(run_a, slow, "--margin", "collision=0.1", "--margin", "conflict=0.1")
    assert worse.returncode == 1, worse.stdout + worse.stderr
    assert worse.stdout.strip().splitlines()[-1].startswith("FAIL")
    collision_line = next(line for line in worse.stdout.splitlines() if " collision " in f" {line} ")
    assert f"{diff:+.4f}" in collision_line and collision_line.endswith("FAIL"), (diff, collision_line)
