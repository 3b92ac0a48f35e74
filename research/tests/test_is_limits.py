"""research/is_limits.py: the efficiency of a fixed proposal estimated on nominal draws, and the bound over
every proposal, checked against values worked out from their integrals (no SUMO)."""

from __future__ import annotations

import importlib.util
import json
import math

import numpy as np
import pandas as pd
import pytest
from scipy import integrate, stats

from pedsafe_sumo import REPO_ROOT
from pedsafe_sumo.sampling.draws import family_to_json, product_to_json
from pedsafe_sumo.sampling.importance import Normal, Product

_spec = importlib.util.spec_from_file_location("is_limits", REPO_ROOT / "research" / "is_limits.py")
tool = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(tool)

#: The toy event: a standard normal input above this; P = 1 - Phi(2.5) = 0.00621.
CUT = 2.5
LAMBDA = 0.1


def _nominal_rows(n: int, seed: int) -> tuple[np.ndarray, pd.DataFrame, dict]:
    x = np.random.default_rng(seed).standard_normal(n)
    return (x > CUT).astype(float), pd.DataFrame({"z": x}), {"z": Normal(0.0, 1.0)}


def test_the_nominal_as_proposal_is_plain_monte_carlo():
    f, inputs, nominal = _nominal_rows(20_000, 1)
    efficiency, mean_q_over_p = tool.proposal_efficiency(f, inputs, nominal, Product(dict(nominal)), LAMBDA)
    assert efficiency == pytest.approx(1.0, rel=1e-12) and mean_q_over_p == pytest.approx(1.0, rel=1e-12)


def test_a_shifted_proposal_matches_its_integral():
    """q = N(2.5, 1) in the defensive mixture 0.1 p + 0.9 q: Var_q(w f) = int_c^inf p^2 / (0.1 p + 0.9 q)
    dx - P^2 (quadrature), against the estimate from 400,000 nominal draws."""
    f, inputs, nominal = _nominal_rows(400_000, 2)
    proposal = Product({"z": Normal(CUT, 1.0)})
    efficiency, mean_q_over_p = tool.proposal_efficiency(f, inputs, nominal, proposal, LAMBDA)
    p = stats.norm.sf(CUT)
    second, _ = integrate.quad(
        lambda x: (
            stats.norm.pdf(x) ** 2 / (LAMBDA * stats.norm.pdf(x) + (1 - LAMBDA) * stats.norm.pdf(x, CUT))
        ),
        CUT,
        CUT + 12.0,  # beyond it both densities underflow; the tail holds < 1e-30
    )
    exact = p * (1 - p) / (second - p**2)
    assert exact > 20  # a proposal that matters, so the check can fail
    assert efficiency == pytest.approx(exact, rel=0.1)
    # E_p[q_mix / p] = 1; q/p = exp(2.5 x - 3.125) has variance e^6.25 - 1 = 517 under p, so the mean of
    # 400,000 has sd 0.9 sqrt(517 / 4e5) = 0.032: 4.5 sd allowed.
    assert mean_q_over_p == pytest.approx(1.0, abs=0.15)


def test_the_sqrt_pi_proposal_gains_on_a_deterministic_event_and_not_on_a_coin():
    """pi(x) in {0, 1} (the event a function of the input): q ∝ p sqrt(pi) mixed with 0.1 p draws the event
    9 times in 10 with weight w = P / (0.1 P + 0.9): efficiency (1 - P) / (w - P) ~ 9 / P = 1,450 on
    P = 0.0062; the logistic fit of a step, smoother, comes short of it (about 320) but far above plain
    MC. pi = 0.05 whatever x (a coin): about 1."""
    f, inputs, _ = _nominal_rows(40_000, 3)
    sharp, _, r2_sharp = tool.sqrt_pi_efficiency(f, inputs, set(), LAMBDA)
    coin = (np.random.default_rng(4).random(len(f)) < 0.05).astype(float)
    flat, _, r2_flat = tool.sqrt_pi_efficiency(coin, inputs, set(), LAMBDA)
    assert sharp > 40 and r2_sharp > 0.5
    assert flat == pytest.approx(1.0, abs=0.1) and r2_flat < 0.01


