"""Hand-built FCD files for the conflicts tests: a car driving east and people near its lane.

The car drives along y = 0 at 10 m/s; its vType is 4 m x 2 m, so SUMO's position (middle of the front
bumper) is 2 m ahead of the centre: centre x = 10 t, FCD x = 10 t + 2. People are 0.5 m wide (radius
0.25 m). Steps every 0.5 s.
"""

from __future__ import annotations

from pathlib import Path

STEP_S = 0.5
CAR_SPEED_MPS = 10.0
TYPES_XML = (
    '<routes>\n    <vType id="car_t" length="4" width="2"/>\n'
    '    <vType id="ped_t" vClass="pedestrian" width="0.5"/>\n</routes>\n'
)


def crossing_walker(time_s: float) -> tuple[float, float, float]:
    """(y, angle, speed) of the walker at x = 20 m: walks north at 1 m/s from y = -2.5 m, stops at -2.0 m
    from t = 0.5 s to 2.0 s (the car passes), walks on from t = 2.5 s (y = -2.0 + (t - 2.5))."""
    if time_s == 0.0:
        return -2.5, 0.0, 1.0
    if time_s <= 2.0:
        return -2.0, 0.0, 0.0
    return -2.0 + (time_s - 2.5), 0.0, 1.0


def write_fcd(path: Path, steps: int, people, car_attrs: str = "") -> Path:
    """An FCD file of `steps` timesteps: the car, and `people` = [(id, t -> (x, y, angle, speed))]."""
    lines = ['<?xml version="1.0" encoding="UTF-8"?>', "<fcd-export>"]
    for k in range(steps):
        t = k * STEP_S
        lines.append(f'    <timestep time="{t:.2f}">')
        lines.append(
            f'        <vehicle id="car" x="{CAR_SPEED_MPS * t + 2:.2f}" y="0.00" angle="90.00" type="car_t" '
            f'speed="{CAR_SPEED_MPS:.2f}" pos="0.00" lane="road_0"{car_attrs}/>'
        )
        for person_id, state in people:
            x, y, angle, speed = state(t)
            lines.append(
                f'        <person id="{person_id}" x="{x:.2f}" y="{y:.2f}" angle="{angle:.2f}" type="ped_t" '
                f'speed="{speed:.2f}" edge="walk"/>'
            )
        lines.append("    </timestep>")
    lines.append("</fcd-export>")
    path.write_text("\n".join(lines) + "\n")
    return path


def walker(t: float) -> tuple[float, float, float, float]:
    y, angle, speed = crossing_walker(t)
    return 20.0, y, angle, speed


def stander(t: float) -> tuple[float, float, float, float]:
    """Stands on the car's path at (40, 0): the car's front reaches 40 - 0.25 m at centre x = 37.75 m."""
    return 40.0, 0.0, 0.0, 0.0
