"""Calibration of the background's desired-speed law against the speeds SUMO measures.

    python -m pedsafe_sumo.demand.calibrate [--net tests/demand/data/straight.net.xml] [--seeds 1 2 3]
        [--duration 1800] [--params FILE] [--write-params FILE]

The paper's non-intersection lognormal (eq. 2) describes *observed* speeds, which already contain the
slowing of fast drivers behind slower leaders. Drawn as independent *desired* speeds at the paper's flow it
is compressed by SUMO's car-following (docs/demand_validation.md, "Calibrated desired speeds"). This tool
solves the inverse problem: it finds the lognormal of desired speeds (log-mu, log-sigma at
traffic.fit_speed_limit_mps, scaled by the limit rule like the fit) such that the speeds SUMO measures
downstream follow the fit. Everything below is fixed before the search and does not depend on its outcome:

- **Target**: the non-intersection fit of the parameters (`speed_nonintersection_log_mu/sigma`), scaled to
  each loop's road limit exactly as the validation compares it (`validate.measure`).
- **Measurements**: the validation's mid-block loops (E1, `validate.MIDBLOCK_OFFSET_M` = 30 m into every
  entering lane) on an open road without a junction (default the two-lane, 1 km
  tests/demand/data/straight.net.xml), the demand generator at the parameters' headway rate (the paper's
  0.1742 veh/s per lane), vehicles only: that test road has no sidewalks, so SUMO would walk the generated
  pedestrians on the carriageway. SUMO's records of the first `--warmup` s are dropped.
- **Objective**: the Kolmogorov-Smirnov distance between the mid-block speeds pooled over the seeds and the
  target. The same seeds at every candidate (common random numbers: a candidate only rescales the same
  normal scores), so differences between candidates are not seed noise.
- **Search**: a grid (GRID_LOG_MU_OFFSETS added to the fit's log-mu x GRID_LOG_SIGMAS), then a compass search
  from the grid's best point: try +-step on log-mu and on log-sigma, move to the best improvement, halve the
  step when none improves, stop below MIN_STEP. Ties keep the earlier point. Nothing here looks at any
  safety result.

`--check LOG_MU LOG_SIGMA` measures one law on the seeds without searching (the out-of-sample check: other
seeds, the mid-lane loops halfway along the road; the fit's own values give exactly the "fit" law's draws).
The result is printed as a table of every evaluation and optionally written as a parameter file
(`--write-params`) holding `traffic.desired_speed_law = "calibrated"` and the two calibrated values. Bad input
ends in one line on stderr and exit status 2.
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from pedsafe_sumo import NETWORKS_DIR, REPO_ROOT
from pedsafe_sumo.demand.generate import generate_demand
from pedsafe_sumo.demand.site import Site, SiteError, load_site
from pedsafe_sumo.demand.validate import (
    Detector,
    detector_lines,
    measure,
    place_detectors,
    read_instant_output,
    run_sumo,
)
from pedsafe_sumo.params import ParameterError, load_params, with_overrides

DEFAULT_NET = REPO_ROOT / "tests" / "demand" / "data" / "straight.net.xml"
DEFAULT_SEEDS = (1, 2, 3)
#: Simulated seconds per seed: 1500 s after the warm-up give about 520 mid-block records per seed on the
#: two-lane road at 0.1742 veh/s per lane, 1560 pooled over three seeds (KS sampling noise about 0.02).
DEFAULT_DURATION_S = 1800.0
DEFAULT_WARMUP_S = 300.0
#: The grid, fixed before the search: log-mu above the fit's (compression only lowers speeds) and log-sigma
#: from a quarter of the fit's spread up to the fit's own.
GRID_LOG_MU_OFFSETS = (0.0, 0.1, 0.2, 0.3)
GRID_LOG_SIGMAS = (0.15, 0.25, 0.35, 0.4857)
#: The compass search's first step on both coordinates and the step below which it stops.
FIRST_STEP = 0.04
MIN_STEP = 0.01


@dataclass(frozen=True)
class Evaluation:
    log_mu: float
    log_sigma: float
    ks_distance: float
    n: int  # pooled mid-block records
    measured_median_mps: float
    target_median_mps: float
    stage: str  # "grid" or "search"


def candidate_params(params: dict, log_mu: float, log_sigma: float) -> dict:
    """`params` with the background's desired speeds drawn from Lognormal(log_mu, log_sigma)."""
    return with_overrides(
        params,
        {
            "traffic.desired_speed_law": "calibrated",
            "traffic.desired_speed_calibrated_log_mu": float(log_mu),
            "traffic.desired_speed_calibrated_log_sigma": float(log_sigma),
        },
    )


