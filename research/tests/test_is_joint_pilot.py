"""research/experiments/is_joint_pilot.py's `--ridge cv`: stratified deterministic folds, and a penalty chosen
by held-out likelihood that goes where theory says (no SUMO)."""

from __future__ import annotations

import importlib.util

import numpy as np
from scipy import special

from pedsafe_sumo import REPO_ROOT

_spec = importlib.util.spec_from_file_location(
    "is_joint_pilot", REPO_ROOT / "research" / "experiments" / "is_joint_pilot.py"
)
tool = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(tool)


def test_folds_are_stratified_and_fixed_by_the_generator() -> None:
    y = np.zeros(200)
    y[[3, 17, 40, 41, 99, 150, 151]] = 1  # 7 collisions over 5 folds: 2, 2, 1, 1, 1
    fold = tool.cv_folds(y, 5, np.random.default_rng(4))
    per_fold = np.bincount(fold[y > 0], minlength=5)
    assert sorted(per_fold.tolist()) == [1, 1, 1, 2, 2]
    assert sorted(np.bincount(fold[y == 0], minlength=5).tolist()) == [38, 38, 39, 39, 39]
    assert np.array_equal(fold, tool.cv_folds(y, 5, np.random.default_rng(4)))
    assert not np.array_equal(fold, tool.cv_folds(y, 5, np.random.default_rng(5)))


def test_held_out_likelihood_is_the_bernoulli_log_likelihood_of_the_other_folds_fits() -> None:
    rng = np.random.default_rng(1)
    x = np.column_stack([np.ones(120), rng.standard_normal((120, 2))])
    y = (rng.random(120) < special.expit(-1 + 2 * x[:, 1])).astype(float)
    fold = np.arange(120) % 3
    expected = 0.0
    for k in range(3):
        beta = tool.fit_logistic(x[fold != k], y[fold != k], 0.3)
        p = special.expit(x[fold == k] @ beta)
        expected += float(np.sum(y[fold == k] * np.log(p) + (1 - y[fold == k]) * np.log(1 - p)))
    assert np.isclose(tool.cv_log_likelihood(x, y, 0.3, fold), expected, rtol=1e-9)


def test_cv_chooses_the_least_penalty_for_a_sharp_signal_and_the_most_for_noise() -> None:
    rng = np.random.default_rng(2)
    z = rng.standard_normal((400, 20))
    x = np.column_stack([np.ones(400), z])
    # The label is the sign of the first input: the sharper the fit, the higher the held-out likelihood.
    sharp, scores = tool.cv_ridge(x, (z[:, 0] > 1.0).astype(float), np.random.default_rng(0))
    assert sharp == min(tool.RIDGE_GRID)
    assert scores[sharp] == max(scores.values())
    # A label independent of all 20 inputs: any slope is overfitting, the largest penalty holds out best.
    noise, _ = tool.cv_ridge(x, (rng.random(400) < 0.1).astype(float), np.random.default_rng(0))
    assert noise == max(tool.RIDGE_GRID)
