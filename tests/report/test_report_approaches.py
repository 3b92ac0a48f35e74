"""`report RUN` on a run of several approaches (batch --approach all): every approach reported in full
(DIR/approach_<arm>/), then Table I and the paired tests pooled over the approaches (DIR/tables/,
DIR/report.html, whose page shows every approach's Table I too). A real batch: crossing on Xueqing, every
approach that hosts it, 2 pairs each; every count is checked against episodes.parquet."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest
from test_html_report import parse

from pedsafe_sumo import REPO_ROOT

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def approach_run(tmp_path_factory) -> tuple[Path, str]:
    run = tmp_path_factory.mktemp("approaches") / "run"
    batch = subprocess.run(
        [sys.executable, "-m", "pedsafe_sumo.batch", "--site", "xueqing", "--scenario", "crossing"]
        + ["--approach", "all", "--episodes", "2", "--seed", "3", "--workers", "1", "--out", str(run)],
        capture_output=True,
        text=True,
        cwd=REPO_ROOT,
        timeout=900,
    )
    assert batch.returncode == 0, batch.stderr[-2000:]
    report = subprocess.run(
        [sys.executable, "-m", "pedsafe_sumo.report", str(run)],
        capture_output=True,
        text=True,
        cwd=REPO_ROOT,
        timeout=600,
    )
    assert report.returncode == 0, report.stderr[-2000:]
    return run, report.stdout


def expected_counts(episodes: pd.DataFrame) -> dict[tuple[str, str], tuple[int, int, int]]:
    """(scenario, condition) -> (episodes that ran, collisions, conflicts without a collision)."""
    ok = episodes[episodes["status"] == "ok"]
    counts = {}
    for (scenario, condition), group in ok.groupby(["scenario", "condition"]):
        collision = group["collision"].astype(bool)
        conflict = group["conflict"].astype(bool) & ~collision
        counts[(scenario, condition)] = (len(group), int(collision.sum()), int(conflict.sum()))
    return counts


def table_counts(csv: Path) -> dict[tuple[str, str], tuple[int, int, int]]:
    table = pd.read_csv(csv)
    return {
        (r.scenario, r.condition): (
            int(r.n),
            round(r.collision_rate * r.n),
            round(r.conflict_rate * r.n),
        )
        for r in table.itertuples()
    }


def test_every_approach_and_the_pool_get_table_one(approach_run):
    run, stdout = approach_run
    episodes = pd.read_parquet(run / "episodes.parquet")
    arms = list(pd.unique(episodes["approach"]))
    assert len(arms) >= 2  # Xueqing hosts crossing on more than one approach
    headings = re.findall(r"^== (.*) ==$", stdout, re.M)
    assert headings == [f"approach {arm}" for arm in arms] + [
        f"pooled over approaches {', '.join(arms)} (SV and V2I paired within an approach)"
    ]
    assert stdout.count("Table I: collision rate") == len(arms) + 1
    for arm in arms:
        assert table_counts(run / f"approach_{arm}" / "tables" / "table1.csv") == expected_counts(
            episodes[episodes["approach"] == arm]
        )
        assert (run / f"approach_{arm}" / "report.html").is_file()
    pooled = expected_counts(episodes)
    assert table_counts(run / "tables" / "table1.csv") == pooled
    assert sum(n for n, _, _ in pooled.values()) == len(episodes)


def test_pooled_page_shows_each_approach_and_links_its_page(approach_run):
    run, _ = approach_run
    episodes = pd.read_parquet(run / "episodes.parquet")
    page = (run / "report.html").read_text(encoding="utf-8")
    tables = parse(page)
    assert tables.sections[:2] == ["verdict", "approaches"]
    for arm in pd.unique(episodes["approach"]):
        expected = expected_counts(episodes[episodes["approach"] == arm])
        shown = {(row[0], row[1].lower()): int(row[2]) for row in tables.tables[f"table-one-{arm}"]}
        assert shown == {key: n for key, (n, _, _) in expected.items()}
        assert f'href="approach_{arm}/report.html"' in page
    verdict = {(row[0], row[1].lower()): (int(row[2]), int(row[3])) for row in tables.tables["verdict-rates"]}
    assert verdict == {key: (n, k) for key, (n, k, _) in expected_counts(episodes).items()}
    # the pooled paired test matches SV and V2I within an approach: as many pairs as episodes per condition
    pairs = {row[1]: int(row[2]) for row in tables.tables["paired-tests"]}
    assert pairs == {"collision": len(episodes) // 2, "conflict": len(episodes) // 2}
