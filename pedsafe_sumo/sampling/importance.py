"""Importance sampling for rare events, with proposals adapted by the cross-entropy method.

The quantity is an expectation under the nominal distribution p of an episode's random inputs x,
mu = E_p[f(x)] (f: collision indicator, injury probability, conflict indicator). Drawing x from a
proposal q instead and weighting each draw by the likelihood ratio w(x) = p(x) / q(x) gives the
unbiased estimator mu_hat = (1/n) sum w_i f(x_i) (Owen 2013, "Monte Carlo theory, methods and
examples", ch. 9). Its 95% interval is the central-limit one on the products w_i f(x_i); the
effective sample size is ESS = (sum w)^2 / sum w^2 (Kong 1992), which equals n under plain Monte
Carlo (every w = 1).

The proposal is a product of independent one-dimensional families, one per random input, each from
the same family as the nominal (normal, log-normal, categorical, beta on an interval), so that the
weight is a product of density ratios computed in closed form. The cross-entropy method (Rubinstein
& Kroese 2004, "The cross-entropy method", algorithm 3.4.1; de Boer et al. 2005, "A tutorial on the
cross-entropy method") adapts it in pilot stages: draw n from the current proposal, keep the elite
(performance S(x) at or above the stage's level gamma_t = min(gamma, the (1 - rho) quantile of S)),
refit each family by weighted maximum likelihood on the elite with weights p/q (smoothed with the
previous parameters, the spread kept above a fraction of the nominal's), until the level
reaches the rare event's threshold gamma. The proposal is then fixed for the final stage. Every
pilot draw is an episode run and is counted in the cost.

Everything here is pure numpy/scipy over arrays: the batch (episodes), the toy problems of the tests
(a Gaussian tail) and any other caller use the same code.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace

import numpy as np
from scipy import special, stats

#: Smallest probability a categorical proposal keeps for any category (so that no category the
#: nominal can produce becomes impossible under the proposal, which would bias the estimator).
MIN_CATEGORY_PROBABILITY = 0.01
#: Beta shape parameters are kept in this range when refitted (a degenerate beta is a point mass).
BETA_SHAPE_RANGE = (0.2, 200.0)
#: A proposal's spread never falls below this fraction of the nominal's (sd of a normal; the
#: equivalent for a beta). Each CE stage refits on the top draws of the previous proposal, which are
#: narrower than it: unchecked, the spread shrinks geometrically and the final weights become
#: heavy-tailed (seen on the Gaussian tail: sd 0.02 after 8 stages, estimates off by a factor 3).
MIN_SPREAD_OF_NOMINAL = 0.2
#: The floor below which a normal proposal's weights have infinite variance where the event does not
#: bound the input: E_q[(p/q)^2] is finite only for sd_q > sd_p / sqrt(2) (Owen 2013, example 9.2 for
#: the normal family). The batch's default floor (--is-min-spread); the toy of the tests showed the
#: geometric narrowing under 0.2: a proposal 0.2 sd wide that stops short of the event leaves its
#: collisions to the defensive branch (weights near 10).
SQRT_HALF = math.sqrt(0.5)
#: CE smoothing: new parameters = alpha * fitted + (1 - alpha) * previous (de Boer et al. 2005 advise
#: 0.4 <= alpha <= 0.9).
SMOOTHING_ALPHA = 0.7


@dataclass(frozen=True)
class Normal:
    """Normal(mean, sd); the log-normal of a speed is this family on log(speed)."""

    mean: float
    sd: float

    def sample(self, rng: np.random.Generator, n: int) -> np.ndarray:
        return rng.normal(self.mean, self.sd, n)

    def log_pdf(self, x: np.ndarray) -> np.ndarray:
        return stats.norm.logpdf(x, self.mean, self.sd)

    def refit(self, x: np.ndarray, w: np.ndarray) -> Normal:
        """Weighted MLE (the CE update for the normal family, Rubinstein & Kroese 2004 eq. 3.42)."""
        mean = float(np.sum(w * x) / np.sum(w))
        sd = float(math.sqrt(np.sum(w * (x - mean) ** 2) / np.sum(w)))
        return Normal(mean, sd)

    def smoothed(
        self, fitted: Normal, alpha: float, nominal: Normal, min_spread: float = MIN_SPREAD_OF_NOMINAL
    ) -> Normal:
        sd = alpha * fitted.sd + (1 - alpha) * self.sd
        mean = alpha * fitted.mean + (1 - alpha) * self.mean
        return Normal(mean, max(sd, min_spread * nominal.sd))


@dataclass(frozen=True)
class Categorical:
    """A draw of one of `len(probabilities)` categories (index 0..k-1)."""

    probabilities: tuple[float, ...]

    def sample(self, rng: np.random.Generator, n: int) -> np.ndarray:
        p = np.asarray(self.probabilities, dtype=float)
        return rng.choice(len(p), size=n, p=p / p.sum()).astype(float)

    def log_pdf(self, x: np.ndarray) -> np.ndarray:
        p = np.asarray(self.probabilities, dtype=float)
        return np.log(p / p.sum())[np.asarray(x, dtype=int)]

    def refit(self, x: np.ndarray, w: np.ndarray) -> Categorical:
        k = len(self.probabilities)
        counts = np.bincount(np.asarray(x, dtype=int), weights=w, minlength=k)
        p = counts / counts.sum()
        return Categorical(tuple(float(v) for v in p))

    def smoothed(
        self,
        fitted: Categorical,
        alpha: float,
        nominal: Categorical,
        min_spread: float = MIN_SPREAD_OF_NOMINAL,
    ) -> Categorical:
        p = alpha * np.asarray(fitted.probabilities) + (1 - alpha) * np.asarray(self.probabilities)
        p = np.maximum(p / p.sum(), MIN_CATEGORY_PROBABILITY)
        return Categorical(tuple(float(v) for v in p / p.sum()))


@dataclass(frozen=True)
class Beta:
    """Beta(a, b) stretched onto [low, high]; Beta(1, 1) is the uniform draw of a scenario's range."""

    a: float
    b: float
    low: float
    high: float

    def sample(self, rng: np.random.Generator, n: int) -> np.ndarray:
        return self.low + (self.high - self.low) * rng.beta(self.a, self.b, n)

    def log_pdf(self, x: np.ndarray) -> np.ndarray:
        width = self.high - self.low
        return stats.beta.logpdf((np.asarray(x) - self.low) / width, self.a, self.b) - math.log(width)

    def refit(self, x: np.ndarray, w: np.ndarray) -> Beta:
        """Weighted method of moments (a closed-form stand-in for the beta MLE, as CE practice uses)."""
        u = (np.asarray(x) - self.low) / (self.high - self.low)
        m = float(np.sum(w * u) / np.sum(w))
        v = float(np.sum(w * (u - m) ** 2) / np.sum(w))
        m = min(max(m, 1e-3), 1 - 1e-3)
        v = max(v, 1e-4)
        common = m * (1 - m) / v - 1
        lo, hi = BETA_SHAPE_RANGE
        if common <= 0:  # spread wider than any beta with this mean: fall back to the flattest one
            common = 2.0
        return replace(self, a=float(np.clip(m * common, lo, hi)), b=float(np.clip((1 - m) * common, lo, hi)))

    def smoothed(
        self, fitted: Beta, alpha: float, nominal: Beta, min_spread: float = MIN_SPREAD_OF_NOMINAL
    ) -> Beta:
        lo, hi = BETA_SHAPE_RANGE
        a = alpha * fitted.a + (1 - alpha) * self.a
        b = alpha * fitted.b + (1 - alpha) * self.b
        # Concentration a + b is the beta's inverse spread: cap it relative to the nominal's, as the
        # normal's sd is floored.
        cap = (nominal.a + nominal.b) / min_spread**2
        if a + b > cap:
            a, b = a * cap / (a + b), b * cap / (a + b)
        return replace(self, a=float(np.clip(a, lo, hi)), b=float(np.clip(b, lo, hi)))


