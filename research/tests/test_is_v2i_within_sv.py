"""research/experiments/is_v2i_within_sv.py: its AUC against the Mann-Whitney U of scipy, and its ridge
logistic against the coefficients that generated the labels (no SUMO)."""

from __future__ import annotations

import importlib.util

import numpy as np
from scipy import stats

from pedsafe_sumo import REPO_ROOT

_spec = importlib.util.spec_from_file_location(
    "is_v2i_within_sv", REPO_ROOT / "research" / "experiments" / "is_v2i_within_sv.py"
)
tool = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(tool)


def test_auc_is_the_mann_whitney_u_over_the_pairs():
    rng = np.random.default_rng(3)
    label = (rng.random(300) < 0.3).astype(float)
    score = rng.normal(size=300) + label
    u = stats.mannwhitneyu(score[label == 1], score[label == 0]).statistic
    assert tool.auc(score, label) == np.float64(u / (label.sum() * (300 - label.sum())))
    assert tool.auc(np.arange(4.0), np.array([0.0, 0, 1, 1])) == 1.0


def test_ridge_logistic_recovers_the_generating_coefficients():
    rng = np.random.default_rng(4)
    x = rng.normal(size=(20_000, 2))
    design = np.column_stack([np.ones(len(x)), x])
    truth = np.array([-1.0, 1.5, -0.5])
    label = (rng.random(len(x)) < 1 / (1 + np.exp(-design @ truth))).astype(float)
    assert np.allclose(tool.ridge_logistic(design, label, ridge=1e-6), truth, atol=0.06)
