"""Exact geometry of an oriented rectangle (the ego's footprint) and a circle (the pedestrian).

All functions are vectorised over numpy arrays (scalars broadcast). Angles in radians, counter-clockwise
from +x; lengths in metres; velocities in m/s; times in s.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

#: A number or an array of numbers (the functions here broadcast over arrays, as numpy does).
FloatOrArray = float | np.ndarray


def to_rectangle_frame(
    x_m: FloatOrArray,
    y_m: FloatOrArray,
    centre_x_m: FloatOrArray,
    centre_y_m: FloatOrArray,
    yaw_rad: FloatOrArray,
) -> tuple[np.ndarray, np.ndarray]:
    """World point(s) -> the rectangle's frame (origin at its centre, +x along its heading)."""
    dx = np.asarray(x_m, dtype=float) - centre_x_m
    dy = np.asarray(y_m, dtype=float) - centre_y_m
    cos, sin = np.cos(yaw_rad), np.sin(yaw_rad)
    return cos * dx + sin * dy, -sin * dx + cos * dy


def box_signed_distance_m(
    local_x_m: FloatOrArray, local_y_m: FloatOrArray, half_length_m: FloatOrArray, half_width_m: FloatOrArray
) -> np.ndarray:
    """Signed distance from a point (in the rectangle frame) to an axis-aligned box centred on the origin.

    Positive outside (Euclidean distance to the nearest edge or corner), zero on the boundary, negative
    inside (minus the distance to the nearest edge).
    """
    qx = np.abs(local_x_m) - half_length_m
    qy = np.abs(local_y_m) - half_width_m
    outside = np.hypot(np.maximum(qx, 0.0), np.maximum(qy, 0.0))
    inside = np.minimum(np.maximum(qx, qy), 0.0)
    return outside + inside


def rectangle_circle_distance_m(
    rect_x_m: FloatOrArray,
    rect_y_m: FloatOrArray,
    rect_yaw_rad: FloatOrArray,
    rect_length_m: FloatOrArray,
    rect_width_m: FloatOrArray,
    circle_x_m: FloatOrArray,
    circle_y_m: FloatOrArray,
    circle_radius_m: FloatOrArray,
) -> np.ndarray:
    """Signed clearance between an oriented rectangle and a circle, m: <= 0 means they touch or overlap.

    The circle's centre is taken into the rectangle's frame; the result is the signed distance from it
    to the rectangle minus the radius (exact for any orientation).
    """
    lx, ly = to_rectangle_frame(circle_x_m, circle_y_m, rect_x_m, rect_y_m, rect_yaw_rad)
    return (
        box_signed_distance_m(lx, ly, 0.5 * np.asarray(rect_length_m), 0.5 * np.asarray(rect_width_m))
        - circle_radius_m
    )


def slab_entry_time_s(
    px: FloatOrArray,
    py: FloatOrArray,
    vx: FloatOrArray,
    vy: FloatOrArray,
    half_x: FloatOrArray,
    half_y: FloatOrArray,
) -> np.ndarray:
    """First time t >= 0 at which p + v t lies in [-half_x, half_x] x [-half_y, half_y] (inf if never)."""
    t_enter = np.zeros(np.broadcast(px, py, vx, vy).shape)
    t_exit = np.full(t_enter.shape, np.inf)
    for p, v, half in ((px, vx, half_x), (py, vy, half_y)):
        p, v, half = np.broadcast_arrays(p, v, half)
        moving = v != 0.0
        with np.errstate(divide="ignore", invalid="ignore"):
            t1 = (-half - p) / v
            t2 = (half - p) / v
        lo = np.where(moving, np.minimum(t1, t2), np.where(np.abs(p) <= half, -np.inf, np.inf))
        hi = np.where(moving, np.maximum(t1, t2), np.where(np.abs(p) <= half, np.inf, -np.inf))
        t_enter = np.maximum(t_enter, lo)
        t_exit = np.minimum(t_exit, hi)
    return np.where(t_enter <= t_exit, t_enter, np.inf)


def circle_entry_time_s(
    px: FloatOrArray,
    py: FloatOrArray,
    vx: FloatOrArray,
    vy: FloatOrArray,
    cx: FloatOrArray,
    cy: FloatOrArray,
    radius: FloatOrArray,
) -> np.ndarray:
    """First time t >= 0 at which p + v t lies within `radius` of (cx, cy) (inf if never)."""
    rx, ry = px - cx, py - cy
    c = rx * rx + ry * ry - radius * radius
    a = vx * vx + vy * vy
    b = 2.0 * (rx * vx + ry * vy)
    disc = b * b - 4.0 * a * c
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (-b - np.sqrt(np.maximum(disc, 0.0))) / (2.0 * a)
    hit = (a > 0.0) & (disc >= 0.0) & (t >= 0.0)
    return np.where(c <= 0.0, 0.0, np.where(hit, t, np.inf))


def rectangle_circle_contact_time_s(
    local_x_m: FloatOrArray,
    local_y_m: FloatOrArray,
    local_vx_mps: FloatOrArray,
    local_vy_mps: FloatOrArray,
    half_length_m: FloatOrArray,
    half_width_m: FloatOrArray,
    radius_m: FloatOrArray,
) -> np.ndarray:
    """Time until a circle moving at constant velocity first touches a fixed box, s (0 if touching now).

    Position and velocity of the circle's centre are in the box's frame (box centred on the origin,
    axis-aligned): for two road users under constant velocity that is the relative motion, and the box
    does not turn. The centre touches the box grown by the radius (a rounded rectangle), which is the
    union of two slabs and four corner discs; the first entry into the union is the smallest entry time
    into its parts. Returns inf where the circle never touches the box.
    """
    px, py = np.asarray(local_x_m, dtype=float), np.asarray(local_y_m, dtype=float)
    vx, vy = np.asarray(local_vx_mps, dtype=float), np.asarray(local_vy_mps, dtype=float)
    a, b, r = np.asarray(half_length_m), np.asarray(half_width_m), np.asarray(radius_m)
    times = [slab_entry_time_s(px, py, vx, vy, a + r, b), slab_entry_time_s(px, py, vx, vy, a, b + r)]
    for sx in (-1.0, 1.0):
        for sy in (-1.0, 1.0):
            times.append(circle_entry_time_s(px, py, vx, vy, sx * a, sy * b, r))
    return np.minimum.reduce(np.broadcast_arrays(*times))


