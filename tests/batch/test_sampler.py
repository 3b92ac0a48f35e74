"""`batch --sampler is`: flags checked in one line, the protocol accepted beside it, and a real
run whose stages, stored proposals and weights are checked against an independent recomputation."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
from batch_cli import batch, resume_after_a_stop_in_the_final_stage

from pedsafe_sumo.batch.__main__ import main, parse_args
from pedsafe_sumo.batch.arguments import resumed_arguments
from pedsafe_sumo.batch.chunks import episode_seed
from pedsafe_sumo.batch.plan import prepare
from pedsafe_sumo.protocol import main as protocol_main
from pedsafe_sumo.report.tables import table_one_of_run
from pedsafe_sumo.sampling.draws import family_from_json, product_from_json
from pedsafe_sumo.sampling.importance import Product, likelihood_ratio
from pedsafe_sumo.sampling.joint import JointProposal
from pedsafe_sumo.sampling.pooling import first_estimated_stage
from pedsafe_sumo.sampling.stages import DEFENSIVE_SHARE

CROSSING = ["--scenario", "crossing", "--episodes", "2"]
PRODUCT = ["--is-family", "product"]


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--sampler", "is", "--is-pilot-stages", "0"], "--is-pilot-stages must lie in 1..10"),
        (["--sampler", "is", "--is-pilot-stages", "1000000000000"], "--is-pilot-stages must lie in 1..10"),
        (["--sampler", "is", "--is-pilot-episodes", "5"], "--is-pilot-episodes must lie in 20..100,000"),
        (["--sampler", "is", "--is-pilot-episodes", "1000000000000"], "--is-pilot-episodes must lie in"),
        (["--is-pilot-stages", "2"], "need --sampler is"),
        (["--is-inputs", "all"], "--is-inputs: need --sampler is"),
        (["--is-family", "joint"], "--is-family: need --sampler is"),
        (["--sampler", "is", "--is-family", "mixture"], "invalid choice"),
        (["--sampler", "is", "--is-inputs", "some"], "invalid choice"),
        (["--sampler", "is", *PRODUCT, "--is-min-spread", "0.01"], "--is-min-spread must lie in 0.05..1"),
        (["--sampler", "is", *PRODUCT, "--is-min-spread", "1e12"], "--is-min-spread must lie in 0.05..1"),
        (["--sampler", "is", "--is-proposal", "/nonexistent/run"], "--is-proposal: cannot read"),
        (["--sampler", "is", "--is-proposal", "X", "--is-pilot-stages", "2"], "leave out the other --is-*"),
        (["--sampler", "is", "--condition", "v2i"], "adapts its proposal on the SV condition"),
        (["--sampler", "is", "--is-family", "joint", "--is-score", "ttc"], "--is-score: not used by"),
        # joint is the default family: the product's own flags alone name the wrong family
        (["--sampler", "is", "--is-inputs", "all"], "--is-inputs: not used by --is-family joint (give"),
        (
            ["--sampler", "is", "--is-family", "joint", "--is-inputs", "all", "--is-min-spread", "0.5"],
            "--is-inputs, --is-min-spread: not used by --is-family joint",
        ),
        (["--sampler", "xyz"], "invalid choice"),
        (["--is-pool-from", "2"], "--is-pool-from: need --sampler is"),
        (["--sampler", "is", "--is-pool-from", "4"], "--is-pool-from must lie in 0..3 (the final stage"),
        (
            ["--sampler", "is", "--is-pilot-stages", "5", "--is-pool-from", "-1"],
            "--is-pool-from must lie in 0..5",
        ),
        (["--sampler", "is", "--is-proposal", "X", "--is-pool-from", "2"], "leave out the other --is-*"),
        (["--is-v2i-factor", "none"], "--is-v2i-factor: need --sampler is"),
        (["--sampler", "is", "--is-v2i-factor", "colour"], "invalid choice"),
        (["--sampler", "is", *PRODUCT, "--is-v2i-factor", "contrast"], "--is-v2i-factor: used only by"),
        (["--sampler", "is", "--is-proposal", "X", "--is-v2i-factor", "none"], "leave out the other --is-*"),
    ],
)
def test_bad_sampler_flags_are_refused_in_one_line(capsys, tmp_path, extra, message):
    out = tmp_path / "run"
    try:
        code = main([*CROSSING, "--out", str(out), *extra])
    except SystemExit as exc:  # argparse's own errors
        code = exc.code
    err = capsys.readouterr().err
    assert code == 2, err
    assert err.startswith("error: ") and err.count("\n") == 1 and message in err, err
    assert not out.exists()


@pytest.mark.parametrize(
    ("run_json", "message"),
    [
        ({"sampler": None}, "is not a run made with --sampler is"),
        (
            {"sampler": {"kind": "is", "pilot_stages": 1}, "sampler_proposals": {"jaywalking": ["", "{}"]}},
            "has 0 of the 2 proposals of crossing",
        ),
        ("not json", "--is-proposal: cannot read"),
    ],
)
def test_a_proposal_source_that_cannot_serve_is_refused_in_one_line(capsys, tmp_path, run_json, message):
    source = tmp_path / "a"
    source.mkdir()
    (source / "run.json").write_text(run_json if isinstance(run_json, str) else json.dumps(run_json))
    out = tmp_path / "run"
    code = main([*CROSSING, "--sampler", "is", "--is-proposal", str(source), "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 2, err
    assert err.startswith("error: ") and err.count("\n") == 1 and message in err, err
    assert not out.exists()


def test_the_sampler_may_be_given_beside_a_protocol(tmp_path):
    """A protocol fixes what is estimated; the sampler only how: --sampler is is accepted with it and
    recorded in the run's identity (compared on --resume). The protocol is written from today's values
    (python -m pedsafe_sumo.protocol write), so that the test does not wait for the newest dated one."""
    protocol = tmp_path / "today.toml"
    assert (
        protocol_main(["write", "today", "--out", str(protocol), "--scenarios", "crossing,jaywalking"]) == 0
    )
    plan = prepare(parse_args(["--protocol", str(protocol), "--sampler", "is", "--out", str(tmp_path / "r")]))
    assert plan.identity["sampler"]["kind"] == "is"
    assert plan.identity["sampler"]["pilot_stages"] == 3 and plan.identity["sampler"]["pilot_episodes"] == 200
    plain = prepare(parse_args(["--protocol", str(protocol), "--out", str(tmp_path / "m")]))
    assert plain.identity["sampler"] is None


def test_the_ttc_score_is_the_default_and_older_runs_resume_with_the_clearance_score(tmp_path):
    """The pilot stages rank a miss by its TTC unless told otherwise; a run.json without is_score ranked
    by clearance, and --resume must keep that (a missing key is filled with the value such runs had, not
    with the current default)."""
    plan = prepare(parse_args(["--scenario", "crossing", "--sampler", "is", "--out", str(tmp_path / "r")]))
    assert plan.identity["sampler"]["score_kind"] == "ttc"
    assert plan.identity["sampler"]["score"].endswith("-min_ttc_s")
    older = {"scenario": "crossing", "sampler": "is", "episodes": 10}
    assert resumed_arguments(older, {})["is_score"] == "clearance"
    assert resumed_arguments({**older, "is_score": "ttc"}, {})["is_score"] == "ttc"
    assert resumed_arguments(older, {"is_score": "ttc"})["is_score"] == "ttc"
    assert (
        resumed_arguments(older, {})["episodes"] == 10
        and resumed_arguments(older, {})["is_pilot_stages"] == 3
    )


def test_the_joint_family_is_the_default_and_older_runs_resume_with_the_product(tmp_path):
    """--sampler is fits the joint proposal unless told otherwise; a run.json without is_family drew from
    the product, and --resume must keep drawing from it."""
    plan = prepare(parse_args(["--scenario", "crossing", "--sampler", "is", "--out", str(tmp_path / "r")]))
    assert plan.identity["sampler"]["family"] == "joint"
    product = prepare(
        parse_args(["--scenario", "crossing", "--sampler", "is", *PRODUCT, "--out", str(tmp_path / "p")])
    )
    assert "family" not in product.identity["sampler"]  # a product run's identity has no family key
    older = {"scenario": "crossing", "sampler": "is", "episodes": 10}
    assert resumed_arguments(older, {})["is_family"] == "product"
    assert resumed_arguments({**older, "is_family": "joint"}, {})["is_family"] == "joint"


def test_table_one_pools_from_stage_2_by_default_and_older_runs_resume_with_the_final_stage_alone(tmp_path):
    """Table I pools the stages from 2 on (--is-pool-from, recorded in the sampler's identity so that a
    resume cannot change it); a run of fewer pilot stages, or one given its final stage, estimates from the
    final stage alone and its identity has no estimate_from_stage key; a run.json without is_pool_from
    resumes with the final stage alone."""

    def sampler_of(*extra: str) -> dict:
        args = parse_args(["--scenario", "crossing", "--sampler", "is", *extra, "--out", str(tmp_path / "r")])
        return prepare(args).identity["sampler"]  # prepare writes nothing

    assert sampler_of()["estimate_from_stage"] == 2
    assert sampler_of("--is-pilot-stages", "10")["estimate_from_stage"] == 2
    assert sampler_of("--is-pilot-stages", "10", "--is-pool-from", "6")["estimate_from_stage"] == 6
    assert sampler_of("--is-pool-from", "0")["estimate_from_stage"] == 0
    # the default capped at the final stage
    assert "estimate_from_stage" not in sampler_of("--is-pilot-stages", "2")
    assert "estimate_from_stage" not in sampler_of("--is-pool-from", "3")
    older = {"scenario": "crossing", "sampler": "is", "episodes": 10}
    assert resumed_arguments(older, {})["is_pool_from"] is None
    assert resumed_arguments({**older, "is_pool_from": 2}, {})["is_pool_from"] == 2


def test_the_v2i_factor_is_on_for_new_joint_runs_and_older_runs_resume_without_it(tmp_path):
    """The joint proposal may aim at V2I's collisions too (--is-v2i-factor contrast, recorded in the
    sampler's identity), by default with the V2I-only term (contrast+v2i-only, a key of its own); the
    identity of 'none', of the product family and of a run.json without is_v2i_factor has neither key, and
    that of 'contrast' no v2i_only key."""

    def sampler_of(*extra: str) -> dict:
        args = parse_args(["--scenario", "crossing", "--sampler", "is", *extra, "--out", str(tmp_path / "r")])
        return prepare(args).identity["sampler"]

    # the default also carries the V2I-only term (its own key); 'contrast' is the factor without it
    assert "v2i_factor" in sampler_of() and "v2i_only" in sampler_of()
    contrast = sampler_of("--is-v2i-factor", "contrast")
    assert "v2i_factor" in contrast and "v2i_only" not in contrast
    assert contrast == {k: v for k, v in sampler_of().items() if k != "v2i_only"}
    for identity in (sampler_of("--is-v2i-factor", "none"), sampler_of(*PRODUCT)):
        assert "v2i_factor" not in identity and "v2i_only" not in identity
    older = {"scenario": "crossing", "sampler": "is", "episodes": 10}
    assert resumed_arguments(older, {})["is_v2i_factor"] == "none"
    assert resumed_arguments({**older, "is_v2i_factor": "contrast"}, {})["is_v2i_factor"] == "contrast"


#: --is-inputs all: 20 pilot pairs (an elite of 2) are too few for the input screen to select anything,
#: and this test checks the weights of a proposal that moves the inputs.
IS_RUN = (
    "--scenario", "right_turn", "--episodes", "3", "--seed", "4", "--sampler", "is",
    "--is-pilot-stages", "1", "--is-pilot-episodes", "20", "--chunk-size", "5", "--is-family", "product",
    "--is-inputs", "all", "--is-pool-from", "0",
)  # fmt: skip


def _expected_weight(record: dict, proposal: Product) -> float:
    """p / (lambda p + (1 - lambda) q) over the proposed inputs, from the densities of
    sampling.importance (not the Draws' running sum)."""
    nominal = Product({name: family_from_json(f) for name, f in record["nominal"].items()})
    inputs = {name: np.array([record["inputs"][name]]) for name in nominal.families}
    ratio = float(likelihood_ratio(nominal, proposal, inputs)[0])  # p / q
    return 1.0 / (DEFENSIVE_SHARE + (1 - DEFENSIVE_SHARE) / ratio)


@pytest.mark.slow
def test_importance_sampled_run_stages_weights_and_workers(tmp_path):
    """Stage 0 (20 pairs) is plain Monte Carlo; stage 1 (3 pairs) draws from the proposal stored in
    run.json, each weight equal to its recomputation, shared by SV and V2I; 1 and 2 workers give the
    same table."""
    out2, out1 = tmp_path / "w2", tmp_path / "w1"
    proc = batch(*IS_RUN, "--workers", "2", "--out", str(out2))
    assert proc.returncode == 0, proc.stderr
    assert "importance sampling" in proc.stdout
    table = pd.read_parquet(out2 / "episodes.parquet")
    assert len(table) == 2 * 23 and (table["status"] == "ok").all()
    assert table["sampler_stage"].tolist() == [0] * 40 + [1] * 6
    assert table["episode"].tolist() == [i for i in range(23) for _ in range(2)]
    assert table["seed"].tolist() == [episode_seed(4, i) for i in range(23) for _ in range(2)]
    pilot, final = table[table.sampler_stage == 0], table[table.sampler_stage == 1]
    assert (pilot["weight"] == 1.0).all()
    run = json.loads((out2 / "run.json").read_text())
    proposals = run["sampler_proposals"]["right_turn"]
    assert proposals[0] == "" and len(proposals) == 2
    proposal = product_from_json(proposals[1])
    assert "ego_speed_log" in proposal.families
    for _, row in final.iterrows():
        record = json.loads(row["sampler_inputs"])
        assert row["weight"] == pytest.approx(_expected_weight(record, proposal), rel=1e-9)
        assert 0 < row["weight"] <= 1 / DEFENSIVE_SHARE + 1e-12
    pairs = table.pivot(index="episode", columns="condition", values="weight")
    assert (pairs["sv"] == pairs["v2i"]).all()
    # --is-pool-from 0: recorded, and Table I's estimate is the weighted mean over both stages' 23 rows
    # (a product proposal has no control variate; the stages' shares are their sizes).
    assert run["sampler"]["estimate_from_stage"] == 0
    assert "stages 0..final, pooled" in proc.stdout
    summary = table_one_of_run(
        table, proposals=run["sampler_proposals"], first_stage=first_estimated_stage(run)
    )
    for condition, rows in table.groupby("condition"):
        row = summary[summary.condition == condition].iloc[0]
        assert row["n"] == 23 and row["stages"] == "0-1"
        expected = float(np.mean(rows["weight"] * rows["collision"].astype(float)))
        assert row["collision_rate"] == pytest.approx(expected, rel=1e-12, abs=1e-15)
    # Same rows on 1 worker.
    proc = batch(*IS_RUN, "--workers", "1", "--out", str(out1))
    assert proc.returncode == 0, proc.stderr
    pd.testing.assert_frame_equal(table, pd.read_parquet(out1 / "episodes.parquet"))
    # Same rows after a stop in the final stage: its parts lost, the run resumed from run.json's proposals.
    run1, proc = resume_after_a_stop_in_the_final_stage(out1, "right_turn")
    assert run1["sampler_proposals"] == run["sampler_proposals"]
    assert proc.returncode == 0, proc.stderr
    assert "runs again" in proc.stderr
    pd.testing.assert_frame_equal(table, pd.read_parquet(out1 / "episodes.parquet"))


#: Crossing under approach staging (the ego from 100-160 m out, the pedestrian walking in), the default
#: joint family: 20 pilot pairs, then 3 pairs from the proposal fitted on them.
IS_APPROACH_RUN = (
    "--scenario", "crossing", "--set", "staging=approach", "--episodes", "3", "--seed", "5",
    "--sampler", "is", "--is-pilot-stages", "1", "--is-pilot-episodes", "20", "--chunk-size", "5",
)  # fmt: skip


@pytest.mark.slow
def test_importance_sampling_under_approach_staging_draws_what_it_weights(tmp_path):
    """Each final-stage episode's weight is 1 / (q/p) of the proposal stored in run.json at the inputs it
    records, and those inputs are the ones the staged episode ran with: the ego's initial speed is the
    proposed ln-speed's exp, clipped to the scenario's 2-20 m/s (Xueqing's approaches are posted
    60 km/h, the speed fit's own limit, so no speed-limit scale applies)."""
    out = tmp_path / "run"
    proc = batch(*IS_APPROACH_RUN, "--workers", "2", "--out", str(out))
    assert proc.returncode == 0, proc.stderr
    table = pd.read_parquet(out / "episodes.parquet")
    assert len(table) == 2 * 23 and (table["status"] == "ok").all()
    pilot, final = table[table.sampler_stage == 0], table[table.sampler_stage == 1]
    assert (pilot["weight"] == 1.0).all() and len(final) == 6
    run = json.loads((out / "run.json").read_text())
    proposal = JointProposal.from_json(run["sampler_proposals"]["crossing"][1])
    for _, row in final.iterrows():
        inputs = json.loads(row["sampler_inputs"])["inputs"]
        ratio = float(proposal.q_over_p({name: np.array([inputs[name]]) for name in proposal.names})[0])
        assert row["weight"] == pytest.approx(1.0 / ratio, rel=1e-9)
        assert row["ego_initial_speed_mps"] == pytest.approx(
            min(20.0, max(2.0, float(np.exp(inputs["ego_speed_log"])))), rel=1e-12
        )
        assert 100.0 <= row["ego_start_distance_m"]
