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

#: Above this argument exp may overflow, where math.exp raises and the C function returns inf (exp
#: overflows above ln(largest double) = 709.78).
EXP_OVERFLOW_FROM = 709.0


def _c_exp(x: float) -> float:
    """The C library's exp of x, inf where it overflows (as the C function returns; math.exp raises)."""
    try:
        return math.exp(x)
    except OverflowError:
        return math.inf


_MATH_EXP = np.frompyfunc(math.exp, 1, 1)
_C_EXP = np.frompyfunc(_c_exp, 1, 1)


def expit(x: FloatOrArray) -> np.ndarray:
    """1 / (1 + exp(-x)) element-wise in double precision: scipy.special.expit's floats."""
    minus_x = -np.asarray(x, dtype=float)
    flat = minus_x.reshape(-1)
    # math.exp itself (a builtin: the fastest call) where it cannot overflow, _c_exp where it may
    may_overflow = flat > EXP_OVERFLOW_FROM
    with np.errstate(over="ignore", under="ignore"):  # exp's own flags: its inf and 0 are the answers
        exp_minus_x = np.asarray(_MATH_EXP(np.where(may_overflow, 0.0, flat)), dtype=float)
        if may_overflow.any():
            exp_minus_x[may_overflow] = np.asarray(_C_EXP(flat[may_overflow]), dtype=float)
    return 1.0 / (1.0 + exp_minus_x.reshape(minus_x.shape))
