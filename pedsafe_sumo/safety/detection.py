"""First detection: when and how far away the AD stack first perceives the pedestrian, and by which sensor."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from pedsafe_sumo.safety import log as steplog

if TYPE_CHECKING:  # pandas only in annotations: importing it costs the conflicts tool 0.3 s
    import pandas as pd


@dataclass(frozen=True)
class FirstDetection:
    #: index of the first step with `perceived` (None if never)
    step: int | None
    #: time of that step, s (NaN if never)
    time_s: float
    #: ego-pedestrian centre distance at that step, m (NaN if never)
    distance_m: float
    #: the sensors whose flags were set at that step, "+"-joined in log order ("" if never or none)
    detected_by: str


def first_detection(log: pd.DataFrame) -> FirstDetection:
    """The first step at which the AD stack perceives the pedestrian (the `perceived` column)."""
    a = steplog.as_arrays(log)
    perceived = np.flatnonzero(a[steplog.PERCEIVED])
    if perceived.size == 0:
        return FirstDetection(None, math.nan, math.nan, "")
    k = int(perceived[0])
    distance = math.hypot(
        a[steplog.PED_X][k] - a[steplog.EGO_X][k], a[steplog.PED_Y][k] - a[steplog.EGO_Y][k]
    )
    sensors = [c.removeprefix(steplog.SENSOR_PREFIX) for c in steplog.sensor_columns(a) if a[c][k]]
    return FirstDetection(k, float(a[steplog.TIME][k]), distance, "+".join(sensors))
