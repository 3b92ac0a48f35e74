"""What a resumed batch takes from the run directory it continues, checked first (docs/trust.md).

The run directory may come from someone else: its files are data. Before the driver locks it, no entry
the driver writes or deletes (.lock, run.json, manifest.json, parts/, steplogs/, cases/, ...) may be a
link leading out of it (run_store confines the paths manifest.json names). The AD stack that run.json
or a protocol file names is imported only under control.stack_source's rule, unless the command names
it (--algorithm, --perception).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from pedsafe_sumo.confine import ConfinementError, check_entries
from pedsafe_sumo.control.stack_source import is_shipped, recorded_stack_origin
from pedsafe_sumo.io.run_store import (
    CASES_DIR,
    EPISODES_FILE,
    LOCK_FILE,
    MANIFEST_FILE,
    PARTS_DIR,
    RUN_FILE,
    STEPLOGS_DIR,
    TMP_SUFFIX,
)
from pedsafe_sumo.settings import UsageError

#: The entries of a run directory the driver opens, writes or deletes.
RUN_ENTRIES = (
    LOCK_FILE,
    RUN_FILE,
    MANIFEST_FILE,
    EPISODES_FILE,
    PARTS_DIR,
    STEPLOGS_DIR,
    CASES_DIR,
    *(name + TMP_SUFFIX for name in (RUN_FILE, MANIFEST_FILE, EPISODES_FILE)),
)


def check_run_entries(run_dir: Path) -> None:
    """UsageError (one line) when an entry of RUN_ENTRIES is a link leading out of `run_dir`."""
    try:
        check_entries(run_dir, RUN_ENTRIES, "cannot resume")
    except ConfinementError as exc:
        raise UsageError(str(exc)) from None


def check_stack_from_file(args: Any, stack: str, arguments: dict[str, Any], resumed: bool) -> None:
    """A stack no flag of this command names, taken from a file (the protocol's [protocol] algorithm, or
    run.json on --resume): refuse one control.stack_source does not import on a file's word, else say
    what it imports."""
    if args.algorithm is not None or args.perception is not None:
        return
    if arguments.get("protocol") is not None:
        source, run_dir = Path(arguments["protocol"]), None
    elif resumed:
        source, run_dir = Path(args.out) / RUN_FILE, Path(args.out)
    else:
        return
    origin = recorded_stack_origin(stack, run_dir, str(source))
    if not is_shipped(stack):  # on stdout: a refusal later stays one line on stderr
        print(f"the AD stack {source} names: {origin}")
