"""CLI: python -m pedsafe_sumo.demand --site NAME_OR_PATH --duration 3600 --seed 1 --out routes/"""

from __future__ import annotations

import sys
import time
from pathlib import Path

from pedsafe_sumo import WRITE_ROOT
from pedsafe_sumo.cli import OneLineParser, check_seed
from pedsafe_sumo.demand.generate import MAX_DURATION_S, generate_demand
from pedsafe_sumo.demand.site import SiteError
from pedsafe_sumo.io.outputs import check_output_dir
from pedsafe_sumo.network.sites import SITE_HELP, resolve_site
from pedsafe_sumo.params import ParameterError


def main(argv: list[str] | None = None) -> int:
    parser = OneLineParser(
        prog="python -m pedsafe_sumo.demand",
        description="Write the site's background vehicle and pedestrian demand as SUMO route files.",
    )
    parser.add_argument("--site", required=True, help=SITE_HELP)
    parser.add_argument(
        "--duration",
        type=float,
        default=3600.0,
        help=f"demand horizon in s, above 0 and at most {MAX_DURATION_S:g} (default 3600)",
    )
    parser.add_argument("--seed", type=int, default=1, help="run seed, 0 to 2**63 - 1 (default 1)")
    parser.add_argument(
        "--out", type=Path, default=WRITE_ROOT / "routes", help="output folder (default routes/)"
    )
    parser.add_argument("--params", type=Path, help="parameter TOML laid over the defaults")
    parser.add_argument("--net", type=Path, help="use this .net.xml instead of the site's network")
    args = parser.parse_args(argv)
    start = time.perf_counter()
    try:
        if not 0 < args.duration <= MAX_DURATION_S:  # also false for NaN
            raise ValueError(
                f"--duration must be > 0 and at most {MAX_DURATION_S:g} s, got {args.duration:g}"
            )
        check_seed(args.seed, error=ValueError)
        check_output_dir(args.out, "--out", ValueError)
        if args.net is None:  # with --net, --site only names the output files
            site = resolve_site(args.site)
            args.site, args.net = site.name, site.file("net.xml")
        files = generate_demand(args.site, args.duration, args.seed, args.out, args.params, net_file=args.net)
    except (SiteError, ParameterError, ValueError, OSError) as exc:
        print(f"pedsafe_sumo.demand: error: {exc}", file=sys.stderr)
        return 2
    print(
        f"wrote {files.n_vehicles} vehicles on {files.n_entering_lanes} entering lanes "
        f"({files.n_routes} routes) "
        f"to {files.vehicles_file} and {files.n_persons} pedestrians to {files.pedestrians_file} "
        f"(site {args.site}, seed {args.seed}, {args.duration:g} s; movements "
        + ", ".join(f"{m} {100 * share:.0f}%" for m, share in files.movement_shares.items())
        + f"; {time.perf_counter() - start:.1f} s)"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
