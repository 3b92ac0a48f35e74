"""A joint proposal over the episode's proposable inputs, learned from the pilot stages (`--is-family joint`).

The cross-entropy stages fit a product of one family per input; a collision is a joint condition (a fast
ego with an early, fast pedestrian), and the product puts mass on combinations that do not collide
(docs/sampling.md, "A joint proposal"). For an event that stays random given the inputs x,
with pi(x) = P(collision | x), the proposal of least variance is q ∝ p sqrt(pi) (Owen, Monte Carlo theory,
methods and examples, 2013, section 9.1). Here

    q(x) = lambda p(x) + (1 - lambda) p(x) sqrt(pi_hat(x)) / c,     c = E_p[sqrt(pi_hat)],

with pi_hat a ridge logistic regression of the SV collision on the pilots' inputs (each continuous input
standardised by its nominal's mean and sd, its square and the pairwise products; categories as
indicators), lambda the defensive share. pi is a conditional probability, so the rows of every pilot stage
pool unweighted, whatever proposal drew them. The fit from the pilot rows, and the guard that replaces it
while the pilots hold few collisions: sampling/joint_fit.py. With the V2I factor (sampling/v2i_factor.py)
sqrt(pi_hat) becomes h, which also aims at V2I's collisions; h <= 1 still.

Drawing: by rejection from the nominal, with the episode's own Generator: a block of candidate vectors is
drawn from the nominal families (in the order of the sorted input names), each kept with probability
(q/p)(x) / B where B = lambda + (1 - lambda) / c >= q/p (sqrt(pi_hat) <= 1); the first kept one is the
episode's. Its weight is p/q = 1 / (lambda + (1 - lambda) sqrt(pi_hat(x)) / c), at most 1/lambda.

Kinematic features: where the scenario draws the ego's speed, the pedestrian's walking speed and the
conflict offset, three functions of x are appended to the design as further continuous inputs (their
squares and their products with every continuous input): the ego's speed v = clip(exp(ego_speed_log)) to the
scenario's bounds (before the approach's speed-limit scale), the pedestrian's time per metre 1/w with w =
exp(mu_g + sigma_g z) of the age group's lognormal (before the sex factor), and the braking margin

    margin_s = conflict_offset_s + VISIBLE_M / w - t_r - v / (2 a_max)

(the seconds left, from the pedestrian's coming into view VISIBLE_M before the ego lane's centre, beyond the
stack's reaction time t_r and the time a full stop from v at a_max takes: negative, no stop before the
conflict point; scenarios/placements/ stages the ego to reach the conflict point conflict_offset_s after
the pedestrian). Each is standardised by its moments on MOMENT_DRAWS nominal draws. They are features of a
fit, not a model of the episode: a wrong VISIBLE_M or t_r costs efficiency, never bias (the weights are
exact whatever pi_hat is). Offline on the rows of paper-v5's 10,000-pair MC run, with a 2-stage pilot, they
raise the efficiency per final episode: right_turn 11.5 -> 19.2, crossing 19.5 -> 55, background_blending
5.0 -> 6.3, jaywalking 4.9 -> 5.4.

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
from scipy import optimize, special

from pedsafe_sumo.sampling.draws import family_from_json, family_to_json, product_from_json
from pedsafe_sumo.sampling.importance import Beta, Categorical, Family, Normal

KIND = "joint"
#: Ridge penalty on the standardised features: research/is_limits.py's value, fixed before the measurement at
#: pilot size and not tuned on it.
RIDGE = 1.0
#: Nominal draws that estimate c = E_p[sqrt(pi_hat)]: relative standard error about 1e-3 for the four
#: Xueqing scenarios (stored per proposal).
NORM_DRAWS = 1_000_000
#: Any fixed seed: the estimate of c must not depend on the run, worker or resume.
NORM_SEED = 17_2026
#: Nominal draws per block of that estimate.
NORM_BLOCK = 100_000
#: The condition whose collisions the V2I factor models (sampling/v2i_factor.py), and the inputs it draws: the
#: pedestrian's clothing and every vehicle colour the scenario draws (names ending in COLOUR_SUFFIX).
V2I_CONDITION = "v2i"
CLOTHING_INPUT = "clothing"
COLOUR_SUFFIX = ".colour"
#: The inputs the kinematic features need (module docstring); a scenario without one of them fits on x alone.
KINEMATIC_INPUTS = ("conflict_offset_s", "ego_speed_log", "ped_age_group", "ped_walking_speed_z")
#: An assumption, not a measurement: SUMO's default lane width 3.2 m less half a car's width 0.9 m, the
#: distance from an occluder's lane-side flank to the ego lane's centre. Offline the efficiency hardly
#: moves between 1.6 and 3.2 m (the separate 1/w feature absorbs it).
VISIBLE_M = 2.3
#: Nominal draws (of NORM_SEED + 1) that give the kinematic features' means and standard deviations.
MOMENT_DRAWS = 100_000
#: The guard (sampling/joint_fit.py): a pilot stage whose pooled pilot rows hold fewer SV collisions than
#: this draws from the region proposal (margin_s < 0) instead of a fit on a handful of collisions; the
#: V2I factor needs as many V2I collisions. A threshold fixed before the offline scores of the guard's
#: variants were seen, not tuned on them.
GUARD_MIN_COLLISIONS = 5
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
    (sampling/v2i_factor.py, which fits it)."""

    #: The vehicle colour inputs, sorted; the clothing is CLOTHING_INPUT.
    colour_inputs: tuple[str, ...]
    #: L[clothing][car colour]: 1 where the two are within the roadside camera's contrast threshold.
    low_contrast: tuple[tuple[int, ...], ...]
    #: b_0, then one b_k per colour input.
    coefficients: tuple[float, ...]
    #: a of h = sqrt(a pi_hat + (1 - a) pi_hat r); NaN until the proposal is normalised.
    target_share: float = math.nan
    #: The V2I-only term (sampling/v2i_factor.py): coefficients of pi_vo on pi_hat's design; () without it.
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
            # Only with the term: a factor without it serialises to the JSON that runs of
            # --is-v2i-factor contrast store, so that they keep their identity.
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


