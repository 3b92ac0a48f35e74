"""`batch --sampler is --is-family joint`: a real run whose joint proposal is fitted on
the pilot, whose weights are recomputed here from the stored coefficients, and whose rows are the same on
1 and 2 workers."""

from __future__ import annotations

import json
import math

import numpy as np
import pandas as pd
import pytest
from batch_cli import batch, resume_after_a_stop_in_the_final_stage
from scipy import special, stats

from pedsafe_sumo.batch.chunks import episode_seed
from pedsafe_sumo.params import load_params
from pedsafe_sumo.sampling.distributions import age_group_speed_distributions
from pedsafe_sumo.scenarios.specs import get_scenario

JOINT_RUN = (
    "--scenario", "background_blending", "--episodes", "3", "--seed", "3", "--sampler", "is",
    "--is-family", "joint", "--is-pilot-stages", "1", "--is-pilot-episodes", "20", "--chunk-size", "5",
)  # fmt: skip


def _expected_weight(record: dict, data: dict) -> float:
    """1 / (lambda + (1 - lambda) sqrt(pi_hat(x)) / c), pi_hat rebuilt from the stored coefficients with
    features written out here: continuous inputs standardised by scipy's mean and sd of the nominal law,
    with squares and pairwise products; categories as indicators of categories 1..k-1."""
    columns, continuous = [1.0], []
    for name in sorted(data["nominal"]):
        fam, x = data["nominal"][name], record["inputs"][name]
        if fam["family"] == "categorical":
            columns += [float(x == k) for k in range(1, len(fam["probabilities"]))]
            continue
        if fam["family"] == "normal":
            law = stats.norm(fam["mean"], fam["sd"])
        else:
            law = stats.beta(fam["a"], fam["b"], loc=fam["low"], scale=fam["high"] - fam["low"])
        z = (x - law.mean()) / law.std()
        continuous.append(z)
        columns += [z, z * z]
    if "kinematics" in data:  # v, 1/w and the braking margin, standardised by stored moments
        kin = data["kinematics"]
        x = record["inputs"]
        v = min(max(math.exp(x["ego_speed_log"]), kin["ego_speed_min_mps"]), kin["ego_speed_max_mps"])
        g = int(x["ped_age_group"])
        w = math.exp(kin["walking_log_mu"][g] + kin["walking_log_sigma"][g] * x["ped_walking_speed_z"])
        margin = x["conflict_offset_s"] + 2.3 / w - 0.4 - v / (2 * 6.0)
        for value, (mean, sd) in zip((v, 1 / w, margin), kin["moments"], strict=True):
            z = (value - mean) / sd
            continuous.append(z)
            columns += [z, z * z]
    columns += [
        continuous[i] * continuous[j] for i in range(len(continuous)) for j in range(i + 1, len(continuous))
    ]
    eta = float(np.dot(columns, data["coefficients"]))
    lam = data["defensive_share"]
    return 1.0 / (lam + (1 - lam) * math.sqrt(float(special.expit(eta))) / data["norm"])


def _check_kinematics(data: dict, scenario: str) -> None:
    """The stored maps are the scenario's bounds, the age groups' laws and the reference stack's braking;
    the stored moments agree with 10^6 draws of the recorded nominal laws made here with numpy."""
    kin = data["kinematics"]
    spec = get_scenario(scenario)
    params = load_params()
    laws = list(age_group_speed_distributions(dict(params["pedestrians"])).values())
    assert (kin["ego_speed_min_mps"], kin["ego_speed_max_mps"]) == (
        spec.ego_speed_min_mps,
        spec.ego_speed_max_mps,
    )
    assert kin["walking_log_mu"] == pytest.approx([law.log_mu for law in laws], rel=1e-12)
    assert kin["walking_log_sigma"] == pytest.approx([law.log_sigma for law in laws], rel=1e-12)
    assert (kin["reaction_time_s"], kin["max_decel_mps2"]) == (0.4, 6.0)  # [algorithm] of defaults.toml
    rng = np.random.default_rng(0)
    n = 1_000_000
    shares = np.array([g["weight_share"] for g in params["pedestrians"]["age_groups"].values()])
    group = rng.choice(len(laws), size=n, p=shares / shares.sum())
    w = np.exp(
        np.array([law.log_mu for law in laws])[group]
        + np.array([law.log_sigma for law in laws])[group] * rng.standard_normal(n)
    )
    ego, offset = data["nominal"]["ego_speed_log"], data["nominal"]["conflict_offset_s"]
    assert offset["family"] == "beta" and offset["a"] == offset["b"] == 1.0  # uniform
    v = np.clip(np.exp(rng.normal(ego["mean"], ego["sd"], n)), spec.ego_speed_min_mps, spec.ego_speed_max_mps)
    margin = rng.uniform(offset["low"], offset["high"], n) + 2.3 / w - 0.4 - v / 12.0
    for value, (mean, sd) in zip((v, 1 / w, margin), kin["moments"], strict=True):
        assert mean == pytest.approx(float(np.mean(value)), abs=5e-3 * float(np.std(value)))
        assert sd == pytest.approx(float(np.std(value)), rel=1e-2)


