"""traffic.desired_speed_law: "fit" (the default) draws from the fitted lognormal whatever the calibrated
values; "calibrated" draws the background's desired speeds from the calibrated lognormal in the route files
and in the episodes alike, and on the open road at the paper's flow SUMO's loops measure speeds closer to the
fit under it."""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

from pedsafe_sumo import NETWORKS_DIR, ROUTES_DIR
from pedsafe_sumo.demand import calibrate
from pedsafe_sumo.demand.generate import generate_demand, vehicle_route_path
from pedsafe_sumo.demand.site import load_site
from pedsafe_sumo.demand.vehicles import generate_vehicles
from pedsafe_sumo.params import ParameterError, load_params, with_overrides

STRAIGHT_NET = Path(__file__).parent / "data" / "straight.net.xml"
#: The straight road's limit (tests/demand/data/straight.net.xml) and the fits' (defaults.toml).
STRAIGHT_LIMIT_MPS = 13.89
FIT_LIMIT_MPS = 16.67


def calibrated_params(**values):
    return with_overrides(load_params(), {"traffic.desired_speed_law": "calibrated", **values})


def lognormal_cdf(x, log_mu, log_sigma):
    """Written out from the definition (not scipy's lognorm, not the code's Lognormal)."""
    return np.array([0.5 * math.erfc(-(math.log(v) - log_mu) / (log_sigma * math.sqrt(2.0))) for v in x])


def test_defaults_draw_from_the_fit_and_hold_calibrated_values_apart_from_it():
    traffic = load_params()["traffic"]
    assert traffic["desired_speed_law"] == "fit"
    calibrated = (traffic["desired_speed_calibrated_log_mu"], traffic["desired_speed_calibrated_log_sigma"])
    assert calibrated != (traffic["speed_nonintersection_log_mu"], traffic["speed_nonintersection_log_sigma"])


@pytest.mark.parametrize(
    ("override", "message"),
    [
        ({"traffic.desired_speed_law": "observed"}, "desired_speed_law' must be one of fit, calibrated"),
        ({"traffic.desired_speed_law": 1}, "desired_speed_law' must be one of"),
        (
            {"traffic.desired_speed_calibrated_log_sigma": 0.0},
            "desired_speed_calibrated_log_sigma' must be > 0",
        ),
        (
            {"traffic.desired_speed_calibrated_log_mu": "fast"},
            "desired_speed_calibrated_log_mu' must be a finite",
        ),
        (
            {"traffic.desired_speed_calibrated_log_mu": 4.5},
            "desired_speed_calibrated_log_mu' must be at most 4",
        ),
    ],
)
def test_bad_law_or_values_are_refused_in_one_line(override, message):
    with pytest.raises(ParameterError, match=message) as info:
        with_overrides(load_params(), override)
    assert "\n" not in str(info.value)


def test_under_fit_the_calibrated_values_change_nothing(tmp_path):
    """Law "fit" with other calibrated values: the shipped Xueqing routes (main's generator, seed 1), byte for
    byte."""
    params = with_overrides(
        load_params(),
        {
            "traffic.desired_speed_law": "fit",
            "traffic.desired_speed_calibrated_log_mu": 2.5,
            "traffic.desired_speed_calibrated_log_sigma": 0.1,
        },
    )
    generate_demand("xueqing", 3600.0, 1, tmp_path, params=params)
    shipped = vehicle_route_path(ROUTES_DIR, "xueqing")
    assert vehicle_route_path(tmp_path, "xueqing").read_bytes() == shipped.read_bytes()


def test_calibrated_desired_speeds_follow_the_calibrated_lognormal_scaled_to_the_road(tmp_path):
    log_mu, log_sigma = 2.1, 0.3
    params = calibrated_params(
        **{
            "traffic.desired_speed_calibrated_log_mu": log_mu,
            "traffic.desired_speed_calibrated_log_sigma": log_sigma,
        }
    )
    demand = generate_demand("straight", 20_000.0, 5, tmp_path, net_file=STRAIGHT_NET, params=params)
    root = ET.parse(demand.vehicles_file).getroot()
    factors = np.array([float(v.get("speedFactor")) for v in root.iter("vehicle")])
    assert factors.size > 6000
    # What SUMO drives on the straight road: speedFactor x the lane's limit (13.89 m/s).
    speeds = factors * STRAIGHT_LIMIT_MPS
    scaled_mu = log_mu + math.log(STRAIGHT_LIMIT_MPS / FIT_LIMIT_MPS)
    ks = stats.kstest(speeds, lambda x: lognormal_cdf(np.atleast_1d(x), scaled_mu, log_sigma)).statistic
    critical = 1.95 / math.sqrt(speeds.size)  # alpha 0.001
    assert ks < critical
    # The test can fail: the same sample is far from the fit's lognormal.
    fit_mu = 1.8304 + math.log(STRAIGHT_LIMIT_MPS / FIT_LIMIT_MPS)
    assert (
        stats.kstest(speeds, lambda x: lognormal_cdf(np.atleast_1d(x), fit_mu, 0.4857)).statistic
        > 5 * critical
    )


