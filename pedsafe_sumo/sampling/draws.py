"""The random inputs of one episode, each drawn through one object that records it with its nominal law.

`Draws` wraps the episode's world Generator. Every per-episode input (the pedestrian's age group, age,
gender, risk type and walking speed, the ego's initial speed, the conflict offset, clothing, occluder
classes and colours, queue gaps, the mid-block distance, the parked and blend gaps, the point of the
signal cycle) is drawn by name through it, and it keeps, per name, the value on the scale of its nominal
family (`sampling.importance`: Normal, Categorical, Beta on an interval) and the family itself.

Without a proposal (plain Monte Carlo, `--sampler mc`) each draw is the plain Generator call of the input's
law, in the order the scenario makes them: the episodes are bit-identical to draws on a bare Generator. With a
proposal (`--sampler is`), an input named in it is drawn from the proposal's family instead, and the
episode's weight is the product of the likelihood ratios p(x) / q(x) of those inputs (every other input
stays nominal and contributes 1). Background traffic has its own stream and is never proposed.

Scales: a log-normal speed is recorded as the standard normal behind it (ego: ln(speed) ~ N(mu, sigma);
walking speed: z ~ N(0, 1) with speed = exp(mu_g + sigma_g z) * gender factor, so one family serves every
age group), a uniform draw on [low, high] as Beta(1, 1) on that interval, a category as its index.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from pedsafe_sumo.sampling.distributions import age_group_speed_distributions
from pedsafe_sumo.sampling.importance import Beta, Categorical, Family, Normal, Product

#: The inputs a proposal may move (when the scenario draws them): those that decide whether the ego and
#: the pedestrian meet and how hard (speeds, timing, the gaps and classes that decide what hides the
#: pedestrian, the age and risk type that decide how they walk and react). The rest (colours, the age
#: within a group, gender, queue gaps further upstream, the signal cycle point) stay nominal: they move
#: the collision rate little, and every proposed input adds variance to the weights.
PROPOSED_INPUTS = (
    "ego_speed_log",
    "ped_walking_speed_z",
    "ped_age_group",
    "ped_risk",
    "conflict_offset_s",
    "midblock_distance_m",
    "parked_gap_m",
    "blend_gap_m",
    "occluder_0.class",
    "occluder_1.class",
    "waiting_0.class",
)


class Draws:
    """Named draws from `rng`, each recorded with its nominal family (module docstring).

    With a proposal q and a defensive share lambda > 0, the episode is drawn from the defensive mixture
    lambda p + (1 - lambda) q (Hesterberg 1995, "Weighted average importance sampling and defensive
    mixture distributions"): one extra uniform draw first picks the nominal (every input by its native
    call) or the proposal, and the weight is p / (lambda p + (1 - lambda) q) = 1 / (lambda + (1 - lambda)
    q/p), at most 1/lambda. Without it a proposal narrower than sqrt(1/2) times the nominal's spread in an
    input the event does not constrain gives weights of infinite variance (E_q[(p/q)^2] diverges), and
    the cross-entropy fit on a few elite episodes narrows every input.
    """

    def __init__(
        self,
        rng: np.random.Generator,
        proposal: Mapping[str, Family] | Any | None = None,
        defensive_share: float = 0.0,
    ) -> None:
        self.rng = rng
        #: A joint proposal (sampling/joint.py): every input it names is drawn up front, jointly, by
        #: rejection from the nominal with this Generator; it carries its own defensive share and weight.
        self.joint = proposal if getattr(proposal, "is_joint", False) else None
        self._joint_inputs: dict[str, float] = {}
        self._joint_log_weight = 0.0
        if self.joint is not None:
            self._joint_inputs, self._joint_log_weight = self.joint.sample(rng)
            proposal, defensive_share = None, 0.0
        self.proposal: Mapping[str, Family] = proposal or {}
        #: name -> the input on its nominal family's scale, in the order drawn.
        self.inputs: dict[str, float] = {}
        #: name -> nominal family (None: a constant, e.g. a uniform range of width 0).
        self.nominals: dict[str, Family | None] = {}
        #: sum over the proposed inputs of ln p(x) - ln q(x).
        self.log_ratio = 0.0
        self.defensive_share = float(defensive_share) if self.proposal else 0.0
        #: Whether this episode's inputs come from the nominal branch of the defensive mixture.
        self.nominal_branch = bool(self.defensive_share > 0 and rng.random() < self.defensive_share)

    @property
    def log_weight(self) -> float:
        """ln of the likelihood ratio of the episode's inputs (0 without a proposal)."""
        if self.joint is not None:
            return self._joint_log_weight
        if self.defensive_share <= 0:
            return self.log_ratio
        lam = self.defensive_share
        # -ln(lam + (1 - lam) exp(-log_ratio)), computed without overflow.
        return -float(np.logaddexp(math.log(lam), math.log1p(-lam) - self.log_ratio))

    @property
    def weight(self) -> float:
        """The likelihood ratio p(x) / q(x) of the episode's inputs (1 without a proposal)."""
        return math.exp(self.log_weight)

    def draw(
        self,
        name: str,
        nominal: Family | None,
        native: Callable[[np.random.Generator], Any],
        encode: Callable[[Any], float] = float,
        decode: Callable[[float], Any] = float,
    ) -> Any:
        """One input: `native(rng)` (the nominal draw as the code always made it) unless the proposal
        names it; `encode` maps a native value onto the family's scale, `decode` back."""
        if name in self.inputs:
            raise ValueError(f"input '{name}' drawn twice in one episode")
        if self.joint is not None and nominal is not None and name in self._joint_inputs:
            if family_to_json(nominal) != family_to_json(self.joint.nominal[name]):
                raise ValueError(f"input '{name}': its nominal law differs from the joint proposal's")
            x = self._joint_inputs[name]
            self.inputs[name] = x
            self.nominals[name] = nominal
            return decode(x)
        q = self.proposal.get(name) if nominal is not None else None
        if q is None or self.nominal_branch:
            value = native(self.rng)
            x = float(encode(value))
        else:
            x = float(q.sample(self.rng, 1)[0])
            value = decode(x)
        if q is not None:
            point = np.array([x])
            self.log_ratio += float(nominal.log_pdf(point)[0] - q.log_pdf(point)[0])
        self.inputs[name] = x
        self.nominals[name] = nominal
        return value

    # ------------------------------------------------------------ the draws the scenarios make
    def uniform(self, name: str, low: float, high: float) -> float:
        """rng.uniform(low, high); nominal Beta(1, 1) on [low, high] (a constant when high <= low)."""
        nominal = Beta(1.0, 1.0, float(low), float(high)) if high > low else None
        return self.draw(name, nominal, lambda rng: float(rng.uniform(low, high)))

    def index(self, name: str, n: int) -> int:
        """int(rng.integers(n)): one of n equally likely categories."""
        return self.draw(name, Categorical((1.0 / n,) * n), lambda rng: int(rng.integers(n)), decode=int)

    def choice(self, name: str, probabilities: np.ndarray) -> int:
        """int(rng.choice(len(p), p=p / p.sum())): a category by its probabilities."""
        p = np.asarray(probabilities, dtype=float) / float(np.sum(probabilities))
        return self.draw(
            name,
            Categorical(tuple(float(v) for v in p)),
            lambda rng: int(rng.choice(len(p), p=p)),
            decode=int,
        )

    def uniform_source(self, name: str) -> _UniformSource:
        """A stand-in for the Generator where a callee makes one rng.uniform(0, 1) draw (signal staging)."""
        return _UniformSource(self, name)

    # ------------------------------------------------------------ records
    def record(self) -> dict[str, Any]:
        """The episode's inputs, the nominal families of those a proposal may move, and the log weight, as
        JSON-able data (episodes.parquet's sampler_inputs; the cross-entropy stages refit on them)."""
        nominal = {
            name: family_to_json(family)
            for name, family in self.nominals.items()
            if name in PROPOSED_INPUTS and family is not None
        }
        return {"inputs": self.inputs, "nominal": nominal, "log_weight": self.log_weight}


