"""Hosting decided by staging (batch/staging_check.py): a combination the static hosting check lists as
hosted but whose episodes cannot be staged for some seed is skipped with the reason, or refused when named
exactly; never an error row.

The site: SUMO's Ingolstadt network at junction gneJ21 (tests/network/data/sumo_nets/README.md), built with
tools/build_network.py --net. Its own approach's lane next to the kerb is about 27 m long: jaywalking's
occluders, parked along the kerb lane mid-block, do not fit on it, while the static check (geometry and
poles) lists jaywalking as hosted.
"""

from __future__ import annotations

import dataclasses
import json
import re
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pandas as pd
import pytest
from batch_cli import batch

from pedsafe_sumo import REPO_ROOT
from pedsafe_sumo.batch.chunks import episode_seed
from pedsafe_sumo.batch.staging_check import unstageable_units
from pedsafe_sumo.control.baseline import BaselineStack
from pedsafe_sumo.network.sites import resolve_site
from pedsafe_sumo.params import load_params
from pedsafe_sumo.scenarios.hosting import hosting_matrix, site_hosting
from pedsafe_sumo.scenarios.specs import SCENARIOS
from pedsafe_sumo.sim.episode import EpisodeRunner

INGOLSTADT = REPO_ROOT / "tests" / "network" / "data" / "sumo_nets" / "ingolstadt.net.xml.gz"
FAILED = (
    "seed (\\d+): vehicle '(\\w+)' would stand ([0-9.]+) m before the start of its lane (\\S+) "
    "\\(([0-9.]+) m long\\)"
)


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("sites") / "ingolstadt"
    proc = subprocess.run(
        [sys.executable, str(REPO_ROOT / "tools" / "build_network.py"), "--net", str(INGOLSTADT),
         "--junction", "gneJ21", "--out", str(out)],
        capture_output=True, text=True, cwd=REPO_ROOT, timeout=300,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    return out


def _lane_length_m(site: Path, lane_id: str) -> float:
    lane = next(
        lane for lane in ET.parse(site / "ingolstadt.net.xml").iter("lane") if lane.get("id") == lane_id
    )
    return float(lane.get("length"))


def test_the_static_check_lists_it_and_staging_finds_why_not(site):
    params = load_params(None)
    resolved = resolve_site(str(site))
    problems = site_hosting(resolved, {k: SCENARIOS[k] for k in ("crossing", "jaywalking")}, params)
    assert problems == {"crossing": None, "jaywalking": None}  # both listed as hosted
    failed = unstageable_units(resolved, params, {"crossing": SCENARIOS["crossing"],
                                                  "jaywalking": SCENARIOS["jaywalking"]}, 1, 3)  # fmt: skip
    assert list(failed) == ["jaywalking"]
    match = re.fullmatch(FAILED + ": SUMO cannot put it there", failed["jaywalking"])
    assert match, failed["jaywalking"]
    # The seed is episode 0's of run seed 1, the lane and its length those of the network file.
    assert int(match.group(1)) == episode_seed(1, 0)
    assert float(match.group(5)) == pytest.approx(_lane_length_m(site, match.group(4)), abs=0.05)


@pytest.mark.slow
def test_sumo_refuses_what_the_check_refuses(site):
    """The episode the check refuses, run: SUMO does not insert every vehicle of its row (the one the
    check names is put elsewhere, a car behind it not at all)."""
    params = load_params(None)
    resolved = resolve_site(str(site))
    why = unstageable_units(resolved, params, {"jaywalking": SCENARIOS["jaywalking"]}, 1, 1)["jaywalking"]
    seed = re.match(FAILED, why).group(1)
    runner = EpisodeRunner(resolved, params, BaselineStack)
    try:
        with pytest.raises(RuntimeError, match="SUMO did not insert vehicle '(queued|occluder)_\\d+'"):
            runner.run(SCENARIOS["jaywalking"], "sv", int(seed))
    finally:
        runner.close()


def test_named_exactly_it_is_refused_in_one_line(site, tmp_path):
    out = tmp_path / "run"
    proc = batch("--site", str(site), "--scenario", "jaywalking", "--episodes", "2", "--out", str(out))
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in proc.stderr
    assert "site ingolstadt cannot stage scenario 'jaywalking': seed" in lines[0]
    assert "SUMO cannot put it there" in lines[0]
    assert not out.exists()


@pytest.mark.slow
def test_with_all_it_is_skipped_with_the_reason_and_no_row_errs(site, tmp_path):
    out = tmp_path / "run"
    proc = batch("--site", str(site), "--scenario", "all", "--episodes", "1", "--condition", "sv",
                 "--workers", "1", "--out", str(out))  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    skip = [line for line in proc.stdout.splitlines() if "jaywalking" in line]
    assert len(skip) == 1 and skip[0].startswith(
        "skipping scenario 'jaywalking' on site ingolstadt: cannot be staged: seed"
    )
    run = json.loads((out / "run.json").read_text())
    # Under SV alone the static check passes every scenario it can read the geometry of; left_turn, whose
    # oncoming leg this junction lacks (its legs: W, N, NE, S), is found by staging its first episode.
    assert list(run["skipped_unstageable"]) == ["jaywalking", "left_turn"]
    assert "no oncoming traffic for the W approach" in run["skipped_unstageable"]["left_turn"]
    assert "jaywalking" not in run["scenarios"]
    rows = pd.read_parquet(out / "episodes.parquet")
    assert "jaywalking" not in set(rows["scenario"]) and len(rows) == len(run["scenarios"])
    assert (rows["error"].fillna("") == "").all(), rows["error"].tolist()


def test_on_xueqing_jaywalking_from_the_south_is_listed_under_sv_and_cannot_be_staged(tmp_path):
    """Xueqing's south approach: under SV alone (no pole needed) the static check lists jaywalking there,
    but its queue behind the occluder does not fit on the 47 m lane before the stop line, for any seed;
    named, it is refused in one line."""
    params = load_params(None)
    xueqing = resolve_site("xueqing")
    hosted, _ = hosting_matrix(xueqing, {"jaywalking": SCENARIOS["jaywalking"]}, params, ["S"], ["sv"])
    assert hosted == [("jaywalking", "S")]
    spec = dataclasses.replace(SCENARIOS["jaywalking"], approach="S")
    why = unstageable_units(xueqing, params, {"jaywalking@S": spec}, 1, 1)["jaywalking@S"]
    match = re.match(FAILED, why)
    assert match and int(match.group(1)) == episode_seed(1, 0), why
    lanes = ET.parse(xueqing.file("net.xml")).iter("lane")
    assert float(match.group(5)) == pytest.approx(
        float(next(lane for lane in lanes if lane.get("id") == match.group(4)).get("length")), abs=0.05
    )
    out = tmp_path / "run"
    proc = batch("--scenario", "jaywalking", "--approach", "S", "--condition", "sv", "--episodes", "3",
                 "--out", str(out))  # fmt: skip
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr.strip().splitlines() == [
        f"error: site xueqing cannot stage scenario 'jaywalking' on approach S: {why}"
    ]
    assert not out.exists()


def test_the_site_summary_lists_it_not_hosted_with_the_staging_reason(site):
    proc = subprocess.run(
        [sys.executable, "-m", "pedsafe_sumo.site", "--site", str(site), "--no-build"],
        capture_output=True, text=True, cwd=REPO_ROOT, timeout=300,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    stripped = [line.strip() for line in proc.stdout.splitlines() if ": " in line]
    lines = {line.split(": ", 1)[0]: line for line in stripped}
    assert lines["crossing"] == "crossing: hosted (its roadside poles see its staging area)"
    assert re.fullmatch(
        "jaywalking: NOT hosted: cannot be staged: " + FAILED + ": SUMO cannot put it there "
        "\\(the batch's staging check\\)",
        lines["jaywalking"],
    ), lines["jaywalking"]
