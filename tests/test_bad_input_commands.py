"""Bad input to a command ends in one line on stderr and exit code 2, before any simulation; no file changes.

One row per case: the files the row sets up in a temporary folder (the command's working folder), the
command line, and a word the error line must hold. Each row runs the command as a subprocess and checks the
exit code, that stderr is exactly one line and no traceback, that no file under the folder was created,
changed or removed, that no `*.tmp` file is left, and that the repository's docs/ is untouched.
"""

from __future__ import annotations

import hashlib
import importlib.util
import json
import os
import shutil
import subprocess
import sys
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import pandas as pd
import pytest

from pedsafe_sumo import NETWORKS_DIR, REPO_ROOT

BILLION_LAUGHS = (
    '<?xml version="1.0"?>\n<!DOCTYPE net [\n <!ENTITY a "aaaaaaaaaa">\n'
    + "".join(f' <!ENTITY {chr(98 + i)} "{("&" + chr(97 + i) + ";") * 10}">\n' for i in range(8))
    + ']>\n<net><location netOffset="&i;"/></net>\n'
)
EXTERNAL_ENTITY = (
    '<?xml version="1.0"?>\n<!DOCTYPE net [<!ENTITY x SYSTEM "file:///etc/passwd">]>\n'
    '<net><location netOffset="&x;"/></net>\n'
)
MALFORMED = '<net><location netOffset="0,0"></net>\n'
EMPTY_FCD = '<?xml version="1.0"?>\n<fcd-export>\n</fcd-export>\n'


def a_file(name: str, text: str = "x\n") -> Callable[[Path], None]:
    def make(folder: Path) -> None:
        (folder / name).parent.mkdir(parents=True, exist_ok=True)
        (folder / name).write_text(text)

    return make


def a_folder(name: str) -> Callable[[Path], None]:
    return lambda folder: (folder / name).mkdir(parents=True)


def a_site(file_suffix: str, text: str) -> Callable[[Path], None]:
    """A copy of the xueqing site folder as ./site whose `file_suffix` file holds `text`."""

    def make(folder: Path) -> None:
        shutil.copytree(NETWORKS_DIR / "xueqing", folder / "site")
        (folder / "site" / f"xueqing.{file_suffix}").write_text(text)

    return make


def a_run(name: str) -> Callable[[Path], None]:
    """The report tests' hand-made run directory (tests/report/report_runs.py) as ./`name`."""

    def make(folder: Path) -> None:
        spec = importlib.util.spec_from_file_location(
            "report_runs", Path(__file__).parent / "report" / "report_runs.py"
        )
        assert spec is not None and spec.loader is not None
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        module.write_standard_run(folder / name)

    return make


def an_unfinished_run(name: str, **entry_values: object) -> Callable[[Path], None]:
    """An unfinished batch run ./`name` with one finished chunk whose manifest entry has `entry_values`."""

    def make(folder: Path) -> None:
        run = folder / name
        (run / "parts").mkdir(parents=True)
        part = run / "parts" / "crossing-000000-000000.parquet"
        pd.DataFrame({"episode": [0]}).to_parquet(part, index=False)
        entry = {
            "key": "crossing-000000-000000",
            "scenario": "crossing",
            "first_episode": 0,
            "last_episode": 0,
            "file": str(part.relative_to(run)),
            "rows": 1,
            "sha256": hashlib.sha256(part.read_bytes()).hexdigest(),
            "n_error": 0,
            "session": 0,
            "completed_utc": "2026-01-01T00:00:00.000+00:00",
            "session_elapsed_s": 1.0,
            **entry_values,
        }
        (run / "manifest.json").write_text(json.dumps({"format": 1, "chunks": {entry["key"]: entry}}))
        (run / "run.json").write_text(json.dumps({"state": "running", "chunks_total": 2}))

    return make


@dataclass(frozen=True)
class Row:
    case: str
    argv: tuple[str, ...]
    #: A word the error line holds (the option or file it is about).
    says: str
    setup: tuple[Callable[[Path], None], ...] = field(default=())


def module(name: str, *args: str) -> tuple[str, ...]:
    return ("-m", f"pedsafe_sumo.{name}", *args)


