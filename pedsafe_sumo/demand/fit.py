"""Maximum-likelihood fits of the traffic distributions from observations (`tools/fit_distributions`).

Input: a CSV with a `headway_s` column (same-lane time headways, s) and/or a `speed_mps` column (spot speeds,
m/s), optionally a `location` column (`intersection` or `non_intersection`) saying where each speed was
observed. Empty cells are skipped (a row may carry only a headway or only a speed).

Fits, as in the paper (eqs. 1-3):
- headway ~ Exponential(rate): MLE rate = 1 / mean; exact 95% interval from 2 * rate * sum(h) ~ chi2(2n).
- speed ~ Lognormal(mu, sigma) of ln(m/s): MLE mu = mean(ln v), sigma = sqrt(mean((ln v - mu)^2));
  95% intervals from the normal theory of ln v (t for mu, chi-square for sigma).
Goodness of fit: one-sample Kolmogorov-Smirnov statistic and p-value against the fitted distribution. The
parameters are estimated from the same data, so the p-value is conservative (Lilliefors); the statistic is the
number to compare between fits.

Output: a table on stdout and a parameter TOML holding the fitted `[traffic]` keys, which the demand generator
reads with `--params`.
"""

from __future__ import annotations

import argparse
import csv
import math
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy import stats

from pedsafe_sumo.params import ParameterError, load_params

LOCATIONS = {
    "intersection": "intersection",
    "non_intersection": "nonintersection",
    "nonintersection": "nonintersection",
    "non-intersection": "nonintersection",
}
#: Speed keys of the `[traffic]` section, per location.
SPEED_KEYS = {
    loc: (f"speed_{loc}_log_mu", f"speed_{loc}_log_sigma") for loc in ("nonintersection", "intersection")
}
CONFIDENCE = 0.95


class FitError(ValueError):
    """The observations cannot be fitted (bad CSV); the message is one line naming the problem."""


@dataclass(frozen=True)
class ParameterEstimate:
    name: str  # the [traffic] key it becomes
    value: float
    ci_low: float
    ci_high: float


@dataclass(frozen=True)
class FitResult:
    """One fitted distribution: its parameters with intervals and the KS goodness of fit."""

    variable: str  # e.g. "headway_s", "speed_mps (non_intersection)"
    distribution: str  # "exponential" or "lognormal"
    n: int
    estimates: tuple[ParameterEstimate, ...]
    ks_statistic: float
    ks_pvalue: float


def fit_exponential(
    headways_s: np.ndarray, key: str = "headway_rate_per_s", confidence: float = CONFIDENCE
) -> FitResult:
    """MLE of the exponential rate (1/s) with its exact interval (95% by default) and the KS test."""
    h = np.asarray(headways_s, dtype=float)
    n = h.size
    if n < 2:
        raise FitError(f"need at least 2 headways to fit, got {n}")
    total_s = float(h.sum())
    rate = n / total_s
    alpha = 1.0 - confidence
    # 2 * rate * sum(h) ~ chi2(2n) exactly for exponential data.
    low = stats.chi2.ppf(alpha / 2, 2 * n) / (2 * total_s)
    high = stats.chi2.ppf(1 - alpha / 2, 2 * n) / (2 * total_s)
    ks = stats.kstest(h, stats.expon(scale=1.0 / rate).cdf)
    return FitResult(
        "headway_s", "exponential", n, (ParameterEstimate(key, rate, low, high),), ks.statistic, ks.pvalue
    )


def fit_lognormal(
    values: np.ndarray, mu_key: str, sigma_key: str, variable: str, confidence: float = CONFIDENCE
) -> FitResult:
    """MLE of ln-mean and ln-sd with intervals (95% by default) and the KS test; values must be > 0."""
    x = np.asarray(values, dtype=float)
    n = x.size
    if n < 3:
        raise FitError(f"need at least 3 observations of {variable} to fit, got {n}")
    logs = np.log(x)
    mu = float(logs.mean())
    sigma_mle = float(np.sqrt(np.mean((logs - mu) ** 2)))
    if sigma_mle == 0.0:
        raise FitError(f"all observations of {variable} are equal; a lognormal cannot be fitted")
    s2 = float(logs.var(ddof=1))
    alpha = 1.0 - confidence
    half = stats.t.ppf(1 - alpha / 2, n - 1) * math.sqrt(s2 / n)
    sigma_low = math.sqrt((n - 1) * s2 / stats.chi2.ppf(1 - alpha / 2, n - 1))
    sigma_high = math.sqrt((n - 1) * s2 / stats.chi2.ppf(alpha / 2, n - 1))
    ks = stats.kstest(x, stats.lognorm(s=sigma_mle, scale=math.exp(mu)).cdf)
    return FitResult(
        variable,
        "lognormal",
        n,
        (
            ParameterEstimate(mu_key, mu, mu - half, mu + half),
            ParameterEstimate(sigma_key, sigma_mle, sigma_low, sigma_high),
        ),
        ks.statistic,
        ks.pvalue,
    )


@dataclass
class Observations:
    headways_s: np.ndarray
    speeds_mps: dict[str, np.ndarray]  # location ("nonintersection"/"intersection") -> speeds


