"""Table I of a `--is-family joint` run with pi_hat as a control variate (report/tables.py,
sampling/control_variate.py): the estimates against the regression written out here (pi_hat from the
coefficients by hand, the estimate as the intercept of least squares); and the plain weighted table,
column for column, wherever the control does not apply (a product proposal, a joint one stored without
E_p[pi_hat], var(C) = 0, too few rows)."""

from __future__ import annotations

import json
import math

import numpy as np
import pandas as pd
import pytest
from scipy import special, stats

from pedsafe_sumo.report.tables import table_one_of_run, table_one_rows, table_one_weighted
from pedsafe_sumo.sampling.draws import product_to_json
from pedsafe_sumo.sampling.importance import Beta, Categorical, Normal, Product
from pedsafe_sumo.sampling.joint import JointProposal

LOG_MU, LOG_SIGMA = 1.5853, 0.3827
NOMINAL = {
    "conflict_offset_s": Beta(1.0, 1.0, -0.6, 0.6),
    "ego_speed_log": Normal(LOG_MU, LOG_SIGMA),
    "ped_risk": Categorical((0.5, 0.25, 0.25)),
}
#: 1; z_o, z_o^2; z_e, z_e^2; risk == 1, risk == 2; z_o z_e (sorted names, the sampler's design).
COEFFICIENTS = (-3.0, 0.8, -0.2, 1.5, 0.1, 0.6, -0.4, 0.3)
MEAN_PI_HAT, MEAN_PI_HAT_SE = 0.09, 2.0e-4
PROPOSAL = JointProposal(NOMINAL, COEFFICIENTS, 0.25, 0.1, 1e-3, MEAN_PI_HAT, MEAN_PI_HAT_SE)
#: table1.csv's columns of an importance-sampling run without the control variate.
PLAIN_COLUMNS = [
    "scenario", "condition", "n", "n_error", "collision_rate", "collision_low", "collision_high",
    "injury_mean", "injury_low", "injury_high", "conflict_rate", "conflict_low", "conflict_high", "ess",
    "n_run", "mean_weight", "max_share", "weight_note",
]  # fmt: skip


def _pi_hat_by_hand(x: dict) -> float:
    z_o = (x["conflict_offset_s"] - 0.0) / (1.2 / math.sqrt(12.0))  # uniform on [-0.6, 0.6]
    z_e = (x["ego_speed_log"] - LOG_MU) / LOG_SIGMA
    b = COEFFICIENTS
    eta = (
        b[0] + b[1] * z_o + b[2] * z_o**2 + b[3] * z_e + b[4] * z_e**2
        + b[5] * (x["ped_risk"] == 1) + b[6] * (x["ped_risk"] == 2) + b[7] * z_o * z_e
    )  # fmt: skip
    return float(special.expit(eta))


def _episodes(n_final: int = 48, scenario: str = "right_turn", same_inputs: bool = False) -> pd.DataFrame:
    """6 pilot pairs (stage 0) and `n_final` final pairs (stage 1) of drawn inputs, weights 1 / (q/p) of
    the proposal, SV collisions more likely where pi_hat is high, V2I's a subset of SV's; one final V2I
    row errored."""
    rng = np.random.default_rng(41)
    rows = []
    for episode in range(6 + n_final):
        stage = 0 if episode < 6 else 1
        x = {
            "conflict_offset_s": float(rng.uniform(-0.6, 0.6)),
            "ego_speed_log": float(rng.normal(LOG_MU + 0.4, LOG_SIGMA)),
            "ped_risk": float(rng.choice(3)),
            "clothing": 2.0,
        }
        if same_inputs:
            x = {"conflict_offset_s": 0.1, "ego_speed_log": 2.0, "ped_risk": 1.0, "clothing": 2.0}
        pi = _pi_hat_by_hand(x)
        weight = 1.0 if stage == 0 else 1.0 / (0.1 + 0.9 * math.sqrt(pi) / 0.25)
        collision_sv = bool(rng.uniform() < min(1.0, 1.5 * pi))
        collision_v2i = collision_sv and bool(rng.uniform() < 0.5)
        injury = float(rng.uniform(0.05, 0.9))
        conflict = bool(rng.uniform() < 0.3)
        record = json.dumps({"inputs": x, "log_weight": -math.log(weight), "nominal": {}})
        for condition, hit in (("sv", collision_sv), ("v2i", collision_v2i)):
            errored = stage == 1 and episode == 9 and condition == "v2i"
            rows.append(
                {
                    "scenario": scenario,
                    "condition": condition,
                    "episode": episode,
                    "collision": hit and not errored,
                    "injury_probability": injury if hit and not errored else (math.nan if errored else 0.0),
                    "conflict": conflict and not errored,
                    "status": "error" if errored else "ok",
                    "weight": weight,
                    "sampler_stage": stage,
                    "sampler_inputs": record,
                }
            )
    return pd.DataFrame(rows)


