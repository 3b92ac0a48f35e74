"""Fixtures of every test: the repository root named on PYTHONPATH.

The test stacks (tests/*/plugin_agents.py) are imported by their dotted name. A replay or a resumed
batch imports a stack that run.json names only from the import path without the current directory
(docs/trust.md); naming the repository root on PYTHONPATH makes the test stacks importable as a user's
own stacks are, for the commands the tests start and for those they call in-process.
"""

from __future__ import annotations

import os

from pedsafe_sumo import REPO_ROOT

_entries = [e for e in os.environ.get("PYTHONPATH", "").split(os.pathsep) if e]
if str(REPO_ROOT) not in _entries:
    os.environ["PYTHONPATH"] = os.pathsep.join([str(REPO_ROOT), *_entries])
