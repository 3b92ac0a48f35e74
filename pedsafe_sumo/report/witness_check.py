"""The loop's collision verdict against the independent witness (safety/witness.py) and against SUMO's own.

Per scenario and condition: the episodes, the collisions the loop found (`collision`), those the witness
found (`witness_collision`), and their agreement: both say collision with first contacts within one step of
each other, or both say none. A run written without the witness's columns has it computed from the
episodes' step logs where they were kept (steplogs/ with --keep-logs all, or cases/); an episode without
either is "not recorded" and left out of the agreement. The loop's time of first contact is not a column:
it is read from the step log (safety.collision.detect_collision) where one was kept; without one, two
collision verdicts agree on the verdict alone and the table counts them as "times unchecked".
SUMO's verdict (`sumo_collision`) is counted where SUMO can see (not null). Only status "ok" rows count.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pandas as pd

from pedsafe_sumo.safety.collision import detect_collision
from pedsafe_sumo.safety.log import LogError
from pedsafe_sumo.safety.witness import witness_collision

OK_STATUS = "ok"
WITNESS_COLUMNS = ("witness_collision", "witness_collision_time_s")
NOT_RECORDED = "not recorded"
#: Two first-contact times "within one step" when they differ by at most the log's step plus this, s
#: (the times are logged sums of the step, which carry rounding far below it).
TIME_SLACK_S = 1e-6

LogLookup = Callable[[str, str, int, int], "pd.DataFrame | None"]

WITNESS_TABLE_COLUMNS = (
    "scenario",
    "condition",
    "n",
    "loop_collisions",
    "witness_collisions",
    "not_recorded",
    "compared",
    "agree",
    "agreement",
    "times_unchecked",
    "disagreements",
    "sumo_seen",
    "sumo_collisions",
    "sumo_agrees_with_loop",
)
DISAGREEMENT_COLUMNS = (
    "scenario",
    "condition",
    "episode",
    "seed",
    "loop_collision",
    "loop_time_s",
    "witness_collision",
    "witness_time_s",
    "sumo_collision",
    "why",
)


@dataclass(frozen=True)
class EpisodeCheck:
    #: the witness's verdict, None when neither the row nor a kept log records it
    witness: bool | None
    witness_time_s: float
    #: the loop's first contact time from the kept log (NaN without a log or a collision)
    loop_time_s: float
    step_s: float
    #: "agree", "agree, time unchecked", "not recorded", or why they disagree
    result: str


def _log_step_s(log: pd.DataFrame) -> float:
    times = np.asarray(log["time_s"], dtype=float)
    return float(np.median(np.diff(times))) if len(times) > 1 else math.nan


def check_episode(row, find_log: LogLookup | None) -> EpisodeCheck:
    """The loop's verdict (row.collision) against the witness's (the row's columns, else the kept log)."""
    loop = bool(row["collision"])
    witness: bool | None = None
    witness_time_s = math.nan
    recorded = row.get("witness_collision")
    if recorded is not None and not pd.isna(recorded):
        witness, witness_time_s = bool(recorded), float(row.get("witness_collision_time_s", math.nan))
    log = None
    if find_log is not None and (witness is None or (loop and witness)):
        try:
            log = find_log(str(row["scenario"]), str(row["condition"]), int(row["episode"]), int(row["seed"]))
        except Exception:  # noqa: BLE001 - a broken log file costs this episode's check, not the report
            log = None
    if witness is None:
        try:
            verdict = witness_collision(log) if log is not None else None
        except KeyError:  # a log without the columns the witness reads (a log of another tool)
            verdict = None
        if verdict is None:
            return EpisodeCheck(None, math.nan, math.nan, math.nan, NOT_RECORDED)
        witness, witness_time_s = verdict.collided, verdict.time_s
    if loop != witness:
        why = "only the loop saw a collision" if loop else "only the witness saw a collision"
        return EpisodeCheck(witness, witness_time_s, math.nan, math.nan, why)
    if not loop:
        return EpisodeCheck(witness, witness_time_s, math.nan, math.nan, "agree")
    if log is None:
        return EpisodeCheck(witness, witness_time_s, math.nan, math.nan, "agree, time unchecked")
    try:
        loop_time_s, step_s = detect_collision(log).time_s, _log_step_s(log)
    except (LogError, KeyError):  # a log the loop's check cannot read: the verdicts alone agree
        return EpisodeCheck(witness, witness_time_s, math.nan, math.nan, "agree, time unchecked")
    if abs(loop_time_s - witness_time_s) <= step_s + TIME_SLACK_S:
        return EpisodeCheck(witness, witness_time_s, loop_time_s, step_s, "agree")
    return EpisodeCheck(
        witness,
        witness_time_s,
        loop_time_s,
        step_s,
        f"first contacts {abs(loop_time_s - witness_time_s):.3f} s apart (more than one step, {step_s:g} s)",
    )


def _groups(episodes: pd.DataFrame):
    order = {"sv": 0, "v2i": 1}
    for scenario in pd.unique(episodes["scenario"]):
        rows = episodes[episodes["scenario"] == scenario]
        for condition in sorted(pd.unique(rows["condition"]), key=lambda c: (order.get(c, 2), str(c))):
            yield str(scenario), str(condition), rows[rows["condition"] == condition]


def witness_agreement(
    episodes: pd.DataFrame, find_log: LogLookup | None = None
) -> tuple[pd.DataFrame, pd.DataFrame]:
    """(per scenario and condition, with a last row "all"; the disagreeing episodes). `find_log` gives an
    episode's kept log or None (indexes.KeptLogs)."""
    ok = episodes[episodes["status"] == OK_STATUS]
    checks = {index: check_episode(row, find_log) for index, row in ok.iterrows()}
    rows, disagreements = [], []
    for scenario, condition, group in [*_groups(ok), ("all", "all", ok)]:
        results = [checks[i] for i in group.index]
        recorded = [c for c in results if c.witness is not None]
        agree = sum(c.result.startswith("agree") for c in recorded)
        sumo = group["sumo_collision"].astype("boolean") if "sumo_collision" in group else None
        seen = sumo.notna().to_numpy() if sumo is not None else np.zeros(len(group), dtype=bool)
        loop = group["collision"].astype("boolean").fillna(False).to_numpy(dtype=bool)
        theirs = sumo.fillna(False).to_numpy(dtype=bool) if sumo is not None else loop
        rows.append(
            {
                "scenario": scenario,
                "condition": condition,
                "n": len(group),
                "loop_collisions": int(loop.sum()),
                "witness_collisions": sum(bool(c.witness) for c in recorded),
                "not_recorded": len(results) - len(recorded),
                "compared": len(recorded),
                "agree": agree,
                "agreement": agree / len(recorded) if recorded else math.nan,
                "times_unchecked": sum(c.result == "agree, time unchecked" for c in recorded),
                "disagreements": len(recorded) - agree,
                "sumo_seen": int(seen.sum()),
                "sumo_collisions": int(theirs[seen].sum()),
                "sumo_agrees_with_loop": int(np.sum(theirs[seen] == loop[seen])),
            }
        )
        if scenario == "all":
            continue
        for index, check in zip(group.index, results):
            if check.witness is None or check.result.startswith("agree"):
                continue
            row = group.loc[index]
            sumo_value = sumo.loc[index] if sumo is not None else pd.NA
            disagreements.append(
                {
                    "scenario": scenario,
                    "condition": condition,
                    "episode": int(row["episode"]),
                    "seed": int(row["seed"]),
                    "loop_collision": bool(row["collision"]),
                    "loop_time_s": check.loop_time_s,
                    "witness_collision": check.witness,
                    "witness_time_s": check.witness_time_s,
                    "sumo_collision": None if pd.isna(sumo_value) else bool(sumo_value),
                    "why": check.result,
                }
            )
    return (
        pd.DataFrame(rows, columns=list(WITNESS_TABLE_COLUMNS)),
        pd.DataFrame(disagreements, columns=list(DISAGREEMENT_COLUMNS)),
    )


WITNESS_TITLE = (
    "Collision witness: the loop's collision against an independent check of the same step logs (shapely\n"
    "polygons); agree = both collide with first contacts within one step, or neither collides; not recorded "
    "= no witness column and no kept log; SUMO = its own check, where it can see (sumo_collision not null)"
)
DISAGREEMENTS_TITLE = "Collision witness: the episodes where the loop and the witness disagree"


def _label(condition: str) -> str:
    return {"sv": "SV", "v2i": "V2I"}.get(condition, condition)


def _time(value: float) -> str:
    return "-" if not math.isfinite(value) else f"{value:.2f} s"


def witness_rows(table: pd.DataFrame) -> tuple[list[str], list[list[str]]]:
    header = [
        "scenario",
        "condition",
        "n",
        "loop collisions",
        "witness collisions",
        "compared",
        "agree",
        "agreement",
        "times unchecked",
        "SUMO sees",
        "SUMO collisions",
        "SUMO = loop",
    ]
    rows = []
    for r in table.itertuples(index=False):
        witness = str(r.witness_collisions) if r.compared else NOT_RECORDED
        if r.compared and r.not_recorded:
            witness += f" ({r.not_recorded} {NOT_RECORDED})"
        rows.append(
            [
                r.scenario,
                _label(r.condition),
                str(r.n),
                str(r.loop_collisions),
                witness,
                str(r.compared),
                str(r.agree),
                "n/a" if not math.isfinite(r.agreement) else f"{100 * r.agreement:.1f}%",
                str(r.times_unchecked),
                str(r.sumo_seen),
                str(r.sumo_collisions) if r.sumo_seen else "-",
                str(r.sumo_agrees_with_loop) if r.sumo_seen else "-",
            ]
        )
    return header, rows


def disagreement_rows(table: pd.DataFrame) -> tuple[list[str], list[list[str]]]:
    header = ["scenario", "condition", "episode", "seed", "loop", "witness", "SUMO", "why"]

    def verdict(collided, time_s: float) -> str:
        return f"collision at {_time(time_s)}" if collided else "none"

    rows = [
        [
            r.scenario,
            _label(r.condition),
            str(r.episode),
            str(r.seed),
            verdict(r.loop_collision, r.loop_time_s),
            verdict(r.witness_collision, r.witness_time_s),
            "cannot see" if r.sumo_collision is None or pd.isna(r.sumo_collision) else str(r.sumo_collision),
            r.why,
        ]
        for r in table.itertuples(index=False)
    ]
    return header, rows
