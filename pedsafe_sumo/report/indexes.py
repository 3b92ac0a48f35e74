"""The report's checks of the indexes themselves, per scenario and condition, as DataFrames.

- stationary contacts: `contact_stationary` (contact while the ego stands: neither a collision nor an
  injury in Table I), counted;
- our `collision` against SUMO's own `sumo_collision`, on the rows where SUMO can see (not null; null
  where it cannot, e.g. mid-block), with the agreement share;
- the share of episodes where PET is defined, and, from the kept logs, why it is not in the rest;
- the proximity measure (`min_clearance_m`, `ego_speed_at_min_clearance_mps`, `drac_mps2`, `close_pass`).

Every function takes the episodes table (and, for the PET reasons, the logs that were kept) and returns a
table, or None with a one-line note when the run lacks the columns it needs. Only status "ok" rows
count, as in Table I. Nothing here draws or prints.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping

import numpy as np
import pandas as pd

from pedsafe_sumo.io.run_store import MANIFEST_FILE, Manifest, RunStoreError
from pedsafe_sumo.safety import log as steplog
from pedsafe_sumo.safety.episode import steps_with_pedestrian
from pedsafe_sumo.safety.geometry import first_polyline_crossing
from pedsafe_sumo.safety.proximity import ProximityModel
from pedsafe_sumo.safety.stats import wilson_interval

OK_STATUS = "ok"
#: Below this speed a road user counts as standing at the end of a log, m/s (the ego: below it a contact is
#: not a collision, safety.collision.STATIONARY_SPEED_MPS; the same for the pedestrian).
STANDING_SPEED_MPS = 0.1
PROXIMITY_COLUMNS = ("min_clearance_m", "ego_speed_at_min_clearance_mps", "drac_mps2", "close_pass")

#: Why PET is undefined in an episode (`pet_undefined_reason`), in the order the report lists them.
REASON_EGO_STOPPED = "paths never crossed: the ego stood when the log ended"
REASON_PED_STOPPED = "paths never crossed: the pedestrian stood when the log ended"
REASON_ENDED = "paths never crossed: both still moving when the log ended"
REASON_NOT_REACHED = "paths crossed, but a road user's body never covered the point"
REASON_NO_LOG = "no log kept (run the batch with --keep-logs all)"
PET_REASONS = (REASON_EGO_STOPPED, REASON_PED_STOPPED, REASON_ENDED, REASON_NOT_REACHED, REASON_NO_LOG)


def _ok(episodes: pd.DataFrame) -> pd.DataFrame:
    return episodes[episodes["status"] == OK_STATUS]


def _groups(episodes: pd.DataFrame):
    """(scenario, condition, rows) in order of first appearance of the scenario, sv before v2i."""
    order = {"sv": 0, "v2i": 1}
    for scenario in pd.unique(episodes["scenario"]):
        rows = episodes[episodes["scenario"] == scenario]
        for condition in sorted(pd.unique(rows["condition"]), key=lambda c: (order.get(c, 2), str(c))):
            yield str(scenario), str(condition), rows[rows["condition"] == condition]


def _flags(column: pd.Series) -> np.ndarray:
    return column.astype("boolean").fillna(False).to_numpy(dtype=bool)


def missing_note(episodes: pd.DataFrame, columns: tuple[str, ...], what: str) -> str:
    """'' when every column is there, else one line naming what is missing and what is left out."""
    missing = [c for c in columns if c not in episodes.columns]
    if not missing:
        return ""
    return f"note: no {', '.join(missing)} in this run (written without these columns): {what} left out"


# ---------------------------------------------------------------- stationary contacts
def stationary_contacts(episodes: pd.DataFrame) -> pd.DataFrame | None:
    """Per scenario and condition: n, contact_stationary (episodes with a contact while the ego stood),
    collision (the ego striking the pedestrian). None without the column."""
    if "contact_stationary" not in episodes.columns:
        return None
    rows = []
    for scenario, condition, group in _groups(_ok(episodes)):
        rows.append(
            {
                "scenario": scenario,
                "condition": condition,
                "n": len(group),
                "contact_stationary": int(_flags(group["contact_stationary"]).sum()),
                "collision": int(_flags(group["collision"]).sum()),
            }
        )
    return pd.DataFrame(rows, columns=["scenario", "condition", "n", "contact_stationary", "collision"])


# ---------------------------------------------------------------- our collision against SUMO's
AGREEMENT_COLUMNS = (
    "scenario",
    "condition",
    "n",
    "sumo_null",
    "compared",
    "both",
    "ours_only",
    "sumo_only",
    "neither",
    "agreement",
)


def collision_agreement(episodes: pd.DataFrame) -> pd.DataFrame | None:
    """Per scenario and condition, and a last row "all": our `collision` against `sumo_collision` on the
    rows where SUMO's value is not null (`sumo_null` counts the others: places SUMO cannot see).
    agreement = (both + neither) / compared, NaN when nothing is compared. None without the column."""
    if "sumo_collision" not in episodes.columns:
        return None
    rows = []
    ok = _ok(episodes)
    for scenario, condition, group in [*_groups(ok), ("all", "all", ok)]:
        sumo = group["sumo_collision"].astype("boolean")
        seen = sumo.notna().to_numpy()
        ours = _flags(group["collision"])[seen]
        theirs = sumo[seen].to_numpy(dtype=bool)
        both, ours_only = int(np.sum(ours & theirs)), int(np.sum(ours & ~theirs))
        sumo_only, neither = int(np.sum(~ours & theirs)), int(np.sum(~ours & ~theirs))
        compared = int(seen.sum())
        rows.append(
            {
                "scenario": scenario,
                "condition": condition,
                "n": len(group),
                "sumo_null": len(group) - compared,
                "compared": compared,
                "both": both,
                "ours_only": ours_only,
                "sumo_only": sumo_only,
                "neither": neither,
                "agreement": (both + neither) / compared if compared else math.nan,
            }
        )
    return pd.DataFrame(rows, columns=list(AGREEMENT_COLUMNS))


def sumo_collision_is_nullable(episodes: pd.DataFrame) -> bool:
    """Whether the run can say 'SUMO cannot see' (a nullable column): a run without it holds a plain
    boolean, False also where SUMO could not have seen a collision."""
    column = episodes["sumo_collision"]
    # An error row's missing value says nothing: only rows that ran can hold SUMO's "cannot see".
    return str(column.dtype) == "boolean" or bool(_ok(episodes)["sumo_collision"].isna().any())


# ---------------------------------------------------------------- PET
def pet_undefined_reason(log) -> str:
    """Why PET is undefined in a log (one of PET_REASONS), from the trajectories alone.

    PET needs the driven and walked centre paths to cross (surrogates.pet_s). When they do not, the log
    says who stood at its end (speed below STANDING_SPEED_MPS: the ego first, as a yielding ego decides
    the encounter), or that both were still moving, i.e. the episode ended before their paths met.
    """
    a = steplog.as_arrays(steps_with_pedestrian(log))
    if first_polyline_crossing(a[steplog.EGO_X], a[steplog.EGO_Y], a[steplog.PED_X], a[steplog.PED_Y]):
        return REASON_NOT_REACHED
    if a[steplog.EGO_SPEED][-1] < STANDING_SPEED_MPS:
        return REASON_EGO_STOPPED
    if math.hypot(a[steplog.PED_VX][-1], a[steplog.PED_VY][-1]) < STANDING_SPEED_MPS:
        return REASON_PED_STOPPED
    return REASON_ENDED


LogLookup = Callable[[str, str, int, int], "pd.DataFrame | None"]


def pet_coverage(episodes: pd.DataFrame, find_log: LogLookup | None = None) -> pd.DataFrame:
    """Per scenario and condition: n, pet_defined (count), share, and the undefined ones by reason.

    `find_log(scenario, condition, episode, seed)` returns that episode's log or None (not kept); without
    it every undefined episode counts under REASON_NO_LOG. One column per reason of PET_REASONS.
    """
    rows = []
    for scenario, condition, group in _groups(_ok(episodes)):
        pet = group["pet_s"].to_numpy(dtype=float)
        defined = np.isfinite(pet)
        row: dict = {
            "scenario": scenario,
            "condition": condition,
            "n": len(group),
            "pet_defined": int(defined.sum()),
            "share": float(defined.mean()) if len(group) else math.nan,
        }
        row.update({reason: 0 for reason in PET_REASONS})
        for record in group[~defined].itertuples(index=False):
            log = find_log(scenario, condition, int(record.episode), int(record.seed)) if find_log else None
            row[REASON_NO_LOG if log is None else pet_undefined_reason(log)] += 1
        rows.append(row)
    return pd.DataFrame(rows, columns=["scenario", "condition", "n", "pet_defined", "share", *PET_REASONS])


# ---------------------------------------------------------------- proximity
PROXIMITY_SUMMARY_COLUMNS = (
    "scenario",
    "condition",
    "n",
    "close_pass",
    "close_pass_rate",
    "close_pass_low",
    "close_pass_high",
    "close_pass_not_conflict",
    "min_clearance_median_m",
    "ego_speed_at_min_clearance_median_mps",
    "drac_defined",
    "drac_over_threshold",
    "drac_median_mps2",
)


def proximity_summary(episodes: pd.DataFrame, drac_threshold_mps2: float) -> pd.DataFrame | None:
    """Per scenario and condition, over the episodes without a collision (as Table I's conflicts):

    close_pass (count), its rate with a Wilson 95 % interval, close_pass_not_conflict (close passes the
    Amini conflict flag misses), the medians of min_clearance_m and ego_speed_at_min_clearance_mps,
    drac_defined (episodes where the pedestrian was ever in or entering the ego's path), drac_over_threshold
    (of those, DRAC above `drac_threshold_mps2`) and the median DRAC where defined. n counts every ok
    episode; the rates are over n. None when the run has no proximity columns.
    """
    if any(c not in episodes.columns for c in PROXIMITY_COLUMNS):
        return None
    rows = []
    for scenario, condition, group in _groups(_ok(episodes)):
        n = len(group)
        free = ~_flags(group["collision"])
        passes = _flags(group["close_pass"]) & free
        missed = passes & ~_flags(group["conflict"])
        clearance = group["min_clearance_m"].to_numpy(dtype=float)[free]
        speed = group["ego_speed_at_min_clearance_mps"].to_numpy(dtype=float)[free]
        drac = group["drac_mps2"].to_numpy(dtype=float)[free]
        drac = drac[np.isfinite(drac)]
        low, high = wilson_interval(int(passes.sum()), n)
        rows.append(
            {
                "scenario": scenario,
                "condition": condition,
                "n": n,
                "close_pass": int(passes.sum()),
                "close_pass_rate": passes.sum() / n if n else math.nan,
                "close_pass_low": low,
                "close_pass_high": high,
                "close_pass_not_conflict": int(missed.sum()),
                "min_clearance_median_m": _median(clearance),
                "ego_speed_at_min_clearance_median_mps": _median(speed),
                "drac_defined": int(drac.size),
                "drac_over_threshold": int(np.sum(drac > drac_threshold_mps2)),
                "drac_median_mps2": _median(drac),
            }
        )
    return pd.DataFrame(rows, columns=list(PROXIMITY_SUMMARY_COLUMNS))


def _median(values: np.ndarray) -> float:
    values = values[np.isfinite(values)]
    return float(np.median(values)) if values.size else math.nan


def proximity_model_of_run(run_info: Mapping | None):
    """The proximity thresholds the run was made with (run.json parameters), else the defaults file's."""
    parameters = run_info.get("parameters") if isinstance(run_info, Mapping) else None
    try:
        return ProximityModel.from_params(parameters if isinstance(parameters, Mapping) else None)
    except (KeyError, TypeError, ValueError):
        return ProximityModel.from_params(None)


# ---------------------------------------------------------------- the logs a run kept
class KeptLogs:
    """`find_log` for `pet_coverage`: an episode's log from steplogs/ (--keep-logs all, located through
    the manifest) or else from cases/ (pairs with a collision or a conflict); None when neither kept it.
    Keeps one step-log file in memory at a time."""

    def __init__(self, run) -> None:
        self.run = run
        self.files: list[tuple[str, int, int, str]] = []
        try:
            manifest = Manifest.load(run.path / MANIFEST_FILE)
        except RunStoreError:
            manifest = None
        if manifest is not None:
            self.files = [
                (r.scenario, r.first_episode, r.last_episode, r.steplog_file)
                for r in manifest.chunks.values()
                if r.steplog_file and (run.path / r.steplog_file).is_file()
            ]
        self._loaded: tuple[str, pd.DataFrame] | None = None

    def _steps(self, name: str) -> pd.DataFrame:
        if self._loaded is None or self._loaded[0] != name:
            self._loaded = (name, pd.read_parquet(self.run.path / name, partitioning=None))
        return self._loaded[1]

    def __call__(self, scenario: str, condition: str, episode: int, seed: int) -> pd.DataFrame | None:
        for file_scenario, first, last, name in self.files:
            if file_scenario == scenario and first <= episode <= last:
                steps = self._steps(name)
                log = steps[(steps["condition"] == condition) & (steps["episode"] == episode)]
                if len(log):
                    return log.reset_index(drop=True)
        case = self.run.case_path(scenario, condition, seed)
        if case.is_file():
            return pd.read_parquet(case, partitioning=None)
        return None


# ---------------------------------------------------------------- formatting
def _num(value: float, digits: int = 2) -> str:
    return "n/a" if value is None or not math.isfinite(float(value)) else f"{value:.{digits}f}"


def _label(condition: str) -> str:
    return {"sv": "SV", "v2i": "V2I"}.get(condition, condition)


def contacts_rows(table: pd.DataFrame) -> tuple[list[str], list[list[str]]]:
    header = ["scenario", "condition", "n", "stationary contacts", "collisions"]
    return header, [
        [r.scenario, _label(r.condition), str(r.n), str(r.contact_stationary), str(r.collision)]
        for r in table.itertuples(index=False)
    ]


def agreement_rows(table: pd.DataFrame) -> tuple[list[str], list[list[str]]]:
    header = [
        "scenario",
        "condition",
        "n",
        "SUMO null",
        "compared",
        "both",
        "ours only",
        "SUMO only",
        "neither",
    ]
    header.append("agreement")
    rows = [
        [
            r.scenario,
            _label(r.condition),
            str(r.n),
            str(r.sumo_null),
            str(r.compared),
            str(r.both),
            str(r.ours_only),
            str(r.sumo_only),
            str(r.neither),
            "n/a" if not math.isfinite(r.agreement) else f"{100 * r.agreement:.1f}%",
        ]
        for r in table.itertuples(index=False)
    ]
    return header, rows


PET_REASON_LABELS = {
    REASON_EGO_STOPPED: "ego stood",
    REASON_PED_STOPPED: "pedestrian stood",
    REASON_ENDED: "log ended",
    REASON_NOT_REACHED: "not reached",
    REASON_NO_LOG: "no log",
}


def pet_rows(table: pd.DataFrame) -> tuple[list[str], list[list[str]]]:
    header = ["scenario", "condition", "n", "PET defined", "share", *PET_REASON_LABELS.values()]
    rows = [
        [
            str(r["scenario"]),
            _label(r["condition"]),
            str(r["n"]),
            str(r["pet_defined"]),
            "n/a" if not math.isfinite(r["share"]) else f"{100 * r['share']:.1f}%",
            *(str(r[reason]) for reason in PET_REASON_LABELS),
        ]
        for r in table.to_dict("records")
    ]
    return header, rows


def proximity_rows(table: pd.DataFrame) -> tuple[list[str], list[list[str]]]:
    header = [
        "scenario",
        "condition",
        "n",
        "close passes [95% CI]",
        "not Amini conflicts",
        "median min clearance m",
        "median speed there m/s",
        "DRAC defined",
        "DRAC over threshold",
        "median DRAC m/s2",
    ]
    rows = []
    for r in table.itertuples(index=False):
        interval = (
            f" [{r.close_pass_low:.4f}, {r.close_pass_high:.4f}]" if math.isfinite(r.close_pass_low) else ""
        )
        rows.append(
            [
                r.scenario,
                _label(r.condition),
                str(r.n),
                f"{r.close_pass} ({_num(r.close_pass_rate, 4)}){interval}",
                str(r.close_pass_not_conflict),
                _num(r.min_clearance_median_m),
                _num(r.ego_speed_at_min_clearance_median_mps),
                str(r.drac_defined),
                str(r.drac_over_threshold),
                _num(r.drac_median_mps2),
            ]
        )
    return header, rows
