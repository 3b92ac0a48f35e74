"""What a screenshot gets on top of sumo-gui's picture, drawn in pixels so that it reads at any zoom:
a ring around the pedestrian, the time and the moment stamped in the top-left corner, and a legend of
the colours in the bottom-left corner.

At the default view (60 m across 1000 px) sumo-gui draws a person about 6 px wide, too small to find
at a glance; the ring is PEDESTRIAN_MARKER_RADIUS_PX in radius whatever the zoom.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

#: The pedestrian's ring, in pixels: 36 px across its outer edge, seen at once on a 1000 px picture.
PEDESTRIAN_MARKER_RADIUS_PX = 16
PEDESTRIAN_MARKER_THICKNESS_PX = 3
#: The stamp: black text on a white box whose top-left corner is STAMP_ORIGIN_PX.
STAMP_ORIGIN_PX = (8, 8)
STAMP_RGB = (255, 255, 255)
TEXT_RGB = (0, 0, 0)
LEGEND_RGB = (255, 255, 255)
FONT = cv2.FONT_HERSHEY_SIMPLEX
#: Text size at a picture 800 px high; it scales with the picture's height (between half and 3 times).
FONT_SCALE = 0.5
LINE_PX = 20
PADDING_PX = 6


@dataclass(frozen=True)
class LegendEntry:
    label: str
    rgb: tuple[int, ...]
    #: "box" (a vehicle), "ring" (the pedestrian's marker), "line" (a field of view), "dot" (a detection)
    symbol: str


def _bgr(rgb: tuple[int, ...]) -> tuple[int, int, int]:
    return (int(rgb[2]), int(rgb[1]), int(rgb[0]))


def _scale(image: np.ndarray) -> float:
    return min(3.0, max(0.5, image.shape[0] / 800))


def draw_pedestrian_marker(image: np.ndarray, centre_px: tuple[float, float], rgb: tuple[int, ...]) -> None:
    """A ring of `rgb` around the pedestrian with a thin black edge on both sides (it shows on a light
    road and on a dark one alike)."""
    centre = (round(centre_px[0]), round(centre_px[1]))
    radius = PEDESTRIAN_MARKER_RADIUS_PX
    cv2.circle(image, centre, radius, (0, 0, 0), PEDESTRIAN_MARKER_THICKNESS_PX + 2, cv2.LINE_AA)
    cv2.circle(image, centre, radius, _bgr(rgb), PEDESTRIAN_MARKER_THICKNESS_PX, cv2.LINE_AA)


def _text_box(image: np.ndarray, origin: tuple[int, int], lines: list[str], fill_rgb, scale: float) -> tuple:
    """A filled box at `origin` (top-left) holding `lines`; returns (x0, y0, x1, y1) of the box."""
    font_scale = FONT_SCALE * scale
    line_px, pad = round(LINE_PX * scale), round(PADDING_PX * scale)
    width = max(cv2.getTextSize(line, FONT, font_scale, 1)[0][0] for line in lines)
    x0, y0 = origin
    x1, y1 = x0 + width + 2 * pad, y0 + len(lines) * line_px + 2 * pad
    cv2.rectangle(image, (x0, y0), (x1, y1), _bgr(fill_rgb), cv2.FILLED)
    cv2.rectangle(image, (x0, y0), (x1, y1), (0, 0, 0), 1)
    for i, line in enumerate(lines):
        baseline_y = y0 + pad + (i + 1) * line_px - round(6 * scale)
        cv2.putText(image, line, (x0 + pad, baseline_y), FONT, font_scale, _bgr(TEXT_RGB), 1, cv2.LINE_AA)
    return x0, y0, x1, y1


def draw_stamp(image: np.ndarray, lines: list[str]) -> tuple[int, int, int, int]:
    """The time and the moment in the top-left corner; returns the box (x0, y0, x1, y1)."""
    return _text_box(image, STAMP_ORIGIN_PX, lines, STAMP_RGB, _scale(image))


def draw_legend(image: np.ndarray, entries: list[LegendEntry]) -> tuple[int, int, int, int]:
    """The legend in the bottom-left corner, a symbol before each label; returns its box."""
    scale = _scale(image)
    line_px, pad = round(LINE_PX * scale), round(PADDING_PX * scale)
    symbol_px = round(14 * scale)
    font_scale = FONT_SCALE * scale
    width = max(cv2.getTextSize(e.label, FONT, font_scale, 1)[0][0] for e in entries) + symbol_px + 3 * pad
    height = len(entries) * line_px + 2 * pad
    x0, y1 = STAMP_ORIGIN_PX[0], image.shape[0] - STAMP_ORIGIN_PX[1]
    y0, x1 = y1 - height, x0 + width
    cv2.rectangle(image, (x0, y0), (x1, y1), _bgr(LEGEND_RGB), cv2.FILLED)
    cv2.rectangle(image, (x0, y0), (x1, y1), (0, 0, 0), 1)
    for i, entry in enumerate(entries):
        top = y0 + pad + i * line_px
        sx, sy = x0 + pad, top + (line_px - symbol_px) // 2
        colour = _bgr(entry.rgb)
        if entry.symbol == "ring":
            centre = (sx + symbol_px // 2, sy + symbol_px // 2)
            cv2.circle(image, centre, symbol_px // 2, (0, 0, 0), 4, cv2.LINE_AA)
            cv2.circle(image, centre, symbol_px // 2, colour, 2, cv2.LINE_AA)
        elif entry.symbol == "line":
            mid = sy + symbol_px // 2
            cv2.line(image, (sx, mid), (sx + symbol_px, mid), colour, max(2, round(2 * scale)))
        elif entry.symbol == "dot":
            cv2.circle(image, (sx + symbol_px // 2, sy + symbol_px // 2), symbol_px // 3, colour, cv2.FILLED)
        else:
            cv2.rectangle(image, (sx, sy), (sx + symbol_px, sy + symbol_px), colour, cv2.FILLED)
            cv2.rectangle(image, (sx, sy), (sx + symbol_px, sy + symbol_px), (0, 0, 0), 1)
        baseline_y = top + line_px - round(6 * scale)
        cv2.putText(
            image,
            entry.label,
            (sx + symbol_px + pad, baseline_y),
            FONT,
            font_scale,
            _bgr(TEXT_RGB),
            1,
            cv2.LINE_AA,
        )
    return x0, y0, x1, y1


def world_to_pixel(
    xy_m: tuple[float, float],
    view_boundary: tuple[tuple[float, float], tuple[float, float]],
    canvas_size_px: tuple[int, int],
) -> tuple[float, float]:
    """Pixel (column, row) of a world point on sumo-gui's canvas of `canvas_size_px` (width, height) that
    shows `view_boundary` ((x_min, y_min), (x_max, y_max), metres; y grows northwards, rows downwards)."""
    (x_min, y_min), (x_max, y_max) = view_boundary
    width_px, height_px = canvas_size_px
    column = (xy_m[0] - x_min) / (x_max - x_min) * width_px
    row = (y_max - xy_m[1]) / (y_max - y_min) * height_px
    return column, row
