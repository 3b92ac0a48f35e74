"""research/is_validation.py on a joint run: the IS estimate with pi_hat as a control variate (the estimate
the report gives), the plain weighted estimate and its efficiencies beside it, and --plain for the columns of
the tables before it; numbers recomputed here from the rows."""

from __future__ import annotations

import json
import math
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest
from scipy import special, stats

from pedsafe_sumo import REPO_ROOT
from pedsafe_sumo.sampling.importance import Normal
from pedsafe_sumo.sampling.joint import JointProposal

sys.path.insert(0, str(REPO_ROOT / "research"))
from is_validation import compare  # noqa: E402

MU, SIGMA = 1.5853, 0.3827
#: pi_hat = expit(-2 + 1.2 z + 0.1 z^2), z the standardised ln speed.
PROPOSAL = JointProposal({"ego_speed_log": Normal(MU, SIGMA)}, (-2.0, 1.2, 0.1), 0.4, 0.1, 1e-3, 0.2, 1e-4)
N_FINAL = 40


def _rows(weighted: bool) -> pd.DataFrame:
    """An IS run (weighted: 5 nominal pilot pairs, N_FINAL final pairs) or an MC run (weight 1, stage 0)."""
    rng = np.random.default_rng(8)
    rows = []
    for episode in range(5 + N_FINAL):
        stage = int(weighted and episode >= 5)
        x = float(rng.normal(MU + 0.5 * stage, SIGMA))
        z = (x - MU) / SIGMA
        pi = float(special.expit(-2.0 + 1.2 * z + 0.1 * z * z))
        weight = 1.0 / (0.1 + 0.9 * math.sqrt(pi) / 0.4) if stage else 1.0
        hit = bool(rng.uniform() < pi)
        for condition in ("sv", "v2i"):
            rows.append(
                {
                    "scenario": "crossing",
                    "condition": condition,
                    "episode": episode,
                    "collision": hit,
                    "injury_probability": 0.5 if hit else 0.0,
                    "conflict": bool(rng.uniform() < 0.2),
                    "status": "ok",
                    "weight": weight,
                    "sampler_stage": stage,
                    "sampler_inputs": json.dumps({"inputs": {"ego_speed_log": x}, "nominal": {}}),
                    "pi": pi,
                }
            )
    return pd.DataFrame(rows)


def test_validation_uses_the_control_variate_with_the_plain_figures_beside():
    is_rows, mc_rows = _rows(True), _rows(False)
    table = compare(
        is_rows.drop(columns="pi"), mc_rows.drop(columns="pi"), {"crossing": ["", PROPOSAL.to_json()]}
    )
    row = table[(table.condition == "sv") & (table["index"] == "collision")].iloc[0]
    final = is_rows[(is_rows.sampler_stage == 1) & (is_rows.condition == "sv")]
    w, f, g = final["weight"].to_numpy(), final["collision"].to_numpy(dtype=float), final["pi"].to_numpy()
    design = np.column_stack([np.ones(N_FINAL), w * g - 0.2])
    (intercept, slope), rss, *_ = np.linalg.lstsq(design, w * f, rcond=None)
    half = stats.norm.ppf(0.975) * math.sqrt(rss[0] / (N_FINAL - 2) / N_FINAL + slope**2 * 1e-8)
    # Every final conflict of these rows comes with a collision: no conflict-without-collision to control.
    assert row["estimator"] == "is+cv (is: conflict)"
    assert row["is_estimate"] == pytest.approx(intercept, rel=1e-9)
    assert row["efficiency_final"] == pytest.approx(
        intercept * (1 - intercept) * (1.959964 / half) ** 2 / N_FINAL, rel=1e-5
    )
    plain = float(np.mean(w * f))
    plain_half = stats.norm.ppf(0.975) * np.std(w * f, ddof=1) / math.sqrt(N_FINAL)
    assert row["plain_estimate"] == pytest.approx(plain, rel=1e-12)
    assert row["plain_efficiency"] == pytest.approx(
        plain * (1 - plain) * (1.959964 / plain_half) ** 2 / (5 + N_FINAL), rel=1e-5
    )
    assert row["mc_estimate"] == pytest.approx(mc_rows[mc_rows.condition == "sv"]["collision"].mean())


def test_plain_flag_gives_the_earlier_columns(tmp_path):
    is_dir, mc_dir = tmp_path / "is", tmp_path / "mc"
    for path, rows in ((is_dir, _rows(True)), (mc_dir, _rows(False))):
        path.mkdir()
        rows.drop(columns="pi").to_parquet(path / "episodes.parquet")
        info = {"sampler_proposals": {"crossing": ["", PROPOSAL.to_json()]}, "sampler_levels": {}}
        (path / "run.json").write_text(json.dumps(info))
    tool = [
        sys.executable,
        str(REPO_ROOT / "research" / "is_validation.py"),
        str(is_dir),
        str(mc_dir),
        "--markdown",
    ]
    cv = subprocess.run(tool, capture_output=True, text=True, timeout=300)
    plain = subprocess.run([*tool, "--plain"], capture_output=True, text=True, timeout=300)
    assert cv.returncode == 0 and plain.returncode == 0, cv.stderr + plain.stderr
    cv_header, plain_header = cv.stdout.splitlines()[0], plain.stdout.splitlines()[0]
    assert "| estimator |" in cv_header and "plain_efficiency_final" in cv_header
    assert "estimator" not in plain_header and "plain_" not in plain_header
    assert plain_header.endswith("| efficiency | efficiency_final |")
    assert "is+cv" in cv.stdout
