"""Bad input to a command ends in one line on stderr and exit code 2, before any simulation; no file changes.
A command that multiplies a grid says how many episodes it will run, and refuses more than --max-runs.

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

from pedsafe_sumo import NETWORKS_DIR, REPO_ROOT, sweep
from pedsafe_sumo.batch.plan import episode_count
from pedsafe_sumo.settings import UsageError

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
#: A site configuration whose additional file is not in the site folder.
CONFIG_NAMING_A_MISSING_FILE = (
    '<configuration><input><net-file value="xueqing.net.xml"/>'
    '<additional-files value="xueqing.poly.xml,gone.add.xml"/></input></configuration>\n'
)
#: Root may create folders in one of mode 555; nobody may in /proc/sys (access(2) says so) or in /proc.
AS_ROOT = os.geteuid() == 0
LOCKED_OUT = "/proc/sys/pedsafe-run" if AS_ROOT else "locked/run"
NO_FOLDER_OUT = "/proc/pedsafe-run"


def a_file(name: str, text: str = "x\n") -> Callable[[Path], None]:
    def make(folder: Path) -> None:
        (folder / name).parent.mkdir(parents=True, exist_ok=True)
        (folder / name).write_text(text)

    return make


def a_folder(name: str) -> Callable[[Path], None]:
    return lambda folder: (folder / name).mkdir(parents=True)


def a_locked_folder(name: str) -> Callable[[Path], None]:
    """A folder of mode 555 (read and enter, no writing); none for root, whose rows use /proc/sys."""

    def make(folder: Path) -> None:
        if not AS_ROOT:
            (folder / name).mkdir()
            (folder / name).chmod(0o555)

    return make


def a_site_without(file_suffix: str) -> Callable[[Path], None]:
    """A copy of the xueqing site folder as ./site without its `file_suffix` file."""

    def make(folder: Path) -> None:
        shutil.copytree(NETWORKS_DIR / "xueqing", folder / "site")
        (folder / "site" / f"xueqing.{file_suffix}").unlink()

    return make


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
CLIP_OSM = (str(REPO_ROOT / "tools" / "clip_osm.py"), "in.osm", "out.osm")
EPISODE = module("episode", "--scenario", "crossing", "--condition", "sv")
NCAP = ("--tests", "CPNA", "--speeds", "20", "--condition", "sv")
BATCH = module("batch", "--scenario", "crossing", "--condition", "sv", "--episodes", "1", "--workers", "1")
SWEEP = module("sweep", "--scenario", "crossing", "--condition", "sv", "--episodes", "1", "--workers", "1")
VARY = ("--vary", "algorithm.reaction_time_s=0.4,1.0")
REPLAY = module("replay", "run", "--episode", "0", "--condition", "sv")

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
    # 6. Requests that multiply beyond --max-runs (each condition of a pair counts).
    Row(
        "batch: 5 scenarios x 2 conditions x 1,000,000 episodes",
        module("batch", "--scenario", "all", "--episodes", "1000000", "--out", "run"),
        "--max-runs",
    ),
    Row(
        "batch: every approach x every scenario x 200,000 episodes",
        module("batch", "--scenario", "all", "--approach", "all", "--episodes", "200000", "--out", "run"),
        "--max-runs",
    ),
    Row("batch --max-runs 0", (*BATCH, "--max-runs", "0", "--out", "run"), "--max-runs"),
    Row("batch --max-runs nan", (*BATCH, "--max-runs", "nan", "--out", "run"), "--max-runs"),
    Row(
        "batch over a lowered --max-runs",
        (*BATCH, "--episodes", "11", "--max-runs", "10", "--out", "run"),
        "--max-runs",
    ),
    Row(
        "sweep: 3 combinations x 5 scenarios x 2 conditions x 100,000 episodes",
        module(
            "sweep",
            "--scenario",
            "all",
            "--episodes",
            "100000",
            "--out",
            "s",
            "--vary",
            "algorithm.reaction_time_s=0.4,1.0,1.5",
        ),
        "--max-runs",
    ),  # fmt: skip
    Row(
        "sweep: 1,600 combinations",
        (
            *SWEEP,
            "--vary",
            "a=" + ",".join(map(str, range(40))),
            "--vary",
            "b=" + ",".join(map(str, range(40))),
            "--out",
            "s",
        ),
        "combinations",
    ),  # fmt: skip
    Row("sweep --max-runs 1", (*SWEEP, *VARY, "--max-runs", "1", "--out", "s"), "--max-runs"),
    # 7. Output folders that are taken or cannot be written.
    Row(
        "ncap --out a non-empty folder of something else",
        module("ncap", "--out", "mine", *NCAP),
        "not empty",
        (a_file("mine/notes.txt"),),
    ),
    Row(
        "batch --out in a folder nobody may write into",
        (*BATCH, "--out", LOCKED_OUT),
        "--out",
        (a_locked_folder("locked"),),
    ),
    Row("batch --out where no folder can be made", (*BATCH, "--out", NO_FOLDER_OUT), "--out"),
    Row(
        "sweep --out in a folder nobody may write into",
        (*SWEEP, *VARY, "--out", LOCKED_OUT),
        "--out",
        (a_locked_folder("locked"),),
    ),
    Row("sweep --out where no folder can be made", (*SWEEP, *VARY, "--out", NO_FOLDER_OUT), "--out"),
    Row("ncap --out where no folder can be made", module("ncap", "--out", NO_FOLDER_OUT, *NCAP), "--out"),
    Row(
        "demand.validate --work under a file",
        module("demand.validate", "--docs", "d", "--work", "taken/w"),
        "--work",
        (a_file("taken"),),
    ),
    # 8. A site's SUMO configuration and view settings, where a command reads them.
    *(
        Row(f"{name}: {what}", argv, says, (make,))
        for name, argv in (
            ("site --no-build", module("site", "--no-build", "--site", "./site")),
            (
                "demand.validate",
                module(
                    "demand.validate",
                    "--site",
                    "./site",
                    "--docs",
                    "d",
                    "--work",
                    "w",
                    "--duration",
                    "60",
                    "--warmup",
                    "10",
                ),
            ),
        )
        for what, says, make in (
            ("malformed .sumocfg", "xueqing.sumocfg", a_site("sumocfg", MALFORMED)),
            ("external entity in .sumocfg", "xueqing.sumocfg", a_site("sumocfg", EXTERNAL_ENTITY)),
            (
                ".sumocfg naming a missing file",
                "gone.add.xml",
                a_site("sumocfg", CONFIG_NAMING_A_MISSING_FILE),
            ),
        )
    ),  # fmt: skip
    Row(
        "site --no-build: malformed view.xml",
        module("site", "--no-build", "--site", "./site"),
        "xueqing.view.xml",
        (a_site("view.xml", MALFORMED),),
    ),
    Row(
        "site --no-build: no view.xml",
        module("site", "--no-build", "--site", "./site"),
        "xueqing.view.xml",
        (a_site_without("view.xml"),),
    ),
    Row(
        "site --no-build: no .sumocfg",
        module("site", "--no-build", "--site", "./site"),
        "xueqing.sumocfg",
        (a_site_without("sumocfg"),),
    ),
    Row(
        "episode --gui: malformed view.xml",
        (*EPISODE, "--gui", "--site", "./site"),
        "xueqing.view.xml",
        (a_site("view.xml", MALFORMED),),
    ),
    # 9. Every numeric option within its stated range, NaN and words included.
    Row("sweep --seed -1", (*SWEEP, *VARY, "--seed", "-1", "--out", "s"), "--seed"),
    Row("sweep --workers 0", (*SWEEP, *VARY, "--workers", "0", "--out", "s"), "--workers"),
    Row("sweep --workers 1000", (*SWEEP, *VARY, "--workers", "1000", "--out", "s"), "--workers"),
    Row("sweep --episodes 2000000", (*SWEEP, *VARY, "--episodes", "2000000", "--out", "s"), "--episodes"),
    Row("sweep --episodes x", (*SWEEP, *VARY, "--episodes", "x", "--out", "s"), "--episodes"),
    Row("sweep --condition car", (*SWEEP, *VARY, "--condition", "car", "--out", "s"), "car"),
    Row("ncap --seed 2**64", module("ncap", "--out", "n", *NCAP, "--seed", str(2**64)), "--seed"),
    Row("replay --delay nan", (*REPLAY, "--delay", "nan"), "--delay"),
    Row("replay --delay 1e9", (*REPLAY, "--delay", "1e9"), "--delay"),
    Row("replay --view-width 1e9", (*REPLAY, "--view-width", "1e9"), "--view-width"),
    Row("replay --view-width nan", (*REPLAY, "--view-width", "nan"), "--view-width"),
    Row("replay --episode x", module("replay", "run", "--episode", "x", "--condition", "sv"), "--episode"),
    Row(
        "conflicts --radius 1e6",
        module("conflicts", "f.xml", "--out", "c.csv", "--radius", "1e6"),
        "--radius",
        (a_file("f.xml", EMPTY_FCD),),
    ),
    Row(
        "conflicts --radius nan",
        module("conflicts", "f.xml", "--out", "c.csv", "--radius", "nan"),
        "--radius",
        (a_file("f.xml", EMPTY_FCD),),
    ),
    Row("compare --confidence x", module("compare", "a", "b", "--confidence", "x"), "--confidence"),
    Row("compare --confidence nan", module("compare", "a", "b", "--confidence", "nan"), "--confidence"),
    Row(
        "compare --margin collision=nan", module("compare", "a", "b", "--margin", "collision=nan"), "--margin"
    ),
    Row("episode --seed 2**64", (*EPISODE, "--seed", str(2**64)), "--seed"),
    Row("episode --agent-timeout nan", (*EPISODE, "--agent-timeout", "nan"), "--agent-timeout"),
    Row("batch --agent-timeout nan", (*BATCH, "--agent-timeout", "nan", "--out", "run"), "--agent-timeout"),
    Row("batch --seed 2**63", (*BATCH, "--seed", str(2**63), "--out", "run"), "--seed"),
    Row("demand --seed -1", module("demand", "--site", "xueqing", "--seed", "-1", "--out", "r"), "--seed"),
    Row(
        "demand --duration x",
        module("demand", "--site", "xueqing", "--duration", "x", "--out", "r"),
        "--duration",
    ),
    Row("demand.validate --seed -1", module("demand.validate", "--docs", "d", "--seed", "-1"), "--seed"),
    Row(
        "protocol write --episodes 0",
        module("protocol", "write", "p", "--out", "p.toml", "--episodes", "0"),
        "--episodes",
    ),
    Row(
        "protocol write --seed -1",
        module("protocol", "write", "p", "--out", "p.toml", "--seed", "-1"),
        "--seed",
    ),
    Row("build_network --center nan,0", (BUILD_NETWORK, "--center", "nan,0", "--out", "site"), "--center"),
    Row("clip_osm --radius nan", (*CLIP_OSM, "--center", "40,116", "--radius", "nan"), "--radius"),
    Row("clip_osm --center 95,0", (*CLIP_OSM, "--center", "95,0", "--radius", "150"), "--center"),
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


def test_batch_counts_units_conditions_and_the_samplers_stages() -> None:
    # 3 units x 2 conditions x 7 episodes; with 2 pilot stages of 50 pairs: 3 x 2 x (2 x 50 + 7).
    arguments = {"episodes": 7}
    assert episode_count(["a", "b", "c"], ["sv", "v2i"], arguments, None)[0] == 42
    sampler = {"pilot_stages": 2, "pilot_episodes": 50}
    assert episode_count(["a", "b", "c"], ["sv", "v2i"], arguments, sampler)[0] == 642


def test_sweep_counts_combinations_scenarios_conditions_and_episodes(tmp_path: Path) -> None:
    args = sweep.parse_args(
        ["--scenario", "crossing,jaywalking", "--episodes", "3", "--out", str(tmp_path / "s"),
         "--vary", "algorithm.reaction_time_s=0.4,1.0,1.5"]
    )  # fmt: skip
    assert len(sweep.validate(args)) == 3
    assert args.total_episodes == 3 * 2 * 2 * 3  # combinations x scenarios x conditions x episodes
    args.max_runs = 35
    with pytest.raises(UsageError, match="= 36 episodes, more than --max-runs 35"):
        sweep.validate(args)


def test_batch_says_how_many_episodes_before_the_first(tmp_path: Path) -> None:
    env = dict(os.environ, PYTHONPATH=str(REPO_ROOT))
    proc = subprocess.run(
        [sys.executable, *BATCH, "--episodes", "2", "--out", str(tmp_path / "run")],
        cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-2000:]
    first = proc.stdout.splitlines()[0]
    assert first == "1 scenario unit(s) x 1 condition(s) x 2 episodes = 2 episodes (--max-runs 1,000,000)"
