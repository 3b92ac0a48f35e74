"""Validation that measures SUMO, not the generator: detectors on the site, SUMO's own output, KS distances.

    python -m pedsafe_sumo.demand.validate --site xueqing [--duration 3600] [--seed 1] [--params FILE]

1. Generates the site's demand (the same generator as `python -m pedsafe_sumo.demand`) into a work folder.
2. Places instantaneous induction loops (E1 with per-vehicle `instantOut` records) on every entering lane
   - mid-block: MIDBLOCK_OFFSET_M downstream of where the lane enters the site (its middle if shorter),
     upstream of the reach of the signal's queues at a demand the junction can carry;
   - mid-lane: halfway along the entering edge (reported, inside the queue reach on the short approaches);
   and inside the junction: halfway along the first internal lane of every vehicle connection of the
   signalised junction.
3. Runs the `sumo` binary for the duration with the site's own .sumocfg (step length, pedestrian model,
   collision checks), and reads the loops' output: each vehicle's speed as its front crosses a loop, and
   the gaps between successive fronts over the same mid-block loop (same-lane headways).
4. Compares with the fits by the Kolmogorov-Smirnov distance, plots ECDFs (docs/figures/*.png), and writes the
   measured part of docs/demand_validation.md. With traffic.background_speed_limit_scaled (docs/sites.md),
   every vehicle's SUMO speed factor is its draw / traffic.fit_speed_limit_mps whatever its entry, so the
   rule predicts at each loop the fit scaled by the posted limit of the road the loop is on (an entering
   lane's; for a junction loop, the limit of the lane the connection comes from) / fit_speed_limit_mps.
   The pooled speeds of a kind of loop are compared with the mixture of those scaled fits, each weighted by
   its loop's share of the records (`scaled_mixture`); where every limit is the fits' it is the fit itself.
   Without the scaling each loop is compared with the fit itself.

When the site cannot carry the demand (more than BACKLOG_MAX_SHARE of the vehicles still waiting to be
inserted at the end: queues back up to where vehicles enter), speeds measured on the approaches are queue
speeds and say nothing about the speed model. The command then lowers the headway rate step by step
(RATE_STEP_FACTOR) until the site carries it, and reports every run. Exit status 1 when the mid-block
speed's KS distance exceeds MIDBLOCK_SPEED_KS_MAX in a run the site carries; 2 on bad input.
"""

from __future__ import annotations

import math
import subprocess
import sys
import tempfile
import time
import xml.etree.ElementTree as ET
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy import optimize, stats

from pedsafe_sumo import NETWORKS_DIR
from pedsafe_sumo.cli import OneLineParser, check_seed
from pedsafe_sumo.demand.generate import MAX_DURATION_S, generate_demand
from pedsafe_sumo.demand.routes_xml import attrs
from pedsafe_sumo.demand.sampling import traffic_distributions
from pedsafe_sumo.demand.site import VEHICLE_CLASS, Site, SiteError, load_site
from pedsafe_sumo.demand.validation_page import measured_markdown, plot_ecdfs, write_report
from pedsafe_sumo.demand.vehicles import background_speed_scale
from pedsafe_sumo.io.outputs import check_output_dir
from pedsafe_sumo.network.sites import SITE_HELP, resolve_site
from pedsafe_sumo.network.sumo_inputs import config_inputs
from pedsafe_sumo.params import ParameterError, load_params, with_overrides
from pedsafe_sumo.sampling.distributions import Lognormal
from pedsafe_sumo.sumo_binaries import sumo_binary

#: Acceptance bound of the validation: mid-block approach speeds vs the non-intersection fit.
MIDBLOCK_SPEED_KS_MAX = 0.10
#: Distance (m) from the start of an entering lane to its mid-block loop. The clipped approaches are 70-180 m
#: long and the signal's queues reach back over most of them, so the loop sits near where vehicles enter, yet
#: after a few seconds of SUMO car-following (insertion gaps, catching up slower leaders).
MIDBLOCK_OFFSET_M = 30.0
#: A run whose share of vehicles never inserted exceeds this is oversaturated (queues reach the entries).
BACKLOG_MAX_SHARE = 0.01