class _UniformSource:
    def __init__(self, draws: Draws, name: str) -> None:
        self._draws, self._name = draws, name

    def uniform(self, low: float, high: float) -> float:
        return self._draws.uniform(self._name, low, high)


def as_draws(rng: np.random.Generator | Draws) -> Draws:
    """`rng` itself when it is a Draws, else a nominal Draws around the Generator (callers that pass a
    bare Generator get the values its own calls would give)."""
    return rng if isinstance(rng, Draws) else Draws(rng)


def draw_pedestrian_traits(draws: Draws, pedestrians: Mapping[str, Any]) -> dict[str, Any]:
    """One pedestrian of the age-group mixture, through `draws`: the same Generator calls in the same
    order as pedsafe_sumo.demand.sampling.sample_pedestrians(rng, pedestrians, 1) (group, risk type,
    gender, age, walking speed), so that under no proposal the pedestrian is the same."""
    groups = list(pedestrians["age_groups"].items())
    weights = np.array([g["weight_share"] for _, g in groups], dtype=float)
    group_p = weights / weights.sum()
    group_index = draws.draw(
        "ped_age_group",
        Categorical(tuple(float(v) for v in group_p)),
        lambda rng: int(rng.choice(len(groups), size=1, p=group_p)[0]),
        decode=int,
    )
    risk_types = ("unaware", "hasten", "yield")
    risk_p = np.array([pedestrians[f"risk_share_{r}"] for r in risk_types], dtype=float)
    risk_p = risk_p / risk_p.sum()
    risk_index = draws.draw(
        "ped_risk",
        Categorical(tuple(float(v) for v in risk_p)),
        lambda rng: int(rng.choice(len(risk_types), size=1, p=risk_p)[0]),
        decode=int,
    )
    female_share = float(pedestrians["gender_female_share"])
    female = bool(
        draws.draw(
            "ped_female",
            Categorical((1.0 - female_share, female_share)),
            lambda rng: int(rng.random(1)[0] < female_share),
            decode=int,
        )
    )
    name, group = groups[group_index]
    age_min, age_max = int(group["age_min_years"]), int(group["age_max_years"])
    n_ages = age_max - age_min + 1
    age_years = draws.draw(
        "ped_age_in_group",
        Categorical((1.0 / n_ages,) * n_ages),
        lambda rng: int(rng.integers(age_min, age_max + 1)),
        encode=lambda age: age - age_min,
        decode=lambda x: age_min + int(x),
    )
    speed = age_group_speed_distributions(dict(pedestrians))[name]
    lognormal_mps = draws.draw(
        "ped_walking_speed_z",
        Normal(0.0, 1.0),
        lambda rng: float(rng.lognormal(mean=speed.log_mu, sigma=speed.log_sigma, size=1)[0]),
        encode=lambda v: (math.log(v) - speed.log_mu) / speed.log_sigma,
        decode=lambda z: math.exp(speed.log_mu + speed.log_sigma * z),
    )
    factor = pedestrians["speed_factor_female" if female else "speed_factor_male"]
    return {
        "age_years": int(age_years),
        "gender": "f" if female else "m",
        "risk": risk_types[risk_index],
        "walking_speed_mps": float(lognormal_mps) * factor,
    }


