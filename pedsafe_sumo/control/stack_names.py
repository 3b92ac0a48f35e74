"""Short names of the AD stacks the package ships, for `--algorithm NAME` (docs/baseline_stack.md).

A name here stands for its "package.module:Class" everywhere a stack is named: the command lines, a
protocol file, run.json. Anything else is taken as "package.module:Class" itself.
"""

from __future__ import annotations

#: name -> stack. "reference": the baseline stack an evaluation compares against; "human": an attentive
#: human driver (docs/human_driver.md); "paper-v7": the stack protocols/paper-v7.toml ran (it brakes for
#: pedestrians only, forgets them after 0.5 s).
SHIPPED_STACKS: dict[str, str] = {
    "reference": "pedsafe_sumo.control.baseline:BaselineStack",
    "human": "pedsafe_sumo.control.human:HumanDriverStack",
    "paper-v7": "pedsafe_sumo.control.reference:ReferenceStack",
}
#: Joins an algorithm and a perception in one stack spec (control.agent.PERCEPTION_JOIN).
_JOIN = "+"


def resolve_stack_name(spec: str) -> str:
    """The "package.module:Class" spec of `spec`, its short names (SHIPPED_STACKS) replaced; each part
    of an "algorithm+perception" spec is resolved alone."""
    return _JOIN.join(SHIPPED_STACKS.get(part, part) for part in spec.split(_JOIN))


def stack_names_help() -> str:
    """One line for a --algorithm help text."""
    return ", ".join(f"{name} ({spec})" for name, spec in SHIPPED_STACKS.items())