@dataclass(frozen=True)
class Detector:
    detector_id: str
    lane_id: str
    pos_m: float
    kind: str  # "midblock", "midlane" or "junction"
    #: The posted limit of the road the loop is on [m/s]: its entering lane's, for a junction loop the
    #: limit of the lane the connection comes from.
    speed_limit_mps: float = math.nan


def main_junction(site: Site):
    """The signalised junction of the study: the traffic-light node with the most incoming vehicle lanes
    (None on a network without traffic lights)."""
    tls = [n for n in site.net.getNodes() if n.getType().startswith("traffic_light")]
    if not tls:
        return None  # e.g. an open road: no junction loops

    def incoming_lanes(node) -> int:
        return sum(1 for e in node.getIncoming() for lane in e.getLanes() if lane.allows(VEHICLE_CLASS))

    return max(tls, key=lambda n: (incoming_lanes(n), n.getID()))


def place_detectors(site: Site) -> list[Detector]:
    """Mid-block and mid-lane loops on the entering lanes, loops on the main junction's internal lanes."""
    detectors = []
    for lane in site.entering_lanes:
        midblock_m = min(MIDBLOCK_OFFSET_M, lane.length_m / 2.0)
        limit_mps = lane.speed_limit_mps
        detectors.append(Detector(f"mid_{lane.lane_id}", lane.lane_id, midblock_m, "midblock", limit_mps))
        detectors.append(
            Detector(f"half_{lane.lane_id}", lane.lane_id, lane.length_m / 2.0, "midlane", limit_mps)
        )
    junction = main_junction(site)
    seen = set()
    for edge in sorted(junction.getIncoming() if junction else [], key=lambda e: e.getID()):
        for lane in edge.getLanes():
            if not lane.allows(VEHICLE_CLASS):
                continue
            for conn in lane.getOutgoing():
                via = conn.getViaLaneID()
                if not via or via in seen or not conn.getTo().allows(VEHICLE_CLASS):
                    continue
                seen.add(via)
                internal = site.net.getLane(via)
                # The posted limit of the road the connection comes from (netconvert gives the internal
                # lane that speed, less where it limits the turn's speed by its curvature).
                half_m, limit_mps = internal.getLength() / 2.0, float(lane.getSpeed())
                detectors.append(Detector(f"jct_{via}", via, half_m, "junction", limit_mps))
    return detectors


def detector_lines(detectors: list[Detector], output_file: str) -> list[str]:
    lines = ['<?xml version="1.0" encoding="UTF-8"?>', "<additional>"]
    for d in detectors:
        lines.append(
            "    <instantInductionLoop "
            + attrs(id=d.detector_id, lane=d.lane_id, pos=f"{d.pos_m:.2f}", file=output_file)
            + "/>"
        )
    lines.append("</additional>")
    return lines


def _site_config(site: Site) -> tuple[Path | None, list[str]]:
    """The site's .sumocfg (None when it has none) and the additional files it names."""
    cfg = site.files.directory / f"{site.files.name}.sumocfg"
    if not cfg.is_file():
        return None, []
    # Checked first: a site's files name no SUMO output and no file outside the site (docs/trust.md).
    return cfg, [str(path) for path in config_inputs(cfg)["additional"]]


#: Settings for a network without a .sumocfg (the test networks).
FALLBACK_OPTIONS = [
    "--step-length",
    "0.1",
    "--pedestrian.model",
    "striping",
    "--collision.check-junctions",
    "true",
]


def run_sumo(
    site: Site,
    route_files: list[Path],
    detector_file: Path,
    end_s: float,
    log_file: Path,
    tripinfo_file: Path | None = None,
) -> subprocess.CompletedProcess:
    """Run the sumo binary headless over the site with the demand and the detectors.

    With the site's own .sumocfg (step length, pedestrian model, junction collision checks, its additional
    files), so the validation sees the simulation the episodes run; only the inputs and outputs change.
    """
    cfg, additionals = _site_config(site)
    cmd = [sumo_binary("sumo"), *(["-c", str(cfg)] if cfg else FALLBACK_OPTIONS)]
    cmd += [
        "--net-file", str(site.files.net_file),
        "--route-files", ",".join(str(p) for p in route_files),
        "--additional-files", ",".join([*additionals, str(detector_file)]),
        "--end", f"{end_s:g}",
        "--no-step-log", "true",
        "--duration-log.statistics", "true",
        "--seed", "1",
        "--log", str(log_file),
    ]  # fmt: skip
    if tripinfo_file is not None:
        # Every inserted vehicle, the ones still driving at the end included: which lanes stopped inserting.
        cmd += ["--tripinfo-output", str(tripinfo_file), "--tripinfo-output.write-unfinished", "true"]
    return subprocess.run(cmd, capture_output=True, text=True, check=False)


