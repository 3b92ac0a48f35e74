"""python -m pedsafe_sumo.demand.calibrate: the search finds the minimum of its objective, a real (tiny)
calibration in SUMO writes a parameter file the loader accepts, and bad input is one line with exit 2."""

from __future__ import annotations

import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from scipy import stats

from pedsafe_sumo import REPO_ROOT
from pedsafe_sumo.demand import calibrate
from pedsafe_sumo.params import load_params

STRAIGHT_NET = Path(__file__).parent / "data" / "straight.net.xml"


class QuadraticBowl(calibrate.Calibration):
    """The search on a known objective (a fake for the logic only; the SUMO objective is tested below)."""

    def __init__(self, args, optimum):
        super().__init__(args, load_params(), site=None, work=Path("."))
        self.optimum = optimum

    def comparisons(self, log_mu, log_sigma, kinds=("midblock",)):
        value = (log_mu - self.optimum[0]) ** 2 + 2.0 * (log_sigma - self.optimum[1]) ** 2
        return [SimpleNamespace(ks_distance=value, n=1, measured_median=0.0, fitted_median=0.0)]


def search_args(**kw):
    base = dict(grid_mu_offsets=[0.0, 0.2], grid_sigmas=[0.2, 0.4], first_step=0.04, min_step=0.01, seeds=[1])
    return SimpleNamespace(**{**base, **kw})


@pytest.mark.parametrize("optimum", [(1.8304 + 0.13, 0.31), (1.8304 + 0.27, 0.45), (1.8304 - 0.05, 0.2)])
def test_grid_then_compass_search_reaches_the_minimum_to_the_last_step(optimum):
    cal = QuadraticBowl(search_args(), optimum)
    best = cal.run()
    # On the lattice of the grid and steps of 0.01 the minimum is within half the last step.
    assert abs(best.log_mu - optimum[0]) <= 0.005 + 1e-9
    assert abs(best.log_sigma - optimum[1]) <= 0.005 + 1e-9
    assert best.ks_distance == min(ev.ks_distance for ev in cal.evaluations)
    assert [ev.stage for ev in cal.evaluations[:4]] == ["grid"] * 4
    # Memoised: no point evaluated twice.
    points = [(ev.log_mu, ev.log_sigma) for ev in cal.evaluations]
    assert len(points) == len(set(points))


@pytest.mark.slow
def test_a_one_point_real_calibration_writes_the_ks_of_sumos_loops_and_a_file_that_loads(tmp_path):
    """One candidate (a one-point grid, no search step): the KS it writes is the one recomputed here from
    SUMO's own loop file against the fit scaled to the road (13.89 / 16.67), and the file loads."""
    out, work = tmp_path / "cal.toml", tmp_path / "work"
    rc = calibrate.main(
        ["--net", str(STRAIGHT_NET), "--seeds", "2", "--duration", "700", "--grid-mu-offsets", "0.2",
         "--grid-sigmas", "0.3", "--first-step", "0.1", "--min-step", "0.2", "--write-params", str(out),
         "--work", str(work)]
    )  # fmt: skip
    assert rc == 0
    traffic = load_params(out)["traffic"]
    assert traffic["desired_speed_law"] == "calibrated"
    assert traffic["desired_speed_calibrated_log_mu"] == pytest.approx(1.8304 + 0.2)
    assert traffic["desired_speed_calibrated_log_sigma"] == 0.3
    # The route file of the run carries that law: speed factor x 16.67 is the draw (limit rule).
    factors = [
        float(v.get("speedFactor"))
        for v in ET.parse(work / "seed_2" / "straight.vehicles.rou.xml").getroot().iter("vehicle")
    ]
    draws = np.log(np.array(factors) * 16.67)
    assert abs(np.median(draws) - 2.0304) < 0.1 and abs(np.std(draws) - 0.3) < 0.05
    speeds = [
        float(el.get("speed"))
        for el in ET.parse(work / "seed_2" / "detectors.out.xml").getroot().iter("instantOut")
        if el.get("state") == "enter" and el.get("id").startswith("mid_") and float(el.get("time")) >= 300
    ]
    assert len(speeds) > 100
    target = stats.lognorm(s=0.4857, scale=np.exp(1.8304) * 13.89 / 16.67)
    ks_written = float(out.read_text().splitlines()[1].split("KS distance ")[1].split()[0])
    assert ks_written == pytest.approx(stats.kstest(speeds, target.cdf).statistic, abs=6e-5)


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--net", "/nonexistent/road.net.xml"], "error:"),
        (["--duration", "200", "--warmup", "300"], "need --duration > --warmup"),
        (["--grid-sigmas", "0", "0.3"], "grid sigmas must be > 0"),
        (["--params", "/nonexistent.toml"], "parameter file not found"),
    ],
)
def test_bad_input_is_one_line_and_exit_2(args, message):
    proc = subprocess.run(
        [sys.executable, "-m", "pedsafe_sumo.demand.calibrate", *args],
        capture_output=True, text=True, cwd=REPO_ROOT, timeout=300,
    )  # fmt: skip
    assert proc.returncode == 2
    assert message in proc.stderr and len(proc.stderr.strip().splitlines()) == 1, proc.stderr
    assert "Traceback" not in proc.stderr