Family = Normal | Categorical | Beta


@dataclass(frozen=True)
class Product:
    """Independent families, one per named random input: a nominal or a proposal distribution."""

    families: Mapping[str, Family]

    def sample(self, rng: np.random.Generator, n: int) -> dict[str, np.ndarray]:
        # A fixed order of draws (sorted names): the same rng gives the same inputs on any machine.
        return {name: self.families[name].sample(rng, n) for name in sorted(self.families)}

    def log_pdf(self, inputs: Mapping[str, np.ndarray]) -> np.ndarray:
        return sum(self.families[name].log_pdf(np.asarray(inputs[name])) for name in self.families)

    def refit(
        self,
        inputs: Mapping[str, np.ndarray],
        w: np.ndarray,
        alpha: float,
        nominal: Product,
        min_spread: float = MIN_SPREAD_OF_NOMINAL,
    ) -> Product:
        """The CE update: weighted MLE per family, smoothed with the current parameters, the spread kept at
        least `min_spread` times the nominal's."""
        return Product(
            {
                name: fam.smoothed(
                    fam.refit(np.asarray(inputs[name]), w), alpha, nominal.families[name], min_spread
                )
                for name, fam in self.families.items()
            }
        )


def likelihood_ratio(nominal: Product, proposal: Product, inputs: Mapping[str, np.ndarray]) -> np.ndarray:
    """w = p(x) / q(x) for each draw, computed in logs (products of small densities underflow)."""
    if set(nominal.families) != set(proposal.families):
        raise ValueError("the nominal and the proposal must describe the same inputs")
    return np.exp(nominal.log_pdf(inputs) - proposal.log_pdf(inputs))


