"""The Euro NCAP pedestrian test grid (protocol.toml beside this module) as frozen data.

A *cell* is one test run: a test (CPNA, CPFA, CPNCO, CPLA), an ego (VUT) test speed and an impact point
on the ego's front; `--tests` and `--speeds` select cells. A test name alone selects all its columns,
`TEST-PCT` one column (the v4.x names: CPNA-25, CPNA-75, CPFA-50, CPNCO-50, CPLA-25, CPLA-50).
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib

PROTOCOL_PATH = Path(__file__).with_name("protocol.toml")
COLOURS = ("green", "yellow", "orange", "brown", "red")
APPROACHES = ("nearside", "farside", "longitudinal", "turning")
CRITERIA = ("mitigation_or_avoidance", "avoidance")
PLACEMENTS = ("crosswalk", "midblock")
KMH_PER_MPS = 3.6
LIGHTINGS = ("day", "night")
ROBUSTNESS_CRITERIA = ("not_red", "same_or_better")


class NcapError(ValueError):
    """A bad --tests / --speeds selection or protocol value; the message is one line."""


@dataclass(frozen=True)
class Dummy:
    name: str
    height_m: float
    width_m: float
    depth_m: float
    age_years: float
    clothing_rgb: tuple[int, int, int]

    @property
    def radius_m(self) -> float:
        """The engine's pedestrian is a circle: half the shoulder width."""
        return self.width_m / 2


@dataclass(frozen=True)
class NcapTest:
    name: str
    description: str
    dummy: Dummy
    ped_speed_kmh: float
    approach: str
    placement: str
    obstructed: bool
    #: The grid's rows: (turn, ego speed km/h); turn is "" except in the turning tests ("farside": a
    #: left turn across the traffic, "nearside": a right turn).
    rows: tuple[tuple[str, float], ...]
    impact_points_pct: tuple[float, ...]
    #: Standard-range cells, as columns (every row) or as (turn, speed, pct) cells; the rest are extended.
    standard_pct: tuple[float, ...]
    standard_cells: tuple[tuple[str, float, float], ...]
    points_standard: float
    points_extended: float
    #: "mitigation_or_avoidance" (colour bands by impact speed) or "avoidance" (green only if avoided).
    criterion: str = "mitigation_or_avoidance"
    #: Turning tests: the dummy walks the exit's crosswalk in the "same" direction as the ego's initial
    #: heading or the "opposite" one.
    direction: str = ""
    #: The lightings the calculator has a load case of this test in ("day"; "night" too for CPNA, CPFA,
    #: CPNCO, CPLA: "CPNA day" and "CPNA night"), each with the same grid and points.
    lightings: tuple[str, ...] = ("day",)

    @property
    def speeds_kmh(self) -> tuple[float, ...]:
        return tuple(dict.fromkeys(speed for _, speed in self.rows))

    def test_range(self, impact_point_pct: float, turn: str = "", speed_kmh: float | None = None) -> str:
        """ "standard" or "extended": which range of the test's points a cell counts in."""
        if self.standard_cells:
            return "standard" if (turn, speed_kmh, impact_point_pct) in self.standard_cells else "extended"
        return "standard" if impact_point_pct in self.standard_pct else "extended"


@dataclass(frozen=True)
class Variation:
    """A robustness variation of the dummy; the nominal run has all zeros."""

    name: str = "nominal"
    speed_delta_kmh: float = 0.0
    heading_delta_deg: float = 0.0
    start_offset_m: float = 0.0
    #: The dummy starts this share of its walk to the impact point nearer (-0.25: 25 % nearer).
    start_share: float = 0.0
    #: The calculator's robustness layer ("Speed", "Initial position offset", "Trajectory/Heading").
    layer: str = ""
    #: test name -> "not_red" or "same_or_better"; the variation applies to these tests only.
    criteria: tuple[tuple[str, str], ...] = ()

    def criterion(self, test: str) -> str | None:
        return dict(self.criteria).get(test)


NOMINAL = Variation()


