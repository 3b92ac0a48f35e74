"""A joint proposal over the episode's proposable inputs, learned from the pilot stages (`--is-family joint`).

The cross-entropy stages fit a product of one family per input; a collision is a joint condition (a fast
ego with an early, fast pedestrian), and the product puts mass on combinations that do not collide
(research/EXPERIMENTS.md, "Importance sampling, session 6"). For an event that stays random given the inputs
x, with pi(x) = P(collision | x), the proposal of least variance is q ∝ p sqrt(pi) (Owen, Monte Carlo theory,
methods and examples, 2013, section 9.1). Here

    q(x) = lambda p(x) + (1 - lambda) p(x) sqrt(pi_hat(x)) / c,     c = E_p[sqrt(pi_hat)],

with pi_hat a ridge logistic regression of the SV collision on the pilots' inputs (each continuous input
standardised by its nominal's mean and sd, its square and the pairwise products; categories as
indicators), lambda the defensive share. pi is a conditional probability, so the rows of every pilot stage
pool unweighted, whatever proposal drew them.

Drawing: by rejection from the nominal, with the episode's own Generator: a block of candidate vectors is
drawn from the nominal families (in the order of the sorted input names), each kept with probability
(q/p)(x) / B where B = lambda + (1 - lambda) / c >= q/p (sqrt(pi_hat) <= 1); the first kept one is the
episode's. Its weight is p/q = 1 / (lambda + (1 - lambda) sqrt(pi_hat(x)) / c), at most 1/lambda.

Kinematic features (session 8; measured offline in research/EXPERIMENTS.md, "Session 7: shaping pi_hat at
pilot size", the `physics` variant): where the scenario draws the ego's speed, the pedestrian's walking speed
and the conflict offset, three functions of x are appended to the design as further continuous inputs (their
squares and their products with every continuous input): the ego's speed v = clip(exp(ego_speed_log)) to the
scenario's bounds (before the approach's speed-limit scale), the pedestrian's time per metre 1/w with w =
exp(mu_g + sigma_g z) of the age group's lognormal (before the sex factor), and the braking margin

    margin_s = conflict_offset_s + VISIBLE_M / w - t_r - v / (2 a_max)

(the seconds left, from the pedestrian's coming into view VISIBLE_M before the ego lane's centre, beyond the
stack's reaction time t_r and the time a full stop from v at a_max takes: negative, no stop before the
conflict point; scenarios/placements/ stages the ego to reach the conflict point conflict_offset_s after
the pedestrian). Each is standardised by its moments on MOMENT_DRAWS nominal draws. They are features of a
fit, not a model of the episode: a wrong VISIBLE_M or t_r costs efficiency, never bias (the weights are
exact whatever pi_hat is). Offline on v5_full's rows, 2-stage pilot: per final episode right_turn 11.5 ->
19.2, crossing 19.5 -> 55, background_blending 5.0 -> 6.3, jaywalking 4.9 -> 5.4.

The guard (session 8): a 200-pair nominal stage 0 of a scenario whose collision rate is 0.75% (crossing)
holds no collision one time in five, and a fit on one or two collisions hardly beats the nominal
(session 7: seed 23's crossing, 3.6x per final episode). So a PILOT stage whose pooled pilot rows hold
fewer than GUARD_MIN_COLLISIONS SV collisions draws from the region proposal instead: pi_hat a steep step
down at margin_s = 0, q ≈ lambda p + (1 - lambda) p 1{margin_s < 0} / P_p(margin_s < 0). It needs no fit:
on v5_full's rows 75 of 75 crossing collisions, 220 of 220 right_turn, 293 of 299 jaywalking (but 303 of
504 blending) had margin_s < 0, where the collision rate is 17-71%. The final stage is always the fit
on the pooled pilot rows (which the guard's stage makes rich in collisions). Pilot rows only train pi_hat,
so a guard that misses collisions costs efficiency, never bias.

The V2I factor (session 12; research/EXPERIMENTS.md, "Importance sampling, session 12"). V2I's collisions lie
inside SV's region, but there the proposable inputs leave V2I's outcome largely to chance: on jaywalking 84%
of V2I's collisions (4% of the SV-only ones) have the pedestrian's clothing within the roadside camera's
contrast threshold of the parked car behind them, which the camera's colour rule then cannot tell apart
(perception/sensors.py). So where the pilots' SV collisions hold at least GUARD_MIN_COLLISIONS V2I collisions,
the proposal also draws the clothing and the vehicles' colours (uniform categories, as the scenarios draw
them) and aims at V2I's collisions too, modelled as pi_v2i = pi_hat r(z) with

    r(z) = P(V2I collision | SV collision, z) = expit(b_0 + sum_k b_k L[clothing, colour_k]),

L[i, j] = 1 where clothing colour i and car colour j differ by less than the roadside camera's
delta_e_threshold (CIE76), b a ridge logistic (RIDGE) on the pilots' pairs whose SV episode collided.
Then sqrt(pi_hat) becomes

    h(x, z) = sqrt(a pi_hat(x) + (1 - a) pi_hat(x) r(z)),    a = m_v2i^2 / (m_sv^2 + m_v2i^2),

m = the nominal means E_p[pi_hat] and E_p[pi_hat r]: the proposal ∝ p sqrt(pi_sv / P_sv^2 + pi_v2i /
P_v2i^2) that minimises the sum of the two rates' relative variances (Owen 2013, section 9.1, applied to
the sum), with the fits for the pi and m for the P. h <= 1, so the envelope B is unchanged; pi_hat r is
V2I's control variate (`mean_pi_v2i`). Where the clothing does not vary the contrast (background blending
dresses the pedestrian in the waiting car's colour) the fit leaves r nearly constant and the proposal
nearly the SV one.

The V2I-only term (session 13; research/EXPERIMENTS.md, "Importance sampling, session 13", part 3). The factor
models V2I's collisions as a subset of SV's. On Xueqing that holds (V2I-only collisions are 0-8% of V2I's
rate), but on the zhixin junction 41% of V2I's jaywalking collisions happen where SV does not collide, and
the proposal drew them at about its defensive floor (V2I 0.15x against MC). So where the pilot pairs hold
enough V2I collisions whose SV episode did not collide (`v2i_only_engages`; `--is-v2i-factor
contrast+v2i-only`), the factor also carries pi_vo, a ridge logistic of "V2I collides, SV does not" on every
pilot pair over pi_hat's design, and V2I is modelled as

    pi_v2i = min(1, pi_hat r + pi_vo),    h = sqrt(a pi_hat + (1 - a) pi_v2i),

a by the same rule on m_v2i = E_p[pi_v2i]; pi_v2i is V2I's control variate. The factor then applies where
either count is enough (r fitted on what SV collisions there are). h <= 1 still, so B stands.

Enough (session 14; research/EXPERIMENTS.md, "Importance sampling, session 14"): GUARD_MIN_COLLISIONS V2I-only
collisions, or V2I_ONLY_MIN_COLLISIONS that make up at least the defensive share lambda of the pilots' V2I
collisions. The second arm is the case where leaving them out costs most: a share s of V2I's rate drawn at the
floor lambda p adds s / lambda times plain Monte Carlo's variance to V2I's, so from s = lambda on, that
region alone makes V2I's estimate no better than MC. Session 13's zhixin seeds held 2-3 such pilot
collisions at shares of 0.15-0.30; the term fitted on their 2 collisions takes V2I from 1.7 and 2.6 to 4.0
and 4.7 per final episode (offline, scored on MC pairs), and without it V2I's interval missed the pooled MC
reference in one seed of three. Xueqing's pilots (21 runs of sessions 11-13) hold 0-13 at shares of
0-0.11, none with 2-4 at a share of 0.1 or more; there a term fitted on 1-3 would cost efficiency
(blending's SV 18% offline). The share is of the pilots' draws, which lean towards SV's collisions, so it
understates the nominal one.

c is estimated once, when the proposal is fitted, on NORM_DRAWS nominal draws of a fixed seed, and
stored with the coefficients in the proposal's JSON (run.json's sampler_proposals), so resume, workers and
Dask rebuild the very proposal. The estimate's relative error (stored as `norm_rel_se`) is the relative
bias it leaves in the estimates and the mean weight: the sampled density is q / Z with Z = E_p[q/p] =
lambda + (1 - lambda) E_p[sqrt(pi_hat)] / c, equal to 1 up to that error.
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd
from scipy import optimize, special

from pedsafe_sumo.sampling.importance import Beta, Categorical, Family, Normal

KIND = "joint"
#: Ridge penalty on the standardised features: research/is_limits.py's value, chosen before the pilot-sized
#: measurement (research/EXPERIMENTS.md, "joint proposal"); not tuned on it.
RIDGE = 1.0
#: Nominal draws that estimate c = E_p[sqrt(pi_hat)]: relative standard error about 1e-3 for the four
#: Xueqing scenarios (stored per proposal).
NORM_DRAWS = 1_000_000
#: Any fixed seed: the estimate of c must not depend on the run, worker or resume.
NORM_SEED = 17_2026
#: Nominal draws per block of that estimate.
NORM_BLOCK = 100_000
#: The condition whose collisions the V2I factor models (module docstring), and the inputs it draws: the
#: pedestrian's clothing and every vehicle colour the scenario draws (names ending in COLOUR_SUFFIX).
V2I_CONDITION = "v2i"
CLOTHING_INPUT = "clothing"
COLOUR_SUFFIX = ".colour"
#: The inputs the kinematic features need (module docstring); a scenario without one of them fits on x alone.
KINEMATIC_INPUTS = ("conflict_offset_s", "ego_speed_log", "ped_age_group", "ped_walking_speed_z")
#: An assumption, not a measurement: SUMO's default lane width 3.2 m less half a car's width 0.9 m, the
#: distance from an occluder's lane-side flank to the ego lane's centre. Offline the efficiency hardly
#: moved between 1.6 and 3.2 m (the separate 1/w feature absorbs it; research/EXPERIMENTS.md, session 7).
VISIBLE_M = 2.3
#: Nominal draws (of NORM_SEED + 1) that give the kinematic features' means and standard deviations.
MOMENT_DRAWS = 100_000
#: The guard: a pilot stage whose pooled pilot rows hold fewer SV collisions than this draws from the
#: region proposal (margin_s < 0) instead of a fit on a handful of collisions (the `adaptive` variant's
#: threshold of research/EXPERIMENTS.md, session 7, fixed there before its scores).
GUARD_MIN_COLLISIONS = 5
#: The V2I-only term's lower count (module docstring, "Enough"): a fit needs more than one point.
V2I_ONLY_MIN_COLLISIONS = 2
#: The guard's step: pi_hat = expit(-GUARD_STEEPNESS margin_s / sd(margin_s)).
GUARD_STEEPNESS = 200.0
#: Candidates drawn per block of the rejection step (the episode's Generator draws whole blocks).
REJECTION_BLOCK = 64
#: A proposal whose bound B needs more candidates than this per episode on average is refused.
MAX_MEAN_TRIES = 100_000


#: One input's part of the design: a standardised continuous input (an array) or a category's indicator
#: columns (a list of arrays, the first category left out).
Block = np.ndarray | list[np.ndarray]


def quadratic_design(n_rows: int, blocks: list[Block]) -> np.ndarray:
    """The logistic model's features: an intercept; per input in order, its indicators or its z and z^2;
    then the products of every pair of continuous inputs. Shared with research/is_limits.py and
    research/experiments/is_joint_pilot.py, so the offline measurements fit the very model the sampler
    does."""
    columns, continuous = [np.ones(n_rows)], []
    for block in blocks:
        if isinstance(block, list):
            columns += block
        else:
            continuous.append(block)
            columns += [block, block * block]
    for i in range(len(continuous)):
        for j in range(i + 1, len(continuous)):
            columns.append(continuous[i] * continuous[j])
    return np.column_stack(columns)


def _moments(family: Family) -> tuple[float, float]:
    """(mean, sd) of a continuous nominal family: the features' standardisation."""
    if isinstance(family, Normal):
        return family.mean, family.sd
    if isinstance(family, Beta):
        s = family.a + family.b
        width = family.high - family.low
        return family.low + width * family.a / s, width * math.sqrt(family.a * family.b / (s * s * (s + 1)))
    raise TypeError(f"no moments for {family!r}")


