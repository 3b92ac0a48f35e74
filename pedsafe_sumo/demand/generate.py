"""Generate a site's demand: the vehicle and pedestrian route files for one seed and duration."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pedsafe_sumo import NETWORKS_DIR
from pedsafe_sumo.demand import routes_xml
from pedsafe_sumo.demand.pedestrians import generate_pedestrians, pedestrian_lines
from pedsafe_sumo.demand.site import load_site
from pedsafe_sumo.demand.vehicles import generate_vehicles, vehicle_lines
from pedsafe_sumo.params import load_params


@dataclass(frozen=True)
class DemandFiles:
    vehicles_file: Path
    pedestrians_file: Path
    n_vehicles: int
    n_persons: int
    n_entering_lanes: int
    n_routes: int
    movement_shares: dict[str, float]  # realised share of vehicles per movement


#: Longest demand horizon [s]: one day; the route files grow with it (about 1.5 MB per simulated hour
#: at the xueqing site).
MAX_DURATION_S = 86400.0


def vehicle_route_path(out_dir: Path, site: str) -> Path:
    return Path(out_dir) / f"{site}.vehicles.rou.xml"


def pedestrian_route_path(out_dir: Path, site: str) -> Path:
    return Path(out_dir) / f"{site}.pedestrians.rou.xml"


def generate_demand(
    site: str,
    duration_s: float,
    seed: int,
    out_dir: Path,
    params_path: Path | None = None,
    networks_dir: Path = NETWORKS_DIR,
    net_file: Path | None = None,
    params: dict | None = None,
    params_label: str | None = None,
) -> DemandFiles:
    """Write <site>.vehicles.rou.xml and <site>.pedestrians.rou.xml into `out_dir`.

    The seed's SeedSequence spawns one stream for vehicles and one for pedestrians, so changing pedestrian
    parameters never changes the vehicles (and vice versa). `params` (already loaded and validated, e.g. with
    overrides) replaces reading `params_path`; `params_label` then says in the files where they came from.
    Raises SiteError / ParameterError / ValueError on bad input.
    """
    if duration_s <= 0:
        raise ValueError(f"duration must be > 0 s, got {duration_s}")
    if seed < 0:
        raise ValueError(f"seed must be >= 0, got {seed}")
    if params is None:
        params = load_params(params_path)
    the_site = load_site(site, networks_dir, net_file)
    vehicle_seq, pedestrian_seq = np.random.SeedSequence(seed).spawn(2)
    vehicles = generate_vehicles(the_site.entering_lanes, params["traffic"], duration_s, vehicle_seq)
    persons = generate_pedestrians(
        the_site.pedestrian_ends, params["pedestrians"], duration_s, pedestrian_seq
    )

    source = params_label or (str(params_path) if params_path is not None else "defaults")
    veh_path = vehicle_route_path(out_dir, site)
    routes_xml.write(
        veh_path,
        routes_xml.header("background vehicles", site, seed, duration_s, source)
        + vehicle_lines(vehicles, the_site.entering_lanes, params["traffic"]),
    )
    ped_path = pedestrian_route_path(out_dir, site)
    routes_xml.write(
        ped_path,
        routes_xml.header("background pedestrians", site, seed, duration_s, source)
        + pedestrian_lines(persons),
    )
    n_routes = len(
        {r.edges for lane in the_site.entering_lanes for rs in lane.routes_by_movement.values() for r in rs}
    )
    counts = {m: sum(v.movement == m for v in vehicles) for m in ("left", "straight", "right")}
    shares = {m: c / max(1, len(vehicles)) for m, c in counts.items()}
    return DemandFiles(
        veh_path, ped_path, len(vehicles), len(persons), len(the_site.entering_lanes), n_routes, shares
    )
