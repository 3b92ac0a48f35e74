"""Protocols: every value of a study fixed in one dated file before it runs.

    python -m pedsafe_sumo.batch --protocol protocols/paper-v7.toml --out DIR [--episodes N] [--workers K]
    pedsafe-sumo batch --protocol paper-v7 --out DIR     # a bare name: a shipped protocol, from any folder
    python -m pedsafe_sumo.protocol write paper-v11 --date 2026-12-01 --out protocols/paper-v11.toml

A protocol file (TOML) holds:
- [protocol]: name, date, description, scenarios (list), conditions, episodes, seed, site, algorithm;
- [scenarios.<name>]: every field of each scenario's spec (scenarios/specs.py);
- [parameters.<section>]: every value of the parameter file (params/defaults.toml).
Above each value a comment gives its source or, for what the paper does not report, the reason it was
chosen (`write` copies them from the comments of defaults.toml and of the spec's fields). A
protocol that leaves out a scenario field or a parameter is refused: nothing falls back silently to
defaults that may change later. The rule (docs/protocols.md): a change after seeing results is a
new dated file, never an edit; run.json records the file and its SHA-256.
"""

from __future__ import annotations

import dataclasses
import datetime
import hashlib
import json
import re
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import tomllib

from pedsafe_sumo import PROTOCOLS_DIR
from pedsafe_sumo.cli import MAX_EPISODES, OneLineParser, check_seed
from pedsafe_sumo.params import DEFAULTS_PATH, ParameterError, load_params, overlay, validate
from pedsafe_sumo.scenarios import specs
from pedsafe_sumo.scenarios.errors import ScenarioError
from pedsafe_sumo.scenarios.specs import SCENARIOS, ScenarioSpec, get_scenario
from pedsafe_sumo.settings import UsageError

#: The keys of a protocol's [protocol] table.
HEADER_KEYS = (
    "name",
    "date",
    "description",
    "scenarios",
    "conditions",
    "episodes",
    "seed",
    "site",
    "algorithm",
)
#: Batch flags a protocol run accepts besides --protocol (and --out, --resume).
OVERRIDABLE_FLAGS = ("episodes", "workers")


class ProtocolError(UsageError):
    """A protocol file that cannot be run as it stands (one line, exit 2)."""


@dataclass(frozen=True)
class Protocol:
    path: Path
    sha256: str
    header: dict[str, Any]
    #: Scenario name -> every field of its spec (but name and description), as the file gives them.
    scenario_fields: dict[str, dict[str, Any]]
    parameters: dict[str, Any]

    @property
    def scenarios(self) -> list[str]:
        return list(self.header["scenarios"])

    def specs(self) -> dict[str, ScenarioSpec]:
        try:
            return {
                name: get_scenario(name).with_overrides(self.scenario_fields[name]) for name in self.scenarios
            }
        except ScenarioError as exc:
            raise ProtocolError(f"protocol {self.path}: {exc}") from None

    def params(self) -> dict[str, Any]:
        params = load_params(None)
        named = _flatten(self.parameters)
        named = with_parameters_before(named)
        missing = sorted(set(_flatten(params)) - set(named))
        if missing:
            raise ProtocolError(
                f"protocol {self.path} does not fix parameter(s) {', '.join(missing[:5])}"
                + (f" and {len(missing) - 5} more" if len(missing) > 5 else "")
                + ": a protocol names every value (a new dated one: python -m pedsafe_sumo.protocol write)"
            )
        try:
            overlay(params, self.parameters, "")
            for dotted, value in named.items():
                if dotted in VALUES_BEFORE["parameters"]:
                    *tables, key = dotted.split(".")
                    target = params
                    for table in tables:
                        target = target[table]
                    target[key] = value
            validate(params)
        except ParameterError as exc:
            raise ProtocolError(f"protocol {self.path}: {exc}") from None
        return params

    def worker_overrides(self) -> dict[str, Any]:
        """Per-scenario field values for the batch workers, as '<scenario>:<field>' keys."""
        return {
            f"{name}:{key}": value
            for name in self.scenarios
            for key, value in self.scenario_fields[name].items()
        }

    def record(self) -> dict[str, Any]:
        """What run.json keeps of the protocol."""
        return {
            "file": str(self.path),
            "sha256": self.sha256,
            "name": self.header["name"],
            "date": self.header["date"],
        }


