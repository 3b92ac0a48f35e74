"""Coarse FCD and turning vehicles: the `uncertain` flag.

A 4 m x 2 m car's front drives east along y = 0 at 10 m/s from x = 0 and, at t = 1.5 s, at (15, 0),
turns north onto x = 15 (heading 0 deg): a 90 degree turn. A person 0.5 m wide stands at (30, 0), ahead
of the car's first heading: extrapolated straight, the car reaches its circle, a TTC that the turn never
lets happen. Its smallest value is at the last sample before the turn: (30 - 0.25 - x) / 10.

- sampled every 1 s (t = 0, 1, 2, 3): last sample heading east at t = 1 s, x = 10: TTC 1.975 s. Period
  1 s > 0.2 s and a 90 degree turn: uncertain.
- sampled every 0.1 s: the same path, last sample heading east at t = 1.5 s, x = 15: TTC 1.475 s.
  Period 0.1 s: not uncertain.
The car never comes closer than 15 - 1 - 0.25 m to the person's circle: no contact in either.
"""

from __future__ import annotations

import pandas as pd
import pytest
from fcd_files import TYPES_XML

from pedsafe_sumo.conflicts.__main__ import main


def front(t: float) -> tuple[float, float, float]:
    """(x, y, SUMO angle) of the car's front at time t."""
    if t <= 1.5:
        return 10.0 * t, 0.0, 90.0
    return 15.0, 10.0 * (t - 1.5), 0.0


def write(path, step_s: float, steps: int):
    lines = ["<fcd-export>"]
    for k in range(steps):
        t = round(k * step_s, 6)
        x, y, angle = front(t)
        lines += [
            f'<timestep time="{t:.2f}">',
            f'<vehicle id="car" x="{x:.3f}" y="{y:.3f}" angle="{angle:.2f}" type="car_t" speed="10.00" '
            'lane="road_0"/>',
            '<person id="p" x="30.00" y="0.00" angle="0.00" type="ped_t" speed="0.00" edge="walk"/>',
            "</timestep>",
        ]
    path.write_text("\n".join(lines + ["</fcd-export>"]) + "\n")
    return path


@pytest.mark.parametrize(
    ("step_s", "steps", "ttc_s", "ttc_time_s", "uncertain"),
    [(1.0, 4, 1.975, 1.0, True), (0.1, 31, 1.475, 1.5, False)],
)
def test_turning_car_on_coarse_fcd_is_uncertain(tmp_path, step_s, steps, ttc_s, ttc_time_s, uncertain):
    types = tmp_path / "types.xml"
    types.write_text(TYPES_XML)
    fcd = write(tmp_path / "turn.fcd.xml", step_s, steps)
    out = tmp_path / "turn.csv"
    assert main([str(fcd), "--out", str(out), "--types", str(types), "--quiet"]) == 0
    row = pd.read_csv(out).iloc[0]
    assert row["ttc_s"] == pytest.approx(ttc_s, abs=1e-9) and row["ttc_time_s"] == ttc_time_s
    assert not row["collision"]
    assert row["fcd_period_s"] == pytest.approx(step_s, abs=1e-9)
    assert row["vehicle_turn_deg"] == pytest.approx(90.0, abs=1e-9)
    assert bool(row["uncertain"]) is uncertain
