"""The error every command prints as one line with exit code 2 (bad command-line input).

Its own module, with no imports, so that a command that needs nothing of the scenario machinery
(`python -m pedsafe_sumo.conflicts`) does not load it to report a bad flag; `pedsafe_sumo.settings`
re-exports it.
"""


class UsageError(ValueError):
    """Bad command-line input; the CLIs print it as one line and exit with 2."""
