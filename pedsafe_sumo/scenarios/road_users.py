"""Sizes and colours of the road users the scenarios stage: vehicle classes, body and clothing colours,
the pedestrian's body."""

from __future__ import annotations

from dataclasses import dataclass

#: Car body colours drawn for occluders and waiting vehicles (RGB 0-255): white, black, silver, grey,
#: red, blue - the common colours of the Beijing fleet.
CAR_COLOURS_RGB = (
    (235, 235, 235),
    (20, 20, 20),
    (192, 192, 192),
    (110, 110, 110),
    (170, 25, 30),
    (30, 60, 150),
)
#: Clothing colours for pedestrians who are not blending: saturated and dark/bright garments.
CLOTHING_COLOURS_RGB = (
    (200, 40, 40),
    (40, 80, 180),
    (40, 140, 60),
    (230, 200, 40),
    (240, 240, 240),
    (30, 30, 30),
)
OCCLUDER_BLACK_RGB = (20, 20, 20)
EGO_BLUE_RGB = (30, 110, 255)


@dataclass(frozen=True)
class VehicleSize:
    length_m: float
    width_m: float
    height_m: float


#: Body sizes of the vehicle classes in the scenes [m]. Height decides what a roof LiDAR (1.9 m) and a
#: 1.6 m camera see over: a 1.5 m car hides a pedestrian's legs only, an SUV or van hides them whole.
VEHICLE_CLASSES = {
    "car": VehicleSize(4.6, 1.8, 1.5),
    "suv": VehicleSize(4.8, 1.9, 1.75),
    "van": VehicleSize(5.0, 1.95, 2.0),
}
#: Shares of the classes among queued and waiting vehicles (assumption: Beijing urban fleet, where
#: SUVs and MPVs make up about a third of new passenger cars).
QUEUE_CLASS_WEIGHTS = {"car": 0.55, "suv": 0.35, "van": 0.10}

#: Radius of the pedestrian's body circle [m].
PEDESTRIAN_RADIUS_M = 0.3


def pedestrian_height_m(gender: str, age_years: float) -> float:
    """Body height of a pedestrian: 1.72 m (male), 1.60 m (female), 1.66 m otherwise, 5 cm less under 19."""
    height_m = {"m": 1.72, "f": 1.60}.get(gender, 1.66)
    if age_years < 19:
        height_m -= 0.05
    return height_m
