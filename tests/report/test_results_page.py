"""tools/results_page.py: a study's page from its runs, on a hand-made run with known answers."""

from __future__ import annotations

import math
import subprocess
import sys

import pandas as pd
import pytest
from report_runs import episode_row, write_standard_run

from pedsafe_sumo import REPO_ROOT

TOOL = REPO_ROOT / "tools" / "results_page.py"
sys.path.insert(0, str(TOOL.parent))
from results_page import (  # noqa: E402
    collision_timing,
    meets_target,
    sweep_markdown,
    sweep_verdicts_markdown,
)

from pedsafe_sumo.report.findings import findings_table  # noqa: E402


def _wilson(successes: int, n: int, z: float = 1.959964) -> tuple[float, float]:
    p = successes / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z / (1 + z * z / n) * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n))
    return centre - half, centre + half


@pytest.mark.parametrize(
    ("collisions", "n", "met"),
    [
        (48, 2400, True),  # 2.0%: half-width 0.00565 < 0.02 / 3
        (36, 2400, True),  # 1.5%: half-width 0.00492 < 0.005
        (24, 1000, False),  # 2.4% of 1,000: half-width 0.0095, above 0.008 and 0.005
        (0, 2400, True),  # none: half-width 0.0008
        (0, 300, False),  # none of 300: half-width 0.0064
    ],
)
def test_the_precision_target_is_a_third_of_the_rate_or_half_a_percent(collisions, n, met):
    low, high = _wilson(collisions, n)
    assert meets_target(collisions / n, low, high) is met


