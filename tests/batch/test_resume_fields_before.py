"""--resume of a run recorded before a scenario field existed: its run.json lacks the field, and the run
went with the field's VALUES_BEFORE value. A command giving that value continues it; one giving another
value is refused, naming the field."""

from __future__ import annotations

import copy
import dataclasses
import json

import pytest

from pedsafe_sumo import REPO_ROOT
from pedsafe_sumo.batch.resume import IDENTITY_KEYS, check_same_run
from pedsafe_sumo.protocol import load_protocol
from pedsafe_sumo.settings import UsageError


@pytest.fixture(scope="module")
def paper_v10(tmp_path_factory):
    """A run directory and the identity a run of protocol paper-v10-xueqing records (its scenarios as the
    batch records them, dataclasses.asdict of each spec; the other keys the same on both sides)."""
    specs = load_protocol(REPO_ROOT / "protocols" / "paper-v10-xueqing.toml").specs()
    identity = {key: None for key in IDENTITY_KEYS}
    identity["scenarios"] = {name: dataclasses.asdict(spec) for name, spec in specs.items()}
    # As run.json stores it (JSON: tuples as lists).
    return tmp_path_factory.mktemp("run"), json.loads(json.dumps(identity, default=str))


def test_a_run_recorded_without_oncoming_moment_resumes_with_its_value_before(paper_v10):
    out, identity = paper_v10
    assert all(fields["oncoming_moment"] == "at_kerb" for fields in identity["scenarios"].values())
    recorded = copy.deepcopy(identity)
    for fields in recorded["scenarios"].values():
        del fields["oncoming_moment"]
    versions = {"pedsafe_sumo": "0", "sumo": "0"}
    check_same_run(out, identity, versions, {**recorded, "versions": versions})  # no refusal


def test_another_value_than_the_one_before_is_refused(paper_v10):
    out, identity = paper_v10
    recorded = copy.deepcopy(identity)
    for fields in recorded["scenarios"].values():
        del fields["oncoming_moment"]
    current = copy.deepcopy(identity)
    current["scenarios"]["crossing"]["oncoming_moment"] = "stop_line"
    versions = {"pedsafe_sumo": "0", "sumo": "0"}
    with pytest.raises(UsageError, match=r"scenarios\.crossing\.oncoming_moment is 'at_kerb' there"):
        check_same_run(out, current, versions, {**recorded, "versions": versions})