def read_instant_output(path: Path) -> dict[str, list[tuple[float, float]]]:
    """detector id -> [(time s, speed m/s)] of every vehicle front entering the loop, in time order."""
    out: dict[str, list[tuple[float, float]]] = {}
    for _event, el in ET.iterparse(path):
        if el.tag == "instantOut" and el.get("state") == "enter":
            out.setdefault(el.get("id"), []).append((float(el.get("time")), float(el.get("speed"))))
        el.clear()
    return out


@dataclass(frozen=True)
class Comparison:
    name: str  # what was measured
    reference: str  # the fit it is compared with
    n: int
    ks_distance: float
    measured_median: float
    fitted_median: float
    samples: np.ndarray
    cdf: Callable[[np.ndarray], np.ndarray]  # x -> F(x) of the fit
    slug: str  # file-name part of its figure


def compare(
    samples: np.ndarray, cdf, name: str, reference: str, fitted_median: float, slug: str
) -> Comparison:
    samples = np.asarray(samples, dtype=float)
    ks = float(stats.kstest(samples, cdf).statistic) if samples.size else math.nan
    median = float(np.median(samples)) if samples.size else math.nan
    return Comparison(name, reference, samples.size, ks, median, fitted_median, samples, cdf, slug)


@dataclass(frozen=True)
class ScaledMixture:
    """The distribution a pooled sample of several loops is compared with: the fit scaled by each loop's
    factor, weighted by that loop's number of records. F(x) = sum_i w_i * F_fit(x / scale_i)."""

    fit: Lognormal
    scales: tuple[float, ...]
    weights: tuple[float, ...]

    def cdf(self, x):
        x = np.asarray(x, dtype=float)
        return sum(w * self.fit.cdf(x / c) for c, w in zip(self.scales, self.weights, strict=True))

    @property
    def median(self) -> float:
        """Where the mixture's CDF is 1/2 (each component's median is the fit's times its scale)."""
        low, high = self.fit.median * min(self.scales), self.fit.median * max(self.scales)
        if high - low <= 1e-12 * high:
            return low
        return float(optimize.brentq(lambda x: float(self.cdf(x)) - 0.5, low, high, xtol=1e-9))


def scaled_mixture(fit: Lognormal, parts: list[tuple[float, int]]) -> ScaledMixture:
    """`fit` scaled per loop: `parts` is [(scale, number of records)]; loops without records drop out."""
    kept = [(scale, n) for scale, n in parts if n > 0]
    if not kept:
        return ScaledMixture(fit, (1.0,), (1.0,))
    total = sum(n for _, n in kept)
    return ScaledMixture(fit, tuple(c for c, _ in kept), tuple(n / total for _, n in kept))


