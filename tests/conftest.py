"""Fixtures of every test, and how the suite runs on several cores.

The repository root named on PYTHONPATH: the test stacks (tests/*/plugin_agents.py) are imported by their
dotted name. A replay or a resumed batch imports a stack that run.json names only from the import path
without the current directory (docs/trust.md); naming the repository root on PYTHONPATH makes the test
stacks importable as a user's own stacks are, for the commands the tests start and for those they call
in-process.

Several cores (`make test`: pytest-xdist, ``-n auto --dist loadgroup``): each test goes to the worker of
its group (the ``xdist_group`` mark set here):

- ``display``: the tests that start sumo-gui under ``xvfb-run -a``, with the rest of their files and every
  test of the logged run they replay (fixture ``replay_run``). ``xvfb-run -a`` takes the first display
  number without a lock file, so two X servers started in the same instant pick the same number and one
  of them fails: one worker starts them one after the other.
- ``small_run``, ``zhixin``: the tests of the session fixtures of that name (a finished batch run, a
  built site folder), made once on one worker rather than once on each.
- otherwise the test's file, so that a file's module-scoped fixtures (a running SUMO, a finished run)
  are made once.

Before the workers start, the controller compiles the numba kernels into their on-disk cache (numba
keeps one index file per function, and two processes that compile different signatures of a function
at the same time can leave an index entry pointing at the other signature's code); the workers then
only read the cache.
"""

from __future__ import annotations

import os

import numpy as np
import pytest

from pedsafe_sumo import REPO_ROOT

_entries = [e for e in os.environ.get("PYTHONPATH", "").split(os.pathsep) if e]
if str(REPO_ROOT) not in _entries:
    os.environ["PYTHONPATH"] = os.pathsep.join([str(REPO_ROOT), *_entries])

#: Session fixtures whose tests share one worker (see the module docstring).
SHARED_FIXTURE_GROUPS = ("small_run", "zhixin")


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    display_files = {item.path for item in items if item.get_closest_marker("gui")}
    for item in items:
        fixtures = set(getattr(item, "fixturenames", ()))
        shared = [name for name in SHARED_FIXTURE_GROUPS if name in fixtures]
        if item.path in display_files or "replay_run" in fixtures:
            group = "display"
        elif shared:
            group = shared[0]
        else:
            group = item.nodeid.split("::", 1)[0]
        item.add_marker(pytest.mark.xdist_group(group))


def pytest_sessionstart(session: pytest.Session) -> None:
    config = session.config
    is_controller = getattr(config.option, "numprocesses", None) and not hasattr(config, "workerinput")
    if is_controller:
        compile_numba_kernels()


def compile_numba_kernels() -> None:
    """One frame through every compiled kernel: the perception pipeline with a roadside unit and its
    V2I link, the ray casting of the sight and vehicle-detection callers, and the clearance kernels."""
    # Imported here: a run on one core never needs them before its tests do.
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
    from pedsafe_sumo.safety.geometry_kernels import rectangle_circle_clearance_m, walks_into_body

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
    walks_into_body(
        *(np.array([v]) for v in (0.0, 0.0, 0.0, 4.5, 1.8, 2.4)), 5.0, 0.0, 4.0, 0.0, 0.25, 0.3, 0.05
    )
