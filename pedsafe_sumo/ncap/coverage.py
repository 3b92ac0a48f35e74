"""What a run covers of the 2026 pedestrian protocol, and what it does not: the one summary line.

The calculator's pedestrian protocol is the frontal tests (CPNA, CPFA, CPNCO, CPLA day and night, CPTA),
their robustness layers, and the low-speed tests (CPMRCm, CPMRCs, CPMFC). Some of it the engine cannot
stage; those parts are refused here with why, and every summary lists them as missing: no run of this
suite is a whole 2026 rating.
"""

from __future__ import annotations

import pandas as pd

from pedsafe_sumo.ncap.protocol import Protocol

#: The calculator's low-speed pedestrian load cases ([CALC] STAGE_SUBELEMENT_TO_LOADCASES "LSC"), refused.
REFUSED_TESTS = {
    "CPMRCm, CPMRCs": (
        "the ego reversing: SUMO drives no negative speed (setSpeed(-2) leaves the ego moving forwards under "
        "its car-following model) and the agent interface refuses a negative target speed"
    ),
    "CPMFC": (
        "the ego moving off from standstill: the staging starts the ego at its test speed on a fixed "
        "collision course; a start from rest, timed by the stack's own acceleration, is not staged"
    ),
}

#: Robustness layers of the calculator's pool ([CALC] test_info.FC_ROBUSTNESS_LAYERS_POOL) that apply to a
#: pedestrian test but the engine cannot stage.
REFUSED_LAYERS = {
    "Driver input pre-crash": (
        "the AD stack is the driver: the engine has no separate driver whose steer and throttle act "
        "before the crash"
    ),
}


#: Layers the calculator applies to a pedestrian test outside its test pool (never verified by a test, so
#: a maker's claim stands); a simulation has no claim to stand on, so they earn nothing here.
UNSTAGED_LAYERS = (
    "Illumination (Sun glare)",
    "Infrastructure / Clutter",
    "Obscuration / Obstruction",
    "Illumination (Night)",
)


def missing_cells(protocol: Protocol, table: pd.DataFrame) -> list[str]:
    """'TEST LIGHTING (n of N cells)' for every load case not fully run without error under every
    condition of the run, in protocol order."""
    nominal = table[table["variation"] == "nominal"]
    conditions = set(nominal["condition"])
    missing = []
    for name, test in protocol.tests.items():
        grid = {(turn, speed, pct) for turn, speed in test.rows for pct in test.impact_points_pct}
        for lighting in test.lightings:
            rows = nominal[(nominal["test"] == name) & (nominal["lighting"] == lighting)]
            ok = rows[rows["status"] == "ok"]
            ran = None
            for condition in conditions or {""}:
                these = ok[ok["condition"] == condition]
                cells = set(zip(these["turn"].fillna(""), these["ego_speed_kmh"], these["impact_point_pct"]))
                ran = cells if ran is None else ran & cells
            absent = len(grid - (ran or set()))
            if absent:
                missing.append(f"{name} {lighting} ({absent} of {len(grid)} cells)")
    return missing


def grid_summary(protocol: Protocol, table: pd.DataFrame) -> str:
    """One line: whether the grid is partial (it always is: REFUSED_*), what is missing and why."""
    parts = missing_cells(protocol, table)
    if not (table["variation"] != "nominal").any():
        parts.append("robustness layers (not run: --robustness)")
    else:
        parts.append(
            f"robustness layers {', '.join(UNSTAGED_LAYERS)} (not staged: outside the calculator's test pool)"
        )
    parts += [f"robustness layer {layer} (refused: {why})" for layer, why in REFUSED_LAYERS.items()]
    parts += [f"{tests} (refused: {why})" for tests, why in REFUSED_TESTS.items()]
    return "ncap: PARTIAL grid, points are partial (not a 2026 rating); missing: " + "; ".join(parts)
