"""Deceleration rate to avoid a crash (DRAC) of a vehicle towards a pedestrian, per step.

DRAC (m/s2) is the constant deceleration that, applied from this step on, stops the vehicle within the
distance it would cover at its current speed before touching the pedestrian: with v the vehicle's
speed and TTC the time to contact under constant velocity (`surrogates.ttc_steps_s`, real shapes), that
distance is d = v * TTC and the deceleration v^2 / (2 d) = v / (2 TTC) (DRAC = v^2 / 2d after Almqvist,
Hyden & Risser 1991, with the pedestrian's own motion taken into d through the TTC). NaN where the two
are not on a collision course (TTC NaN) and +inf where they already touch (TTC 0).
"""

from __future__ import annotations

import math

import numpy as np

from pedsafe_sumo.safety import log as steplog
from pedsafe_sumo.safety.surrogates import ttc_steps_s


def drac_steps_mps2(log) -> np.ndarray:
    """Per-step DRAC of the ego towards the pedestrian, m/s2 (NaN off a collision course, inf in contact)."""
    a = steplog.as_arrays(log)
    ttc = ttc_steps_s(a)
    speed = a[steplog.EGO_SPEED]
    with np.errstate(divide="ignore", invalid="ignore"):
        drac = np.where(ttc > 0.0, speed / (2.0 * ttc), np.where(ttc == 0.0, np.inf, np.nan))
    return drac


def max_drac_mps2(log, last_step: int | None = None) -> float:
    """Largest finite per-step DRAC up to `last_step` (all steps if None), m/s2; NaN if never on course.

    Steps in contact (inf) are left out: the deceleration before the contact is the informative one.
    """
    drac = drac_steps_mps2(log)
    if last_step is not None:
        drac = drac[: last_step + 1]
    finite = drac[np.isfinite(drac)]
    return float(finite.max()) if finite.size else math.nan