def read_observations(path: str | Path, default_location: str = "nonintersection") -> Observations:
    """Parse the CSV; raise FitError (one line, with the line number) on anything that cannot be fitted."""
    path = Path(path)
    try:
        handle = open(path, newline="", encoding="utf-8")
    except OSError as exc:
        raise FitError(f"cannot read {path}: {exc.strerror}") from None
    with handle:
        reader = csv.DictReader(handle)
        fields = [f.strip() for f in (reader.fieldnames or [])]
        reader.fieldnames = fields
        if "headway_s" not in fields and "speed_mps" not in fields:
            raise FitError(f"{path}: needs a 'headway_s' or 'speed_mps' column, found columns {fields}")
        headways: list[float] = []
        speeds: dict[str, list[float]] = {"nonintersection": [], "intersection": []}
        try:
            for row in reader:
                line = reader.line_num
                raw_h = (row.get("headway_s") or "").strip()
                if raw_h:
                    h = _parse_float(raw_h, "headway_s", path, line)
                    if h <= 0:
                        raise FitError(f"{path}:{line}: headway_s must be > 0, got {raw_h}")
                    headways.append(h)
                raw_v = (row.get("speed_mps") or "").strip()
                if raw_v:
                    v = _parse_float(raw_v, "speed_mps", path, line)
                    if v <= 0:
                        raise FitError(f"{path}:{line}: speed_mps must be > 0 (lognormal fit), got {raw_v}")
                    raw_loc = (row.get("location") or "").strip().lower()
                    if raw_loc and raw_loc not in LOCATIONS:
                        raise FitError(
                            f"{path}:{line}: location must be intersection or non_intersection: {raw_loc!r}"
                        )
                    speeds[LOCATIONS[raw_loc] if raw_loc else default_location].append(v)
        except csv.Error as exc:
            raise FitError(f"{path}: malformed CSV: {exc}") from None
        except UnicodeDecodeError:
            raise FitError(f"{path}: not a UTF-8 text CSV") from None
    return Observations(np.array(headways), {k: np.array(v) for k, v in speeds.items() if v})


def _parse_float(raw: str, column: str, path: Path, line: int) -> float:
    try:
        value = float(raw)
    except ValueError:
        raise FitError(f"{path}:{line}: {column} is not a number: {raw!r}") from None
    if not math.isfinite(value):
        raise FitError(f"{path}:{line}: {column} is not finite: {raw!r}")
    return value


def fit_observations(obs: Observations) -> list[FitResult]:
    """Every fit the observations allow: headway exponential, one lognormal per speed location."""
    results = []
    if obs.headways_s.size:
        results.append(fit_exponential(obs.headways_s))
    for loc, speeds in obs.speeds_mps.items():
        mu_key, sigma_key = SPEED_KEYS[loc]
        label = "non_intersection" if loc == "nonintersection" else loc
        results.append(fit_lognormal(speeds, mu_key, sigma_key, f"speed_mps ({label})"))
    if not results:
        raise FitError("the CSV holds no observations")
    return results


def format_table(results: list[FitResult]) -> str:
    rows = [("variable", "distribution", "n", "parameter", "estimate", "95% CI", "KS D", "KS p")]
    for r in results:
        for i, e in enumerate(r.estimates):
            first = i == 0
            rows.append(
                (
                    r.variable if first else "",
                    r.distribution if first else "",
                    str(r.n) if first else "",
                    e.name,
                    f"{e.value:.4f}",
                    f"[{e.ci_low:.4f}, {e.ci_high:.4f}]",
                    f"{r.ks_statistic:.4f}" if first else "",
                    f"{r.ks_pvalue:.3g}" if first else "",
                )
            )
    widths = [max(len(row[c]) for row in rows) for c in range(len(rows[0]))]
    lines = ["  ".join(cell.ljust(w) for cell, w in zip(row, widths, strict=True)).rstrip() for row in rows]
    lines.insert(1, "  ".join("-" * w for w in widths))
    return "\n".join(lines)


def params_toml(results: list[FitResult], source: str) -> str:
    """A parameter file holding the fitted `[traffic]` keys, each with its interval and KS in a comment."""
    lines = [
        f"# Fitted by tools/fit_distributions from {source} (maximum likelihood, 95% intervals).",
        "# Use with: python -m pedsafe_sumo.demand --params THIS_FILE ...",
        "[traffic]",
    ]
    for r in results:
        lines.append(
            f"# {r.variable}: {r.distribution}, n = {r.n}, KS D {r.ks_statistic:.4f} (p = {r.ks_pvalue:.3g})"
        )
        for e in r.estimates:
            lines.append(f"{e.name} = {e.value!r}  # 95% CI [{e.ci_low:.6g}, {e.ci_high:.6g}]")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="fit_distributions",
        description="MLE fits (exponential headways, lognormal speeds) with 95%% intervals and KS goodness "
        "of fit; writes a parameter TOML for `python -m pedsafe_sumo.demand --params`.",
    )
    parser.add_argument("csv", help="CSV with columns headway_s and/or speed_mps [, location]")
    parser.add_argument("--out", "-o", help="write the fitted parameters to this TOML file")
    parser.add_argument(
        "--speed-location",
        choices=("non_intersection", "intersection"),
        default="non_intersection",
        help="which fit speeds without a location column belong to (default non_intersection)",
    )
    args = parser.parse_args(argv)
    try:
        obs = read_observations(args.csv, LOCATIONS[args.speed_location])
        results = fit_observations(obs)
    except FitError as exc:
        print(f"fit_distributions: error: {exc}", file=sys.stderr)
        return 2
    print(format_table(results))
    if args.out:
        # Load it back: a file the generator would reject must not pass silently.
        text = params_toml(results, Path(args.csv).name)
        out = Path(args.out)
        try:
            out.parent.mkdir(parents=True, exist_ok=True)
            out.write_text(text, encoding="utf-8")
            load_params(out)
        except (OSError, ParameterError) as exc:
            print(f"fit_distributions: error: bad parameter file {out}: {exc}", file=sys.stderr)
            return 2
        print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