@dataclass(frozen=True)
class Cell:
    test: NcapTest
    ego_speed_kmh: float
    impact_point_pct: float
    variation: Variation = NOMINAL
    turn: str = ""
    #: "day" or "night" (the onboard camera's night model, ncap/night.py).
    lighting: str = "day"

    @property
    def test_range(self) -> str:
        return self.test.test_range(self.impact_point_pct, self.turn, self.ego_speed_kmh)

    @property
    def cell_id(self) -> str:
        """Unique, file-name safe: CPNA-25_30kmh, CPTAsame-50_farside10kmh (and _speed+3 etc. for a
        robustness run)."""
        base = f"{self.test.name}-{_num(self.impact_point_pct)}_{self.turn}{_num(self.ego_speed_kmh)}kmh"
        if self.lighting != "day":
            base = f"{base}_{self.lighting}"
        return base if self.variation is NOMINAL else f"{base}_{self.variation.name}"


@dataclass(frozen=True)
class Protocol:
    tests: dict[str, NcapTest]
    bands: dict[float, tuple[tuple[str, float], ...]]
    cell_scores: dict[str, float]
    tolerance_kmh: float
    start_ttc_s: float
    time_after_impact_s: float
    midblock_distance_m: float
    obstruction: dict[str, Any]
    robustness: tuple[Variation, ...]
    raw: dict[str, Any]
    #: Brake onset: the commanded deceleration [m/s2] whose first step marks it (metrics.cell_metrics).
    brake_onset_decel_mps2: float = 1.0


def _num(value: float) -> str:
    return str(int(value)) if float(value).is_integer() else f"{value:g}"


@lru_cache(maxsize=2)
def load_protocol(path: Path = PROTOCOL_PATH) -> Protocol:
    raw = tomllib.loads(Path(path).read_text(encoding="utf-8"))
    dummies = {
        name: Dummy(name=name, **{**values, "clothing_rgb": tuple(values["clothing_rgb"])})
        for name, values in raw["dummies"].items()
    }
    tests = {}
    for name, t in raw["tests"].items():
        test = NcapTest(
            name=name,
            description=t["description"],
            dummy=dummies[t["dummy"]],
            ped_speed_kmh=float(t["ped_speed_kmh"]),
            approach=t["approach"],
            placement=t["placement"],
            obstructed=bool(t["obstructed"]),
            rows=tuple((str(turn), float(speed)) for turn, speed in t["rows"])
            if "rows" in t
            else tuple(("", float(speed)) for speed in t["speeds_kmh"]),
            impact_points_pct=tuple(float(p) for p in t["impact_points_pct"]),
            standard_pct=tuple(float(p) for p in t.get("standard_pct", ())),
            standard_cells=tuple((str(a), float(b), float(c)) for a, b, c in t.get("standard_cells", ())),
            points_standard=float(t["points_standard"]),
            points_extended=float(t["points_extended"]),
            criterion=t.get("criterion", "mitigation_or_avoidance"),
            direction=t.get("direction", ""),
            lightings=tuple(t.get("lightings", ("day",))),
        )
        if test.approach not in APPROACHES or test.placement not in PLACEMENTS:
            raise NcapError(f"protocol test {name}: unknown approach or placement")
        if not set(test.standard_pct) <= set(test.impact_points_pct):
            raise NcapError(f"protocol test {name}: standard_pct not among impact_points_pct")
        if test.criterion not in CRITERIA:
            raise NcapError(f"protocol test {name}: unknown criterion '{test.criterion}'")
        if (test.approach == "turning") != (test.direction in ("same", "opposite")):
            raise NcapError(
                f"protocol test {name}: a turning test, and only one, has direction same|opposite"
            )
        if not test.lightings or not set(test.lightings) <= set(LIGHTINGS) or test.lightings[0] != "day":
            raise NcapError(f"protocol test {name}: lightings must start with day and be among {LIGHTINGS}")
        tests[name] = test
    bands = {
        float(vut): tuple((str(colour), float(upper)) for colour, upper in edges)
        for vut, edges in raw["bands"].items()
    }
    for edges in bands.values():
        if edges[-1] != ("red", math.inf) or any(c not in COLOURS for c, _ in edges):
            raise NcapError("protocol bands: every list ends with red to inf and names known colours")
    rob = raw["robustness"]
    variations = tuple(
        Variation(
            name=v["name"],
            speed_delta_kmh=float(v.get("speed_delta_kmh", 0.0)),
            heading_delta_deg=float(v.get("heading_delta_deg", 0.0)),
            start_share=float(v.get("start_share", 0.0)),
            layer=v["layer"],
            criteria=tuple((str(t), str(c)) for t, c in v["criterion"].items()),
        )
        for v in rob["variations"]
    )
    for v in variations:
        if not set(dict(v.criteria)) <= set(tests) or not set(dict(v.criteria).values()) <= set(
            ROBUSTNESS_CRITERIA
        ):
            raise NcapError(f"protocol robustness {v.name}: unknown test or criterion")
    timing = raw["timing"]
    return Protocol(
        tests=tests,
        bands=bands,
        cell_scores={c: float(raw["cell_scores"][c]) for c in COLOURS},
        tolerance_kmh=float(raw["tolerance"]["impact_speed_kmh"]),
        start_ttc_s=float(timing["start_ttc_s"]),
        time_after_impact_s=float(timing["time_after_impact_s"]),
        midblock_distance_m=float(timing["midblock_distance_m"]),
        obstruction=dict(raw["obstruction"]),
        robustness=variations,
        raw=raw,
        brake_onset_decel_mps2=float(raw["metrics"]["brake_onset_decel_mps2"]),
    )


