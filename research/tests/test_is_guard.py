"""research/experiments/is_guard.py: a guarded proposal's variance scored on rows drawn from the unguarded
one, against the variance worked out by quadrature (no SUMO)."""

from __future__ import annotations

import importlib.util
import math
import sys

import numpy as np
import pytest
from scipy import integrate, special, stats

from pedsafe_sumo import REPO_ROOT

_spec = importlib.util.spec_from_file_location(
    "is_guard", REPO_ROOT / "research" / "experiments" / "is_guard.py"
)
tool = importlib.util.module_from_spec(_spec)
sys.modules[_spec.name] = tool
_spec.loader.exec_module(tool)

SHARE = 0.1
THRESHOLD = 2.0


def _pi(x):
    """A smooth 'fit' of f = 1{x > 2} that underrates the event just above the threshold."""
    return special.expit(3.0 * (x - 2.6))


def _quad(function, low=-12.0, high=14.0) -> float:
    value, _ = integrate.quad(function, low, high, limit=200, points=[THRESHOLD])
    return value


def test_guarded_roots_by_hand() -> None:
    h = np.array([0.0, 0.1, 0.5])
    assert np.allclose(tool.guarded_root(h, "share", 0.3, 0.04), h)
    # shrink 0.25, m = 0.04: sqrt(0.75 h^2 + 0.01)
    assert np.allclose(
        tool.guarded_root(h, "shrink", 0.25, 0.04), [0.1, math.sqrt(0.0175), math.sqrt(0.1975)]
    )
    # floor 0.5, m = 0.04: sqrt(max(h^2, 0.02))
    assert np.allclose(tool.guarded_root(h, "floor", 0.5, 0.04), [math.sqrt(0.02), math.sqrt(0.02), 0.5])


@pytest.mark.parametrize(("kind", "level"), [("share", math.nan), ("shrink", 0.2), ("floor", 0.5)])
def test_a_guarded_proposals_variance_from_rows_of_the_unguarded_one(kind: str, level: float) -> None:
    # p = N(0, 1), f = 1{x > 2}; the rows come from q = p (lambda + (1 - lambda) sqrt(pi) / c), drawn by
    # rejection; the variant's variance E_p[f p/q'] - P^2 and its variance with pi as the control at the
    # best slope are integrated over x.
    p = stats.norm.pdf
    m = _quad(lambda t: p(t) * _pi(t))
    c = _quad(lambda t: p(t) * math.sqrt(_pi(t)))

    def root_new(t: float) -> float:
        return float(tool.guarded_root(np.array([math.sqrt(_pi(t))]), kind, level, m)[0])

    c_new = _quad(lambda t: p(t) * root_new(t))

    def w_new(t: float) -> float:
        return 1.0 / (SHARE + (1 - SHARE) * root_new(t) / c_new)

    rate = float(stats.norm.sf(THRESHOLD))
    moments = {  # E_p[w' a b] for a, b in {f, g}
        "ff": _quad(lambda t: p(t) * w_new(t), THRESHOLD, 14.0),
        "fg": _quad(lambda t: p(t) * w_new(t) * _pi(t), THRESHOLD, 14.0),
        "gg": _quad(lambda t: p(t) * w_new(t) * _pi(t) ** 2),
    }
    slope = (moments["fg"] - rate * m) / (moments["gg"] - m * m)
    expected_cv = (
        moments["ff"] - 2 * slope * moments["fg"] + slope**2 * moments["gg"] - (rate - slope * m) ** 2
    )
    rng = np.random.default_rng(5)
    candidates = rng.normal(size=8_000_000)
    ratio = SHARE + (1 - SHARE) * np.sqrt(_pi(candidates)) / c
    x = candidates[rng.random(candidates.size) * (SHARE + (1 - SHARE) / c) < ratio][:400_000]
    assert x.size == 400_000
    f = (x > THRESHOLD).astype(float)
    w = 1.0 / (SHARE + (1 - SHARE) * np.sqrt(_pi(x)) / c)
    new_root = tool.guarded_root(np.sqrt(_pi(x)), kind, level, m)
    weights_new = 1.0 / (SHARE + (1 - SHARE) * new_root / c_new)
    p_hat, plain, with_cv = tool.variances(f, w, weights_new, _pi(x), m)
    assert math.isclose(p_hat, rate, rel_tol=0.02)
    assert math.isclose(plain, moments["ff"] - rate**2, rel_tol=0.05)
    assert math.isclose(with_cv, expected_cv, rel_tol=0.08)


def test_pooled_efficiency_adds_relative_variances() -> None:
    # Two runs of one scenario: P 0.02 and 0.03, plain variances 0.0004 and 0.0018 (relative 1 and 2):
    # pooled P 0.025, efficiency (1 - 0.025) / (0.025 * 1.5) = 26.
    import pandas as pd

    frame = pd.DataFrame(
        {
            "run": ["a", "b"],
            "scenario": ["s", "s"],
            "factor": [False, False],
            "variant": ["sampler", "sampler"],
            **{f"{c} P": [0.02, 0.03] for c in ("sv", "v2i")},
            **{f"{c} var": [0.0004, 0.0018] for c in ("sv", "v2i")},
            **{f"{c} var cv": [0.0004, 0.0018] for c in ("sv", "v2i")},
        }
    )
    row = tool.pooled(frame).iloc[0]
    assert math.isclose(row["sv plain"], 0.975 / (0.025 * 1.5))
    assert math.isclose(row["v2i cv"], 0.975 / (0.025 * 1.5))