def _regression(y: np.ndarray, c: np.ndarray) -> tuple[float, float, float]:
    """Estimate and 95% interval: least squares of Y on (1, C), the intercept (E[C] = 0); variance
    RSS / (n - 2) / n + slope^2 se(E_p[pi_hat])^2."""
    design = np.column_stack([np.ones_like(c), c])
    (intercept, slope), rss, *_ = np.linalg.lstsq(design, y, rcond=None)
    n = len(y)
    half = stats.norm.ppf(0.975) * math.sqrt(float(rss[0]) / (n - 2) / n + slope**2 * MEAN_PI_HAT_SE**2)
    return float(intercept), float(intercept - half), float(intercept + half)


def test_table_estimates_are_the_regression_written_out():
    episodes = _episodes()
    table = table_one_of_run(episodes, proposals={"right_turn": ["", PROPOSAL.to_json()]})
    assert list(table.columns) == [*PLAIN_COLUMNS, "estimator"]
    for condition in ("sv", "v2i"):
        final = episodes[(episodes.sampler_stage == 1) & (episodes.condition == condition)]
        final = final[final.status == "ok"]
        w = final["weight"].to_numpy()
        g = np.array([_pi_hat_by_hand(json.loads(t)["inputs"]) for t in final["sampler_inputs"]])
        c = w * g - MEAN_PI_HAT
        collision = final["collision"].to_numpy(dtype=float)
        injury = final["injury_probability"].to_numpy(dtype=float)
        conflict = (final["conflict"] & ~final["collision"]).to_numpy(dtype=float)
        row = table[table.condition == condition].iloc[0]
        assert row["estimator"] == "is+cv"
        assert row["n"] == len(final) and row["n_run"] == 6 + 48
        for name, f in (("collision", collision), ("injury", injury), ("conflict", conflict)):
            mean, low, high = _regression(w * f, c)
            prefix = "injury" if name == "injury" else name
            value = row["injury_mean"] if name == "injury" else row[f"{name}_rate"]
            assert value == pytest.approx(mean, rel=1e-10, abs=1e-14), name
            assert row[f"{prefix}_low"] == pytest.approx(max(0.0, low), rel=1e-10, abs=1e-14), name
            assert row[f"{prefix}_high"] == pytest.approx(high, rel=1e-10), name
        # ess and the weights' check stay those of the weights
        assert row["ess"] == pytest.approx(w.sum() ** 2 / (w**2).sum(), rel=1e-12)
        assert row["mean_weight"] == pytest.approx(w.mean(), rel=1e-12)
    header, cells = table_one_rows(table)
    assert header[-1] == "estimator" and [r[-1] for r in cells] == ["is+cv", "is+cv"]
    # The control does move the estimates (else the comparison above would not tell the two apart).
    plain = table_one_of_run(episodes)
    assert not np.allclose(plain["collision_rate"], table["collision_rate"])


