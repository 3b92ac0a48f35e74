"""Validator of the ``[perception]`` section of the parameter file (registered on import)."""

from __future__ import annotations

import math
from typing import Any

from pedsafe_sumo.params import ParameterError, register_validator


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
    _probability(t, "miss_probability", where)


def _mount(t: dict, where: str) -> None:
    _num(t, "forward_offset_m", where)
    _num(t, "left_offset_m", where)
    _positive(t, "height_m", where)


@register_validator("perception")
def validate_perception(section: dict[str, Any], where: str = "perception") -> None:
    scene = section["scene"]
    _rgb(scene, "ground_rgb", f"{where}.scene")
    _rgb(scene, "sky_rgb", f"{where}.scene")

    cam = section["camera"]
    w = f"{where}.camera"
    _camera(cam, w)
    _mount(cam, w)
    _num(cam, "yaw_offset_deg", w)
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

    rsu = section["roadside_camera"]
    w = f"{where}.roadside_camera"
    _camera(rsu, w)
    _positive(rsu, "default_height_m", w)
    if not -90 < _num(rsu, "default_pitch_down_deg", w) < 90:
        raise ParameterError(f"parameter '{w}.default_pitch_down_deg' must be in (-90, 90)")

    v2i = section["v2i"]
    w = f"{where}.v2i"
    _non_negative(v2i, "latency_s", w)
    _probability(v2i, "packet_loss_probability", w)
    _non_negative(v2i, "position_noise_sigma_m", w)

    raw = section.get("raw")
    if raw is not None:  # absent from the parameters of runs older than issue 15
        w = f"{where}.raw"
        for key in ("camera_image_width_px", "camera_image_height_px", "roadside_image_width_px",
                    "roadside_image_height_px"):  # fmt: skip
            _positive_int(raw, key, w)
        _positive(raw, "render_max_distance_m", w)
        _positive(raw, "signal_visibility_m", w)

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
    if occ["canopy_base_m"] >= occ["canopy_top_m"]:
        raise ParameterError(f"parameter '{w}.canopy_base_m' must be below '{w}.canopy_top_m'")
    if occ["tree_crown_base_m"] >= occ["tree_height_m"]:
        raise ParameterError(f"parameter '{w}.tree_crown_base_m' must be below '{w}.tree_height_m'")
    for key in ("building_rgb", "tree_trunk_rgb", "tree_crown_rgb"):
        _rgb(occ, key, w)
    if not isinstance(occ.get("use_polygon_colours"), bool):
        raise ParameterError(f"parameter '{w}.use_polygon_colours' must be true or false")
