"""Validator of the ``[perception]`` section of the parameter file (registered on import)."""

from __future__ import annotations

import math
from typing import Any

from pedsafe_sumo.params import (
    Bounds,
    ParameterError,
    check_lower_bounds,
    check_upper_bounds,
    register_validator,
)

#: Upper bounds of the sensor settings, with why (every ray a step costs time: the bounds keep one step
#: from taking minutes). Mounts: a sensor more than 10 m from the vehicle's centre is not on it.
MOUNT_UPPER_BOUNDS: Bounds = {
    "forward_offset_m": (10.0, "outside the vehicle"),
    "left_offset_m": (10.0, "outside the vehicle"),
    "height_m": (10.0, "above any road vehicle"),
}
CAMERA_UPPER_BOUNDS: Bounds = {
    "width_px": (8192.0, "an 8K sensor"),
    "height_px": (8192.0, "an 8K sensor"),
    "min_height_px": (8192.0, "an 8K sensor's height"),
    # CIE76 distances between sRGB colours stay below about 260 (black to blue-white extremes).
    "delta_e_threshold": (300.0, "larger than the distance of any two sRGB colours"),
    "background_max_distance_m": (1000.0, "farther than any sight line at the site"),
}
#: Sample points per pedestrian = lateral x height fractions, each a ray per step and sensor.
MAX_SAMPLE_FRACTIONS = 64
LIDAR_UPPER_BOUNDS: Bounds = {
    "channels": (256.0, "twice the densest spinning LiDAR (128 channels)"),
    "range_m": (500.0, "twice the longest automotive LiDAR range"),
    "min_returns": (100_000.0, "more returns than a scan has"),
    "cluster_tolerance_m": (10.0, "merges whole cars and pedestrians"),
}
LIDAR_LOWER_BOUNDS: Bounds = {
    # Rays per scan = channels x 360 / resolution: 32 x 7200 at 0.05 deg.
    "horizontal_resolution_deg": (0.05, "finer than any spinning LiDAR (0.08 deg)"),
}
ROADSIDE_UPPER_BOUNDS: Bounds = {"default_height_m": (50.0, "four times a roadside pole (12 m)")}
V2I_UPPER_BOUNDS: Bounds = {
    "latency_s": (10.0, "a message 10 s old describes another scene"),
    "position_noise_sigma_m": (100.0, "noise wider than the junction"),
}
# One ray per pixel: 3840 x 2160 is 8.3 million rays a frame, a 4K sensor and already minutes per episode.
RAW_UPPER_BOUNDS: Bounds = {
    "camera_image_width_px": (3840.0, "a 4K image: one ray per pixel, 8.3 million rays a frame"),
    "camera_image_height_px": (2160.0, "a 4K image: one ray per pixel, 8.3 million rays a frame"),
    "roadside_image_width_px": (3840.0, "a 4K image: one ray per pixel, 8.3 million rays a frame"),
    "roadside_image_height_px": (2160.0, "a 4K image: one ray per pixel, 8.3 million rays a frame"),
    "render_max_distance_m": (2000.0, "five times the study site's diameter"),
    "signal_visibility_m": (1000.0, "no signal head is legible from further than 1 km"),
}
OCCLUDER_UPPER_BOUNDS: Bounds = {
    "level_height_m": (20.0, "four times a storey"),
    "default_building_height_m": (1000.0, "taller than any building (828 m)"),
    "canopy_base_m": (150.0, "taller than any tree (116 m)"),
    "canopy_top_m": (150.0, "taller than any tree (116 m)"),
    "hedge_height_m": (10.0, "a hedge is not a wall"),
    "tree_row_spacing_m": (1000.0, "no longer a row"),
    "tree_trunk_radius_m": (10.0, "wider than any trunk"),
    "tree_crown_base_m": (150.0, "taller than any tree (116 m)"),
    "tree_crown_radius_m": (50.0, "wider than any crown"),
    "tree_height_m": (150.0, "taller than any tree (116 m)"),
}
OCCLUDER_LOWER_BOUNDS: Bounds = {
    # Trees per row = length / spacing: a tiny spacing fills memory with trunks.
    "tree_row_spacing_m": (1.0, "trunks closer than a metre are a wall"),
}


def _num(table: dict, key: str, where: str) -> float:
    value = table.get(key)
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise ParameterError(f"parameter '{where}.{key}' must be a finite number, got {value!r}")
    return float(value)