@dataclass(frozen=True)
class Kinematics:
    """What turns the inputs x into the kinematic features (module docstring)."""

    ego_speed_min_mps: float
    ego_speed_max_mps: float
    #: The walking-speed lognormal of each age group, in the order of ped_age_group's categories.
    walking_log_mu: tuple[float, ...]
    walking_log_sigma: tuple[float, ...]
    reaction_time_s: float
    max_decel_mps2: float
    visible_m: float = VISIBLE_M
    #: (mean, sd) of v, 1/w and margin_s under the nominal; () until with_moments.
    moments: tuple[tuple[float, float], ...] = ()

    def raw(self, x: Mapping[str, np.ndarray]) -> list[np.ndarray]:
        """[v (m/s), 1/w (s/m), margin_s (s)] at the inputs x."""
        v = np.clip(
            np.exp(np.asarray(x["ego_speed_log"], dtype=float)),
            self.ego_speed_min_mps,
            self.ego_speed_max_mps,
        )
        group = np.asarray(x["ped_age_group"], dtype=float).astype(int)
        z = np.asarray(x["ped_walking_speed_z"], dtype=float)
        w = np.exp(np.asarray(self.walking_log_mu)[group] + np.asarray(self.walking_log_sigma)[group] * z)
        margin = (
            np.asarray(x["conflict_offset_s"], dtype=float)
            + self.visible_m / w
            - self.reaction_time_s
            - v / (2.0 * self.max_decel_mps2)
        )
        return [v, 1.0 / w, margin]

    def blocks(self, x: Mapping[str, np.ndarray]) -> list[Block]:
        return [(f - mean) / sd for f, (mean, sd) in zip(self.raw(x), self.moments, strict=True)]

    def with_moments(self, nominal: Mapping[str, Family]) -> Kinematics:
        rng = np.random.default_rng(NORM_SEED + 1)
        draws = {name: nominal[name].sample(rng, MOMENT_DRAWS) for name in sorted(nominal)}
        moments = tuple((float(np.mean(f)), float(np.std(f))) for f in self.raw(draws))
        return dataclasses.replace(self, moments=moments)

    def to_dict(self) -> dict[str, Any]:
        return {**dataclasses.asdict(self), "moments": [list(m) for m in self.moments]}

    @staticmethod
    def from_dict(data: Mapping[str, Any]) -> Kinematics:
        return Kinematics(
            float(data["ego_speed_min_mps"]),
            float(data["ego_speed_max_mps"]),
            tuple(float(v) for v in data["walking_log_mu"]),
            tuple(float(v) for v in data["walking_log_sigma"]),
            float(data["reaction_time_s"]),
            float(data["max_decel_mps2"]),
            float(data["visible_m"]),
            tuple((float(m), float(sd)) for m, sd in data["moments"]),
        )