def test_product_or_meanless_joint_proposals_leave_the_table_as_it_was():
    """Bit-identical: a product proposal and a stored joint one without E_p[pi_hat] (its JSON without the
    keys) give the table of no proposals, with its columns; and that table is the plain weighted one."""
    episodes = _episodes()
    plain = table_one_of_run(episodes)
    assert list(plain.columns) == PLAIN_COLUMNS
    product = product_to_json(Product({"ego_speed_log": Normal(LOG_MU + 0.3, LOG_SIGMA)}))
    older = json.loads(PROPOSAL.to_json())
    del older["mean_pi_hat"], older["mean_pi_hat_se"]
    for proposals in ({"right_turn": ["", product]}, {"right_turn": ["", json.dumps(older)]}, {}):
        again = table_one_of_run(episodes, proposals=proposals)
        pd.testing.assert_frame_equal(again, plain, check_exact=True)
    # The plain table, by the formula: (1/n) sum w f over the final stage's SV rows.
    final = episodes[(episodes.sampler_stage == 1) & (episodes.condition == "sv")]
    expected = float(np.mean(final["weight"] * final["collision"]))
    assert plain[plain.condition == "sv"]["collision_rate"].iloc[0] == pytest.approx(expected, rel=1e-12)


def test_constant_control_or_too_few_rows_keep_the_plain_estimates():
    """var(C) = 0 (every final episode with the same inputs and weight) and a final stage of 10 episodes:
    the plain estimates, the row labelled "is"; another scenario of the same table with the control keeps
    it."""
    joint = PROPOSAL.to_json()
    for episodes in (_episodes(same_inputs=True), _episodes(n_final=10)):
        both = pd.concat([episodes, _episodes(scenario="crossing")], ignore_index=True)
        table = table_one_weighted(both, proposals={"right_turn": ["", joint], "crossing": ["", joint]})
        plain = table_one_weighted(both)
        ours = table[table.scenario == "right_turn"].drop(columns="estimator")
        theirs = plain[plain.scenario == "right_turn"].copy()
        # An index with no event in the stage: the bound from the joint proposal's weight bound (10), which
        # the plain table, without the proposals, does not know (test_a_condition_with_no_collision_...).
        for rate, high in (("collision_rate", "collision_high"), ("injury_mean", "injury_high")):
            none = (theirs[rate] == 0.0).to_numpy()
            assert ours.loc[none, high].to_numpy() == pytest.approx(
                -math.log(0.025) * 10 / ours.loc[none, "n"]
            )
            theirs.loc[none, high] = ours.loc[none, high]
        pd.testing.assert_frame_equal(ours, theirs, check_exact=True)
        assert (table[table.scenario == "right_turn"]["estimator"] == "is").all()
        assert (table[table.scenario == "crossing"]["estimator"] == "is+cv").all()


def test_rows_without_the_proposals_inputs_are_refused():
    episodes = _episodes()
    episodes["sampler_inputs"] = json.dumps({"inputs": {"ego_speed_log": 2.0}, "nominal": {}})
    with pytest.raises(ValueError, match="lack the proposal's inputs conflict_offset_s, ped_risk"):
        table_one_weighted(episodes, proposals={"right_turn": ["", PROPOSAL.to_json()]})