def measure(
    records: dict[str, list[tuple[float, float]]], detectors: list[Detector], traffic: dict, warmup_s: float
) -> list[Comparison]:
    """KS comparisons of the loop records (after `warmup_s`) with the fitted distributions, each loop's
    speeds with the fit scaled as the background's desired speeds are at that loop (module docstring)."""
    headway, nonint, inter = traffic_distributions(traffic)
    by_id = {d.detector_id: d for d in detectors}
    speeds_by_kind: dict[str, list[np.ndarray]] = {"midblock": [], "midlane": [], "junction": []}
    scales_by_kind: dict[str, list[tuple[float, int]]] = {"midblock": [], "midlane": [], "junction": []}
    mid_headways = []
    for det_id, events in records.items():
        times = np.array([t for t, _ in events])
        speeds = np.array([v for _, v in events])
        keep = times >= warmup_s
        kind = by_id[det_id].kind
        speeds_by_kind[kind].append(speeds[keep])
        scale = background_speed_scale(by_id[det_id].speed_limit_mps, traffic)
        scales_by_kind[kind].append((scale, int(keep.sum())))
        if kind == "midblock":
            # Headway: gap between successive fronts over the same loop, both after the warm-up.
            mid_headways.append(np.diff(times[keep]))

    def cat(parts):
        return np.concatenate(parts) if parts else np.array([])

    mid, half, junction = (
        scaled_mixture(fit, scales_by_kind[kind])
        for fit, kind in ((nonint, "midblock"), (nonint, "midlane"), (inter, "junction"))
    )

    def reference(name: str, mixture: ScaledMixture) -> str:
        return name if set(mixture.scales) == {1.0} else f"{name}, scaled to each loop's limit"

    return [
        compare(cat(speeds_by_kind["midblock"]), mid.cdf, "speed, mid-block approach (m/s)",
                reference("non-intersection lognormal", mid), mid.median, "speed_midblock"),
        compare(cat(speeds_by_kind["midlane"]), half.cdf, "speed, middle of entering edge (m/s)",
                reference("non-intersection lognormal", half), half.median, "speed_midlane"),
        compare(cat(speeds_by_kind["junction"]), junction.cdf, "speed, within the junction (m/s)",
                reference("intersection lognormal", junction), junction.median, "speed_junction"),
        compare(cat(mid_headways), headway.cdf, "same-lane headway, mid-block (s)", "exponential",
                math.log(2) / headway.rate_per_s, "headway_midblock"),
    ]  # fmt: skip


def sumo_statistics(log_text: str) -> dict[str, str]:
    """Lines of SUMO's --duration-log.statistics summary (inserted, waiting, teleports...), first of each."""
    wanted = ("Inserted", "Running", "Waiting", "Teleports", "Emergency Braking", "Jammed", "DepartDelay")
    out: dict[str, str] = {}
    for line in log_text.splitlines():
        key, _, value = line.strip().partition(":")
        if key in wanted and key not in out:
            out[key] = value.strip()
    return out


def backlog_share(sim_stats: dict[str, str], n_vehicles: int) -> float:
    """Share of the generated vehicles SUMO still had waiting for insertion at the end."""
    waiting = int(sim_stats.get("Waiting", "0").split()[0] or 0)
    return waiting / n_vehicles if n_vehicles else 0.0


#: A lane that inserted nothing in the last STALL_S of the run while a vehicle due before that waited is
#: stalled. A lane at capacity inserts whenever its queue moves (every signal cycle); one stalled this long
#: is usually blocked by a single vehicle SUMO cannot insert (the route files insert at
#: departSpeed="desired": a very fast draw never finds the gap its speed needs), and every vehicle behind it
#: counts as backlog although the road could take them.
STALL_S = 600.0


@dataclass(frozen=True)
class StalledLane:
    lane_id: str
    last_insertion_s: float  # -1 when the lane inserted nothing at all
    waiting: int
    head_id: str
    head_due_s: float
    head_desired_mps: float

    def line(self) -> str:
        since = f"after {self.last_insertion_s:.0f} s" if self.last_insertion_s >= 0 else "at all"
        return (
            f"insertion stalled on lane {self.lane_id}: nothing inserted {since} while {self.waiting} "
            f"vehicles waited; the first of them, {self.head_id} (due at {self.head_due_s:.0f} s), wants "
            f"{self.head_desired_mps:.1f} m/s"
        )


def stalled_lanes(
    route_file: Path, tripinfo_file: Path, end_s: float, lane_speed_mps: dict[str, float]
) -> list[StalledLane]:
    """The entering lanes that stopped inserting (STALL_S) while vehicles due on them waited: from the route
    file (each vehicle's due time, departure lane and speed factor) and SUMO's tripinfo output (which
    vehicles it inserted, and when)."""
    routes = ET.parse(route_file).getroot()
    first_edge = {r.get("id"): r.get("edges", "").split()[0] for r in routes.iter("route")}
    inserted = {
        t.get("id"): float(t.get("depart", "nan")) for t in ET.parse(tripinfo_file).getroot().iter("tripinfo")
    }
    by_lane: dict[str, list[tuple[float, str, float]]] = {}
    last: dict[str, float] = {}
    for vehicle in routes.iter("vehicle"):
        lane = f"{first_edge[vehicle.get('route')]}_{vehicle.get('departLane')}"
        vid, due_s = vehicle.get("id"), float(vehicle.get("depart"))
        if vid in inserted:
            last[lane] = max(last.get(lane, -1.0), inserted[vid])
        elif due_s < end_s:
            by_lane.setdefault(lane, []).append((due_s, vid, float(vehicle.get("speedFactor", "1"))))
    stalled = []
    for lane, waiting in sorted(by_lane.items()):
        due_s, vid, factor = min(waiting)
        last_s = last.get(lane, -1.0)
        if due_s < end_s - STALL_S and last_s < end_s - STALL_S:
            speed = factor * lane_speed_mps.get(lane, float("nan"))
            stalled.append(StalledLane(lane, last_s, len(waiting), vid, due_s, speed))
    return stalled


