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
    """One frame through every compiled kernel (the package's own warm-up, which says when it compiles)."""
    # Imported here: a run on one core never needs them before its tests do.
    from pedsafe_sumo.compiled_kernels import prepare_compiled_kernels

    prepare_compiled_kernels()
