"""Pedestrian-vehicle interactions, conflicts and surrogate safety measures from any SUMO FCD output.

    python -m pedsafe_sumo.conflicts run.fcd.xml --out conflicts.csv
    python -m pedsafe_sumo.conflicts run.fcd.xml.gz --out conflicts.parquet --net site.net.xml \\
        --types routes.rou.xml --ssm conflicts.ssm.xml

Every pair of a vehicle and a walking person that come within the interaction radius gives one row
per interaction (docs/conflicts.md): TTC, PET, DRAC, Amini MD/TMD/CS and its conflict flag, the
minimum clearance, speeds, place and times. The file is read one timestep at a time; a run that lasts
more than a few seconds shows a progress bar over the file's bytes on stderr. Bad input ends
in one line on stderr and exit status 2; an earlier output of the same name is left as it was.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path
from typing import Any

import tomllib

from pedsafe_sumo.cli import OneLineParser, check_range
from pedsafe_sumo.conflicts.fcd import FcdError, read_fcd
from pedsafe_sumo.conflicts.interactions import InteractionTracker
from pedsafe_sumo.conflicts.output import TABLE_SUFFIXES, SsmWriter, TableWriter
from pedsafe_sumo.conflicts.places import NetError, PlaceFinder
from pedsafe_sumo.conflicts.sizes import SizeBook, TypesError
from pedsafe_sumo.io.outputs import check_output_file
from pedsafe_sumo.network.sites import SiteError, resolve_site
from pedsafe_sumo.params import DEFAULTS_PATH, ParameterError, load_params
from pedsafe_sumo.usage import UsageError

#: Every vehicle-pedestrian pair within the radius is followed step by step: a kilometre is beyond any
#: sight line at a junction, and a larger radius only makes every pair of the file an interaction.
MAX_RADIUS_M = 1000.0
#: A run shorter than this shows no progress bar: a few seconds is when waiting without news starts.
PROGRESS_DELAY_S = 3.0


class _Progress:
    """The progress bar over the bytes of the file (as stored), on stderr: made, and tqdm imported, only
    once a run has lasted PROGRESS_DELAY_S (a shorter run, or --quiet, does not pay tqdm's import); its
    clock starts with the run."""

    def __init__(self, fcd: Path, quiet: bool) -> None:
        self.fcd, self.quiet = fcd, quiet
        self.started = time.perf_counter()
        self.bar: Any = None

    def __call__(self, position: int) -> None:
        if self.bar is None:
            if self.quiet or time.perf_counter() - self.started < PROGRESS_DELAY_S:
                return
            from tqdm import tqdm  # here, not at the top: see the class docstring

            self.bar = tqdm(
                total=self.fcd.stat().st_size,
                unit="B",
                unit_scale=True,
                desc=self.fcd.name,
                mininterval=1.0,
                file=sys.stderr,
            )
            self.bar.start_t -= time.perf_counter() - self.started  # the run began before the bar
        self.bar.update(position - self.bar.n)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = OneLineParser(prog="python -m pedsafe_sumo.conflicts", description=__doc__.splitlines()[0])
    parser.add_argument("fcd", type=Path, metavar="FCD.xml", help="SUMO FCD output (.xml or .xml.gz)")
    parser.add_argument(
        "--out", type=Path, required=True, metavar="FILE", help="output table: .csv or .parquet"
    )
    parser.add_argument(
        "--net", type=Path, metavar="NET.xml", help="the network: adds lane_id and crossing_id"
    )
    parser.add_argument(
        "--site",
        metavar="NAME_OR_PATH",
        help="a pedsafe_sumo site (name or folder) whose network is the --net",
    )
    parser.add_argument(
        "--types",
        type=Path,
        action="append",
        default=[],
        metavar="FILE",
        help="SUMO route/additional file whose vTypes give the road users' sizes (repeatable)",
    )
    parser.add_argument("--ssm", type=Path, metavar="FILE.xml", help="also write an SSM-device-like XML")
    parser.add_argument(
        "--radius",
        type=float,
        metavar="M",
        help=f"interaction radius, m, above 0 and at most {MAX_RADIUS_M:g} [parameter file: 50]",
    )
    parser.add_argument(
        "--params", type=Path, metavar="FILE.toml", help="parameter file laid over the defaults"
    )
    parser.add_argument(
        "--quiet", action="store_true", help="no summary on stdout and no progress bar on stderr"
    )
    return parser.parse_args(argv)


def site_net(net: Path | None, site: str | None) -> Path | None:
    """The network file: --net, or the one of --site (UsageError when both are given or the site is bad)."""
    if site is None:
        return net
    if net is not None:
        raise UsageError("give --net or --site, not both")
    try:
        return resolve_site(site, verify=False).file("net.xml")
    except SiteError as exc:
        raise UsageError(str(exc)) from None


def conflicts_section(params_path: Path | None) -> dict:
    """The [conflicts] parameters. With a parameter file, the whole file is laid over the defaults and
    checked as every command checks it (`load_params`). Without one, the defaults' section is read as it
    stands: the defaults pass those checks (tests/params), and checking them would import the modules
    of every section (the perception kernels, numba: some 0.3 s of CPU, as much as a short run)."""
    if params_path is not None:
        return load_params(params_path)["conflicts"]
    with open(DEFAULTS_PATH, "rb") as handle:
        return tomllib.load(handle)["conflicts"]


def run(args: argparse.Namespace) -> dict[str, float]:
    if args.out.suffix.lower() not in TABLE_SUFFIXES:
        raise UsageError(f"--out must end in .csv or .parquet, got {args.out}")
    if args.ssm is not None and args.ssm.suffix.lower() != ".xml":
        raise UsageError(f"--ssm writes XML: give a file name ending in .xml, got {args.ssm}")
    if not args.fcd.is_file():
        raise UsageError(f"FCD file not found: {args.fcd}")
    check_output_file(args.out, "--out", UsageError)
    if args.ssm is not None:
        check_output_file(args.ssm, "--ssm", UsageError)
    args.net = site_net(args.net, args.site)
    section = conflicts_section(args.params)
    for key, value in section.items():
        if (
            isinstance(value, bool)
            or not isinstance(value, (int, float))
            or not math.isfinite(value)
            or value <= 0
        ):
            raise UsageError(f"parameter conflicts.{key} must be a positive number, got {value!r}")
    radius_m = section["interaction_radius_m"] if args.radius is None else args.radius
    where = "--radius" if args.radius is not None else "parameter conflicts.interaction_radius_m"
    check_range(radius_m, where, 0, MAX_RADIUS_M, unit=" m", low_open=True)
    sizes = SizeBook.from_params(section, args.types)
    place = None
    if args.net is not None:
        try:
            place = PlaceFinder(args.net)
        except NetError as exc:
            raise UsageError(str(exc)) from None
    table = TableWriter(args.out)
    ssm = (
        SsmWriter(
            args.ssm,
            section["ssm_ttc_threshold_s"],
            section["ssm_drac_threshold_mps2"],
            section["ssm_pet_threshold_s"],
        )
        if args.ssm is not None
        else None
    )

    counts = {"collisions": 0, "geometry_artefacts": 0}

    def emit(row):
        counts["collisions"] += bool(row["collision"])
        counts["geometry_artefacts"] += bool(row["geometry_artefact"])
        table.write(row)
        if ssm is not None:
            ssm.write(row)

    tracker = InteractionTracker(radius_m, sizes, emit, place, place.meeting if place is not None else None)
    started = time.perf_counter()
    progress = _Progress(args.fcd, quiet=args.quiet)
    try:
        try:
            for step in read_fcd(args.fcd, progress=progress):
                tracker.step(step)
            tracker.finish()
        finally:
            progress.close()
    except BaseException:
        table.abort()
        if ssm is not None:
            ssm.abort()
        raise
    table.close()
    if ssm is not None:
        ssm.close()
    return {
        "steps": tracker.steps,
        "fcd_rows": tracker.vehicle_rows + tracker.person_rows,
        "interactions": tracker.interactions,
        "ssm_kept": ssm.kept if ssm is not None else 0,
        **counts,
        "seconds": time.perf_counter() - started,
    }


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    try:
        summary = run(args)
    except (UsageError, FcdError, TypesError, ParameterError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    if not args.quiet:
        rate = summary["fcd_rows"] / summary["seconds"] if summary["seconds"] > 0 else math.inf
        print(
            f"{args.fcd}: {summary['steps']} timesteps, {summary['fcd_rows']} FCD rows, "
            f"{summary['interactions']} interactions ({summary['collisions']} collisions, "
            f"{summary['geometry_artefacts']} geometry artefacts) -> {args.out}"
            + (f", {summary['ssm_kept']} in {args.ssm}" if args.ssm is not None else "")
            + f" ({summary['seconds']:.1f} s, {rate:,.0f} FCD rows/s)"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