@pytest.mark.slow
def test_joint_run_weights_recomputed_and_same_rows_on_one_and_two_workers(tmp_path):
    out2, out1 = tmp_path / "w2", tmp_path / "w1"
    proc = batch(*JOINT_RUN, "--workers", "2", "--out", str(out2))
    assert proc.returncode == 0, proc.stderr
    table = pd.read_parquet(out2 / "episodes.parquet")
    assert len(table) == 2 * 23 and (table["status"] == "ok").all()
    assert table["seed"].tolist() == [episode_seed(3, i) for i in range(23) for _ in range(2)]
    pilot, final = table[table.sampler_stage == 0], table[table.sampler_stage == 1]
    assert (pilot["weight"] == 1.0).all()
    run = json.loads((out2 / "run.json").read_text())
    assert run["sampler"]["family"] == "joint"
    proposals = run["sampler_proposals"]["background_blending"]
    # The pilot of this seed holds a collision, so the final stage has a joint proposal (not the nominal).
    assert pilot[pilot.condition == "sv"]["collision"].sum() >= 1
    data = json.loads(proposals[1])
    assert data["kind"] == "joint" and "ego_speed_log" in data["nominal"]
    _check_kinematics(data, "background_blending")
    for _, row in final.iterrows():
        record = json.loads(row["sampler_inputs"])
        assert row["weight"] == pytest.approx(_expected_weight(record, data), rel=1e-9)
    pairs = table.pivot(index="episode", columns="condition", values="weight")
    assert (pairs["sv"] == pairs["v2i"]).all()
    proc = batch(*JOINT_RUN, "--workers", "1", "--out", str(out1))
    assert proc.returncode == 0, proc.stderr
    assert json.loads((out1 / "run.json").read_text())["sampler_proposals"] == run["sampler_proposals"]
    pd.testing.assert_frame_equal(table, pd.read_parquet(out1 / "episodes.parquet"))
    # Same rows after a stop in the final stage: its parts lost, the run resumed from run.json's proposal.
    _, proc = resume_after_a_stop_in_the_final_stage(out1, "background_blending")
    assert proc.returncode == 0, proc.stderr
    assert "runs again" in proc.stderr
    pd.testing.assert_frame_equal(table, pd.read_parquet(out1 / "episodes.parquet"))


@pytest.mark.slow
def test_a_pilot_without_collisions_draws_its_next_stage_where_no_stop_is_possible(tmp_path):
    """crossing (SV collision rate about 0.75%): a 20-pair nominal stage 0 holds fewer than 5 collisions,
    so pilot stage 1 is the guard's region proposal (run.json's sampler_levels says so). Witness: the
    braking margin computed here from each row's own recorded speeds and conflict offset, against the
    rows of stage 0: nearly all of stage 1 lies below 0 (the defensive 10% aside), where stage 0 rarely
    does; and the stage's weights are those of the stored proposal, recomputed by hand."""
    out = tmp_path / "guard"
    proc = batch(
        "--scenario", "crossing", "--episodes", "3", "--seed", "5", "--sampler", "is", "--is-family",
        "joint", "--is-pilot-stages", "2", "--is-pilot-episodes", "20", "--chunk-size", "10",
        "--out", str(out),
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    run = json.loads((out / "run.json").read_text())
    level = run["sampler_levels"]["crossing"][0]
    assert level["n_collisions_sv"] < 5 and level["guard"] is True
    table = pd.read_parquet(out / "episodes.parquet")
    sv = table[table.condition == "sv"]
    records = [json.loads(t) for t in sv["sampler_inputs"]]
    offset = np.array([r["inputs"]["conflict_offset_s"] for r in records])
    speed = sv["ego_initial_speed_mps"].to_numpy(float)
    margin = offset + 2.3 / sv["ped_speed_mps"].to_numpy(float) - 0.4 - speed / 12.0
    stage = sv["sampler_stage"].to_numpy()
    assert (margin[stage == 1] < 0).mean() >= 0.8 > (margin[stage == 0] < 0).mean()
    data = json.loads(run["sampler_proposals"]["crossing"][1])
    for (_, row), record in zip(sv.iterrows(), records, strict=True):
        if row["sampler_stage"] == 1:
            assert row["weight"] == pytest.approx(_expected_weight(record, data), rel=1e-9)
