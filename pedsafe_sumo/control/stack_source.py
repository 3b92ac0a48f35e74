"""Where an AD stack a file names may be imported from (docs/trust.md).

A replay and a resumed batch read the AD stack ("package.module:Class", with "+perception" after it)
from run.json, a batch --protocol from the protocol file: files that may come from someone else.
Importing a module runs its code, so a name from a file is imported only when the module is found
outside the current directory:

- the stack of the package itself (pedsafe_sumo.*, the shipped reference stack) always is;
- any other module must be found on the import path without the current directory: an installed
  package, or a folder the user put on PYTHONPATH. Python puts the current directory first on the path
  of `python -m` ('' or its full path); a module there is refused, and so is a module the current
  directory holds beside an installed one of the same name (it would be imported in its place, here or
  in a worker) or one inside the run directory.

A stack the user names on the command line (--algorithm, --perception) is imported as named, from the
current directory too: the user chose it. Every refusal is one AlgorithmLoadError line that names the
module and says how to run it anyway.
"""

from __future__ import annotations

import os
import sys
from importlib.machinery import PathFinder
from pathlib import Path

from pedsafe_sumo.confine import is_inside
from pedsafe_sumo.control.agent import PERCEPTION_JOIN, AlgorithmLoadError
from pedsafe_sumo.control.stack_names import resolve_stack_name

#: The package's own modules: the program that is running, trusted as it is.
SHIPPED_PACKAGE = "pedsafe_sumo"


def _named_on_pythonpath(directory: Path) -> bool:
    entries = [e for e in os.environ.get("PYTHONPATH", "").split(os.pathsep) if e]
    return any(Path(e).resolve() == directory for e in entries)


def import_path_without_cwd() -> list[str]:
    """sys.path without the current directory ('' or its path), unless PYTHONPATH names it."""
    cwd = Path.cwd().resolve()
    if _named_on_pythonpath(cwd):
        return list(sys.path)
    return [entry for entry in sys.path if entry and Path(entry).resolve() != cwd]


def _origin(top: str, path: list[str]) -> Path | None:
    """The file or folder the import system would load top-level module `top` from, on `path`."""
    spec = PathFinder.find_spec(top, path)
    if spec is None:
        return None
    if spec.origin not in (None, "namespace"):
        return Path(spec.origin)
    locations = list(spec.submodule_search_locations or [])
    return Path(locations[0]) if locations else None


def is_shipped(spec: str) -> bool:
    """Whether every module of the stack `spec` is pedsafe_sumo's own (a shipped stack, by its spec or
    its short name)."""
    return all(
        part.partition(":")[0].split(".")[0] == SHIPPED_PACKAGE
        for part in resolve_stack_name(spec).split(PERCEPTION_JOIN)
    )


def recorded_stack_origin(spec: str, run_dir: Path | None, named_by: str = "run.json") -> str:
    """Check that every module of the stack `spec`, read from the file `named_by` (run.json of `run_dir`,
    or a protocol file with `run_dir` None), may be imported (module docstring) and say where each
    comes from; AlgorithmLoadError (one line) when not."""
    cwd = Path.cwd().resolve()
    cwd_implicit = not _named_on_pythonpath(cwd)
    found = []
    for part in resolve_stack_name(spec).split(PERCEPTION_JOIN):
        module = part.partition(":")[0]
        top = module.split(".")[0]
        if top == SHIPPED_PACKAGE:
            found.append(f"{module} (pedsafe_sumo itself)")
            continue
        origin = _origin(top, import_path_without_cwd())
        if origin is None:
            raise AlgorithmLoadError(
                f"{named_by} names the AD stack '{spec}', whose module '{top}' is not installed (a module in "
                f"the current directory is not imported on a file's word): put its folder on PYTHONPATH "
                "or name it with --algorithm"
            )
        if run_dir is not None and is_inside(origin, run_dir):
            raise AlgorithmLoadError(
                f"{named_by} names the AD stack '{spec}', whose module '{top}' lies in the run directory "
                f"{run_dir}: name it with --algorithm to run it"
            )
        if cwd_implicit and _origin(top, [str(cwd)]) is not None:
            raise AlgorithmLoadError(
                f"the current directory holds a module '{top}' that would be imported in place of the "
                f"installed one {named_by} names: run from another directory or name it with --algorithm"
            )
        found.append(f"{module} from {origin}")
    return ", ".join(found)


def stack_to_replay(recorded: str, named: str | None, run_dir: Path) -> tuple[str, str]:
    """The stack a replay imports and a note saying which and from where ("" for pedsafe_sumo's own
    stack): `named` (--algorithm) when given, else the `recorded` one if the rule above lets it be
    imported (AlgorithmLoadError if not)."""
    if named is None:
        origin = recorded_stack_origin(recorded, run_dir)
        return recorded, "" if is_shipped(recorded) else f"AD stack from run.json: {origin}"
    differs = "" if named == recorded else f"; the run recorded {recorded}"
    return named, f"AD stack named by --algorithm: {named}{differs}"