BUILD_NETWORK = str(REPO_ROOT / "tools" / "build_network.py")
EPISODE = module("episode", "--scenario", "crossing", "--condition", "sv")
NCAP = ("--tests", "CPNA", "--speeds", "20", "--condition", "sv")

ROWS = [
    # 1. Unwritable or occupied outputs.
    Row("report: tables/ is a file", module("report", "run"), "tables", (a_run("run"), a_file("run/tables"))),
    Row(
        "report: report.html is a folder",
        module("report", "run"),
        "report.html",
        (a_run("run"), a_folder("run/report.html")),
    ),
    Row(
        "compare --out under a file",
        module("compare", "a", "b", "--out", "taken/cmp"),
        "--out",
        (a_file("taken"),),
    ),
    Row(
        "conflicts --out under a file",
        module("conflicts", "f.xml", "--out", "taken/c.csv"),
        "--out",
        (a_file("f.xml", EMPTY_FCD), a_file("taken")),
    ),
    Row(
        "conflicts --ssm is a folder",
        module("conflicts", "f.xml", "--out", "c.csv", "--ssm", "ssm.xml"),
        "--ssm",
        (a_file("f.xml", EMPTY_FCD), a_folder("ssm.xml")),
    ),
    Row(
        "replay --export-fcd is a folder",
        module("replay", "run", "--episode", "0", "--condition", "sv", "--export-fcd", "e.fcd.xml"),
        "--export-fcd",
        (a_folder("e.fcd.xml"),),
    ),
    Row(
        "replay --export-fcd under a file",
        module("replay", "run", "--episode", "0", "--condition", "sv", "--export-fcd", "taken/e.fcd.xml"),
        "--export-fcd",
        (a_file("taken"),),
    ),
    Row("episode --log is a folder", (*EPISODE, "--log", "log.csv"), "--log", (a_folder("log.csv"),)),
    Row(
        "episode --case-dir under a file",
        (*EPISODE, "--case-dir", "taken/cases"),
        "--case-dir",
        (a_file("taken"),),
    ),
    Row(
        "sweep --out under a file",
        module("sweep", "--scenario", "crossing", "--vary", "ped_start_delay_s=1,2", "--out", "taken/s"),
        "--out",
        (a_file("taken"),),
    ),
    Row("ncap --out under a file", module("ncap", "--out", "taken/n", *NCAP), "--out", (a_file("taken"),)),
    Row(
        "build_network --out under a file",
        (BUILD_NETWORK, "--out", "taken/site"),
        "--out",
        (a_file("taken"),),
    ),
    Row(
        "demand --out under a file",
        module("demand", "--site", "xueqing", "--out", "taken/r"),
        "--out",
        (a_file("taken"),),
    ),
    # 2. XML the parser rejects, in a site's files.
    *(
        Row(f"{name}: {what} in {suffix}", argv, f"xueqing.{suffix}", (a_site(suffix, text),))
        for name, argv in (
            ("episode", (*EPISODE, "--site", "./site")),
            ("ncap", module("ncap", "--out", "n", "--site", "./site", *NCAP)),
            ("site --no-build", module("site", "--no-build", "--site", "./site")),
        )
        for suffix in ("net.xml", "rsu.add.xml")
        for what, text in (
            ("billion laughs", BILLION_LAUGHS),
            ("external entity", EXTERNAL_ENTITY),
            ("malformed XML", MALFORMED),
        )
    ),
    # 3. Non-finite and out-of-range numbers.
    Row(
        "demand --duration inf",
        module("demand", "--site", "xueqing", "--duration", "inf", "--out", "r"),
        "--duration",
    ),
    Row(
        "demand --duration nan",
        module("demand", "--site", "xueqing", "--duration", "nan", "--out", "r"),
        "--duration",
    ),
    Row(
        "demand --duration 1e12",
        module("demand", "--site", "xueqing", "--duration", "1e12", "--out", "r"),
        "--duration",
    ),
    Row("build_network --radius inf", (BUILD_NETWORK, "--radius", "inf", "--out", "site"), "radius"),
    Row("build_network --radius nan", (BUILD_NETWORK, "--radius", "nan", "--out", "site"), "radius"),
    Row("build_network --radius 1e9", (BUILD_NETWORK, "--radius", "1e9", "--out", "site"), "radius"),
    Row(
        "batch --set ...=nan",
        module(
            "batch",
            "--scenario",
            "crossing",
            "--episodes",
            "1",
            "--out",
            "run",
            "--set",
            "conflicts.interaction_radius_m=nan",
        ),
        "interaction_radius_m",
    ),
    Row(
        "batch --set ...=inf",
        module(
            "batch",
            "--scenario",
            "crossing",
            "--episodes",
            "1",
            "--out",
            "run",
            "--set",
            "traffic.headway_rate_per_s=inf",
        ),
        "headway_rate_per_s",
    ),
    Row(
        "episode --params with nan",
        (*EPISODE, "--params", "p.toml"),
        "interaction_radius_m",
        (a_file("p.toml", "[conflicts]\ninteraction_radius_m = nan\n"),),
    ),
    Row(
        "demand.validate --duration inf",
        module("demand.validate", "--docs", "d", "--duration", "inf"),
        "--duration",
    ),
    Row(
        "demand.validate --warmup nan",
        module("demand.validate", "--docs", "d", "--warmup", "nan"),
        "--warmup",
    ),
    # 4. demand.validate writes only where it is told to.
    Row("demand.validate without --docs", module("demand.validate", "--site", "xueqing"), "--docs"),
    Row(
        "demand.validate --docs under a file",
        module("demand.validate", "--docs", "taken/docs"),
        "--docs",
        (a_file("taken"),),
    ),
    # 5. Hand-edited run files with values of the wrong JSON type.
    *(
        Row(
            f"report --partial: manifest {key} of the wrong type",
            module("report", "run", "--partial"),
            key,
            (an_unfinished_run("run", **{key: value}),),
        )
        for key, value in (("rows", "1"), ("file", 3), ("first_episode", 0.5), ("n_error", True))
    ),
    *(
        Row(
            f"batch --resume: run.json {where} of the wrong type",
            module("batch", "--resume", "--out", "run"),
            where,
            (
                a_file(
                    "run/run.json",
                    json.dumps({"state": "running", "arguments": {}, "sessions": [], **values}),
                ),
            ),
        )
        for where, values in (
            ("arguments.seed", {"arguments": {"seed": "1"}}),
            ("arguments.episodes", {"arguments": {"episodes": [10]}}),
            ("sessions", {"sessions": "x"}),
            ("versions", {"versions": []}),
        )
    ),
    Row(
        "report --partial: manifest entry not an object",
        module("report", "run", "--partial"),
        "not a JSON object",
        (
            a_file("run/run.json", '{"state": "running"}'),
            a_file("run/manifest.json", '{"format": 1, "chunks": {"k": [1]}}'),
        ),
    ),
]


