"""The batch under `--sampler is`: stage by stage, each stage's proposal refitted on the one before.

The stages, the score and the cross-entropy update are in sampling/stages.py (docs/sampling.md). This
module plans the chunks of every stage (their layout is known from the start; their proposals are known
once the stage before has finished), stores each stage's proposal in run.json under
`sampler_proposals` (scenario -> one JSON proposal per stage, "" for the nominal of stage 0) the moment
it is computed, and runs the stages in order. A resumed run takes the stored proposals, so its rows are
the rows an uninterrupted run would have written, on any number of workers or on Dask.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Any

from pedsafe_sumo.batch.chunks import Chunk, Task, episode_seed
from pedsafe_sumo.batch.runner import scenario_spec
from pedsafe_sumo.io.run_store import read_parts
from pedsafe_sumo.sampling.distributions import age_group_speed_distributions
from pedsafe_sumo.sampling.draws import product_from_json, product_to_json
from pedsafe_sumo.sampling.importance import MIN_SPREAD_OF_NOMINAL
from pedsafe_sumo.sampling.joint import GUARD_MIN_COLLISIONS, NORM_DRAWS, VISIBLE_M, Kinematics
from pedsafe_sumo.sampling.joint import RIDGE as JOINT_RIDGE
from pedsafe_sumo.sampling.joint_fit import joint_update
from pedsafe_sumo.sampling.pooling import POOL_FROM_KEY, pooled_from_stage
from pedsafe_sumo.sampling.stages import (
    ADAPT_CONDITION,
    COLLISION_SCORE,
    DEFENSIVE_SHARE,
    ELITE_FRACTION,
    INPUTS_ALL,
    INPUTS_SCREENED,
    SCORE_CLEARANCE,
    SCORE_TTC,
    SCREEN_P_VALUE,
    cross_entropy_update,
    stage_layout,
)
from pedsafe_sumo.sampling.v2i_factor import V2I_ONLY_MIN_COLLISIONS, low_contrast_table, v2i_only_count
from pedsafe_sumo.scenarios.road_users import CAR_COLOURS_RGB, CLOTHING_COLOURS_RGB

#: --is-family: the cross-entropy product of one family per input, or the joint sqrt(pi_hat) proposal.
FAMILY_PRODUCT = "product"
FAMILY_JOINT = "joint"
#: run.json's record of pi_hat's design under the joint family: the inputs and the kinematic features.
JOINT_FEATURES_KEY = "joint_features"
JOINT_FEATURES = (
    f"inputs + kinematics (v, 1/w, margin_s with visible_m {VISIBLE_M}); pilot guard margin_s < 0 below "
    f"{GUARD_MIN_COLLISIONS} collisions"
)
FAMILIES = (FAMILY_PRODUCT, FAMILY_JOINT)
#: --is-v2i-factor: whether the joint proposal also aims at V2I's collisions (sampling/v2i_factor.py), and
#: run.json's record of it (the key only when on, so that the identity of a run without it has no such key).
V2I_FACTOR_CONTRAST = "contrast"
#: The factor with its V2I-only term (sampling/v2i_factor.py, "The V2I-only term").
V2I_FACTOR_CONTRAST_V2I_ONLY = "contrast+v2i-only"
V2I_FACTOR_NONE = "none"
V2I_FACTORS = (V2I_FACTOR_CONTRAST_V2I_ONLY, V2I_FACTOR_CONTRAST, V2I_FACTOR_NONE)
V2I_FACTOR_KEY = "v2i_factor"
#: run.json's record of the V2I-only term (the key only when on, so that runs of 'contrast' keep theirs).
V2I_ONLY_KEY = "v2i_only"
V2I_ONLY_RECORD = (
    f"plus pi_vo, a ridge logistic over pi_hat's design of V2I's collisions whose SV episode did not "
    f"collide, where the pilot pairs hold at least {GUARD_MIN_COLLISIONS}, or {V2I_ONLY_MIN_COLLISIONS} "
    f"that make up the defensive share of their V2I collisions; pi_v2i = min(1, pi_hat r + pi_vo)"
)
V2I_FACTOR_RECORD = (
    "pi_hat r, r a ridge logistic of V2I's collision on the pilots' SV collisions over low-contrast "
    f"indicators (clothing against each vehicle colour, the roadside camera's delta E threshold), at least "
    f"{GUARD_MIN_COLLISIONS} V2I collisions; a = m_v2i^2 / (m_sv^2 + m_v2i^2)"
)
SAMPLER_MC = "mc"
SAMPLER_IS = "is"
PROPOSALS_KEY = "sampler_proposals"
LEVELS_KEY = "sampler_levels"


#: The sampler settings a run with --is-proposal takes from the run whose proposals it shares.
SHARED_KEY = "shared_proposals"


class SamplerError(ValueError):
    """A sampler setting that cannot be used (one line for the batch's stderr)."""


def sampler_identity(arguments: dict[str, Any], scenarios: list[str] | None = None) -> dict[str, Any] | None:
    """What run.json records of the sampler (None under plain Monte Carlo).

    With `is_proposal` (batch --is-proposal RUN): the settings and every stage's proposal of that run
    (shared_proposal_of), so that this run draws the very episodes and weights it drew.
    """
    if arguments["sampler"] != SAMPLER_IS:
        return None
    if arguments.get("is_proposal"):
        return shared_proposal_of(Path(arguments["is_proposal"]), scenarios or [])
    identity = {
        "kind": SAMPLER_IS,
        "pilot_stages": int(arguments["is_pilot_stages"]),
        "pilot_episodes": int(arguments["is_pilot_episodes"]),
        "adapt_condition": ADAPT_CONDITION,
        "elite_fraction": ELITE_FRACTION,
        "defensive_share": DEFENSIVE_SHARE,
        "score": "collision: 1 + impact_speed_mps; otherwise -min_clearance_m",
        "threshold": COLLISION_SCORE,
        "inputs": arguments.get("is_inputs", INPUTS_SCREENED),
        "screen_p_value": SCREEN_P_VALUE,
        "min_spread_of_nominal": float(arguments["is_min_spread"]),
    }
    if arguments.get("is_family", FAMILY_PRODUCT) != FAMILY_PRODUCT:
        # Only when not the product, so that product runs keep their identity.
        identity.update(family=arguments["is_family"], ridge=JOINT_RIDGE, norm_draws=NORM_DRAWS)
        # A run.json without this key fitted without the kinematic features: its resume is refused.
        identity[JOINT_FEATURES_KEY] = JOINT_FEATURES
        factor = arguments.get("is_v2i_factor", V2I_FACTOR_NONE)
        if factor in (V2I_FACTOR_CONTRAST, V2I_FACTOR_CONTRAST_V2I_ONLY):
            identity[V2I_FACTOR_KEY] = V2I_FACTOR_RECORD
        if factor == V2I_FACTOR_CONTRAST_V2I_ONLY:
            identity[V2I_ONLY_KEY] = V2I_ONLY_RECORD
    first_pooled = pooled_from_stage(arguments.get("is_pool_from"), identity["pilot_stages"])
    if first_pooled < identity["pilot_stages"]:
        # Only when pilots are pooled, so that runs made before --is-pool-from keep their identity.
        identity[POOL_FROM_KEY] = first_pooled
    if arguments.get("is_score", SCORE_CLEARANCE) != SCORE_CLEARANCE:
        # Only when not the first score, so that runs made before --is-score keep their identity.
        identity.update(score="collision: 1 + impact_speed_mps; otherwise -min_ttc_s", score_kind=SCORE_TTC)
    return identity


def shared_proposal_of(source: Path, scenarios: list[str]) -> dict[str, Any]:
    """The sampler of the run at `source` (its directory or its run.json), with every stage's proposal
    of each of `scenarios` under SHARED_KEY and their SHA-256; SamplerError (one line) when that run is
    not an importance-sampling run that has fixed every proposal of these scenarios."""
    path = source / "run.json" if source.is_dir() else source
    try:
        info = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise SamplerError(f"--is-proposal: cannot read {path}: {exc}") from None
    sampler = info.get("sampler") if isinstance(info, dict) else None
    if not isinstance(sampler, dict) or sampler.get("kind") != SAMPLER_IS:
        raise SamplerError(f"--is-proposal: {path} is not a run made with --sampler is")
    stored = info.get(PROPOSALS_KEY) or {}
    shared = {}
    n_stages = int(sampler["pilot_stages"]) + 1
    for scenario in scenarios:
        proposals = stored.get(scenario, [])
        if len(proposals) < n_stages:
            raise SamplerError(
                f"--is-proposal: {path} has {len(proposals)} of the {n_stages} proposals of {scenario} "
                "(a scenario it did not run, or a run that stopped before its final stage)"
            )
        shared[scenario] = list(proposals[:n_stages])
    digest = hashlib.sha256(json.dumps(shared, sort_keys=True).encode()).hexdigest()
    settings = {key: value for key, value in sampler.items() if key not in (SHARED_KEY, "shared_sha256")}
    return {**settings, SHARED_KEY: shared, "shared_sha256": digest}


def plan_sampled_chunks(
    scenarios: list[str], conditions: list[str], identity: dict[str, Any], proposals: dict[str, list[str]]
) -> list[Chunk]:
    """Every chunk of every stage, scenario by scenario; a stage whose proposal `proposals` lacks gets
    "" (enough for the layout and the chunk keys, which do not depend on it)."""
    sampler = identity["sampler"]
    layout = stage_layout(
        sampler["pilot_stages"], sampler["pilot_episodes"], identity["episodes_per_scenario"]
    )
    pairs = identity["chunk_size_pairs"] or 1
    chunks = []
    for scenario in scenarios:
        for stage in layout:
            known = proposals.get(scenario, [])
            proposal = known[stage.stage] if stage.stage < len(known) else ""
            end = stage.first_episode + stage.n_episodes
            for first in range(stage.first_episode, end, pairs):
                last = min(first + pairs, end) - 1
                tasks = tuple(
                    Task(
                        scenario,
                        i,
                        episode_seed(identity["run_seed"], i),
                        tuple(conditions),
                        proposal,
                        stage.stage,
                    )
                    for i in range(first, last + 1)
                )
                chunks.append(Chunk(scenario, first, last, tasks))
    return chunks


def _stage_of(chunk: Chunk) -> int:
    return chunk.tasks[0].stage


def kinematics_of(config: Any, scenario: str) -> Kinematics:
    """The kinematic features' maps of `scenario` under the run's parameters (sampling/joint.py): its ego
    speed bounds, the age groups' walking-speed lognormals in the order the draws number them, and the
    [algorithm] reaction time and braking of the parameters."""
    spec = scenario_spec(scenario, config.scenario_overrides)
    laws = list(age_group_speed_distributions(dict(config.params["pedestrians"])).values())
    algorithm = config.params["algorithm"]
    return Kinematics(
        float(spec.ego_speed_min_mps),
        float(spec.ego_speed_max_mps),
        tuple(law.log_mu for law in laws),
        tuple(law.log_sigma for law in laws),
        float(algorithm["reaction_time_s"]),
        float(algorithm["max_decel_mps2"]),
    )


def low_contrast_of(config: Any) -> tuple[tuple[int, ...], ...]:
    """The V2I factor's table L (sampling/joint.py): the scenarios' clothing against their car colours at
    the roadside camera's delta E threshold of the run's parameters."""
    threshold = float(config.params["perception"]["roadside_camera"]["delta_e_threshold"])
    return low_contrast_table(CLOTHING_COLOURS_RGB, CAR_COLOURS_RGB, threshold)


def _joint_stage(
    plan: Any,
    identity: dict[str, Any],
    proposals: dict[str, list[str]],
    run_dir: Any,
    scenario: str,
    stage: int,
    levels: dict[str, list[dict[str, Any]]],
) -> str:
    """`--is-family joint`: the proposal of `stage`, fitted on the SV rows of every pilot stage before it
    (sampling/joint.py); for a pilot stage while those rows hold fewer than GUARD_MIN_COLLISIONS
    collisions, the guard's region proposal; "" (the nominal) where neither applies and they hold none."""
    earlier = [
        c
        for c in plan_sampled_chunks([scenario], plan.conditions, identity, proposals)
        if _stage_of(c) < stage
    ]
    rows = read_parts(run_dir.path, [run_dir.manifest.chunks[c.key] for c in earlier])
    kinematics = kinematics_of(plan.config, scenario) if identity["sampler"].get(JOINT_FEATURES_KEY) else None
    pilot_stage = stage < int(identity["sampler"]["pilot_stages"])
    low_contrast = low_contrast_of(plan.config) if identity["sampler"].get(V2I_FACTOR_KEY) else None
    proposal, n_collisions, guard = joint_update(
        rows,
        ADAPT_CONDITION,
        float(identity["sampler"]["defensive_share"]),
        kinematics,
        pilot_stage,
        low_contrast,
        bool(identity["sampler"].get(V2I_ONLY_KEY)),
    )
    factor = proposal.v2i_factor if proposal else None
    levels.setdefault(scenario, []).append(
        {
            "after_stage": stage - 1,
            "family": FAMILY_JOINT,
            "n_rows_sv": int(((rows["condition"] == ADAPT_CONDITION) & (rows["status"] == "ok")).sum()),
            "n_collisions_sv": n_collisions,
            "proposed": proposal.names if proposal else [],
            "norm": proposal.norm if proposal else None,
            "mean_tries": proposal.bound if proposal else None,
            "guard": guard,
            **(
                {"v2i_factor": factor.coefficients, "v2i_target_share": factor.target_share}
                if factor is not None
                else {}
            ),
            **(
                {"v2i_only_terms": len(factor.v2i_only_coefficients)}
                if factor is not None and factor.v2i_only_coefficients
                else {}
            ),
            # What report/tables.py's v2i_only_note reads: V2I-only collisions the proposal may not aim at.
            "v2i_only_pilot_collisions": v2i_only_count(rows) if len(rows) else 0,
        }
    )
    return proposal.to_json() if proposal else ""


def run_sampled(
    plan: Any, backend: Any, run_dir: Any, run_info: dict[str, Any], on_chunk_done: Any
) -> list[Chunk]:
    """Run the stages in order (module docstring); returns every chunk of the run."""
    identity = plan.identity
    n_stages = identity["sampler"]["pilot_stages"] + 1
    proposals: dict[str, list[str]] = run_info.setdefault(PROPOSALS_KEY, {})
    levels: dict[str, list[dict[str, Any]]] = run_info.setdefault(LEVELS_KEY, {})
    for stage in range(n_stages):
        for scenario in plan.scenarios:
            known = proposals.setdefault(scenario, [])
            if len(known) > stage:
                continue
            if stage == 0:
                known.append("")
                continue
            shared = identity["sampler"].get(SHARED_KEY)
            if shared is not None:  # --is-proposal: the other run's proposal, not refitted
                known.append(shared[scenario][stage])
                continue
            if identity["sampler"].get("family", FAMILY_PRODUCT) == FAMILY_JOINT:
                known.append(_joint_stage(plan, identity, proposals, run_dir, scenario, stage, levels))
                continue
            previous = [
                c
                for c in plan_sampled_chunks([scenario], plan.conditions, identity, proposals)
                if _stage_of(c) == stage - 1
            ]
            rows = read_parts(run_dir.path, [run_dir.manifest.chunks[c.key] for c in previous])
            current = product_from_json(known[stage - 1]).families
            # A run.json without these keys proposed every input (no screen), with the spread floor of 0.2,
            # and ranked by clearance.
            update = cross_entropy_update(
                rows,
                current,
                identity["sampler"].get("inputs", INPUTS_ALL),
                identity["sampler"].get("min_spread_of_nominal", MIN_SPREAD_OF_NOMINAL),
                identity["sampler"].get("score_kind", SCORE_CLEARANCE),
            )
            known.append(product_to_json(update.proposal))
            levels.setdefault(scenario, []).append(
                {
                    "after_stage": stage - 1,
                    "level": update.level,
                    "n_elite": update.n_elite,
                    "n_collisions_sv": update.n_collisions,
                    "proposed": sorted(update.proposal.families),
                    "screen_p_values": update.screen,
                }
            )
        run_dir.save_run_info(run_info)
        chunks = plan_sampled_chunks(plan.scenarios, plan.conditions, identity, proposals)
        todo = [c for c in chunks if _stage_of(c) == stage and c.key not in run_dir.manifest.chunks]
        if todo:
            backend.run(plan.config, todo, on_chunk_done)
    return plan_sampled_chunks(plan.scenarios, plan.conditions, identity, proposals)