@dataclass
class Run:
    label: str  # "paper" or "sustainable"
    headway_rate_per_s: float
    n_vehicles: int
    n_persons: int
    sim_stats: dict[str, str]
    backlog: float
    comparisons: list[Comparison]
    figures: list[Path]
    stalled: list[StalledLane] = field(default_factory=list)

    @property
    def oversaturated(self) -> bool:
        return self.backlog > BACKLOG_MAX_SHARE


def run_once(args, site: Site, params: dict, rate_per_s: float, label: str, work: Path) -> Run:
    """Generate the demand at `rate_per_s`, run SUMO with the loops, measure."""
    params = with_overrides(params, {"traffic.headway_rate_per_s": rate_per_s})
    work.mkdir(parents=True, exist_ok=True)
    source = f"{args.params or 'defaults'} with traffic.headway_rate_per_s={rate_per_s:.6g}"
    demand = generate_demand(
        args.site, args.duration, args.seed, work, net_file=args.net, params=params, params_label=source
    )
    detectors = place_detectors(site)
    det_file = work / "detectors.add.xml"
    det_out = work / "detectors.out.xml"
    det_file.write_text("\n".join(detector_lines(detectors, det_out.name)) + "\n", encoding="utf-8")
    log_file = work / "sumo.log"
    tripinfo_file = work / "tripinfo.xml"
    result = run_sumo(
        site,
        [demand.vehicles_file, demand.pedestrians_file],
        det_file,
        args.duration,
        log_file,
        tripinfo_file,
    )
    log_text = log_file.read_text(encoding="utf-8") if log_file.is_file() else ""
    if result.returncode != 0:
        last = (result.stderr or log_text).strip().splitlines()[-1:] or ["(no output)"]
        raise RuntimeError(f"sumo exited with {result.returncode}: {last[0]}")
    records = read_instant_output(det_out)
    comparisons = measure(records, detectors, params["traffic"], args.warmup)
    sim_stats = sumo_statistics(result.stdout + "\n" + log_text)
    lane_speed_mps = {lane.lane_id: lane.speed_limit_mps for lane in site.entering_lanes}
    stalled = stalled_lanes(demand.vehicles_file, tripinfo_file, args.duration, lane_speed_mps)
    return Run(
        label, rate_per_s, demand.n_vehicles, demand.n_persons, sim_stats,
        backlog_share(sim_stats, demand.n_vehicles), comparisons, [], stalled,
    )  # fmt: skip


#: When the site cannot carry the demand, the rate is lowered by this factor per try (two tries halve it),
#: at most RATE_TRIES_MAX times.
RATE_STEP_FACTOR = 1.0 / math.sqrt(2.0)
RATE_TRIES_MAX = 6


def validate(args) -> list[Run]:
    params = load_params(args.params)
    site = load_site(args.site, NETWORKS_DIR, args.net)
    _site_config(site)  # its .sumocfg and the files it names, before the first run (one line)
    rate = float(params["traffic"]["headway_rate_per_s"])
    runs = []
    with tempfile.TemporaryDirectory(prefix="pedsafe_validate_") as tmp:
        work = Path(args.work) if args.work else Path(tmp)
        runs.append(run_once(args, site, params, rate, "configured", work / "configured"))
        tries = 0
        while runs[-1].oversaturated and tries < RATE_TRIES_MAX:
            rate *= RATE_STEP_FACTOR
            tries += 1
            label = "reduced" if tries < RATE_TRIES_MAX else "lowest"
            runs.append(run_once(args, site, params, rate, f"{label}_{tries}", work / f"reduced_{tries}"))
    # Figures for the configured demand and for the last (carried) one; the runs between are in the table.
    for run, name in (
        (runs[0], "configured"),
        (runs[-1], "carried" if not runs[-1].oversaturated else "lowest"),
    ):
        if run.figures:
            continue
        title = f"{args.site}, {name} demand: {run.headway_rate_per_s:.4g} veh/s per lane, seed {args.seed}"
        run.figures = plot_ecdfs(run.comparisons, args.docs / "figures", f"demand_{args.site}_{name}", title)
    return runs