def robustness_of(protocol: Protocol, test: NcapTest) -> tuple[Variation, ...]:
    """The robustness variations that apply to a test (those with a criterion for it)."""
    return tuple(v for v in protocol.robustness if v.criterion(test.name) is not None)


def parse_speeds(text: str | None) -> tuple[float, ...] | None:
    """'10,20,30' -> (10.0, 20.0, 30.0); None keeps every speed of each test's grid."""
    if text is None:
        return None
    speeds = []
    for part in text.split(","):
        try:
            value = float(part)
        except ValueError:
            raise NcapError(f"--speeds: '{part.strip()}' is not a number (km/h, comma-separated)") from None
        if not math.isfinite(value) or value <= 0:
            raise NcapError(f"--speeds: {part.strip()} km/h is not a positive speed")
        speeds.append(value)
    return tuple(speeds)


def select_cells(
    protocol: Protocol,
    tests: str | None = None,
    speeds_kmh: tuple[float, ...] | None = None,
    robustness: bool = False,
    lightings: tuple[str, ...] = ("day",),
) -> list[Cell]:
    """The cells of `tests` ('CPNA,CPFA-50'; None: every test) at `speeds_kmh` (None: each grid's), in
    each of `lightings` the test has a load case in (a night-only selection skips the day-only tests).

    A speed outside a selected test's grid is an error: the protocol has no such cell.
    """
    unknown = [lighting for lighting in lightings if lighting not in LIGHTINGS]
    if unknown or not lightings:
        raise NcapError(f"--lighting must be day, night or both, got '{','.join(lightings)}'")
    wanted: dict[str, set[float] | None] = {}
    names = [t.strip() for t in tests.split(",")] if tests else list(protocol.tests)
    for token in names:
        name, _, pct = token.partition("-")
        test = protocol.tests.get(name)
        if test is None:
            raise NcapError(f"--tests: unknown test '{token}' (known: {', '.join(protocol.tests)})")
        if not pct:
            wanted[name] = None
            continue
        try:
            value = float(pct)
        except ValueError:
            raise NcapError(f"--tests: '{token}' should be TEST or TEST-PCT, e.g. CPNA-25") from None
        if value not in test.impact_points_pct:
            columns = ", ".join(_num(p) for p in test.impact_points_pct)
            raise NcapError(f"--tests: {name} has no {_num(value)} % column (it has: {columns})")
        if name not in wanted or wanted[name] is not None:
            wanted.setdefault(name, set()).add(value)
    cells = []
    for name, columns in wanted.items():
        test = protocol.tests[name]
        speeds = speeds_kmh if speeds_kmh is not None else test.speeds_kmh
        outside = [s for s in speeds if s not in test.speeds_kmh]
        if outside:
            grid = ", ".join(_num(s) for s in test.speeds_kmh)
            raise NcapError(f"--speeds: {name} has no {_num(outside[0])} km/h row (its grid: {grid})")
        for lighting in (lighting for lighting in lightings if lighting in test.lightings):
            for turn, speed in test.rows:
                if speed not in speeds:
                    continue
                for pct in test.impact_points_pct:
                    if columns is not None and pct not in columns:
                        continue
                    cells.append(Cell(test, speed, pct, turn=turn, lighting=lighting))
                    # The calculator's night load cases have no robustness points (TOTAL_SCORES None).
                    if robustness and lighting == "day":
                        cells += [Cell(test, speed, pct, v, turn) for v in robustness_of(protocol, test)]
    return cells