def test_the_page_holds_the_runs_numbers_beside_the_papers(tmp_path):
    run = write_standard_run(tmp_path / "run")
    page = tmp_path / "page" / "results.md"
    notes = tmp_path / "notes.md"
    notes.write_text("## Mechanisms\n\nWritten by hand.\n")
    proc = subprocess.run(
        [sys.executable, str(TOOL), "--run", f"Standard={run}", "--out", str(page),
         "--figures", str(tmp_path / "page" / "figures"), "--notes", str(notes)],
        capture_output=True, text=True, cwd=REPO_ROOT, timeout=300,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    text = page.read_text()
    low, high = _wilson(3, 10)
    # crossing SV: 3 collisions of 10, the paper's 0.23 beside it, the target not met at n = 10
    assert f"| crossing | SV | 10 | 0.3000 [{low:.4f}, {high:.4f}] | 0.23 | no |" in text
    # the paired test: 3 SV-only collisions, none V2I-only -> p = 2 / 2^3
    assert "| crossing | collision | 10 | 3 | 0 | 0.25 |" in text
    # jaywalking's pair with a V2I error is dropped: 5 SV-only of 10 pairs -> p = 2 / 2^5
    assert "| jaywalking | collision | 10 | 5 | 0 | 0.0625 |" in text
    # at a glance: the same interval under the run's label and condition, the paper's SV and V2I beside it
    head = "| scenario | Standard, SV | Standard, V2I | paper, SV | paper, V2I |"
    assert head in text
    glance = text[text.index(head) :].splitlines()
    crossing = next(line for line in glance if line.startswith("| crossing |"))
    assert crossing.startswith(f"| crossing | 0.3000 [{low:.4f}, {high:.4f}] | ")
    assert crossing.endswith(" | 0.23 | 0.0075 |")
    assert "](figures/standard_first_detection_distance.png)" in text
    assert text.rstrip().endswith("## Mechanisms\n\nWritten by hand.")
    assert (tmp_path / "page" / "figures" / "standard_first_detection_distance.png").stat().st_size > 10_000


def test_a_missing_run_directory_is_one_line_exit_2(tmp_path):
    proc = subprocess.run(
        [sys.executable, str(TOOL), "--run", f"X={tmp_path / 'none'}", "--out", str(tmp_path / "p.md"),
         "--figures", str(tmp_path / "f")],
        capture_output=True, text=True, cwd=REPO_ROOT, timeout=300,
    )  # fmt: skip
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1
    assert not (tmp_path / "p.md").exists()


def _log(contact_after_m: float, perceived_from_s: float | None, step_off_s: float = 1.0) -> pd.DataFrame:
    """An ego at 10 m/s along x, 0.05 s steps; the pedestrian steps off at `step_off_s`; the contact comes
    `contact_after_m` after the step-off's position; perceived from `perceived_from_s` (None: never)."""
    rows = []
    contact_s = step_off_s + contact_after_m / 10.0
    for k in range(int(round((contact_s + 0.5) / 0.05)) + 1):
        t = k * 0.05
        rows.append(
            {
                "time_s": t,
                "ego_x_m": 10.0 * t,
                "ego_y_m": 0.0,
                "ego_speed_mps": 10.0,
                "perceived": perceived_from_s is not None and t >= perceived_from_s - 1e-9,
                "braking": False,
                "clearance_m": 10.0 * (contact_s - t),
                "ped_state": "waiting" if t < step_off_s - 1e-9 else "walking",
            }
        )
    return pd.DataFrame(rows)


def test_a_collision_is_late_when_the_stack_could_not_have_stopped_from_the_step_off():
    # 10 m/s, 0.4 s and 6 m/s2 need 10 * 0.4 + 100 / 12 = 12.33 m.
    late = collision_timing(_log(10.0, 0.0), 0.4, 6.0)
    assert late["kind"] == "late"
    # The distance is counted from the step-off, though the pedestrian was perceived long before it.
    assert late["driven_m"] == pytest.approx(10.0, abs=1e-9)
    assert late["needed_m"] == pytest.approx(12.333333, abs=1e-6)
    in_time = collision_timing(_log(13.0, 0.0), 0.4, 6.0)
    assert in_time["kind"] == "in time"
    # 13 - 12.33 = 0.67 m to spare at 10 m/s: 0.067 s.
    assert in_time["spare_s"] == pytest.approx(0.0666667, abs=1e-6)
    # Perceived 0.2 s after the step-off: 2 m fewer to stop in.
    assert collision_timing(_log(13.0, 1.2), 0.4, 6.0)["kind"] == "late"
    assert collision_timing(_log(13.0, None), 0.4, 6.0)["kind"] == "never"


def _sweep_combination(folder, collisions: dict[tuple[str, str], set[int]], pairs: int = 20):
    """episodes.parquet of one combination: `pairs` paired episodes per scenario, colliding where named."""
    rows = [
        episode_row(
            scenario, condition, episode, collision=episode in collisions.get((scenario, condition), set())
        )
        for scenario in ("crossing", "jaywalking", "background_blending")
        for condition in ("sv", "v2i")
        for episode in range(pairs)
    ]
    folder.mkdir(parents=True)
    pd.DataFrame(rows).to_parquet(folder / "episodes.parquet")


def test_the_sweep_verdicts_name_the_values_where_a_finding_fails(tmp_path):
    sweep = tmp_path / "study-reaction"
    # k=1: crossing SV 8 of 20, V2I none (8 SV-only: p = 2 / 2^8); jaywalking SV 10, V2I 1 of the same
    # (9 SV-only: p = 2 / 2^9); blending SV 1 (p = 1). Every finding holds.
    _sweep_combination(
        sweep / "k=1",
        {("crossing", "sv"): set(range(8)), ("jaywalking", "sv"): set(range(10)),
         ("jaywalking", "v2i"): {0}, ("background_blending", "sv"): {0}},
    )  # fmt: skip
    # k=2: crossing as above; jaywalking SV 2, V2I 3 (V2I worse, 1 V2I-only: p = 1): V2I is not safer
    # everywhere and jaywalking (2) is below crossing (8).
    _sweep_combination(
        sweep / "k=2",
        {("crossing", "sv"): set(range(8)), ("jaywalking", "sv"): {0, 1}, ("jaywalking", "v2i"): {0, 1, 2}},
    )
    findings_table({"k=1": sweep / "k=1", "k=2": sweep / "k=2"}).to_csv(sweep / "findings.csv", index=False)
    running = tmp_path / "study-latency"
    running.mkdir()

    verdicts = sweep_verdicts_markdown([sweep, running]).splitlines()
    assert verdicts[0] == "| finding | study-reaction |"  # the unfinished sweep has no column
    rows = {line.split(" | ")[0].lstrip("| "): line.split(" | ")[1].rstrip(" |") for line in verdicts[2:]}
    assert rows["V2I is safer than SV in every scenario (point estimates; an equal collision rate counts "
                "when V2I's conflict rate is no higher)"] == "fails at 2"  # fmt: skip
    assert rows["jaywalking is the most dangerous of the paper's three scenarios (SV)"] == "fails at 2"
    assert rows["background blending is the safest of them (SV)"] == "holds at every value (2)"
    assert rows["V2I collides significantly less than SV (paired, p < 0.05) in"] == (
        "1: crossing, jaywalking; 2: crossing"
    )
    table = sweep_markdown(sweep)
    assert f"| k=1 | jaywalking | 0.5000 [{_wilson(10, 20)[0]:.4f}, {_wilson(10, 20)[1]:.4f}] | " in table
    assert f"| 9 | 0 | {2 / 2**9:.3g} |" in table
    assert sweep_markdown(running) == "Still running: no combination's verdict yet."
