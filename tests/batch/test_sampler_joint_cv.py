"""A real `batch --sampler is --is-family joint` run whose report estimates Table I with pi_hat as a control
variate: the table's figures recomputed here from episodes.parquet and run.json (pi_hat of each episode
recovered from its weight, the estimate as the intercept of least squares)."""

from __future__ import annotations

import json
import math
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest
from batch_cli import batch
from scipy import stats

from pedsafe_sumo import REPO_ROOT

#: 20 nominal pilot pairs then 30 final pairs (the least the control variate is used on): on this seed the
#: pilot holds an SV collision, so the final stage draws from a joint proposal (tests/batch/
#: test_sampler_joint.py), and the final stage holds collisions under both conditions.
JOINT_CV_RUN = (
    "--scenario", "background_blending", "--episodes", "30", "--seed", "3", "--sampler", "is",
    "--is-family", "joint", "--is-pilot-stages", "1", "--is-pilot-episodes", "20", "--chunk-size", "10",
)  # fmt: skip


@pytest.mark.slow
def test_joint_run_report_uses_the_control_variate(tmp_path):
    out = tmp_path / "joint"
    proc = batch(*JOINT_CV_RUN, "--workers", "1", "--out", str(out))
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert proc.stdout.count("(is+cv)") == 2, proc.stdout[-2000:]
    report = subprocess.run(
        [sys.executable, "-m", "pedsafe_sumo.report", str(out)],
        capture_output=True, text=True, cwd=REPO_ROOT, timeout=300,
    )  # fmt: skip
    assert report.returncode == 0, report.stderr[-2000:]
    table = pd.read_csv(out / "tables" / "table1.csv")
    markdown = (out / "tables" / "table1.md").read_text()
    assert "| is+cv |" in markdown and "is+cv = with pi_hat of the joint proposal" in markdown
    rows = pd.read_parquet(out / "episodes.parquet")
    proposal = json.loads(
        json.loads((out / "run.json").read_text())["sampler_proposals"]["background_blending"][1]
    )
    lam, c_norm = proposal["defensive_share"], proposal["norm"]
    mean_g, se_g = proposal["mean_pi_hat"], proposal["mean_pi_hat_se"]
    assert math.isfinite(mean_g) and 0 < se_g < mean_g
    for condition in ("sv", "v2i"):
        final = rows[(rows.sampler_stage == 1) & (rows.condition == condition) & (rows.status == "ok")]
        assert len(final) == 30
        w = final["weight"].to_numpy()
        # w = 1 / (lambda + (1 - lambda) sqrt(pi_hat) / c), solved for pi_hat
        g = ((1.0 / w - lam) * c_norm / (1.0 - lam)) ** 2
        design = np.column_stack([np.ones(len(w)), w * g - mean_g])
        collision = final["collision"].to_numpy(dtype=float)
        assert collision.sum() >= 1
        (intercept, slope), rss, *_ = np.linalg.lstsq(design, w * collision, rcond=None)
        half = stats.norm.ppf(0.975) * math.sqrt(rss[0] / (len(w) - 2) / len(w) + slope**2 * se_g**2)
        row = table[table.condition == condition].iloc[0]
        assert row["estimator"] == "is+cv"
        assert row["collision_rate"] == pytest.approx(intercept, rel=1e-6)
        assert row["collision_high"] == pytest.approx(intercept + half, rel=1e-6)
        assert row["collision_low"] == pytest.approx(max(0.0, intercept - half), rel=1e-6, abs=1e-12)
        assert row["ess"] == pytest.approx(w.sum() ** 2 / (w**2).sum(), rel=1e-9)
        assert row["n"] == 30 and row["n_run"] == 50
        # not the plain weighted estimate
        assert abs(row["collision_rate"] - np.mean(w * collision)) > 1e-6
