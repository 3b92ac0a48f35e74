"""The demand validation compares each loop's speeds with the fit scaled to that loop's speed limit, as the
background's desired speeds are scaled (traffic.background_speed_limit_scaled): the
pooled speeds against the mixture of the scaled fits, weighted by each loop's records. Checked against a
KS distance computed here by hand from the lognormal's formula (math.erf), not with scipy."""

from __future__ import annotations

import math

import pytest

from pedsafe_sumo.demand.validate import Detector, measure
from pedsafe_sumo.params import load_params, with_overrides

MU, SIGMA = 1.8304, 0.4857  # the non-intersection fit (defaults.toml)
FIT_LIMIT_MPS = 16.67


def lognormal_cdf(x: float, scale: float) -> float:
    """P(scale * V <= x) for V lognormal(MU, SIGMA): Phi((ln(x / scale) - MU) / SIGMA)."""
    z = (math.log(x / scale) - MU) / SIGMA
    return 0.5 * (1.0 + math.erf(z / math.sqrt(2.0)))


def ks_by_hand(samples: list[float], cdf) -> float:
    """sup |ECDF - F| over the sorted sample: max over i of i/n - F(x_i) and F(x_i) - (i-1)/n."""
    xs = sorted(samples)
    n = len(xs)
    return max(max(i / n - cdf(x), cdf(x) - (i - 1) / n) for i, x in enumerate(xs, start=1))


#: A 60 km/h loop (the fits' limit) with three vehicles, a 40 km/h one with two; one record of each
#: before the 10 s warm-up, which is left out.
DETECTORS = [
    Detector("mid_a", "a_0", 30.0, "midblock", FIT_LIMIT_MPS),
    Detector("mid_b", "b_0", 30.0, "midblock", 11.11),
]
RECORDS = {
    "mid_a": [(5.0, 1.0), (12.0, 5.1), (20.0, 6.4), (31.0, 8.9)],
    "mid_b": [(2.0, 30.0), (15.0, 3.2), (27.0, 4.6)],
}


def test_each_loop_is_compared_with_the_fit_scaled_to_its_limit():
    traffic = load_params()["traffic"]
    assert traffic["background_speed_limit_scaled"] is True
    assert traffic["fit_speed_limit_mps"] == FIT_LIMIT_MPS
    midblock = measure(RECORDS, DETECTORS, traffic, warmup_s=10.0)[0]
    # Weights 3/5 (loop a, scale 1) and 2/5 (loop b, scale 11.11 / 16.67).
    scale_b = 11.11 / 16.67

    def mixture(x: float) -> float:
        return 0.6 * lognormal_cdf(x, 1.0) + 0.4 * lognormal_cdf(x, scale_b)

    samples = [5.1, 6.4, 8.9, 3.2, 4.6]
    assert midblock.n == 5
    assert midblock.ks_distance == pytest.approx(ks_by_hand(samples, mixture), abs=1e-9)
    # The mixture's median: where 0.6 F(x) + 0.4 F(x / scale_b) = 1/2, between the two medians.
    median = midblock.fitted_median
    assert math.exp(MU) * scale_b < median < math.exp(MU)
    assert mixture(median) == pytest.approx(0.5, abs=1e-9)
    assert "scaled to each loop's limit" in midblock.reference
    # Not the unscaled comparison (what the validation did before): that distance is another number.
    assert abs(midblock.ks_distance - ks_by_hand(samples, lambda x: lognormal_cdf(x, 1.0))) > 0.01


def test_without_the_scaling_every_loop_is_compared_with_the_fit_itself():
    traffic = with_overrides(load_params(), {"traffic.background_speed_limit_scaled": False})["traffic"]
    midblock = measure(RECORDS, DETECTORS, traffic, warmup_s=10.0)[0]
    samples = [5.1, 6.4, 8.9, 3.2, 4.6]
    unscaled = ks_by_hand(samples, lambda x: lognormal_cdf(x, 1.0))
    assert midblock.ks_distance == pytest.approx(unscaled, abs=1e-9)
    assert midblock.fitted_median == pytest.approx(math.exp(MU), rel=1e-12)
    assert midblock.reference == "non-intersection lognormal"


def test_the_switch_is_true_or_false_and_nothing_else():
    from pedsafe_sumo.params import ParameterError

    with pytest.raises(ParameterError, match="background_speed_limit_scaled' must be true or false"):
        with_overrides(load_params(), {"traffic.background_speed_limit_scaled": 1})


def test_the_loops_carry_the_limit_of_their_entering_lane():
    """On Xueqing: six 60 km/h entering lanes and the two 40 km/h side roads (docs/sites.md)."""
    from pedsafe_sumo import NETWORKS_DIR
    from pedsafe_sumo.demand.site import load_site
    from pedsafe_sumo.demand.validate import place_detectors

    site = load_site("xueqing", NETWORKS_DIR)
    limits = {d.lane_id: round(d.speed_limit_mps, 2) for d in place_detectors(site) if d.kind == "midblock"}
    assert sorted(limits.values()) == [11.11, 11.11] + [16.67] * 6
    assert {lane.rsplit("_", 1)[0] for lane, limit in limits.items() if limit == 11.11} == {
        "-121510223",
        "121510226#0",
    }
    # A junction loop: the limit of the lane its connection comes from.
    net = site.net
    for d in (d for d in place_detectors(site) if d.kind == "junction"):
        feeding = [
            c.getFromLane().getSpeed()
            for edge in net.getNode(net.getLane(d.lane_id).getEdge().getFromNode().getID()).getIncoming()
            for lane in edge.getLanes()
            for c in lane.getOutgoing()
            if c.getViaLaneID() == d.lane_id
        ]
        assert feeding and d.speed_limit_mps == feeding[0]