def _positive(table, key, where):
    if _num(table, key, where) <= 0:
        raise ParameterError(f"parameter '{where}.{key}' must be > 0, got {table[key]!r}")


def _non_negative(table, key, where):
    if _num(table, key, where) < 0:
        raise ParameterError(f"parameter '{where}.{key}' must be >= 0, got {table[key]!r}")


def _probability(table, key, where):
    if not 0.0 <= _num(table, key, where) <= 1.0:
        raise ParameterError(
            f"parameter '{where}.{key}' is a probability and must be in [0, 1], got {table[key]!r}"
        )


def _positive_int(table, key, where):
    value = table.get(key)
    if isinstance(value, bool) or not isinstance(value, int) or value <= 0:
        raise ParameterError(f"parameter '{where}.{key}' must be a positive integer, got {value!r}")


def _rgb(table, key, where):
    value = table.get(key)
    if (
        not isinstance(value, list)
        or len(value) != 3
        or not all(isinstance(v, int | float) and not isinstance(v, bool) and 0 <= v <= 255 for v in value)
    ):
        raise ParameterError(f"parameter '{where}.{key}' must be three numbers 0-255 (sRGB), got {value!r}")


def _fractions(table, key, where, lo, hi):
    value = table.get(key)
    if (
        not isinstance(value, list)
        or not value
        or not all(isinstance(v, int | float) and not isinstance(v, bool) and lo <= v <= hi for v in value)
    ):
        raise ParameterError(f"parameter '{where}.{key}' must be a non-empty list of numbers in [{lo}, {hi}]")


def _strings(table, key, where):
    value = table.get(key)
    if not isinstance(value, list) or not all(isinstance(v, str) and v for v in value):
        raise ParameterError(f"parameter '{where}.{key}' must be a list of non-empty strings")


def _camera(t: dict, where: str) -> None:
    if not 0 < _num(t, "hfov_deg", where) < 180:
        raise ParameterError(f"parameter '{where}.hfov_deg' must be in (0, 180), got {t['hfov_deg']!r}")
    _positive_int(t, "width_px", where)
    _positive_int(t, "height_px", where)
    _probability(t, "min_visible_fraction", where)
    _non_negative(t, "min_height_px", where)
    _non_negative(t, "delta_e_threshold", where)
    _positive(t, "background_max_distance_m", where)
    _fractions(t, "sample_lateral_fractions", where, -1.0, 1.0)
    _fractions(t, "sample_height_fractions", where, 0.0, 1.0)
    for key in ("sample_lateral_fractions", "sample_height_fractions"):
        if len(t[key]) > MAX_SAMPLE_FRACTIONS:
            raise ParameterError(
                f"parameter '{where}.{key}' must have at most {MAX_SAMPLE_FRACTIONS} values (each is a ray "
                f"per pedestrian and step), got {len(t[key])}"
            )
    _probability(t, "miss_probability", where)
    check_upper_bounds(t, CAMERA_UPPER_BOUNDS, where)


def _mount(t: dict, where: str) -> None:
    _num(t, "forward_offset_m", where)
    _num(t, "left_offset_m", where)
    _positive(t, "height_m", where)
    for key in ("forward_offset_m", "left_offset_m"):
        if abs(t[key]) > MOUNT_UPPER_BOUNDS[key][0]:
            raise ParameterError(
                f"parameter '{where}.{key}' must be within +-{MOUNT_UPPER_BOUNDS[key][0]:g} "
                f"({MOUNT_UPPER_BOUNDS[key][1]}), got {t[key]!r}"
            )
    check_upper_bounds(t, {"height_m": MOUNT_UPPER_BOUNDS["height_m"]}, where)


#: [perception.v2i] signal_source: "fresher" the signal head as the onboard camera reads it now wherever it
#: can (with SPaT's time to the switch while SPaT tells the same state), SPaT elsewhere; "spat" the SPaT
#: message whenever one has arrived, in place of the camera's reading (sim/observation.py).
V2I_SIGNAL_SOURCES = ("fresher", "spat")


