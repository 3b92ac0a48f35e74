"""The command `pedsafe-sumo` (also `python -m pedsafe_sumo`): one subcommand per task, each the command
line of a module of the package (`pedsafe-sumo batch ...` is `python -m pedsafe_sumo.batch ...`).

    pedsafe-sumo --version
    pedsafe-sumo batch --scenario crossing --episodes 100 --out results/crossing
    pedsafe-sumo report results/crossing
    pedsafe-sumo site build --osm my.osm --center 40.0064,116.3462 --name mysite --out sites/mysite
"""

from __future__ import annotations

import importlib
import sys

from pedsafe_sumo import CHECKOUT_ROOT, __version__

PROG = "pedsafe-sumo"
#: Subcommand -> (module whose main(argv) it runs, what it does).
COMMANDS: dict[str, tuple[str, str]] = {
    "batch": ("pedsafe_sumo.batch.__main__", "a batch of paired SV/V2I episodes, and its Table I"),
    "report": (
        "pedsafe_sumo.report.__main__",
        "Table I with 95% intervals, paired tests, figures, report.html",
    ),
    "replay": ("pedsafe_sumo.replay.__main__", "replay a logged episode in sumo-gui, render or export it"),
    "compare": ("pedsafe_sumo.compare", "build against build: paired non-inferiority at a margin"),
    "conflicts": (
        "pedsafe_sumo.conflicts.__main__",
        "pedestrian conflicts and surrogate measures of a SUMO run",
    ),
    "ncap": ("pedsafe_sumo.ncap.__main__", "the Euro NCAP 2026 pedestrian AEB grids, SV against V2I"),
    "sweep": ("pedsafe_sumo.sweep", "one paired batch per combination of settings"),
    "site": (
        "pedsafe_sumo.site.__main__",
        "rebuild a study site and summarise it ('site build': a new site)",
    ),
    "demand": ("pedsafe_sumo.demand.__main__", "background traffic and pedestrians for a site (.rou.xml)"),
    "episode": ("pedsafe_sumo.episode", "run one episode and tell a human what happened"),
    "protocol": ("pedsafe_sumo.protocol", "write a dated protocol fixing every value of a study"),
}
#: `pedsafe-sumo site build ...`: the site build (tools/build_network.py in a checkout).
SITE_BUILD_MODULE = "pedsafe_sumo.site.build_command"


def version_lines() -> list[str]:
    """The package's version, SUMO's, and the git commit when run from a checkout."""
    # Imported here: sumolib takes a moment to import, and only --version needs it.
    import sumolib.version

    from pedsafe_sumo.provenance import git_commit

    lines = [f"{PROG} {__version__}", f"SUMO {sumolib.version.gitDescribe().removeprefix('v')}"]
    commit = git_commit()
    if commit:
        lines.append(f"commit {commit} ({CHECKOUT_ROOT})")
    return lines


def usage() -> str:
    width = max(len(name) for name in COMMANDS)
    rows = [f"  {name:<{width}}  {what}" for name, (_, what) in COMMANDS.items()]
    return "\n".join(
        [
            f"usage: {PROG} [--version] COMMAND [ARGS ...]",
            "",
            "Pedestrian safety of autonomous driving on Eclipse SUMO. Commands:",
            *rows,
            "",
            f"'{PROG} COMMAND --help' describes a command's options.",
        ]
    )


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    if not argv or argv[0] in ("-h", "--help", "help"):
        print(usage())
        return 0 if argv else 2
    if argv[0] == "--version":
        print("\n".join(version_lines()))
        return 0
    command, rest = argv[0], argv[1:]
    if command not in COMMANDS:
        print(f"{PROG}: error: unknown command '{command}' (known: {', '.join(COMMANDS)})", file=sys.stderr)
        return 2
    module_name = COMMANDS[command][0]
    if command == "site" and rest[:1] == ["build"]:
        module_name, rest = SITE_BUILD_MODULE, rest[1:]
    # Only the chosen command's module is imported: each one imports SUMO, numba or matplotlib.
    module = importlib.import_module(module_name)
    return int(module.main(rest) or 0)


if __name__ == "__main__":
    sys.exit(main())
