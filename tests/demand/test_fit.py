"""tools/fit_distributions: recovers known parameters, writes a parameter file the generator reads, and
rejects bad CSVs with one clear line and exit status 2."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from pedsafe_sumo import REPO_ROOT
from pedsafe_sumo.demand.fit import main
from pedsafe_sumo.params import load_params

TOOL = REPO_ROOT / "tools" / "fit_distributions"


def _synthetic_csv(path, n=4000, seed=3):
    rng = np.random.default_rng(seed)
    headway = rng.exponential(1 / 0.25, n)
    speed_free = rng.lognormal(2.0, 0.3, n)
    speed_jct = rng.lognormal(1.4, 0.5, n)
    rows = ["headway_s,speed_mps,location"]
    for i in range(n):
        rows.append(f"{headway[i]:.6f},{speed_free[i]:.6f},non_intersection")
        rows.append(f",{speed_jct[i]:.6f},intersection")
    path.write_text("\n".join(rows) + "\n")


def test_fit_recovers_known_parameters_and_writes_loadable_params(tmp_path, capsys):
    csv_path = tmp_path / "obs.csv"
    _synthetic_csv(csv_path)
    out = tmp_path / "fitted.toml"
    assert main([str(csv_path), "--out", str(out)]) == 0
    table = capsys.readouterr().out
    assert "headway_rate_per_s" in table and "KS D" in table
    traffic = load_params(out)["traffic"]
    truth = {
        "headway_rate_per_s": 0.25,
        "speed_nonintersection_log_mu": 2.0,
        "speed_nonintersection_log_sigma": 0.3,
        "speed_intersection_log_mu": 1.4,
        "speed_intersection_log_sigma": 0.5,
    }
    text = out.read_text()
    for key, value in truth.items():
        assert traffic[key] == pytest.approx(value, rel=0.05)
        # The 95% interval written beside the value covers the truth.
        line = next(line for line in text.splitlines() if line.startswith(f"{key} ="))
        low, high = (float(v) for v in line.split("CI [")[1].rstrip("]").split(","))
        assert low <= value <= high


def test_speeds_without_location_go_to_the_chosen_fit(tmp_path):
    rng = np.random.default_rng(5)
    csv_path = tmp_path / "speeds.csv"
    csv_path.write_text("speed_mps\n" + "\n".join(f"{v:.5f}" for v in rng.lognormal(1.5, 0.4, 2000)) + "\n")
    out = tmp_path / "p.toml"
    assert main([str(csv_path), "--speed-location", "intersection", "--out", str(out)]) == 0
    assert "speed_intersection_log_mu" in out.read_text()
    assert "speed_nonintersection" not in out.read_text()


@pytest.mark.parametrize(
    ("content", "message"),
    [
        ("time_s,lane\n1,2\n", "needs a 'headway_s' or 'speed_mps' column"),
        ("headway_s\n3.1\nfast\n", ":3: headway_s is not a number: 'fast'"),
        ("speed_mps\n5.0\n-1.2\n", ":3: speed_mps must be > 0"),
        ("speed_mps\n5.0\n0\n", ":3: speed_mps must be > 0"),
        ("headway_s\n2.0\n-3\n", ":3: headway_s must be > 0"),
        ("speed_mps,location\n5.0,bridge\n", "location must be intersection or non_intersection"),
        ("headway_s\n4.0\n", "need at least 2 headways"),
        ("headway_s,speed_mps\n", "holds no observations"),
    ],
)
def test_bad_csv_is_one_clear_line_and_exit_2(tmp_path, content, message):
    csv_path = tmp_path / "bad.csv"
    csv_path.write_text(content)
    result = subprocess.run([sys.executable, str(TOOL), str(csv_path)], capture_output=True, text=True)
    assert result.returncode == 2
    assert "Traceback" not in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1
    assert message in result.stderr


def test_missing_csv_file(tmp_path):
    result = subprocess.run(
        [sys.executable, str(TOOL), str(tmp_path / "nope.csv")], capture_output=True, text=True
    )
    assert result.returncode == 2 and "cannot read" in result.stderr
