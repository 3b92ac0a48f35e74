"""The compiled (numba) kernels made ready before a command's episodes start: loaded from numba's cache,
or compiled into it once, with a line on stderr saying so.

Without this, each process compiles the kernels the first time an episode uses them: a batch would sit at
0% without a word for the minutes the first compilation takes, in every worker at once. A command that
runs episodes calls :func:`prepare_compiled_kernels` once; the batch's workers then only load them from
the cache (``perception/numba_cache.py`` says where it is).
"""

from __future__ import annotations

import sys
import time
from typing import TextIO

import numpy as np

from pedsafe_sumo.control.path_kernels import first_ahead, first_in_corridor, project_points, widening_rows
from pedsafe_sumo.control.tracker_kernels import mixed_estimates
from pedsafe_sumo.params import load_params
from pedsafe_sumo.perception import (
    EgoPose,
    Pedestrians,
    RoadsideUnit,
    SensorSuite,
    StaticOccluders,
    V2ILink,
    VehicleBoxes,
    WorldSnapshot,
    perceive,
)
from pedsafe_sumo.perception.raycast import cast_rays
from pedsafe_sumo.perception.raycast_kernels import COMPILED_KERNELS, KERNEL_CACHE_DIR
from pedsafe_sumo.safety.geometry_kernels import rectangle_circle_clearance_m, walks_into_body

#: What the first compilation takes, as the message announces it: 90 s measured on 2 shared cores
#: (docs/decisions/2026-11-27-installed-package.md); the line after it gives this machine's time.
COMPILE_ESTIMATE_S = 90


def kernels_cached() -> bool:
    """Whether numba's cache holds code of the current source of every kernel. Reads numba's cache index
    (numba has no public call for it); False when it cannot tell."""
    try:
        return all(kernel._cache._cache_file._load_index() for kernel in COMPILED_KERNELS)  # type: ignore[attr-defined]
    except Exception:  # noqa: BLE001  # any failure to read numba's internals: say it compiles
        return False


def run_every_kernel() -> None:
    """One frame through every compiled kernel, with the argument types the episodes use: the perception
    pipeline with a roadside unit and its V2I link, the ray casting of the sight and vehicle-detection
    callers, the clearance kernels, the reference stack's path kernels and its tracker's mixing."""
    grey, red = (120, 120, 120), (200, 30, 30)
    vehicles = VehicleBoxes.build(
        ["ego", "car"], [0.0, 15.0], [0.0, 3.0], [0.0, 0.3], [4.5, 4.8], [1.8, 1.9], [1.5, 1.6], [grey, grey]
    )
    pedestrians = Pedestrians.build(["ped"], [20.0], [-1.0], [0.25], [1.7], [red])
    building = np.array([[30.0, 5.0], [40.0, 5.0], [40.0, 15.0], [30.0, 15.0]])
    static = StaticOccluders.build(
        [("b", "building", building, 0.0, 10.0, grey)],
        [(25.0, -6.0, 0.15, 0.0, 2.5, (90, 60, 30)), (25.0, -6.0, 2.0, 2.5, 7.0, (40, 110, 40))],
    )
    unit = RoadsideUnit("rsu", 22.0, -12.0, 6.0, float(np.radians(90.0)), float(np.radians(30.0)))
    suite = SensorSuite.from_params(load_params()["perception"], [unit])
    link = V2ILink(suite.v2i, np.random.default_rng(1))
    ego = EgoPose(0.0, 0.0, 0.0, "ego")
    rng = np.random.default_rng(0)
    for step in range(3):
        perceive(
            WorldSnapshot(0.05 * step, vehicles, pedestrians, static), ego, suite, rng, 0.05 * step, link
        )
    snapshot = WorldSnapshot(0.0, vehicles, pedestrians, static)
    origin = np.array([[0.0, 0.0, 1.6], [0.0, 0.0, 1.6]])
    direction = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    ones = np.ones(2, dtype=np.int64)
    for skip_vehicle in (0, np.full(2, -1)):  # one for all groups; one per group (read-only once broadcast)
        cast_rays(
            snapshot, origin, direction, np.full(2, 50.0), np.arange(2), ones, np.full(2, -1), skip_vehicle
        )
    rectangle_circle_clearance_m(0.0, 0.0, 0.0, 4.5, 1.8, 3.0, 1.0, 0.25)
    segment = np.array([0.0])
    s_m, lat_m = project_points(
        np.array([1.0]), np.array([1.0]), segment, segment, segment + 1.0, segment,
        segment - np.inf, segment + np.inf, segment,
    )  # fmt: skip
    times = np.array([0.0])
    times.setflags(write=False)  # the planner's sample times are read-only
    start = first_ahead(s_m, times, 0.0, 1.0, 2.0, 4.5)
    widening_rows(s_m, times, 0, segment, segment + 1.0, segment)
    probs, states, covs = np.array([0.5, 0.5]), np.zeros((2, 4)), np.zeros((2, 4, 4))
    for weights in (np.ones((2, 2)), probs[:, None]):  # the models' starts; the combined estimate
        mixed_estimates(weights, states, covs)
    for sigmas in (np.zeros(0), np.ones(1)):
        first_in_corridor(s_m, lat_m, times, max(start, 0), sigmas, 2.0, 0.0, 1.0, 2.0, 4.5, 1.9)
    walks_into_body(
        *(np.array([v]) for v in (0.0, 0.0, 0.0, 4.5, 1.8, 2.4)), 5.0, 0.0, 4.0, 0.0, 0.25, 0.3, 0.05
    )


def prepare_compiled_kernels(stream: TextIO | None = None) -> float | None:
    """Load every kernel from numba's cache, or compile it there, announcing it on `stream` (stderr): one
    line before, one with the time it took after. Returns the compilation time [s], None when every
    kernel came from the cache."""
    stream = sys.stderr if stream is None else stream
    announced = not kernels_cached()
    if announced:
        print(
            f"compiling the perception kernels (about {COMPILE_ESTIMATE_S} s, once; cached in "
            f"{KERNEL_CACHE_DIR}) ...",
            file=stream,
            flush=True,
        )
    # Misses counted from here: a kernel this process already compiled for other argument types (a test,
    # a caller of its own) is not this call's compilation.
    misses_before = _cache_misses()
    started = time.perf_counter()
    run_every_kernel()
    took_s = time.perf_counter() - started
    compiled = _cache_misses() > misses_before
    if compiled:
        print(f"compiled the perception kernels in {took_s:.0f} s", file=stream, flush=True)
    elif announced:
        print(f"loaded the perception kernels from the cache in {took_s:.0f} s", file=stream, flush=True)
    return took_s if compiled else None


def _cache_misses() -> int:
    """Compilations this process has made of the kernels (numba's per-kernel cache-miss counts)."""
    return sum(sum(kernel.stats.cache_misses.values()) for kernel in COMPILED_KERNELS)