@dataclass(frozen=True)
class Estimate:
    """An importance-sampling estimate of E_p[f] with its interval and effective sample size."""

    mean: float
    low: float
    high: float
    n: int
    ess: float


def no_event_bound(samples: Sequence[tuple[int, float]], confidence: float = 0.95) -> float:
    """Upper bound on E_p[f], f in [0, 1], when none of the draws of `samples` had f != 0: each sample is
    (n_t, W_t), n_t draws from a proposal q_t whose weight p/q_t never exceeds W_t (1 for the nominal,
    1/lambda for a defensive mixture of share lambda). NaN where some W_t is unknown (NaN or infinite).

    Under q_t the event {f != 0} has probability at least P / W_t (P = P_p(f != 0) >= E_p[f]), so no event
    in all the draws has probability at most exp(-P sum_t n_t / W_t), whatever the stages' proposals were
    adapted from (the bound holds given each stage's past). Setting that to alpha/2 gives

        P <= -ln(alpha/2) / sum_t (n_t / W_t),

    the rule of three (Hanley & Lippman-Hand 1983) on n_t / W_t equivalent nominal draws. With every weight
    1 it is the rule of three on n.
    """
    alpha = 1.0 - confidence
    total = 0.0
    for n, max_weight in samples:
        if not (math.isfinite(max_weight) and max_weight > 0):
            return math.nan
        total += n / max_weight
    return -math.log(alpha / 2) / total if total > 0 else math.nan