@dataclass(frozen=True)
class ContrastFactor:
    """The V2I factor r(z) = expit(b_0 + sum_k b_k L[clothing, colour_k]) and the share a of pi_hat in h
    (module docstring)."""

    #: The vehicle colour inputs, sorted; the clothing is CLOTHING_INPUT.
    colour_inputs: tuple[str, ...]
    #: L[clothing][car colour]: 1 where the two are within the roadside camera's contrast threshold.
    low_contrast: tuple[tuple[int, ...], ...]
    #: b_0, then one b_k per colour input.
    coefficients: tuple[float, ...]
    #: a of h = sqrt(a pi_hat + (1 - a) pi_hat r); NaN until the proposal is normalised.
    target_share: float = math.nan
    #: The V2I-only term (module docstring): coefficients of pi_vo on pi_hat's design; () without it.
    v2i_only_coefficients: tuple[float, ...] = ()

    @property
    def names(self) -> tuple[str, ...]:
        return (CLOTHING_INPUT, *self.colour_inputs)

    def nominal(self) -> dict[str, Family]:
        """The factor's inputs' nominal laws: n equally likely categories, as Draws.index draws them."""
        n_clothing, n_cars = len(self.low_contrast), len(self.low_contrast[0])
        laws: dict[str, Family] = {CLOTHING_INPUT: Categorical((1.0 / n_clothing,) * n_clothing)}
        return laws | {name: Categorical((1.0 / n_cars,) * n_cars) for name in self.colour_inputs}

    def design(self, x: Mapping[str, np.ndarray]) -> np.ndarray:
        table = np.asarray(self.low_contrast, dtype=float)
        clothing = np.atleast_1d(np.asarray(x[CLOTHING_INPUT], dtype=float)).astype(int)
        columns = [np.ones(len(clothing))]
        for name in self.colour_inputs:
            columns.append(table[clothing, np.atleast_1d(np.asarray(x[name], dtype=float)).astype(int)])
        return np.column_stack(columns)

    def r(self, x: Mapping[str, np.ndarray]) -> np.ndarray:
        """P(V2I collision | SV collision) at the inputs `x`."""
        return special.expit(self.design(x) @ np.asarray(self.coefficients))

    def to_dict(self) -> dict[str, Any]:
        return {
            "colour_inputs": list(self.colour_inputs),
            "low_contrast": [list(row) for row in self.low_contrast],
            "coefficients": list(self.coefficients),
            "target_share": self.target_share,
            # Only with the term, so that a factor without it serialises as before (session 12).
            **(
                {"v2i_only_coefficients": list(self.v2i_only_coefficients)}
                if self.v2i_only_coefficients
                else {}
            ),
        }

    @staticmethod
    def from_dict(data: Mapping[str, Any]) -> ContrastFactor:
        return ContrastFactor(
            tuple(str(v) for v in data["colour_inputs"]),
            tuple(tuple(int(v) for v in row) for row in data["low_contrast"]),
            tuple(float(v) for v in data["coefficients"]),
            float(data["target_share"]),
            tuple(float(v) for v in data.get("v2i_only_coefficients", ())),
        )


