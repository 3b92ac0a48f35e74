"""The arguments that decide a batch's results: their defaults, the ones given, the ones of a resumed run.

run.json records them under `arguments`; `--resume` takes them from there, and a flag given again must
repeat its value (batch/resume.py checks the run's identity built from them).
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from pedsafe_sumo.batch.sampled import (
    FAMILY_JOINT,
    FAMILY_PRODUCT,
    SAMPLER_MC,
    V2I_FACTOR_CONTRAST_V2I_ONLY,
    V2I_FACTOR_NONE,
)
from pedsafe_sumo.control.timeout import DEFAULT_AGENT_TIMEOUT_S
from pedsafe_sumo.io.step_logs import KEEP_EVENTS
from pedsafe_sumo.sampling.importance import SQRT_HALF
from pedsafe_sumo.sampling.stages import (
    DEFAULT_PILOT_EPISODES,
    DEFAULT_PILOT_STAGES,
    DEFAULT_POOL_FROM_STAGE,
    INPUTS_SCREENED,
    SCORE_CLEARANCE,
    SCORE_TTC,
)
from pedsafe_sumo.sim.episode import DEFAULT_ALGORITHM

DEFAULT_EPISODES = 100
#: The arguments that decide a run's results (and its chunk layout), with their defaults. run.json
#: records them; --resume takes them from there, and a flag given again must repeat its value.
RUN_ARGUMENT_DEFAULTS: dict[str, Any] = {
    "scenario": None,
    "condition": "both",
    "episodes": DEFAULT_EPISODES,
    "seed": 1,
    "site": "xueqing",
    "params": None,
    "set": [],
    "algorithm": DEFAULT_ALGORITHM,
    "perception": None,
    "chunk_size": None,
    "protocol": None,
    "agent_timeout": DEFAULT_AGENT_TIMEOUT_S,
    "keep_logs": KEEP_EVENTS,
    "approach": None,
    "sampler": SAMPLER_MC,
    "is_pilot_stages": DEFAULT_PILOT_STAGES,
    "is_pilot_episodes": DEFAULT_PILOT_EPISODES,
    "is_inputs": INPUTS_SCREENED,
    "is_min_spread": SQRT_HALF,
    "is_proposal": None,
    # TTC: the clearance score drives the proposal away from collisions on Xueqing's crossing; the TTC
    # score agrees with plain MC on all four scenarios (docs/decisions/2026-11-23-is-score-ttc.md).
    "is_score": SCORE_TTC,
    # joint: against a 10,000-pair MC run it needs fewer episodes than the product on all four scenarios
    # (docs/decisions/2026-11-23-is-family-joint.md); the product stays one flag away.
    "is_family": FAMILY_JOINT,
    # Table I pools the pilot stages from stage 2 with the final one
    # (docs/decisions/2026-11-23-is-pooling-and-pilot-stages.md).
    "is_pool_from": DEFAULT_POOL_FROM_STAGE,
    # The joint proposal also aims at V2I's collisions where the pilots hold enough of them, including
    # those where SV does not collide (sampling/v2i_factor.py; docs/decisions/2026-11-23-is-v2i-factor.md,
    # docs/decisions/2026-11-24-is-v2i-only-term.md).
    "is_v2i_factor": V2I_FACTOR_CONTRAST_V2I_ONLY,
}
#: The value a run.json without one of these keys stands for: its run was made with that value, before
#: run.json recorded the argument (or while the default was this value). --resume fills the missing key
#: with it, not with the current default, so that the run stays the same run.
RESUME_DEFAULTS_OF_OLDER_RUNS: dict[str, Any] = {
    "is_score": SCORE_CLEARANCE,
    "is_family": FAMILY_PRODUCT,
    # None: the final stage alone, Table I's estimator without --is-pool-from.
    "is_pool_from": None,
    "is_v2i_factor": V2I_FACTOR_NONE,
}


def explicit_arguments(args: argparse.Namespace) -> dict[str, Any]:
    """The run arguments given on the command line, paths made absolute where run.json needs them so."""
    given = {name: getattr(args, name) for name in RUN_ARGUMENT_DEFAULTS if getattr(args, name) is not None}
    if "params" in given:
        given["params"] = str(Path(given["params"]).resolve())
    if "protocol" in given:
        given["protocol"] = str(Path(given["protocol"]))
    if "is_proposal" in given:
        given["is_proposal"] = str(Path(given["is_proposal"]).resolve())
    return given


def resumed_arguments(recorded: dict[str, Any], explicit: dict[str, Any]) -> dict[str, Any]:
    """A resumed run's arguments: the flags given again over the recorded ones, over the values a run.json
    without a key stands for (RESUME_DEFAULTS_OF_OLDER_RUNS), over the current defaults."""
    return {**RUN_ARGUMENT_DEFAULTS, **RESUME_DEFAULTS_OF_OLDER_RUNS, **recorded, **explicit}
