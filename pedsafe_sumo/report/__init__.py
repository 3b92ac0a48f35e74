"""The report of a batch run (docs/report.md): Table I with intervals, paired tests, figures.

    python -m pedsafe_sumo.report DIR

`rundir` reads and checks the run directory, `tables` builds and formats the tables (statistics from
`pedsafe_sumo.safety.stats`), `summaries` computes what the figures show, `figures` draws them.
"""

from pedsafe_sumo.report.rundir import ReportError, RunDirectory, load_run, run_header
from pedsafe_sumo.report.tables import paired_of_run, table_one_of_run

__all__ = ["ReportError", "RunDirectory", "load_run", "paired_of_run", "run_header", "table_one_of_run"]