def low_contrast_table(
    clothing_rgb: Any, car_rgb: Any, delta_e_threshold: float
) -> tuple[tuple[int, ...], ...]:
    """`L[i][j]` = 1 where clothing colour i and car colour j differ by less than `delta_e_threshold` (CIE76,
    the cameras' rule: perception/sensors.py)."""
    from pedsafe_sumo.perception.sensors import delta_e_cie76

    clothing, cars = np.asarray(clothing_rgb, dtype=float), np.asarray(car_rgb, dtype=float)
    return tuple(
        tuple(int(delta_e_cie76(colour[None, :], car[None, :])[0] < delta_e_threshold) for car in cars)
        for colour in clothing
    )


@dataclass(frozen=True)
class JointProposal:
    """q ∝ lambda p + (1 - lambda) p h / c over the inputs of `nominal`, h = sqrt(pi_hat) or, with the V2I
    factor, sqrt(a pi_hat + (1 - a) pi_hat r) (module docstring)."""

    nominal: Mapping[str, Family]
    coefficients: tuple[float, ...]
    norm: float
    defensive_share: float
    norm_rel_se: float = 0.0
    #: E_p[pi_hat] and its standard error, on the very NORM_DRAWS nominal draws that give c: the known mean
    #: of the control variate pi_hat (report/tables.py). NaN in proposals stored before it.
    mean_pi_hat: float = math.nan
    mean_pi_hat_se: float = math.nan
    #: The kinematic features' maps (module docstring); None: the design of x alone (proposals stored
    #: before session 8, scenarios that lack a KINEMATIC_INPUTS input).
    kinematics: Kinematics | None = None
    #: The V2I factor (module docstring); None: h = sqrt(pi_hat), the proposal of SV alone.
    v2i_factor: ContrastFactor | None = None
    #: E_p[pi_hat r] and its standard error, V2I's control variate's known mean; NaN without the factor.
    mean_pi_v2i: float = math.nan
    mean_pi_v2i_se: float = math.nan

    is_joint = True

    @property
    def names(self) -> list[str]:
        """Every input the proposal draws (pi_hat's and the V2I factor's), sorted."""
        return sorted(self.nominal)

    @property
    def design_names(self) -> list[str]:
        """The inputs of pi_hat's design: every drawn input but the V2I factor's."""
        factor = set(self.v2i_factor.names) if self.v2i_factor is not None else set()
        return [name for name in self.names if name not in factor]

    @property
    def bound(self) -> float:
        """B >= (q/p)(x) for every x: the rejection step's envelope."""
        return self.defensive_share + (1 - self.defensive_share) / self.norm

    def features(self, x: Mapping[str, np.ndarray]) -> np.ndarray:
        blocks: list[Block] = []
        for name in self.design_names:
            family = self.nominal[name]
            v = np.atleast_1d(np.asarray(x[name], dtype=float))
            if isinstance(family, Categorical):
                blocks.append([(v == k).astype(float) for k in range(1, len(family.probabilities))])
            else:
                mean, sd = _moments(family)
                blocks.append((v - mean) / sd)
        if self.kinematics is not None:
            blocks += self.kinematics.blocks(x)
        return quadratic_design(len(np.atleast_1d(x[self.design_names[0]])), blocks)

    def pi_hat(self, x: Mapping[str, np.ndarray]) -> np.ndarray:
        """The fitted P(SV collision | x) at the inputs `x` (name -> values on the drawn scales)."""
        return special.expit(self.features(x) @ np.asarray(self.coefficients))

    def _pi_and_v2i(self, x: Mapping[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        """(pi_hat, the modelled P(V2I collision)) at `x`, the design built once: pi_hat r, or with the
        V2I-only term min(1, pi_hat r + pi_vo)."""
        if self.v2i_factor is None:
            raise ValueError("this proposal has no V2I factor")
        design = self.features(x)
        pi = special.expit(design @ np.asarray(self.coefficients))
        v2i = pi * self.v2i_factor.r(x)
        if self.v2i_factor.v2i_only_coefficients:
            v2i_only = special.expit(design @ np.asarray(self.v2i_factor.v2i_only_coefficients))
            v2i = np.minimum(1.0, v2i + v2i_only)
        return pi, v2i

    def pi_v2i_hat(self, x: Mapping[str, np.ndarray]) -> np.ndarray:
        """The modelled P(V2I collision | x, z) at the inputs `x` (the V2I factor's): pi_hat r, plus pi_vo
        with the V2I-only term."""
        return self._pi_and_v2i(x)[1]

    def root_pi(self, x: Mapping[str, np.ndarray]) -> np.ndarray:
        """h: sqrt(pi_hat), or with the V2I factor sqrt(a pi_hat + (1 - a) pi_v2i) (module docstring)."""
        if self.v2i_factor is None:
            return np.sqrt(self.pi_hat(x))
        share = self.v2i_factor.target_share
        if not self.v2i_factor.v2i_only_coefficients:  # session 12's expression, to the last bit
            pi = self.pi_hat(x)
            return np.sqrt(pi * (share + (1 - share) * self.v2i_factor.r(x)))
        pi, v2i = self._pi_and_v2i(x)
        return np.sqrt(share * pi + (1 - share) * v2i)

    def q_over_p(self, x: Mapping[str, np.ndarray]) -> np.ndarray:
        lam = self.defensive_share
        return lam + (1 - lam) * self.root_pi(x) / self.norm

    def sample_nominal(self, rng: np.random.Generator, n: int) -> dict[str, np.ndarray]:
        return {name: self.nominal[name].sample(rng, n) for name in self.names}

    def sample(self, rng: np.random.Generator) -> tuple[dict[str, float], float]:
        """One episode's inputs drawn from q by rejection, and ln of their weight p/q."""
        bound = self.bound
        while True:
            x = self.sample_nominal(rng, REJECTION_BLOCK)
            u = rng.random(REJECTION_BLOCK)
            ratio = self.q_over_p(x)
            kept = np.flatnonzero(u * bound < ratio)
            if kept.size:
                k = int(kept[0])
                return {name: float(x[name][k]) for name in self.names}, -math.log(float(ratio[k]))

    def to_json(self) -> str:
        from pedsafe_sumo.sampling.draws import family_to_json

        return json.dumps(
            {
                "kind": KIND,
                "nominal": {name: family_to_json(self.nominal[name]) for name in self.names},
                "coefficients": list(self.coefficients),
                "norm": self.norm,
                "norm_rel_se": self.norm_rel_se,
                "mean_pi_hat": self.mean_pi_hat,
                "mean_pi_hat_se": self.mean_pi_hat_se,
                "defensive_share": self.defensive_share,
                "ridge": RIDGE,
                **({"kinematics": self.kinematics.to_dict()} if self.kinematics is not None else {}),
                **(
                    {
                        "v2i_factor": self.v2i_factor.to_dict(),
                        "mean_pi_v2i": self.mean_pi_v2i,
                        "mean_pi_v2i_se": self.mean_pi_v2i_se,
                    }
                    if self.v2i_factor is not None
                    else {}
                ),
            },
            sort_keys=True,
        )

    @staticmethod
    def from_json(text: str) -> JointProposal:
        from pedsafe_sumo.sampling.draws import family_from_json

        data = json.loads(text)
        if data.get("kind") != KIND:
            raise ValueError("not a joint proposal")
        return JointProposal(
            {name: family_from_json(f) for name, f in data["nominal"].items()},
            tuple(float(v) for v in data["coefficients"]),
            float(data["norm"]),
            float(data["defensive_share"]),
            float(data.get("norm_rel_se", 0.0)),
            float(data.get("mean_pi_hat", math.nan)),
            float(data.get("mean_pi_hat_se", math.nan)),
            Kinematics.from_dict(data["kinematics"]) if "kinematics" in data else None,
            ContrastFactor.from_dict(data["v2i_factor"]) if "v2i_factor" in data else None,
            float(data.get("mean_pi_v2i", math.nan)),
            float(data.get("mean_pi_v2i_se", math.nan)),
        )


def is_joint_json(text: str) -> bool:
    return bool(text) and text.lstrip().startswith("{") and json.loads(text).get("kind") == KIND


def fit_logistic(
    x: np.ndarray, y: np.ndarray, ridge: float = RIDGE, row_weight: np.ndarray | None = None
) -> np.ndarray:
    """Ridge logistic regression (the intercept unpenalised); `row_weight` scales each row's log-likelihood
    (None: every row 1, the sampler's fit)."""
    sw = np.ones(len(y)) if row_weight is None else np.asarray(row_weight, dtype=float)

    def loss(b: np.ndarray) -> tuple[float, np.ndarray]:
        eta = x @ b
        grad = x.T @ (sw * (special.expit(eta) - y))
        grad[1:] += ridge * b[1:]
        nll = float(np.sum(sw * (np.logaddexp(0, eta) - y * eta)))
        return nll + 0.5 * ridge * float(np.sum(b[1:] ** 2)), grad

    return optimize.minimize(loss, np.zeros(x.shape[1]), jac=True, method="L-BFGS-B").x


def margin_column(nominal: Mapping[str, Family]) -> int:
    """The design column of the standardised braking margin's linear term (JointProposal.features: the
    intercept, each input's indicators or z and z^2 in sorted order, then v, 1/w and margin_s)."""
    column = 1
    for name in sorted(nominal):
        family = nominal[name]
        column += len(family.probabilities) - 1 if isinstance(family, Categorical) else 2
    return column + 4


def region_proposal(
    nominal: Mapping[str, Family], kinematics: Kinematics | None, defensive_share: float
) -> JointProposal | None:
    """The guard of a pilot without collisions (module docstring): pi_hat a steep logistic step down at
    margin_s = 0, so that q ≈ lambda p + (1 - lambda) p 1{margin_s < 0} / P_p(margin_s < 0); None where the
    scenario lacks a kinematic input."""
    if kinematics is None or not set(KINEMATIC_INPUTS) <= set(nominal):
        return None
    kinematics = kinematics.with_moments(nominal)
    mean_s, sd_s = kinematics.moments[2]
    shell = JointProposal(dict(nominal), (), 1.0, defensive_share, kinematics=kinematics)
    probe = shell.features(shell.sample_nominal(np.random.default_rng(NORM_SEED), 1))
    coefficients = np.zeros(probe.shape[1])
    # eta = -GUARD_STEEPNESS margin_s / sd: pi_hat = 1/2 at margin_s = 0, sqrt(pi_hat) 4.5e-5 at +0.1 sd.
    coefficients[margin_column(nominal)] = -GUARD_STEEPNESS
    coefficients[0] = -GUARD_STEEPNESS * mean_s / sd_s
    proposal = normalised(nominal, coefficients, defensive_share, kinematics)
    return proposal if proposal.norm > 0 and proposal.bound <= MAX_MEAN_TRIES else None


def fit_joint(
    inputs: Mapping[str, np.ndarray],
    collision: np.ndarray,
    nominal: Mapping[str, Family],
    defensive_share: float,
    ridge: float = RIDGE,
    kinematics: Kinematics | None = None,
) -> JointProposal | None:
    """The joint proposal fitted on pilot rows (`inputs` name -> values, `collision` 0/1); None when the
    rows hold no collision (the next stage then stays nominal) or the envelope would be too loose. With
    `kinematics`, the kinematic features join the design where every KINEMATIC_INPUTS input is drawn."""
    y = np.asarray(collision, dtype=float)
    if not y.any():
        return None
    if kinematics is not None:
        kinematics = kinematics.with_moments(nominal) if set(KINEMATIC_INPUTS) <= set(nominal) else None
    shell = JointProposal(dict(nominal), (), 1.0, defensive_share, kinematics=kinematics)
    proposal = normalised(
        nominal, fit_logistic(shell.features(inputs), y, ridge), defensive_share, kinematics
    )
    if not proposal.norm > 0 or proposal.bound > MAX_MEAN_TRIES:
        return None
    return proposal


def normalised(
    nominal: Mapping[str, Family],
    coefficients: Any,
    defensive_share: float,
    kinematics: Kinematics | None = None,
    v2i_factor: ContrastFactor | None = None,
) -> JointProposal:
    """The proposal of these coefficients with c = E_p[h] and E_p[pi_hat] estimated on NORM_DRAWS nominal
    draws of NORM_SEED (in blocks, so that the design matrix of a million draws is never held at once);
    with `v2i_factor` (whose inputs `nominal` holds), also E_p[pi_hat r] and from both the share a."""
    shell = JointProposal(
        dict(nominal),
        tuple(float(v) for v in coefficients),
        1.0,
        defensive_share,
        kinematics=kinematics,
        v2i_factor=v2i_factor,
    )
    draws = shell.sample_nominal(np.random.default_rng(NORM_SEED), NORM_DRAWS)
    blocks = [
        {name: values[start : start + NORM_BLOCK] for name, values in draws.items()}
        for start in range(0, NORM_DRAWS, NORM_BLOCK)
    ]
    with_only = v2i_factor is not None and bool(v2i_factor.v2i_only_coefficients)
    if with_only:  # pi_hat and pi_v2i from one design per block
        both = [shell._pi_and_v2i(block) for block in blocks]
        pi = np.concatenate([b[0] for b in both])
    else:
        pi = np.concatenate([shell.pi_hat(block) for block in blocks])
    factor_means: dict[str, Any] = {}
    if v2i_factor is None:
        root = np.sqrt(pi)
    elif not v2i_factor.v2i_only_coefficients:
        r = np.concatenate([v2i_factor.r(block) for block in blocks])
        pi_v2i = pi * r
        mean_sv, mean_v2i = float(np.mean(pi)), float(np.mean(pi_v2i))
        share = mean_v2i**2 / (mean_sv**2 + mean_v2i**2) if mean_sv > 0 else 1.0
        root = np.sqrt(pi * (share + (1 - share) * r))
    else:
        pi_v2i = np.concatenate([b[1] for b in both])
        mean_sv, mean_v2i = float(np.mean(pi)), float(np.mean(pi_v2i))
        share = mean_v2i**2 / (mean_sv**2 + mean_v2i**2) if mean_sv > 0 else 1.0
        root = np.sqrt(share * pi + (1 - share) * pi_v2i)
    if v2i_factor is not None:
        factor_means = {
            "v2i_factor": dataclasses.replace(v2i_factor, target_share=float(share)),
            "mean_pi_v2i": mean_v2i,
            "mean_pi_v2i_se": float(np.std(pi_v2i) / math.sqrt(len(pi_v2i))),
        }
    norm = float(np.mean(root))
    rel_se = float(np.std(root) / math.sqrt(len(root)) / norm) if norm > 0 else math.inf
    return JointProposal(
        dict(nominal),
        shell.coefficients,
        norm,
        defensive_share,
        rel_se,
        float(np.mean(pi)),
        float(np.std(pi) / math.sqrt(len(pi))),
        kinematics,
        **factor_means,
    )


def sv_v2i_pairs(rows: pd.DataFrame) -> pd.DataFrame:
    """The pairs of `rows` (both conditions, status ok on both sides) by episode: SV's collision and
    sampler_inputs, V2I's collision as `collision_v2i`."""
    from pedsafe_sumo.sampling.stages import ADAPT_CONDITION

    ok = rows[rows["status"] == "ok"]
    sv = ok[ok["condition"] == ADAPT_CONDITION].set_index("episode")
    v2i = ok[ok["condition"] == V2I_CONDITION].set_index("episode")
    return sv[["collision", "sampler_inputs"]].join(
        v2i[["collision"]].rename(columns={"collision": "collision_v2i"}), how="inner"
    )


def v2i_only_count(rows: pd.DataFrame) -> int:
    """How many pairs of `rows` have a V2I collision and no SV collision (the V2I-only term's data)."""
    pairs = sv_v2i_pairs(rows)
    return int((~pairs["collision"].astype(bool) & pairs["collision_v2i"].astype(bool)).sum())


def v2i_only_engages(n_v2i_only: int, n_v2i: int, defensive_share: float) -> bool:
    """Whether pilot pairs holding `n_v2i_only` V2I-only collisions among `n_v2i` V2I collisions are enough
    for the V2I-only term (module docstring, "Enough")."""
    if n_v2i_only >= GUARD_MIN_COLLISIONS:
        return True
    return n_v2i_only >= V2I_ONLY_MIN_COLLISIONS and n_v2i_only >= defensive_share * n_v2i


def with_v2i_factor(
    proposal: JointProposal,
    rows: pd.DataFrame,
    low_contrast: tuple[tuple[int, ...], ...],
    v2i_only: bool = False,
) -> JointProposal | None:
    """`proposal` with the V2I factor (module docstring) fitted on the pairs of `rows` (pilot rows of both
    conditions) whose SV episode collided; None where they hold fewer than GUARD_MIN_COLLISIONS V2I
    collisions, the scenario draws no clothing or no vehicle colour in every pilot episode, or the
    envelope would be too loose (the proposal of SV alone then stands).

    With `v2i_only`, where the pairs hold enough V2I collisions whose SV episode did not collide
    (`v2i_only_engages`), the factor also carries the V2I-only term pi_vo, a ridge logistic of those on
    every pair over pi_hat's design (module docstring); the factor then applies where either count is
    enough."""
    pairs = sv_v2i_pairs(rows)
    hit = pairs[pairs["collision"].astype(bool)]
    y = hit["collision_v2i"].astype(float).to_numpy()
    y_only = (~pairs["collision"].astype(bool) & pairs["collision_v2i"].astype(bool)).to_numpy(dtype=float)
    n_v2i = int(pairs["collision_v2i"].astype(bool).sum())
    with_only = v2i_only and v2i_only_engages(int(y_only.sum()), n_v2i, proposal.defensive_share)
    if y.sum() < GUARD_MIN_COLLISIONS and not with_only:
        return None
    records = [json.loads(text)["inputs"] for text in pairs["sampler_inputs"]]
    colour_inputs = sorted(
        name for name in records[0] if name.endswith(COLOUR_SUFFIX) and all(name in r for r in records)
    )
    if not colour_inputs or not all(CLOTHING_INPUT in r for r in records):
        return None
    factor = ContrastFactor(tuple(colour_inputs), low_contrast, ())
    hit_records = [json.loads(text)["inputs"] for text in hit["sampler_inputs"]]
    z = {name: np.array([r[name] for r in hit_records], dtype=float) for name in factor.names}
    coefficients = fit_logistic(factor.design(z), y, RIDGE)
    factor = dataclasses.replace(factor, coefficients=tuple(float(b) for b in coefficients))
    if with_only:
        x = {name: np.array([r[name] for r in records], dtype=float) for name in proposal.names}
        only = fit_logistic(proposal.features(x), y_only, RIDGE)
        factor = dataclasses.replace(factor, v2i_only_coefficients=tuple(float(b) for b in only))
    nominal = {**proposal.nominal, **factor.nominal()}
    fitted = normalised(nominal, proposal.coefficients, proposal.defensive_share, proposal.kinematics, factor)
    return fitted if fitted.norm > 0 and fitted.bound <= MAX_MEAN_TRIES else None


def joint_update(
    rows: pd.DataFrame,
    condition: str,
    defensive_share: float,
    kinematics: Kinematics | None = None,
    pilot_stage: bool = False,
    low_contrast: tuple[tuple[int, ...], ...] | None = None,
    v2i_only: bool = False,
) -> tuple[JointProposal | None, int, bool]:
    """The proposal of the next stage from every pilot row so far of `condition` (status ok), their
    collisions, and whether it is the guard's region proposal (a `pilot_stage` with fewer than
    GUARD_MIN_COLLISIONS collisions, where the scenario has the kinematic inputs) rather than the fit.
    With `low_contrast` (the V2I factor's table L), the fit gains the V2I factor where with_v2i_factor
    finds it can (the pairs of `rows` with both conditions), with `v2i_only` its V2I-only term."""
    from pedsafe_sumo.sampling.stages import _inputs_and_nominal

    both = rows
    rows = rows[(rows["condition"] == condition) & (rows["status"] == "ok")]
    inputs, nominal = _inputs_and_nominal(rows)
    y = rows["collision"].astype(float).to_numpy()
    n_collisions = int(y.sum())
    if pilot_stage and kinematics is not None and n_collisions < GUARD_MIN_COLLISIONS:
        region = region_proposal(nominal.families, kinematics, defensive_share)
        if region is not None:
            return region, n_collisions, True
    proposal = fit_joint(inputs, y, nominal.families, defensive_share, kinematics=kinematics)
    if proposal is not None and low_contrast is not None:
        proposal = with_v2i_factor(proposal, both, low_contrast, v2i_only) or proposal
    return proposal, n_collisions, False


def proposal_of_json(text: str) -> Any:
    """A task's proposal: None (nominal), a JointProposal, or the product's families."""
    if not text:
        return None
    if is_joint_json(text):
        return JointProposal.from_json(text)
    from pedsafe_sumo.sampling.draws import product_from_json

    return product_from_json(text).families