#: Margin of the bounding-box tests of `first_polyline_crossing`, per metre of the largest coordinate (plus
#: one): far above the rounding of its parametric test, far below any real gap.
BOX_MARGIN_PER_M = 1e-9


def first_polyline_crossing(
    ax_m: np.ndarray, ay_m: np.ndarray, bx_m: np.ndarray, by_m: np.ndarray, block: int = 256
) -> tuple[float, float] | None:
    """The first point where polyline A crosses polyline B (first along A, then along B), or None.

    Segments of zero length and parallel segments never cross. Endpoints count (a crossing exactly at a
    vertex is found). A's segments are tested in blocks of `block` against those of B's segments whose
    bounding boxes overlap the block's (zero-length ones left out), so memory stays bounded and long logs
    with long standstills stay fast.
    """
    ax, ay, bx, by = (np.asarray(v, dtype=float) for v in (ax_m, ay_m, bx_m, by_m))
    if len(ax) < 2 or len(bx) < 2:
        return None
    # Segment i of A: a_i + s (a_{i+1} - a_i); segment j of B: b_j + u (b_{j+1} - b_j); s, u in [0, 1].
    all_bdx, all_bdy = np.diff(bx), np.diff(by)
    moving_b = np.flatnonzero(np.hypot(all_bdx, all_bdy) > 0)
    if moving_b.size == 0:
        return None
    b_lo_x, b_hi_x = np.minimum(bx[:-1], bx[1:]), np.maximum(bx[:-1], bx[1:])
    b_lo_y, b_hi_y = np.minimum(by[:-1], by[1:]), np.maximum(by[:-1], by[1:])
    margin = BOX_MARGIN_PER_M * (
        1.0 + max(np.abs(ax).max(), np.abs(ay).max(), np.abs(bx).max(), np.abs(by).max())
    )
    eps = 1e-12
    for start in range(0, len(ax) - 1, block):
        stop = min(start + block + 1, len(ax))
        xs, ys = ax[start:stop], ay[start:stop]
        near = moving_b[
            (b_hi_x[moving_b] >= xs.min() - margin)
            & (b_lo_x[moving_b] <= xs.max() + margin)
            & (b_hi_y[moving_b] >= ys.min() - margin)
            & (b_lo_y[moving_b] <= ys.max() + margin)
        ]
        if near.size == 0:
            continue
        b0x, b0y = bx[None, near], by[None, near]
        bdx, bdy = all_bdx[None, near], all_bdy[None, near]
        b_len = np.hypot(bdx, bdy)
        a0x, a0y = xs[:-1, None], ys[:-1, None]
        adx, ady = np.diff(xs)[:, None], np.diff(ys)[:, None]
        denom = adx * bdy - ady * bdx
        wx, wy = b0x - a0x, b0y - a0y
        scale = np.hypot(adx, ady) * b_len
        with np.errstate(divide="ignore", invalid="ignore"):
            s = (wx * bdy - wy * bdx) / denom
            u = (wx * ady - wy * adx) / denom
        hit = (np.abs(denom) > eps * scale) & (scale > 0) & (s >= -eps) & (s <= 1 + eps)
        hit &= (u >= -eps) & (u <= 1 + eps)
        if hit.any():
            i, j = np.argwhere(hit)[0]
            return float(a0x[i, 0] + s[i, j] * adx[i, 0]), float(a0y[i, 0] + s[i, j] * ady[i, 0])
    return None


def path_boxes_apart(
    ax_m: np.ndarray, ay_m: np.ndarray, bx_m: np.ndarray, by_m: np.ndarray, starts: Sequence[int] | np.ndarray
) -> np.ndarray:
    """Of pairs of polylines stacked one pair after another (pair k: the points from starts[k] up to the
    next start, or to the end, of A and of B; at least one each): True where the bounding boxes of A's
    and B's points are further apart than the margin of `first_polyline_crossing`'s box tests, which
    then finds no crossing (every segment's box lies inside its polyline's box; the margin here, from the
    largest coordinate of all pairs, is at least each pair's own). False where they may cross, or where
    a coordinate is NaN."""
    at = np.asarray(starts, dtype=np.intp)
    a_lo_x, a_hi_x = np.minimum.reduceat(ax_m, at), np.maximum.reduceat(ax_m, at)
    a_lo_y, a_hi_y = np.minimum.reduceat(ay_m, at), np.maximum.reduceat(ay_m, at)
    b_lo_x, b_hi_x = np.minimum.reduceat(bx_m, at), np.maximum.reduceat(bx_m, at)
    b_lo_y, b_hi_y = np.minimum.reduceat(by_m, at), np.maximum.reduceat(by_m, at)
    largest = max(float(np.abs(v).max(initial=0.0)) for v in (ax_m, ay_m, bx_m, by_m))
    margin = BOX_MARGIN_PER_M * (1.0 + largest)
    return (
        (b_hi_x < a_lo_x - margin)
        | (b_lo_x > a_hi_x + margin)
        | (b_hi_y < a_lo_y - margin)
        | (b_lo_y > a_hi_y + margin)
    )