def test_calibrated_and_fit_draw_the_same_normal_scores():
    """The law only rescales the same draws (common random numbers: the calibration compares candidates on
    them), and headways, lanes and routes are unchanged."""
    site = load_site("straight", NETWORKS_DIR, STRAIGHT_NET)
    fit_params = load_params()
    cal_params = calibrated_params(
        **{"traffic.desired_speed_calibrated_log_mu": 2.2, "traffic.desired_speed_calibrated_log_sigma": 0.25}
    )
    fit = generate_vehicles(site.entering_lanes, fit_params["traffic"], 600.0, np.random.SeedSequence(3))
    cal = generate_vehicles(site.entering_lanes, cal_params["traffic"], 600.0, np.random.SeedSequence(3))
    assert [(v.vehicle_id, v.depart_s, v.route_id) for v in fit] == [
        (v.vehicle_id, v.depart_s, v.route_id) for v in cal
    ]
    scale = STRAIGHT_LIMIT_MPS / FIT_LIMIT_MPS
    for f, c in zip(fit, cal, strict=True):
        z = (math.log(f.desired_speed_mps / scale) - 1.8304) / 0.4857
        assert c.desired_speed_mps == pytest.approx(scale * math.exp(2.2 + 0.25 * z), rel=1e-9)


@pytest.mark.slow
def test_the_episode_background_draws_from_the_same_law():
    """The episode engine's background traffic (sim/episode.py) goes through the same switch: same vehicles,
    each desired speed the calibrated law's value of the same normal score."""
    from pedsafe_sumo.control.reference import ReferenceStack
    from pedsafe_sumo.network.sites import resolve_site
    from pedsafe_sumo.scenarios.specs import get_scenario
    from pedsafe_sumo.sim.episode import EpisodeRunner

    log_mu, log_sigma = 2.05, 0.33
    spec = get_scenario("background_blending")
    params = {
        "fit": load_params(),
        "calibrated": calibrated_params(
            **{
                "traffic.desired_speed_calibrated_log_mu": log_mu,
                "traffic.desired_speed_calibrated_log_sigma": log_sigma,
            }
        ),
    }
    runners = {law: EpisodeRunner(resolve_site("xueqing"), p, ReferenceStack) for law, p in params.items()}
    try:
        compared = 0
        for seed in (1, 2):
            fit = {v.vehicle_id: v for v in runners["fit"].draw_setup(spec, seed).background}
            cal = {v.vehicle_id: v for v in runners["calibrated"].draw_setup(spec, seed).background}
            for vid in fit.keys() & cal.keys():
                # speed factor x the fits' limit = the draw before the limit scaling (the rule's definition).
                z = (math.log(fit[vid].speed_factor * FIT_LIMIT_MPS) - 1.8304) / 0.4857
                assert cal[vid].speed_factor * FIT_LIMIT_MPS == pytest.approx(
                    math.exp(log_mu + log_sigma * z), rel=1e-9
                )
                compared += 1
        assert compared > 20
    finally:
        for runner in runners.values():
            runner.close()


def _midblock_speeds(tmp_path: Path, params: dict, seed: int, duration_s: float) -> np.ndarray:
    """Speeds SUMO's E1 loops record 30 m into both lanes of the straight road after a 300 s warm-up,
    read from the loops' own output file."""
    site = load_site("straight", NETWORKS_DIR, STRAIGHT_NET)
    calibrate.simulate_loops(site, "straight", STRAIGHT_NET, params, seed, duration_s, tmp_path)
    speeds = []
    for el in ET.parse(tmp_path / "detectors.out.xml").getroot().iter("instantOut"):
        if el.get("state") == "enter" and el.get("id").startswith("mid_") and float(el.get("time")) >= 300:
            speeds.append(float(el.get("speed")))
    return np.array(speeds)


@pytest.mark.slow
def test_on_the_open_road_the_calibrated_law_brings_sumos_speeds_closer_to_the_fit(tmp_path):
    """At the paper's flow, a seed the calibration did not use: the mid-block KS distance from SUMO's loops
    against the fit (scaled to the road's 13.89 m/s) is smaller under "calibrated" than under "fit"."""
    fit_params = load_params()
    cal_params = with_overrides(fit_params, {"traffic.desired_speed_law": "calibrated"})
    assert fit_params["traffic"]["headway_rate_per_s"] == 0.1742
    target_mu = 1.8304 + math.log(STRAIGHT_LIMIT_MPS / FIT_LIMIT_MPS)
    ks = {}
    for law, params in (("fit", fit_params), ("calibrated", cal_params)):
        speeds = _midblock_speeds(tmp_path / law, params, seed=11, duration_s=1200.0)
        assert speeds.size > 250
        ks[law] = stats.kstest(speeds, lambda x: lognormal_cdf(np.atleast_1d(x), target_mu, 0.4857)).statistic
    assert ks["calibrated"] < ks["fit"], ks
