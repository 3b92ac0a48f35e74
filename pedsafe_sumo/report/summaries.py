"""What the figures show, computed without drawing: binned means, the 90% detection distance, the case pair.

Every function here is pure (DataFrames and arrays in, numbers out) so that the figures' numbers can
be tested without looking at pixels; `figures.py` only draws them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from pedsafe_sumo.report.rundir import RunDirectory

MPS_TO_KMH = 3.6  # [km/h per m/s]
OK_STATUS = "ok"
ONBOARD_COLUMNS = ("detected_onboard_camera", "detected_onboard_lidar")
ROADSIDE_COLUMN = "detected_roadside"
#: The scenario of the paper's injury (S-curve) and case figures.
CASE_SCENARIO = "jaywalking"


def ok_episodes(episodes: pd.DataFrame) -> pd.DataFrame:
    """The episodes that ran (status "ok"); errors are counted in Table I and left out of the figures."""
    return episodes[episodes["status"] == OK_STATUS]


# ------------------------------------------------------------ binned means
def quantile_edges(values, n_bins: int) -> np.ndarray:
    """Edges of up to n_bins bins holding about equal numbers of the finite values (their quantiles).

    Equal-count bins suit the skewed initial speeds (lognormal) and the discrete ages: every bin's
    mean rests on about as many episodes. Repeated quantiles (many equal values) merge bins; all values
    equal give one bin.
    """
    values = np.asarray(values, dtype=float)
    values = values[np.isfinite(values)]
    if values.size == 0:
        return np.array([0.0, 1.0])
    edges = np.unique(np.quantile(values, np.linspace(0.0, 1.0, n_bins + 1)))
    if edges.size < 2:
        return np.array([edges[0] - 0.5, edges[0] + 0.5])
    return edges


def binned_mean(x, y, edges) -> pd.DataFrame:
    """Mean of y in bins of x: columns x_mean (mean x of the bin's members), mean, n; empty bins left out.

    Bins are [edge_i, edge_i+1), the last one closed, so the maximum falls in the last bin; values
    outside the edges or not finite are left out.
    """
    x, y, edges = (np.asarray(a, dtype=float) for a in (x, y, edges))
    keep = np.isfinite(x) & np.isfinite(y) & (x >= edges[0]) & (x <= edges[-1])
    x, y = x[keep], y[keep]
    index = np.clip(np.searchsorted(edges, x, side="right") - 1, 0, len(edges) - 2)
    rows = []
    for i in range(len(edges) - 1):
        members = index == i
        if members.any():
            rows.append(
                {
                    "x_mean": float(x[members].mean()),
                    "mean": float(y[members].mean()),
                    "n": int(members.sum()),
                }
            )
    return pd.DataFrame(rows, columns=["x_mean", "mean", "n"])


# ------------------------------------------------------- detection distance
def distance_detected_by_share(distances_m, share_percent: int = 90) -> float:
    """The largest distance X such that at least `share_percent` % of the episodes first detect the
    pedestrian at X or farther: the paper's "V2I detects beyond 13 m in 90% of episodes".

    Never-detected episodes (NaN) count as not detected at any distance, so they stay in the
    denominator. X is the k-th smallest value (0-based) with k = floor(n (100 - share) / 100); it is
    -inf when fewer than `share_percent` % of the episodes detect at all, NaN without episodes.
    """
    d = np.asarray(distances_m, dtype=float)
    n = d.size
    if n == 0:
        return math.nan
    d = np.sort(np.where(np.isnan(d), -np.inf, d))
    k = (n * (100 - share_percent)) // 100
    return float(d[k])


@dataclass(frozen=True)
class DetectionSummary:
    scenario: str
    condition: str
    #: first-detection distances of the detected episodes, m
    distances_m: np.ndarray
    n: int
    n_never: int
    #: `distance_detected_by_share(..., 90)`, m
    distance_90_m: float


def detection_summaries(episodes: pd.DataFrame) -> list[DetectionSummary]:
    """Per scenario and condition (sv before v2i), the first-detection distances of the ok episodes."""
    ok = ok_episodes(episodes)
    out = []
    for scenario in pd.unique(ok["scenario"]):
        for condition in sorted(
            pd.unique(ok.loc[ok["scenario"] == scenario, "condition"]), key=_condition_key
        ):
            d = ok.loc[
                (ok["scenario"] == scenario) & (ok["condition"] == condition), "first_detection_distance_m"
            ]
            d = d.to_numpy(dtype=float)
            out.append(
                DetectionSummary(
                    str(scenario),
                    str(condition),
                    d[np.isfinite(d)],
                    int(d.size),
                    int(np.isnan(d).sum()),
                    distance_detected_by_share(d, 90),
                )
            )
    return out


def _condition_key(condition: str) -> tuple[int, str]:
    return ({"sv": 0, "v2i": 1}.get(condition, 2), str(condition))


# ---------------------------------------------------------------- case pair
@dataclass(frozen=True)
class CasePair:
    scenario: str
    episode: int
    seed: int
    #: first perception time (episodes.parquet first_detection_time_s), s; NaN if never perceived
    sv_first_detection_s: float
    v2i_first_detection_s: float
    sv_collision: bool
    v2i_collision: bool

    @property
    def gap_s(self) -> float:
        """How much earlier V2I perceived the pedestrian than SV (+inf when SV never did)."""
        return _gap(self.sv_first_detection_s, self.v2i_first_detection_s)


def _gap(sv_s: float, v2i_s: float) -> float:
    if math.isnan(sv_s) and math.isnan(v2i_s):
        return math.nan
    return (math.inf if math.isnan(sv_s) else sv_s) - (math.inf if math.isnan(v2i_s) else v2i_s)


def choose_case_pair(run: RunDirectory, preferred_scenario: str = CASE_SCENARIO) -> CasePair | None:
    """The paired episode for the case figure, or None when no pair has both case files.

    A candidate is an episode whose SV and V2I rows are both "ok" and whose two case logs
    (`cases/<scenario>_<condition>_<seed>.parquet`) both exist. Among the candidates of
    `preferred_scenario` (else of the first scenario of the run that has one), the pair where V2I
    perceived the pedestrian earliest relative to SV wins: the largest first_detection_time_s(SV) -
    first_detection_time_s(V2I), where never perceived counts as perceived at +inf (so an SV run that
    never saw the pedestrian beats any finite gap, and pairs where neither saw come last). Ties go to the
    smallest episode number.
    """
    ok = ok_episodes(run.episodes)
    sides = [
        ok[ok["condition"] == c].set_index(["scenario", "episode"])[
            ["seed", "first_detection_time_s", "collision"]
        ]
        for c in ("sv", "v2i")
    ]
    pairs = (
        sides[0]
        .merge(sides[1], how="inner", left_index=True, right_index=True, suffixes=("_sv", "_v2i"))
        .reset_index()
    )
    if pairs.empty:
        return None
    kept = {p.name for p in run.cases_dir.glob("*.parquet")} if run.cases_dir.is_dir() else set()
    candidates = []
    for r in pairs.itertuples(index=False):
        if int(r.seed_sv) != int(r.seed_v2i):
            continue  # not the same initial world: not a pair
        if not all(run.case_path(r.scenario, c, r.seed_sv).name in kept for c in ("sv", "v2i")):
            continue
        candidates.append(
            CasePair(
                str(r.scenario),
                int(r.episode),
                int(r.seed_sv),
                float(r.first_detection_time_s_sv),
                float(r.first_detection_time_s_v2i),
                bool(r.collision_sv),
                bool(r.collision_v2i),
            )
        )
    if not candidates:
        return None
    scenarios = [c.scenario for c in candidates]
    scenario = preferred_scenario if preferred_scenario in scenarios else scenarios[0]
    chosen = [c for c in candidates if c.scenario == scenario]

    def rank(pair: CasePair) -> tuple[int, float, int]:
        gap = pair.gap_s
        return (1, 0.0, pair.episode) if math.isnan(gap) else (0, -gap, pair.episode)

    return min(chosen, key=rank)


@dataclass(frozen=True)
class CaseTrace:
    condition: str
    frame: np.ndarray
    speed_kmh: np.ndarray
    #: frame of the first step with an onboard (camera or LiDAR) detection; None if none
    first_onboard_frame: int | None
    #: frame of the first step with a roadside detection reaching the vehicle (V2I only); None if none
    first_roadside_frame: int | None
    collision: bool
    #: simulation time of each logged step, s (the figure's axis)
    time_s: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def time_of_frame(self, frame: int | None) -> float | None:
        """The logged time of `frame` (None for None)."""
        if frame is None:
            return None
        return float(self.time_s[int(np.flatnonzero(self.frame == frame)[0])])


def frames_of(time_s) -> np.ndarray:
    """Simulation frame numbers of the logged steps: time / step length, the step length being the
    median time difference of the log (the log skips no step, but may start after t = 0)."""
    t = np.asarray(time_s, dtype=float)
    if t.size < 2:
        return np.arange(t.size)
    step_s = float(np.median(np.diff(t)))
    return np.rint(t / step_s).astype(int)


def _first_frame(frames: np.ndarray, flags: np.ndarray) -> int | None:
    hits = np.flatnonzero(flags)
    return int(frames[hits[0]]) if hits.size else None


def case_trace(log: pd.DataFrame, condition: str, collision: bool) -> CaseTrace:
    """Speed against frame of one case log, with its first onboard and first roadside detection frames."""
    frames = frames_of(log["time_s"])
    onboard = np.zeros(len(log), dtype=bool)
    for column in ONBOARD_COLUMNS:
        if column in log.columns:
            onboard |= log[column].to_numpy(dtype=bool)
    roadside = (
        log[ROADSIDE_COLUMN].to_numpy(dtype=bool)
        if ROADSIDE_COLUMN in log.columns
        else np.zeros(len(log), bool)
    )
    return CaseTrace(
        condition,
        frames,
        log["ego_speed_mps"].to_numpy(dtype=float) * MPS_TO_KMH,
        _first_frame(frames, onboard),
        _first_frame(frames, roadside),
        collision,
        log["time_s"].to_numpy(dtype=float),
    )


def load_case_traces(run: RunDirectory, pair: CasePair) -> list[CaseTrace]:
    """The SV and V2I traces of a case pair, read from DIR/cases (the logs only; no SUMO needed)."""
    collisions = {"sv": pair.sv_collision, "v2i": pair.v2i_collision}
    return [
        case_trace(
            pd.read_parquet(run.case_path(pair.scenario, c, pair.seed), partitioning=None), c, collisions[c]
        )
        for c in ("sv", "v2i")
    ]
