"""What a ray can hit, as the ray casts, the sensor rules and the compiled kernels share it.

The kind codes of a hit surface, the hits of one cast (:class:`RayHits`), the CIELAB colour of an
sRGB colour (the camera's contrast rule) and the camera's near plane. This module imports no other
module of the perception layer, so everything above it can.

The compiled kernels (:mod:`.raycast_kernels`, :mod:`.kernels`) freeze these constants into their
cached code: after changing one, touch those two files so that numba compiles them again.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

KIND_NONE = 0  #: nothing within t_max (sky, or beyond range)
KIND_GROUND = 1
KIND_VEHICLE = 2
KIND_PEDESTRIAN = 3
KIND_PRISM = 4  #: building / canopy / hedge wall; index = polygon index
KIND_CYLINDER = 5  #: tree trunk or crown; index = cylinder index

NEAR_CLIP_M = 0.05  #: camera near plane (m): nothing is imaged closer than this


@dataclass(frozen=True)
class RayHits:
    """Per ray: distance ``t_m`` to the first hit (inf when none), its ``kind`` and object ``index``."""

    t_m: np.ndarray
    kind: np.ndarray
    index: np.ndarray


def rgb_to_lab(rgb: np.ndarray) -> np.ndarray:
    """(K, 3) sRGB 0-255 -> (K, 3) CIELAB (L 0-100) through OpenCV (D65)."""
    arr = (np.asarray(rgb, dtype=np.float32).reshape(1, -1, 3)) / np.float32(255.0)
    if arr.shape[1] == 0:
        return np.zeros((0, 3))
    return cv2.cvtColor(arr, cv2.COLOR_RGB2Lab).reshape(-1, 3).astype(float)
