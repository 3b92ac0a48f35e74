"""research/experiments/is_v2i_proposal.py: another proposal's efficiency scored on rows drawn from a first
one, against the efficiency worked out by numerical integration (no SUMO)."""

from __future__ import annotations

import importlib.util
import json
import math
import sys

import numpy as np
import pandas as pd
import pytest
from scipy import integrate, stats

from pedsafe_sumo import REPO_ROOT

_spec = importlib.util.spec_from_file_location(
    "is_v2i_proposal", REPO_ROOT / "research" / "experiments" / "is_v2i_proposal.py"
)
tool = importlib.util.module_from_spec(_spec)
sys.modules[_spec.name] = tool
_spec.loader.exec_module(tool)


def _second_moment(shift: float) -> float:
    """E_p[1{x > 2} p/q] for p = N(0, 1), q = N(shift, 1), by quadrature."""

    def integrand(t: float) -> float:
        return math.exp(2 * stats.norm.logpdf(t) - stats.norm.logpdf(t, shift))

    value, _ = integrate.quad(integrand, 2.0, 14.0)
    return value


def test_the_efficiency_of_another_proposal_from_rows_of_the_first() -> None:
    # p = N(0, 1), f = 1{x > 2}; the rows are drawn from q = N(2, 1), the proposal scored is q' = N(2.5, 1).
    # Its efficiency per episode, P (1 - P) / (E_p[f p/q'] - P^2), by quadrature over [2, 14] (the rest is
    # below 1e-40; p^2/q' written in logs so that it does not underflow to 0/0).
    rate = float(stats.norm.sf(2.0))
    second = _second_moment(2.5)
    expected = rate * (1 - rate) / (second - rate**2)
    rng = np.random.default_rng(11)
    x = rng.normal(2.0, 1.0, 400_000)
    f = (x > 2.0).astype(float)
    w = stats.norm.pdf(x) / stats.norm.pdf(x, 2.0)
    w_new = stats.norm.pdf(x) / stats.norm.pdf(x, 2.5)
    p_hat, plain, with_cv = tool.reweighted_efficiency(f, w, w_new)
    assert math.isclose(p_hat, rate, rel_tol=0.01)
    assert math.isclose(plain, expected, rel_tol=0.03)
    assert math.isnan(with_cv)
    # The rows' own proposal scored on its rows: q = N(2, 1)'s efficiency by quadrature.
    second_q = _second_moment(2.0)
    _, own, _ = tool.reweighted_efficiency(f, w, w)
    assert math.isclose(own, rate * (1 - rate) / (second_q - rate**2), rel_tol=0.03)


def test_a_control_equal_to_the_outcome_leaves_no_variance() -> None:
    # g = f with its exact mean: the best slope is 1 and w'(f - g) + mu = P exactly.
    rng = np.random.default_rng(12)
    x = rng.normal(2.0, 1.0, 50_000)
    f = (x > 2.0).astype(float)
    w = stats.norm.pdf(x) / stats.norm.pdf(x, 2.0)
    p_hat, plain, with_cv = tool.reweighted_efficiency(f, w, w, f, float(np.mean(w * f)))
    assert with_cv > 1e6 * plain


def test_the_contrast_table_separates_v2i_collisions_decided_by_one_cars_colour() -> None:
    """is_v2i_contrast.contrast_table on pairs whose V2I collides exactly where the clothing matches car 1's
    colour (red on red, L = 1) and never otherwise: AUC 1 and all/none below the threshold for car 1;
    car 0's colour, drawn independently, tells nothing (its AUC near 1/2)."""
    spec = importlib.util.spec_from_file_location(
        "is_v2i_contrast", REPO_ROOT / "research" / "experiments" / "is_v2i_contrast.py"
    )
    contrast = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = contrast
    spec.loader.exec_module(contrast)
    rng = np.random.default_rng(3)
    rows = []
    for _ in range(600):
        car_1 = int(rng.integers(6))
        match = rng.random() < 0.3
        record = {"clothing": 0, "car_0.colour": int(rng.integers(6)), "car_1.colour": 4 if match else car_1}
        low = record["car_1.colour"] == 4  # clothing 0 is red; car colour 4 the red car
        rows.append(
            {"collision": True, "collision_v2i": bool(low), "sampler_inputs": json.dumps({"inputs": record})}
        )
    table = contrast.contrast_table(pd.DataFrame(rows), 15.0).set_index("colour input")
    assert table.loc["car_1.colour", "AUC of -delta E"] == 1.0
    assert table.loc["car_1.colour", "V2I too: below threshold"] == 1.0
    assert table.loc["car_1.colour", "SV only: below threshold"] == 0.0
    assert abs(table.loc["car_0.colour", "AUC of -delta E"] - 0.5) < 0.1


def test_a_constant_fit_gives_the_nominal_and_one_try() -> None:
    # pi_hat constant: sqrt(pi) / c = 1 everywhere, so q/p = share + (1 - share) = 1 and one try per draw.
    from pedsafe_sumo.sampling.importance import Normal
    from pedsafe_sumo.sampling.joint import JointProposal

    model = JointProposal({"x": Normal(0.0, 1.0)}, (-2.0, 0.0, 0.0), 1.0, 0.1)
    rng = np.random.default_rng(4)
    nominal_x, x = {"x": rng.normal(size=1000)}, {"x": rng.normal(size=50)}
    q_over_p, tries = tool._q_over_p_and_tries(model, nominal_x, x, 0.1)
    assert np.allclose(q_over_p, 1.0)
    assert tries == pytest.approx(1.0)