def test_pooled_stages_are_each_stages_own_estimate_weighted_by_its_share():
    """--is-pool-from 0 on a run of a nominal stage 0 and a joint stage 1: stage 0's weighted mean and
    stage 1's regression (written out above), weighted by their shares of the episodes, the variances
    added with the squared shares (sampling/pooling.py)."""
    episodes = _episodes()
    proposals = {"right_turn": ["", PROPOSAL.to_json()]}
    table = table_one_of_run(episodes, proposals=proposals, first_stage=0)
    assert list(table.columns) == [*PLAIN_COLUMNS, "estimator", "stages"]
    z = stats.norm.ppf(0.975)
    for condition in ("sv", "v2i"):
        rows = episodes[(episodes.condition == condition) & (episodes.status == "ok")]
        nominal, final = rows[rows.sampler_stage == 0], rows[rows.sampler_stage == 1]
        y0 = nominal["weight"].to_numpy() * nominal["collision"].to_numpy(dtype=float)
        w1 = final["weight"].to_numpy()
        y1 = w1 * final["collision"].to_numpy(dtype=float)
        g1 = np.array([_pi_hat_by_hand(json.loads(t)["inputs"]) for t in final["sampler_inputs"]])
        mean1, _, high1 = _regression(y1, w1 * g1 - MEAN_PI_HAT)
        var0 = float(np.var(y0, ddof=1)) / len(y0) if np.any(y0) else 0.0
        var1 = ((high1 - mean1) / z) ** 2
        n0, n1 = len(y0), len(y1)
        share0, share1 = n0 / (n0 + n1), n1 / (n0 + n1)
        row = table[table.condition == condition].iloc[0]
        assert row["n"] == n0 + n1 and row["stages"] == "0-1"
        assert row["collision_rate"] == pytest.approx(share0 * float(np.mean(y0)) + share1 * mean1, rel=1e-9)
        half = z * math.sqrt(share0**2 * var0 + share1**2 * var1)
        assert row["collision_high"] - row["collision_rate"] == pytest.approx(half, rel=1e-9)
    # the final stage alone (first_stage None, or the final stage's number): the table before pooling
    alone = table_one_of_run(episodes, proposals=proposals)
    pd.testing.assert_frame_equal(alone, table_one_of_run(episodes, proposals=proposals, first_stage=1))
    assert "stages" not in alone.columns


def test_the_paired_table_of_an_importance_sampling_run_is_weighted():
    """The pairs of an IS run were drawn from the proposal: the paired table's SV and V2I rates are the
    weighted estimates over Table I's stages, and p the normal test of the weighted paired differences
    (written out here: mean(w d) over its standard error), not McNemar's on the counts as drawn."""
    from pedsafe_sumo.report.tables import paired_of_run, paired_title

    episodes = _episodes()
    paired = paired_of_run(episodes)
    assert (paired["test"] == "weighted z").all() and "importance sampling" in paired_title(paired)
    final = episodes[(episodes.sampler_stage == 1)]
    sv = final[final.condition == "sv"].set_index("episode")
    v2i = final[(final.condition == "v2i") & (final.status == "ok")].set_index("episode")
    sv = sv.loc[v2i.index]  # the errored V2I episode's pair is left out
    w = sv["weight"].to_numpy()
    f_sv, f_v2i = sv["collision"].to_numpy(dtype=float), v2i["collision"].to_numpy(dtype=float)
    row = paired[paired.outcome == "collision"].iloc[0]
    assert row["n_pairs"] == len(w) == 47
    assert row["sv_rate"] == pytest.approx(np.mean(w * f_sv), rel=1e-12)
    assert row["v2i_rate"] == pytest.approx(np.mean(w * f_v2i), rel=1e-12)
    d = w * (f_sv - f_v2i)
    z = np.mean(d) / (np.std(d, ddof=1) / math.sqrt(len(d)))
    assert row["p_value"] == pytest.approx(2 * stats.norm.sf(abs(z)), rel=1e-9)
    # a plain MC run keeps McNemar's table, without the column
    plain = episodes.assign(sampler_stage=0, weight=1.0)
    assert "test" not in paired_of_run(plain).columns


