"""Compiled (numba) form of the IMM tracker's mixing (control/imm_tracker.py): the weighted mean of the
two models' estimates and their covariance with the spread of the means, which the tracker forms three
times a track and step (each model's start, and the combined estimate), about twenty numpy calls on
4 x 4 arrays each time.

Bit-identical to the numpy form: elementwise sums and products only, in the same order (numba compiles
without fast-math, so no product is fused into an FMA and no sum reassociated; the covariance is summed
from 0.0 as ``np.zeros`` then ``+=`` sums it). ``tests/control/test_imm_tracker.py`` checks the tracker
against the models worked one at a time with numpy. Compiled on first use and cached on disk, as the
perception kernels (:func:`pedsafe_sumo.perception.raycast_kernels._jit`).
"""

from __future__ import annotations

import numpy as np

from pedsafe_sumo.perception.raycast_kernels import _jit


@_jit  # numba compiles it; the annotations are for readers
def mixed_estimates(
    weights: np.ndarray, states: np.ndarray, covs: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """For each column j of `weights` (2, J): x_j = w_0j x_0 + w_1j x_1 and
    P_j = 0 + w_0j (P_0 + d_0 d_0^T) + w_1j (P_1 + d_1 d_1^T), d_i = x_i - x_j; `states` (2, n),
    `covs` (2, n, n). Returns x (J, n) and P (J, n, n)."""
    n_out = weights.shape[1]
    n = states.shape[1]
    x = np.empty((n_out, n))
    p = np.empty((n_out, n, n))
    d = np.empty((2, n))
    for j in range(n_out):
        w0 = weights[0, j]
        w1 = weights[1, j]
        for a in range(n):
            x[j, a] = w0 * states[0, a] + w1 * states[1, a]
        for i in range(2):
            for a in range(n):
                d[i, a] = states[i, a] - x[j, a]
        for a in range(n):
            for b in range(n):
                total = 0.0 + w0 * (covs[0, a, b] + d[0, a] * d[0, b])
                p[j, a, b] = total + w1 * (covs[1, a, b] + d[1, a] * d[1, b])
    return x, p
