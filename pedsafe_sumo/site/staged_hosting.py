"""The site summary's hosting lines with the batch's staging check (batch/staging_check.py) over a sample
of seeds: a combination whose poles see its staging area but whose episodes cannot be staged is listed
NOT hosted, with the seed and why, as the batch would skip or refuse it."""

from __future__ import annotations

from typing import Any

from pedsafe_sumo.batch.arguments import RUN_ARGUMENT_DEFAULTS
from pedsafe_sumo.batch.staging_check import unstageable_units
from pedsafe_sumo.params import load_params
from pedsafe_sumo.scenarios.hosting import hosting_lines

#: Episodes staged per combination for the summary: the first ones of a batch with the default --seed.
#: A sample, not the batch's own check (which stages every seed a run draws): about 2-5 ms each, so the
#: summary of a four-approach site (about 20 combinations) takes a few seconds more.
SUMMARY_EPISODES = 20


def staged_hosting_lines(site) -> list[str]:
    """hosting_lines, with the staging of the first SUMMARY_EPISODES episodes of the default run seed."""
    params = load_params(None)
    run_seed = RUN_ARGUMENT_DEFAULTS["seed"]

    def staged(units: dict[str, Any]) -> dict[str, str]:
        failed = unstageable_units(site, params, units, run_seed, SUMMARY_EPISODES, say=lambda _line: None)
        return {unit: f"{why} (the batch's staging check)" for unit, why in failed.items()}

    return hosting_lines(site, params, staged)