def draw_lognormal(draws: Draws, name: str, log_mu: float, log_sigma: float) -> float:
    """rng.lognormal(log_mu, log_sigma, 1)[0] (a Lognormal fit's sample), recorded as ln(x) ~ N(mu, sigma)."""
    return draws.draw(
        name,
        Normal(log_mu, log_sigma),
        lambda rng: float(rng.lognormal(mean=log_mu, sigma=log_sigma, size=1)[0]),
        encode=math.log,
        decode=math.exp,
    )


# ---------------------------------------------------------------- (de)serialising families
def family_to_json(family: Family) -> dict[str, Any]:
    if isinstance(family, Normal):
        return {"family": "normal", "mean": family.mean, "sd": family.sd}
    if isinstance(family, Categorical):
        return {"family": "categorical", "probabilities": list(family.probabilities)}
    return {"family": "beta", "a": family.a, "b": family.b, "low": family.low, "high": family.high}


def family_from_json(data: Mapping[str, Any]) -> Family:
    kind = data.get("family")
    if kind == "normal":
        return Normal(float(data["mean"]), float(data["sd"]))
    if kind == "categorical":
        return Categorical(tuple(float(v) for v in data["probabilities"]))
    if kind == "beta":
        return Beta(float(data["a"]), float(data["b"]), float(data["low"]), float(data["high"]))
    raise ValueError(f"unknown family {kind!r}")


def product_to_json(product: Product) -> str:
    """A proposal as canonical JSON (sorted names), as run.json and the tasks carry it."""
    return json.dumps(
        {name: family_to_json(f) for name, f in sorted(product.families.items())}, sort_keys=True
    )


def product_from_json(text: str) -> Product:
    return Product({name: family_from_json(f) for name, f in json.loads(text).items()} if text else {})