def test_v2i_takes_pi_hat_r_as_its_control_under_the_v2i_factor():
    """A final stage drawn from a proposal with the V2I factor (sampling/joint.py): Table I's V2I row is
    the regression on C = w pi_hat r - E_p[pi_hat r], r = expit(b_0 + b_1 L[clothing, car colour]) written
    out here; the SV row keeps pi_hat."""
    from pedsafe_sumo.sampling.joint import ContrastFactor

    table_l = ((1, 0), (0, 1))  # two clothing colours, two car colours: low contrast on the diagonal
    b0, b1, mean_v2i = -1.0, 2.5, 0.05
    factor = ContrastFactor(("waiting_0.colour",), table_l, (b0, b1), 0.3)
    nominal = {**NOMINAL, **factor.nominal()}
    proposal = JointProposal(
        nominal,
        COEFFICIENTS,
        0.25,
        0.1,
        1e-3,
        MEAN_PI_HAT,
        MEAN_PI_HAT_SE,
        None,
        factor,
        mean_v2i,
        MEAN_PI_HAT_SE,
    )
    episodes = _episodes()
    rng = np.random.default_rng(43)
    colours = {e: (float(rng.integers(2)), float(rng.integers(2))) for e in episodes["episode"].unique()}

    def with_colours(row: pd.Series) -> str:
        record = json.loads(row["sampler_inputs"])
        record["inputs"]["clothing"], record["inputs"]["waiting_0.colour"] = colours[row["episode"]]
        return json.dumps(record)

    episodes["sampler_inputs"] = episodes.apply(with_colours, axis=1)
    table = table_one_of_run(episodes, proposals={"right_turn": ["", proposal.to_json()]})
    for condition in ("sv", "v2i"):
        final = episodes[(episodes.sampler_stage == 1) & (episodes.condition == condition)]
        final = final[final.status == "ok"]
        w = final["weight"].to_numpy()
        inputs = [json.loads(t)["inputs"] for t in final["sampler_inputs"]]
        g = np.array([_pi_hat_by_hand(x) for x in inputs])
        if condition == "v2i":
            low = np.array([table_l[int(x["clothing"])][int(x["waiting_0.colour"])] for x in inputs])
            g = g * special.expit(b0 + b1 * low)
        mean, low_end, high = _regression(
            w * final["collision"].to_numpy(dtype=float),
            w * g - (mean_v2i if condition == "v2i" else MEAN_PI_HAT),
        )
        row = table[table.condition == condition].iloc[0]
        assert row["collision_rate"] == pytest.approx(mean, rel=1e-10), condition
        assert row["collision_high"] == pytest.approx(high, rel=1e-10), condition


def test_a_condition_with_no_collision_is_bounded_by_its_stages_weight_bounds():
    """No V2I collision anywhere: the upper end is -ln(0.025) / (n_0 / 1 + n_1 / 10), the nominal stage's
    rows counted whole and the joint stage's (defensive share 0.1: weights at most 10) at a tenth; without
    the proposals, the rule of three on the ESS of the weights."""
    episodes = _episodes()
    v2i = episodes["condition"] == "v2i"
    episodes.loc[v2i, "collision"] = False
    episodes.loc[v2i & (episodes.status == "ok"), "injury_probability"] = 0.0
    proposals = {"right_turn": ["", PROPOSAL.to_json()]}
    rows = episodes[v2i & (episodes.status == "ok")]
    n0, n1 = int((rows.sampler_stage == 0).sum()), int((rows.sampler_stage == 1).sum())
    pooled = table_one_of_run(episodes, proposals=proposals, first_stage=0)
    row = pooled[pooled.condition == "v2i"].iloc[0]
    assert row["collision_rate"] == 0.0 and row["collision_low"] == 0.0
    assert row["collision_high"] == pytest.approx(-math.log(0.025) / (n0 + n1 / 10))
    assert row["injury_high"] == pytest.approx(-math.log(0.025) / (n0 + n1 / 10))
    final = table_one_of_run(episodes, proposals=proposals)
    assert final[final.condition == "v2i"].iloc[0]["collision_high"] == pytest.approx(
        -math.log(0.025) * 10 / n1
    )
    w = rows["weight"].to_numpy()
    without = table_one_of_run(episodes, first_stage=0)
    assert without[without.condition == "v2i"].iloc[0]["collision_high"] == pytest.approx(
        -math.log(0.025) / (w.sum() ** 2 / (w**2).sum())
    )