def snapshot(root: Path) -> dict[str, str]:
    """Every file and folder under `root`, with the SHA-256 of each file's bytes."""
    found = {}
    for path in sorted(root.rglob("*")):
        rel = str(path.relative_to(root))
        found[rel] = "dir" if path.is_dir() else hashlib.sha256(path.read_bytes()).hexdigest()
    return found


@pytest.mark.parametrize("row", ROWS, ids=[row.case for row in ROWS])
def test_bad_input_is_one_line_exit_2_and_changes_nothing(row: Row, tmp_path: Path) -> None:
    work = tmp_path / "work"
    work.mkdir()
    for make in row.setup:
        make(work)
    before, docs_before = snapshot(work), snapshot(REPO_ROOT / "docs")
    env = dict(os.environ, PYTHONPATH=str(REPO_ROOT))
    proc = subprocess.run(
        [sys.executable, *row.argv], cwd=work, env=env, capture_output=True, text=True, timeout=120
    )
    lines = proc.stderr.splitlines()
    assert proc.returncode == 2, proc.stderr[-2000:]
    assert "Traceback" not in proc.stderr
    assert len(lines) == 1, proc.stderr[-2000:]
    assert row.says in lines[0], lines[0]
    assert snapshot(work) == before
    assert not list(tmp_path.rglob("*.tmp"))
    assert snapshot(REPO_ROOT / "docs") == docs_before