def main(argv: list[str] | None = None) -> int:
    parser = OneLineParser(prog="python -m pedsafe_sumo.demand.validate", description=__doc__.split("\n")[0])
    parser.add_argument("--site", default="xueqing", help=SITE_HELP)
    parser.add_argument(
        "--duration",
        type=float,
        default=3600.0,
        help=f"simulated time in s, above 0 and at most {MAX_DURATION_S:g} (default 3600)",
    )
    parser.add_argument(
        "--warmup", type=float, default=300.0, help="s of records ignored at the start, less than --duration"
    )
    parser.add_argument("--seed", type=int, default=1, help="run seed, 0 to 2**63 - 1 (default 1)")
    parser.add_argument("--params", type=Path, help="parameter TOML laid over the defaults")
    parser.add_argument("--net", type=Path, help="use this .net.xml instead of the site's network")
    parser.add_argument(
        "--docs",
        type=Path,
        metavar="DIR",
        help="folder to write demand_validation.md and figures/ into (required: the command never writes "
        "into the repository unasked; give the repository's docs/ to refresh the page there)",
    )
    parser.add_argument("--work", type=Path, help="keep the routes, loops and SUMO output here")
    args = parser.parse_args(argv)
    started = time.perf_counter()
    try:
        if args.docs is None:
            raise ValueError("give --docs DIR, the folder to write demand_validation.md and figures/ into")
        check_output_dir(args.docs, "--docs", ValueError)
        if not 0 < args.duration <= MAX_DURATION_S:  # also false for NaN
            raise ValueError(
                f"--duration must be > 0 and at most {MAX_DURATION_S:g} s, got {args.duration:g}"
            )
        if not 0 <= args.warmup < args.duration:
            raise ValueError(f"--warmup must be >= 0 s and less than --duration, got {args.warmup:g}")
        check_seed(args.seed, error=ValueError)
        if args.work is not None:
            check_output_dir(args.work, "--work", ValueError)
        if args.net is None:  # with --net, --site only names the output files
            site = resolve_site(args.site)
            args.site, args.net = site.name, site.file("net.xml")
        runs = validate(args)
        site = load_site(args.site, NETWORKS_DIR, args.net)
        n_loops = {
            k: sum(d.kind == k for d in place_detectors(site)) for k in ("midblock", "midlane", "junction")
        }
        write_report(
            args.docs / "demand_validation.md",
            measured_markdown(args, runs, n_loops, MIDBLOCK_OFFSET_M),
            args.site,
        )
    except (SiteError, ParameterError, OSError, RuntimeError, ValueError) as exc:
        print(f"pedsafe_sumo.demand.validate: error: {exc}", file=sys.stderr)
        return 2
    failed = False
    for run in runs:
        state = "OVERSATURATED" if run.oversaturated else "carried"
        print(
            f"[{run.label}: {run.headway_rate_per_s:.4g} veh/s/lane, {state}, "
            f"backlog {100 * run.backlog:.1f}%]"
        )
        for lane in run.stalled:
            print(f"  warning: {lane.line()}")
        for c in run.comparisons:
            print(f"  {c.name:38s} vs {c.reference:27s} n={c.n:6d}  KS D={c.ks_distance:.3f}  "
                  f"median {c.measured_median:.2f} (fit {c.fitted_median:.2f})")  # fmt: skip
        if not run.oversaturated and not run.comparisons[0].ks_distance <= MIDBLOCK_SPEED_KS_MAX:
            failed = True
    print(f"wrote {args.docs / 'demand_validation.md'} ({time.perf_counter() - started:.0f} s)")
    if failed:
        print(
            f"mid-block speed KS distance above {MIDBLOCK_SPEED_KS_MAX} in a run the site carries",
            file=sys.stderr,
        )
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