def simulate_loops(
    site: Site, site_name: str, net: Path, params: dict, seed: int, duration_s: float, work: Path
) -> tuple[dict[str, list[tuple[float, float]]], list[Detector]]:
    """Generate the vehicles of `params` for `seed`, run SUMO over `net` with the validation's loops, and
    return the loops' records (detector id -> [(time s, speed m/s)]) and the detectors. Vehicles only."""
    work.mkdir(parents=True, exist_ok=True)
    demand = generate_demand(site_name, duration_s, seed, work, net_file=net, params=params)
    detectors = place_detectors(site)
    det_file, det_out = work / "detectors.add.xml", work / "detectors.out.xml"
    det_file.write_text("\n".join(detector_lines(detectors, det_out.name)) + "\n", encoding="utf-8")
    log_file = work / "sumo.log"
    result = run_sumo(site, [demand.vehicles_file], det_file, duration_s, log_file)
    if result.returncode != 0:
        log_text = log_file.read_text(encoding="utf-8") if log_file.is_file() else ""
        last = (result.stderr or log_text).strip().splitlines()[-1:] or ["(no output)"]
        raise RuntimeError(f"sumo exited with {result.returncode}: {last[0]}")
    return read_instant_output(det_out), detectors


def pooled_records(
    per_seed: list[dict[str, list[tuple[float, float]]]],
) -> dict[str, list[tuple[float, float]]]:
    """The records of several seeds, per detector, one after the other (the speeds are what is pooled)."""
    out: dict[str, list[tuple[float, float]]] = {}
    for records in per_seed:
        for det_id, events in records.items():
            out.setdefault(det_id, []).extend(events)
    return out


class Calibration:
    """The objective (pooled mid-block KS) with its evaluations memoised, and the search over it."""

    def __init__(self, args, params: dict, site: Site, work: Path) -> None:
        self.args, self.params, self.site, self.work = args, params, site, work
        self.evaluations: list[Evaluation] = []
        self._cache: dict[tuple[float, float], Evaluation] = {}

    def comparisons(self, log_mu: float, log_sigma: float, kinds=("midblock",)) -> list:
        """validate.measure's comparisons of the pooled records of the seeds under this desired-speed law."""
        cand = candidate_params(self.params, log_mu, log_sigma)
        per_seed: list[dict[str, list[tuple[float, float]]]] = []
        detectors: list[Detector] = []
        for seed in self.args.seeds:
            records, detectors = simulate_loops(
                self.site, self.args.site, self.args.net, cand, seed, self.args.duration,
                self.work / f"seed_{seed}",
            )  # fmt: skip
            per_seed.append(records)
        # The target is the fit of the parameters (not the candidate): measure compares with
        # speed_nonintersection_*, scaled per loop as the background is.
        return measure(pooled_records(per_seed), detectors, self.params["traffic"], self.args.warmup)

    def evaluate(self, log_mu: float, log_sigma: float, stage: str) -> Evaluation:
        key = (round(log_mu, 6), round(log_sigma, 6))
        if key in self._cache:
            return self._cache[key]
        started = time.perf_counter()
        mid = self.comparisons(*key)[0]
        ev = Evaluation(key[0], key[1], mid.ks_distance, mid.n, mid.measured_median, mid.fitted_median, stage)
        self._cache[key] = ev
        self.evaluations.append(ev)
        print(
            f"  {stage:6s} log_mu {ev.log_mu:.4f}  log_sigma {ev.log_sigma:.4f}  KS {ev.ks_distance:.4f}  "
            f"n {ev.n}  median {ev.measured_median_mps:.2f} (target {ev.target_median_mps:.2f})  "
            f"[{time.perf_counter() - started:.0f} s]",
            flush=True,
        )
        return ev

    def run(self) -> Evaluation:
        fit_mu = float(self.params["traffic"]["speed_nonintersection_log_mu"])
        best = None
        for offset in self.args.grid_mu_offsets:
            for sigma in self.args.grid_sigmas:
                ev = self.evaluate(fit_mu + offset, sigma, "grid")
                if best is None or ev.ks_distance < best.ks_distance:
                    best = ev
        assert best is not None
        step = self.args.first_step
        while step >= self.args.min_step - 1e-12:
            moves = [(step, 0.0), (-step, 0.0), (0.0, step), (0.0, -step)]
            trials = [
                self.evaluate(best.log_mu + dm, best.log_sigma + ds, "search")
                for dm, ds in moves
                if best.log_sigma + ds > 0
            ]
            better = min(trials, key=lambda ev: ev.ks_distance)
            if better.ks_distance < best.ks_distance:
                best = better
            else:
                step /= 2.0
        return best


def check(cal: Calibration, log_mu: float, log_sigma: float) -> int:
    """Print the validation's comparisons (mid-block, mid-lane, headways) of one law on the seeds: the
    out-of-sample check of a calibrated law (other seeds, the mid-lane loops)."""
    print(f"law Lognormal({log_mu:g}, {log_sigma:g}) of desired speeds at the fits' limit:")
    for c in cal.comparisons(log_mu, log_sigma):
        if c.n:
            print(
                f"  {c.name:38s} vs {c.reference:56s} n={c.n:6d}  KS D={c.ks_distance:.3f}  "
                f"median {c.measured_median:.2f} (fit {c.fitted_median:.2f})"
            )
    return 0