def test_the_cli_reads_a_run_and_an_is_runs_proposal(tmp_path, capsys):
    """Two tiny run directories (episodes.parquet, run.json): the table has the proposal's efficiency."""
    f, inputs, nominal = _nominal_rows(4_000, 5)
    record = [
        json.dumps(
            {"inputs": {"z": float(z)}, "nominal": {"z": family_to_json(nominal["z"])}, "log_weight": 0.0}
        )
        for z in inputs["z"]
    ]
    rows = pd.DataFrame(
        {"scenario": "toy", "condition": "sv", "status": "ok", "collision": f > 0, "sampler_inputs": record}
    )
    (tmp_path / "mc").mkdir()
    rows.to_parquet(tmp_path / "mc" / "episodes.parquet")
    (tmp_path / "is").mkdir()
    proposal = product_to_json(Product({"z": Normal(CUT, 1.0)}))
    info = {
        "sampler": {"kind": "is", "defensive_share": LAMBDA},
        "sampler_proposals": {"toy": ["", proposal]},
    }
    (tmp_path / "is" / "run.json").write_text(json.dumps(info))
    assert tool.main([str(tmp_path / "mc"), "--proposal", str(tmp_path / "is")]) == 0
    out = capsys.readouterr().out
    assert "proposal_efficiency" in out and "toy" in out
    assert tool.main([str(tmp_path / "nothing")]) == 2


def test_the_product_fit_is_the_truncated_normal_of_the_event():
    """The event x > 2.5 of a standard normal: the family fitted on its draws is the truncated normal's mean
    lambda = phi(c) / (1 - Phi(c)) and sd sqrt(1 + c lambda - lambda^2) (= 0.37, floored at 0.7071);
    its efficiency in the 0.1 defensive mixture, by quadrature, against the tool's held-out estimate."""
    f, inputs, nominal = _nominal_rows(400_000, 6)
    got = tool.product_fit_efficiency(f, inputs, nominal, ["z"], LAMBDA, 0.7071)
    lam = stats.norm.pdf(CUT) / stats.norm.sf(CUT)
    sd = max(math.sqrt(1 + CUT * lam - lam**2), 0.7071)
    p = stats.norm.sf(CUT)
    second, _ = integrate.quad(
        lambda x: (
            stats.norm.pdf(x) ** 2 / (LAMBDA * stats.norm.pdf(x) + (1 - LAMBDA) * stats.norm.pdf(x, lam, sd))
        ),
        CUT,
        CUT + 12.0,
    )
    exact = p * (1 - p) / (second - p**2)
    assert exact > 20
    assert got == pytest.approx(exact, rel=0.1)
    assert math.isnan(tool.product_fit_efficiency(f, inputs, nominal, [], LAMBDA, 0.7071))


def test_joint_proposal_efficiency_matches_its_integral():
    """research/is_limits.joint_efficiency on 200,000 nominal rows of x ~ N(0, 1), y ~ Bernoulli(pi(x)) with
    pi(x) = expit(-7 + 3 x), for the joint proposal of pi_hat = pi: P(1 - P) / (E_p[pi / r] - P^2),
    r = 0.1 + 0.9 sqrt(pi) / c, every expectation by quadrature (c too)."""
    from pedsafe_sumo.sampling.joint import normalised

    nominal = {"x": Normal(0.0, 1.0)}
    joint = normalised(nominal, (-7.0, 3.0, 0.0), 0.1)  # features 1, z, z^2
    rng = np.random.default_rng(8)
    x = rng.normal(size=200_000)
    pi = lambda v: 1.0 / (1.0 + np.exp(7.0 - 3.0 * v))  # noqa: E731
    y = (rng.random(x.size) < pi(x)).astype(float)
    density = stats.norm.pdf
    big_p = integrate.quad(lambda v: density(v) * pi(v), -10, 10)[0]
    c = integrate.quad(lambda v: density(v) * np.sqrt(pi(v)), -10, 10)[0]
    assert joint.norm == pytest.approx(c, rel=5e-3)
    second = integrate.quad(lambda v: density(v) * pi(v) / (0.1 + 0.9 * np.sqrt(pi(v)) / c), -10, 10)[0]
    expected = big_p * (1 - big_p) / (second - big_p**2)
    efficiency, mean_ratio = tool.joint_efficiency(y, pd.DataFrame({"x": x}), joint)
    assert efficiency == pytest.approx(expected, rel=0.1)
    assert mean_ratio == pytest.approx(1.0, abs=0.01)
    assert expected > 3  # (3.94) the proposal gains: the check can tell it from plain MC's 1