@register_validator("perception")
def validate_perception(section: dict[str, Any], where: str = "perception") -> None:
    scene = section["scene"]
    _rgb(scene, "ground_rgb", f"{where}.scene")
    _rgb(scene, "sky_rgb", f"{where}.scene")

    cam = section["camera"]
    w = f"{where}.camera"
    _camera(cam, w)
    _mount(cam, w)
    if not -360 <= _num(cam, "yaw_offset_deg", w) <= 360:
        raise ParameterError(
            f"parameter '{w}.yaw_offset_deg' must be in [-360, 360], got {cam['yaw_offset_deg']!r}"
        )
    if not -90 < _num(cam, "pitch_down_deg", w) < 90:
        raise ParameterError(f"parameter '{w}.pitch_down_deg' must be in (-90, 90)")

    lid = section["lidar"]
    w = f"{where}.lidar"
    _mount(lid, w)
    _positive_int(lid, "channels", w)
    lo, hi = _num(lid, "elevation_min_deg", w), _num(lid, "elevation_max_deg", w)
    if not -90 <= lo <= hi <= 90 or (lid["channels"] > 1 and lo == hi):
        raise ParameterError(
            f"parameters '{w}.elevation_min_deg' <= '{w}.elevation_max_deg' must lie in [-90, 90]"
        )
    res = _num(lid, "horizontal_resolution_deg", w)
    if not 0 < res <= 360:
        raise ParameterError(f"parameter '{w}.horizontal_resolution_deg' must be in (0, 360], got {res!r}")
    _positive(lid, "range_m", w)
    _positive_int(lid, "min_returns", w)
    _positive(lid, "cluster_tolerance_m", w)
    _probability(lid, "miss_probability", w)
    check_upper_bounds(lid, LIDAR_UPPER_BOUNDS, w)
    check_lower_bounds(lid, LIDAR_LOWER_BOUNDS, w)

    rsu = section["roadside_camera"]
    w = f"{where}.roadside_camera"
    _camera(rsu, w)
    _positive(rsu, "default_height_m", w)
    if not -90 < _num(rsu, "default_pitch_down_deg", w) < 90:
        raise ParameterError(f"parameter '{w}.default_pitch_down_deg' must be in (-90, 90)")
    check_upper_bounds(rsu, ROADSIDE_UPPER_BOUNDS, w)

    v2i = section["v2i"]
    w = f"{where}.v2i"
    _non_negative(v2i, "latency_s", w)
    _probability(v2i, "packet_loss_probability", w)
    _non_negative(v2i, "position_noise_sigma_m", w)
    if v2i.get("signal_source", "spat") not in V2I_SIGNAL_SOURCES:
        raise ParameterError(
            f"parameter '{w}.signal_source' must be one of {', '.join(V2I_SIGNAL_SOURCES)}, "
            f"got {v2i['signal_source']!r}"
        )
    check_upper_bounds(v2i, V2I_UPPER_BOUNDS, w)

    raw = section.get("raw")
    if raw is not None:  # absent from the parameters recorded by runs without raw sensors
        w = f"{where}.raw"
        for key in ("camera_image_width_px", "camera_image_height_px", "roadside_image_width_px",
                    "roadside_image_height_px"):  # fmt: skip
            _positive_int(raw, key, w)
        _positive(raw, "render_max_distance_m", w)
        _positive(raw, "signal_visibility_m", w)
        check_upper_bounds(raw, RAW_UPPER_BOUNDS, w)

    occ = section["occluders"]
    w = f"{where}.occluders"
    for key in ("building_type_prefixes", "canopy_type_prefixes", "hedge_type_prefixes"):
        _strings(occ, key, w)
    for key in ("tree_poi_types", "tree_row_types"):
        _strings(occ, key, w)
    for key in (
        "level_height_m",
        "default_building_height_m",
        "hedge_height_m",
        "tree_row_spacing_m",
        "tree_trunk_radius_m",
        "tree_crown_base_m",
        "tree_crown_radius_m",
        "tree_height_m",
        "canopy_top_m",
    ):
        _positive(occ, key, w)
    _non_negative(occ, "canopy_base_m", w)
    check_upper_bounds(occ, OCCLUDER_UPPER_BOUNDS, w)
    check_lower_bounds(occ, OCCLUDER_LOWER_BOUNDS, w)
    if occ["canopy_base_m"] >= occ["canopy_top_m"]:
        raise ParameterError(f"parameter '{w}.canopy_base_m' must be below '{w}.canopy_top_m'")
    if occ["tree_crown_base_m"] >= occ["tree_height_m"]:
        raise ParameterError(f"parameter '{w}.tree_crown_base_m' must be below '{w}.tree_height_m'")
    for key in ("building_rgb", "tree_trunk_rgb", "tree_crown_rgb"):
        _rgb(occ, key, w)
    if not isinstance(occ.get("use_polygon_colours"), bool):
        raise ParameterError(f"parameter '{w}.use_polygon_colours' must be true or false")