def write_params_file(path: Path, best: Evaluation, command: str) -> None:
    path.write_text(
        f"# Written by {command}\n"
        f"# pooled mid-block KS distance {best.ks_distance:.4f} (n {best.n})\n"
        "[traffic]\n"
        'desired_speed_law = "calibrated"\n'
        f"desired_speed_calibrated_log_mu = {best.log_mu:.4f}\n"
        f"desired_speed_calibrated_log_sigma = {best.log_sigma:.4f}\n",
        encoding="utf-8",
    )


def parse_args(argv: list[str] | None):
    parser = argparse.ArgumentParser(
        prog="python -m pedsafe_sumo.demand.calibrate", description=__doc__.split("\n")[0]
    )
    parser.add_argument("--net", type=Path, default=DEFAULT_NET, help="open road to calibrate on (.net.xml)")
    parser.add_argument("--site", default="straight", help="name of the route files (default straight)")
    parser.add_argument("--seeds", type=int, nargs="+", default=list(DEFAULT_SEEDS))
    parser.add_argument("--duration", type=float, default=DEFAULT_DURATION_S, help="simulated s per seed")
    parser.add_argument("--warmup", type=float, default=DEFAULT_WARMUP_S, help="s of records ignored")
    parser.add_argument("--params", type=Path, help="parameter TOML laid over the defaults (target, flow)")
    parser.add_argument("--grid-mu-offsets", type=float, nargs="+", default=list(GRID_LOG_MU_OFFSETS))
    parser.add_argument("--grid-sigmas", type=float, nargs="+", default=list(GRID_LOG_SIGMAS))
    parser.add_argument("--first-step", type=float, default=FIRST_STEP)
    parser.add_argument("--min-step", type=float, default=MIN_STEP)
    parser.add_argument("--write-params", type=Path, help="write the calibrated [traffic] keys to this TOML")
    parser.add_argument(
        "--check",
        type=float,
        nargs=2,
        metavar=("LOG_MU", "LOG_SIGMA"),
        help="no search: measure this desired-speed law on the seeds and print every loop's comparison",
    )
    parser.add_argument("--work", type=Path, help="keep the last candidate's files here")
    args = parser.parse_args(argv)
    if not args.duration > args.warmup >= 0:
        parser.exit(2, f"{parser.prog}: error: need --duration > --warmup >= 0\n")
    if any(s < 0 for s in args.seeds):
        parser.exit(2, f"{parser.prog}: error: seeds must be >= 0\n")
    if not (args.first_step > 0 and args.min_step > 0) or any(s <= 0 for s in args.grid_sigmas):
        parser.exit(2, f"{parser.prog}: error: steps and grid sigmas must be > 0\n")
    return args


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    started = time.perf_counter()
    command = "python -m pedsafe_sumo.demand.calibrate " + " ".join(sys.argv[1:] if argv is None else argv)
    try:
        params = load_params(args.params)
        site = load_site(args.site, NETWORKS_DIR, args.net)
        if args.write_params is not None and not args.write_params.parent.is_dir():
            raise OSError(f"folder of --write-params does not exist: {args.write_params.parent}")
        with tempfile.TemporaryDirectory(prefix="pedsafe_calibrate_") as tmp:
            cal = Calibration(args, params, site, Path(args.work) if args.work else Path(tmp))
            print(
                f"calibrating on {args.net} at {params['traffic']['headway_rate_per_s']:g} veh/s per lane, "
                f"seeds {' '.join(map(str, args.seeds))}, {args.duration:g} s each",
                flush=True,
            )
            if args.check is not None:
                return check(cal, *args.check)
            best = cal.run()
    except (SiteError, ParameterError, OSError, RuntimeError, ValueError) as exc:
        print(f"pedsafe_sumo.demand.calibrate: error: {exc}", file=sys.stderr)
        return 2
    fit = params["traffic"]
    print(
        f"best: desired_speed_calibrated_log_mu = {best.log_mu:.4f}, desired_speed_calibrated_log_sigma = "
        f"{best.log_sigma:.4f} (median {math.exp(best.log_mu):.2f} m/s at the fits' limit; the fit: "
        f"{fit['speed_nonintersection_log_mu']}, {fit['speed_nonintersection_log_sigma']}); pooled mid-block "
        f"KS {best.ks_distance:.4f} (n {best.n}); {len(cal.evaluations)} evaluations, "
        f"{time.perf_counter() - started:.0f} s"
    )
    if args.write_params is not None:
        write_params_file(args.write_params, best, command)
        print(f"wrote {args.write_params}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
