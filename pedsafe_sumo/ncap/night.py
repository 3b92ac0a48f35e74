"""The onboard camera at night, for the night load cases of the 2026 protocol ("CPNA night" ...).

The day camera (perception/sensors.py, its parameters in params/defaults.toml) detects a pedestrian whose
projected height reaches `min_height_px`, so its range for a pedestrian of height H is f H / min_height_px
(f = width_px / (2 tan(hfov / 2))). The night camera is the same camera with that threshold divided by
protocol.toml `[night] camera_range_share` (the range scales by the share) and its per-frame miss
probability raised to `[night] camera_miss_probability`. The onboard LiDAR and the roadside camera are
unchanged. The day parameters are never modified: night_params returns a copy.
"""

from __future__ import annotations

import copy
import math
from typing import Any

from pedsafe_sumo.ncap.protocol import NcapError, Protocol


def camera_range_m(camera: dict[str, Any], height_m: float) -> float:
    """The distance within which the camera's projected height of a pedestrian reaches min_height_px."""
    focal_px = camera["width_px"] / (2 * math.tan(math.radians(camera["hfov_deg"]) / 2))
    return focal_px * height_m / camera["min_height_px"]


def night_params(params: dict[str, Any], protocol: Protocol) -> dict[str, Any]:
    """A copy of `params` with the onboard camera's night model (module docstring)."""
    night = protocol.raw["night"]
    share = float(night["camera_range_share"])
    miss = float(night["camera_miss_probability"])
    if not 0.0 < share <= 1.0 or not 0.0 <= miss <= 1.0:
        raise NcapError("protocol [night]: camera_range_share in (0, 1], camera_miss_probability in [0, 1]")
    out = copy.deepcopy(params)
    camera = out["perception"]["camera"]
    camera["min_height_px"] = camera["min_height_px"] / share
    camera["miss_probability"] = max(camera["miss_probability"], miss)
    return out
