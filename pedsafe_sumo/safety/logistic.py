"""The logistic function of the risk models, float for float the one of scipy.special.

scipy.special.expit(x) is 1 / (1 + exp(-x)) in double precision with the C library's exp. numpy's own
exp (SIMD) differs from the C library's in the last bit of some arguments; Python's `math.exp` is the C
library's. So `expit` here takes exp element by element from `math.exp` and does the rest in numpy:
the same floats as scipy's, without scipy.special's import (a third of the conflicts tool's start-up;
docs/decisions/2026-11-28-expit-without-scipy.md). tests/safety/test_logistic.py compares the two.
"""

from __future__ import annotations

import math

import numpy as np

from pedsafe_sumo.safety.geometry import FloatOrArray


def _c_exp(x: float) -> float:
    """The C library's exp of x, inf where it overflows (as the C function returns; math.exp raises)."""
    try:
        return math.exp(x)
    except OverflowError:
        return math.inf


_C_EXP = np.frompyfunc(_c_exp, 1, 1)


def expit(x: FloatOrArray) -> np.ndarray:
    """1 / (1 + exp(-x)) element-wise in double precision: scipy.special.expit's floats."""
    minus_x = -np.asarray(x, dtype=float)
    with np.errstate(over="ignore"):  # exp's overflow flag: inf is the C function's answer, as in scipy
        exp_minus_x = np.asarray(_C_EXP(minus_x), dtype=float)
    return 1.0 / (1.0 + exp_minus_x)