def _flatten(tree: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in tree.items():
        dotted = f"{prefix}.{key}" if prefix else key
        if isinstance(value, dict):
            out.update(_flatten(value, dotted))
        else:
            out[dotted] = value
    return out


def spec_fields(spec: ScenarioSpec) -> dict[str, Any]:
    return {k: v for k, v in dataclasses.asdict(spec).items() if k not in ("name", "description")}


#: Values a protocol written before they existed does not name, with the value that gives the behaviour
#: it was run with: scenario fields (by field) and parameters (dotted). A protocol that names none of a
#: group gets these; one that names some must name all. The scenario fields are one group; the parameters
#: form one group per table (values added to a table together), so a protocol written after one table's
#: values and before another's still runs.
VALUES_BEFORE: dict[str, dict[str, Any]] = {
    # The approach staging (ScenarioSpec.staging): the fixed staging never reads the other fields.
    "scenarios": {
        "staging": "fixed",
        "ego_start_min_m": 100.0,
        "ego_start_max_m": 160.0,
        "ped_appear_min_s": 3.0,
        "walk_in_min_s": 2.0,
        "walk_in_max_s": 10.0,
        "walk_on_m": 15.0,
        "kerb_gap_min_m": 0.3,
        "kerb_gap_max_m": 1.0,
        # The kerb-lane queue and waiting vehicle of the approach staging: placed standing at the start.
        "queue_staging": "placed",
        # Approach staging's oncoming vehicle (left_turn): across the line of sight when the pedestrian
        # reaches the kerb, wherever the ego then is (paper-v8 and paper-v10, which the staging check
        # refuses on xueqing_two_phase: docs/decisions/2026-11-28-left-turn-sight-line-staging.md).
        "oncoming_moment": "at_kerb",
    },
    "parameters": {
        # The pedestrian's kerb wait and side strike (params/defaults.toml [pedestrians]).
        "pedestrians.yield_at_kerb": False,
        "pedestrians.body_rule_needs_notice": False,
        # The proximity measure over every step with the pedestrian (safety/proximity.py SCOPE_EPISODE); the
        # corridor values are then unused.
        "safety.proximity_scope": "episode",
        "safety.interaction_margin_m": 0.5,
        "safety.interaction_horizon_s": 4.0,
        # The ego's physical limits: none applied before them.
        "vehicle.physical_limits": False,
        "vehicle.max_decel_mps2": 9.0,
        "vehicle.max_accel_mps2": 4.0,
        # The reference stack's tracker: the constant-velocity Kalman filter alone.
        "algorithm.tracker_motion_model": "cv",
        # No validation gate in the tracker; under V2I the SPaT message in place of the camera's reading.
        "algorithm.tracker_gate": "none",
        "perception.v2i.signal_source": "spat",
    },
}


#: The scenario fields of VALUES_BEFORE by the change that added them: a protocol that names none of a
#: group's fields was written before it and gets the group's "before" values.
SCENARIO_GROUPS_BEFORE: tuple[tuple[str, ...], ...] = (
    (
        "staging", "ego_start_min_m", "ego_start_max_m", "ped_appear_min_s", "walk_in_min_s",
        "walk_in_max_s", "walk_on_m", "kerb_gap_min_m", "kerb_gap_max_m",
    ),
    ("queue_staging",),
    ("oncoming_moment",),
)  # fmt: skip


def with_values_before(given: dict[str, Any], before: dict[str, Any]) -> dict[str, Any]:
    """`given` completed with the `before` values when it names none of them."""
    if before and not set(before) & set(given):
        return {**given, **before}
    return given


#: The parameters of VALUES_BEFORE that came together, named by one protocol or by none; every other
#: parameter of VALUES_BEFORE is grouped with those of its own table.
PARAMETER_GROUPS_BEFORE: tuple[tuple[str, ...], ...] = (
    ("algorithm.tracker_motion_model",),
    ("algorithm.tracker_gate", "perception.v2i.signal_source"),
)


def with_parameters_before(named: dict[str, Any]) -> dict[str, Any]:
    """Dotted parameters completed, group by group (PARAMETER_GROUPS_BEFORE, else the table), with the
    VALUES_BEFORE of each group they name none of."""
    grouped = {dotted: group for group in PARAMETER_GROUPS_BEFORE for dotted in group}
    groups: dict[Any, dict[str, Any]] = {}
    for dotted, value in VALUES_BEFORE["parameters"].items():
        groups.setdefault(grouped.get(dotted, dotted.rsplit(".", 1)[0]), {})[dotted] = value
    for before in groups.values():
        named = with_values_before(named, before)
    return named


def shipped_protocols() -> list[str]:
    """Names of the protocols shipped with the package (protocols/ of the checkout, or its installed copy)."""
    return sorted(p.stem for p in PROTOCOLS_DIR.glob("*.toml"))


def find_protocol(path: Path) -> Path:
    """The file a --protocol value names: an existing path as given; a bare name (paper-v7 or
    paper-v7.toml) not found in the working folder is the shipped protocol of that name."""
    if path.exists() or str(path.parent) != ".":
        return path
    shipped = PROTOCOLS_DIR / (path.name if path.suffix == ".toml" else f"{path.name}.toml")
    return shipped if shipped.is_file() else path


def load_protocol(path: Path) -> Protocol:
    """Read and check a protocol file (a path, or a shipped protocol's name: find_protocol); raises
    ProtocolError naming the first problem."""
    path = find_protocol(path)
    try:
        data = path.read_bytes()
        tree = tomllib.loads(data.decode("utf-8"))
    except FileNotFoundError:
        shipped = ", ".join(shipped_protocols()) or "none"
        raise ProtocolError(
            f"protocol file not found: {path} (give a protocol file's path, or a shipped protocol's name: "
            f"{shipped})"
        ) from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise ProtocolError(f"protocol {path} is not valid TOML: {exc}") from None
    except OSError as exc:
        raise ProtocolError(f"cannot read protocol {path}: {exc.strerror or exc}") from None
    unknown = sorted(set(tree) - {"protocol", "scenarios", "parameters"})
    if unknown:
        raise ProtocolError(f"protocol {path}: unknown table(s) {', '.join(unknown)}")
    header = tree.get("protocol", {})
    missing = [key for key in HEADER_KEYS if key not in header]
    if missing:
        raise ProtocolError(f"protocol {path}: [protocol] lacks {', '.join(missing)}")
    extra = sorted(set(header) - set(HEADER_KEYS))
    if extra:
        raise ProtocolError(f"protocol {path}: unknown [protocol] key(s) {', '.join(extra)}")
    scenarios = header["scenarios"]
    if not isinstance(scenarios, list) or not scenarios or any(s not in SCENARIOS for s in scenarios):
        raise ProtocolError(f"protocol {path}: scenarios must list known scenarios ({', '.join(SCENARIOS)})")
    if header["conditions"] not in ("sv", "v2i", "both"):
        raise ProtocolError(f"protocol {path}: conditions must be sv, v2i or both")
    for key in ("episodes", "seed"):
        if not isinstance(header[key], int) or header[key] < (1 if key == "episodes" else 0):
            raise ProtocolError(f"protocol {path}: {key} must be a whole number (episodes >= 1, seed >= 0)")
    fields = tree.get("scenarios", {})
    for name in scenarios:
        given = fields.get(name)
        if given is None:
            raise ProtocolError(f"protocol {path}: no [scenarios.{name}] table")
        for group in SCENARIO_GROUPS_BEFORE:
            given = with_values_before(given, {key: VALUES_BEFORE["scenarios"][key] for key in group})
        fields[name] = given
        wanted = set(spec_fields(get_scenario(name)))
        if set(given) != wanted:
            lacks, unknown_fields = sorted(wanted - set(given)), sorted(set(given) - wanted)
            raise ProtocolError(
                f"protocol {path}: [scenarios.{name}] "
                + (
                    f"lacks {', '.join(lacks)}"
                    if lacks
                    else f"has unknown field(s) {', '.join(unknown_fields)}"
                )
            )
    return Protocol(
        path=path,
        sha256=hashlib.sha256(data).hexdigest(),
        header=header,
        scenario_fields={name: fields[name] for name in scenarios},
        parameters=tree.get("parameters", {}),
    )


# ------------------------------------------------------------------------------------------- writing
def parameter_reasons(defaults_text: str) -> dict[str, str]:
    """Dotted parameter key -> the comment of defaults.toml that gives its source or reason (the
    comment on its line, else the comment block above it)."""
    reasons: dict[str, str] = {}
    section = ""
    block: list[str] = []
    # The comment block above a [section] header explains its keys that have none of their own (and
    # those of the sections after it that have none either: [pedestrians.age_groups.*]).
    section_note = ""
    after_value = False
    for raw in defaults_text.splitlines():
        line = raw.strip()
        if not line:
            block, after_value = [], False
            continue
        if line.startswith("#"):
            if after_value:  # a comment after a value starts the next key's block
                block, after_value = [], False
            block.append(line.lstrip("#").strip())
            continue
        header = re.match(r"^\[([^\]]+)\]", line)
        if header:
            section = header.group(1).strip()
            section_note = " ".join(block) or section_note
            block = []
            continue
        assignment = re.match(r"^([A-Za-z0-9_]+)\s*=\s*(.*)$", line)
        if assignment:
            key = f"{section}.{assignment.group(1)}" if section else assignment.group(1)
            inline = assignment.group(2).split(" #", 1)
            text = inline[1].strip() if len(inline) == 2 else " ".join(block)
            reasons[key] = text or " ".join(block) or section_note
            after_value = True
    return reasons


def field_reasons(source: str) -> dict[str, str]:
    """ScenarioSpec field -> its `#:` comment in scenarios/specs.py."""
    reasons: dict[str, str] = {}
    body = source.split("class ScenarioSpec", 1)[1].split("\n    @property", 1)[0]
    block: list[str] = []
    last = ""
    for raw in body.splitlines():
        line = raw.strip()
        if line.startswith("#:"):
            block.append(line[2:].strip())
            continue
        field = re.match(r"^([a-z_0-9]+)\s*:\s*[^=]+=", line) or re.match(r"^([a-z_0-9]+)\s*:\s*str$", line)
        if field:
            # A field without a comment of its own shares the one above (the max of a min/max pair).
            reasons[field.group(1)] = " ".join(block) or last
            last = reasons[field.group(1)]
        block = []
    return reasons


def scenario_value_reasons(source: str) -> dict[tuple[str, str], str]:
    """(scenario, field) -> the comment above that field's value in the scenario's SCENARIOS entry."""
    reasons: dict[tuple[str, str], str] = {}
    name = ""
    block: list[str] = []
    lines = source.split("\nSCENARIOS", 1)[-1].splitlines()
    for previous, raw in zip(["", *lines], lines):
        line = raw.strip()
        if previous.strip() == "ScenarioSpec(":
            name, block = line.strip('",'), []
            continue
        if line.startswith("#"):
            block.append(line.lstrip("#").strip())
            continue
        value = re.match(r"^([a-z_0-9]+)=", line)
        if value and name and block:
            reasons[(name, value.group(1))] = " ".join(block)
        block = []
    return reasons


def _toml_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, float)):
        return repr(value)
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    raise TypeError(f"cannot write {value!r} to TOML")