def is_estimate(
    values: np.ndarray,
    weights: np.ndarray | None = None,
    confidence: float = 0.95,
    max_weight: float = math.nan,
) -> Estimate:
    """Unbiased estimate (1/n) sum w f, a central-limit interval on the products w f, and the ESS.

    With every weight 1 this is plain Monte Carlo. When no draw has f != 0, the sample variance is 0
    and the central-limit interval would be [0, 0] as if certain; then the upper end is
    no_event_bound's -ln(alpha/2) W / n, with `max_weight` W a known bound on the weights p/q (f takes
    values in [0, 1]: indicators and probabilities). Without one (NaN), it is -ln(alpha/2) / ESS, the
    rule of three on the effective sample, which can fall below the truth when
    the event lies where q/p is lower than n / ESS (docs/sampling.md, "No event").
    """
    f = np.asarray(values, dtype=float)
    w = np.ones_like(f) if weights is None else np.asarray(weights, dtype=float)
    if f.shape != w.shape:
        raise ValueError(f"values and weights differ in shape: {f.shape} and {w.shape}")
    n = len(f)
    if n == 0:
        return Estimate(math.nan, math.nan, math.nan, 0, 0.0)
    products = w * f
    mean = float(np.mean(products))
    ess = float(np.sum(w) ** 2 / np.sum(w**2)) if np.any(w > 0) else 0.0
    if n == 1:
        return Estimate(mean, math.nan, math.nan, 1, ess)
    alpha = 1.0 - confidence
    if not np.any(products != 0):
        bound = no_event_bound([(n, max_weight)], confidence)
        return Estimate(0.0, 0.0, bound if math.isfinite(bound) else -math.log(alpha / 2) / ess, n, ess)
    z = float(special.ndtri(1.0 - alpha / 2))
    half = z * float(np.std(products, ddof=1)) / math.sqrt(n)
    return Estimate(mean, mean - half, mean + half, n, ess)


@dataclass(frozen=True)
class Stage:
    """One stage of the cross-entropy adaptation: the proposal it drew from and what it drew."""

    proposal: Product
    inputs: dict[str, np.ndarray]
    weights: np.ndarray
    scores: np.ndarray
    level: float


@dataclass
class CrossEntropyResult:
    """The fixed proposal after the pilot stages, and the stages (every one of their draws was run)."""

    proposal: Product
    stages: list[Stage] = field(default_factory=list)

    @property
    def pilot_draws(self) -> int:
        return sum(len(stage.scores) for stage in self.stages)


def cross_entropy(
    nominal: Product,
    score: Callable[[dict[str, np.ndarray]], np.ndarray],
    threshold: float,
    rng: np.random.Generator,
    draws_per_stage: int,
    elite_fraction: float = 0.1,
    max_stages: int = 10,
    smoothing: float = SMOOTHING_ALPHA,
) -> CrossEntropyResult:
    """Adapt a proposal for the rare event {score(x) >= threshold} under `nominal` (module docstring).

    `score` maps a batch of inputs (name -> array of draws) to one performance value per draw (for an
    episode: e.g. minus the closest approach, so that a collision is the largest). Stops when a
    stage's level reaches the threshold, plus one stage (the proposal then makes the event common), or
    after `max_stages`, and returns the last refitted proposal.
    """
    if not 0.0 < elite_fraction < 1.0:
        raise ValueError(f"elite_fraction must lie in (0, 1), got {elite_fraction}")
    if draws_per_stage < 10:
        raise ValueError(f"draws_per_stage must be at least 10, got {draws_per_stage}")
    proposal = nominal
    result = CrossEntropyResult(nominal)
    reached = 0
    for _ in range(max_stages):
        inputs = proposal.sample(rng, draws_per_stage)
        weights = likelihood_ratio(nominal, proposal, inputs)
        scores = np.asarray(score(inputs), dtype=float)
        level = min(threshold, float(np.quantile(scores, 1.0 - elite_fraction)))
        result.stages.append(Stage(proposal, inputs, weights, scores, level))
        elite = scores >= level
        elite_inputs = {name: values[elite] for name, values in inputs.items()}
        proposal = proposal.refit(elite_inputs, weights[elite], smoothing, nominal)
        result.proposal = proposal
        if level >= threshold:
            reached += 1
            # The first stage to reach the threshold refits on the few of its draws in the event; one
            # more stage drawn from that proposal, centred on the event, estimates the event's own
            # spread (without it the proposal is too narrow and the weights heavy-tailed).
            if reached == 2:
                break
    return result