@dataclass(frozen=True)
class JointProposal:
    """q ∝ lambda p + (1 - lambda) p h / c over the inputs of `nominal`, h = sqrt(pi_hat) or, with the V2I
    factor, sqrt(a pi_hat + (1 - a) pi_hat r) (module docstring; sampling/v2i_factor.py)."""

    nominal: Mapping[str, Family]
    coefficients: tuple[float, ...]
    norm: float
    defensive_share: float
    norm_rel_se: float = 0.0
    #: E_p[pi_hat] and its standard error, on the very NORM_DRAWS nominal draws that give c: the known mean
    #: of the control variate pi_hat (report/tables.py). NaN in a stored proposal without it.
    mean_pi_hat: float = math.nan
    mean_pi_hat_se: float = math.nan
    #: The kinematic features' maps (module docstring); None: the design of x alone (a stored proposal
    #: without them, a scenario that lacks a KINEMATIC_INPUTS input).
    kinematics: Kinematics | None = None
    #: The V2I factor (sampling/v2i_factor.py); None: h = sqrt(pi_hat), the proposal of SV alone.
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
        """h: sqrt(pi_hat), or with the V2I factor sqrt(a pi_hat + (1 - a) pi_v2i) (v2i_factor.py)."""
        if self.v2i_factor is None:
            return np.sqrt(self.pi_hat(x))
        share = self.v2i_factor.target_share
        # Without the V2I-only term, pi (a + (1 - a) r) rather than a pi + (1 - a) pi r: the two differ in
        # the last bit, and the runs of --is-v2i-factor contrast draw with this one.
        if not self.v2i_factor.v2i_only_coefficients:
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


def proposal_of_json(text: str) -> Any:
    """A task's proposal: None (nominal), a JointProposal, or the product's families."""
    if not text:
        return None
    if is_joint_json(text):
        return JointProposal.from_json(text)
    return product_from_json(text).families