def _comment(text: str, width: int = 108) -> list[str]:
    words, lines, line = text.split(), [], "#"
    for word in words:
        if len(line) + 1 + len(word) > width:
            lines.append(line)
            line = "#"
        line += " " + word
    lines.append(line)
    return lines


def protocol_text(header: dict[str, Any]) -> str:
    """A complete protocol: the header given, every scenario field and parameter as they stand now,
    each with its source or reason."""
    specs_source = Path(specs.__file__).read_text(encoding="utf-8")
    p_reasons = parameter_reasons(DEFAULTS_PATH.read_text(encoding="utf-8"))
    f_reasons = field_reasons(specs_source)
    v_reasons = scenario_value_reasons(specs_source)
    out = [
        f"# Protocol {header['name']}, fixed {header['date']} before any of its runs. Never edit it after",
        "# a run: a change is a new dated file (docs/protocols.md). Above each value: its source, or for",
        "# what the paper does not report, the reason it was chosen (python -m pedsafe_sumo.protocol write).",
        "",
        "[protocol]",
    ]
    for key in HEADER_KEYS:
        out.append(f"{key} = {_toml_value(header[key])}")
    for name in header["scenarios"]:
        spec = get_scenario(name)
        out += ["", f"[scenarios.{name}]", *_comment(spec.description)]
        for key, value in spec_fields(spec).items():
            default = next(f.default for f in dataclasses.fields(ScenarioSpec) if f.name == key)
            reason = f_reasons.get(key, "")
            own = v_reasons.get((name, key), "")
            if default is dataclasses.MISSING:
                reason = f"{reason} This scenario's value (scenarios/specs.py). {own}"
            elif value != default:
                reason = f"{reason} This scenario's value (scenarios/specs.py; default {default!r}). {own}"
            out += [*_comment(reason or "(no reason recorded)"), f"{key} = {_toml_value(value)}"]

    def tables(tree: dict[str, Any], prefix: str) -> None:
        leaves = {k: v for k, v in tree.items() if not isinstance(v, dict)}
        if leaves:
            out.extend(["", f"[parameters.{prefix}]"])
            for key, value in leaves.items():
                dotted = f"{prefix}.{key}"
                out.extend(
                    [
                        *_comment(p_reasons.get(dotted, "") or "(no reason recorded)"),
                        f"{key} = {_toml_value(value)}",
                    ]
                )
        for key, value in tree.items():
            if isinstance(value, dict):
                tables(value, f"{prefix}.{key}")

    for section, tree in load_params(None).items():
        tables(tree, section)
    return "\n".join(out) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = OneLineParser(prog="python -m pedsafe_sumo.protocol", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    write = sub.add_parser("write", help="write a new protocol from today's scenarios and parameters")
    write.add_argument("name")
    write.add_argument("--out", type=Path, required=True)
    write.add_argument("--date", default=datetime.date.today().isoformat())
    write.add_argument("--description", default="")
    write.add_argument("--scenarios", default=",".join(SCENARIOS))
    write.add_argument("--conditions", default="both")
    write.add_argument(
        "--episodes", type=int, default=10000, help=f"episodes per scenario, 1 to {MAX_EPISODES:,} [10000]"
    )
    write.add_argument("--seed", type=int, default=1, help="run seed, 0 to 2**63 - 1 [1]")
    write.add_argument("--site", default="xueqing")
    write.add_argument("--algorithm", default="pedsafe_sumo.control.reference:ReferenceStack")
    args = parser.parse_args(argv)
    if args.out.exists():
        print(f"error: {args.out} exists: a protocol is never rewritten, choose a new name", file=sys.stderr)
        return 2
    try:
        if not 1 <= args.episodes <= MAX_EPISODES:
            raise UsageError(f"--episodes must lie in 1..{MAX_EPISODES:,}, got {args.episodes}")
        check_seed(args.seed)
    except UsageError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    header = {
        "name": args.name,
        "date": args.date,
        "description": args.description,
        "scenarios": [s for s in args.scenarios.split(",") if s],
        "conditions": args.conditions,
        "episodes": args.episodes,
        "seed": args.seed,
        "site": args.site,
        "algorithm": args.algorithm,
    }
    unknown = [s for s in header["scenarios"] if s not in SCENARIOS]
    if unknown:
        print(
            f"error: unknown scenario(s) {', '.join(unknown)} (known: {', '.join(SCENARIOS)})",
            file=sys.stderr,
        )
        return 2
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(protocol_text(header), encoding="utf-8")
    load_protocol(args.out).params()  # the file just written must load
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
