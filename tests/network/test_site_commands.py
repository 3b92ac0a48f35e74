"""Every command takes --site NAME_OR_PATH: a copy of the Xueqing folder under another name, anywhere, is
used by path; run.json records where it was, and replay finds it there and refuses it once it differs."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from pedsafe_sumo import NETWORKS_DIR, REPO_ROOT
from pedsafe_sumo.replay.rundir import ReplayError, load_logged_episode


def _copy(tmp_path: Path) -> Path:
    folder = tmp_path / "elsewhere" / "my_junction"
    shutil.copytree(NETWORKS_DIR / "xueqing", folder)
    return folder


def _run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, *args], capture_output=True, text=True, cwd=REPO_ROOT, timeout=300)


def test_demand_takes_a_site_folder(tmp_path):
    folder = _copy(tmp_path)
    proc = _run(
        "-m", "pedsafe_sumo.demand", "--site", str(folder), "--duration", "60", "--out", str(tmp_path)
    )
    assert proc.returncode == 0, proc.stderr
    routes = ET.parse(tmp_path / "xueqing.vehicles.rou.xml").getroot()
    net_edges = {e.get("id") for e in ET.parse(folder / "xueqing.net.xml").getroot().iter("edge")}
    used = {edge for route in routes.iter("route") for edge in route.get("edges").split()}
    assert used and used <= net_edges


def test_network_summary_takes_a_site_folder(tmp_path):
    folder = _copy(tmp_path)
    proc = _run("-m", "pedsafe_sumo.site", "--site", str(folder), "--no-build")
    assert proc.returncode == 0, proc.stderr
    assert "site xueqing: main junction" in proc.stdout and "crossing: hosted" in proc.stdout


@pytest.mark.slow
def test_an_unknown_site_is_one_line_for_every_command(tmp_path):
    for command in (
        ["-m", "pedsafe_sumo.demand", "--out", str(tmp_path)],
        ["-m", "pedsafe_sumo.episode", "--scenario", "crossing"],
        ["-m", "pedsafe_sumo.site", "--no-build"],
        [str(REPO_ROOT / "tools" / "screenshot_site.py"), "--out", str(tmp_path / "x.png")],
    ):
        proc = _run(*command, "--site", str(tmp_path / "nowhere"))
        assert proc.returncode == 2, (command, proc.stderr)
        lines = proc.stderr.strip().splitlines()
        assert len(lines) == 1 and "does not exist" in lines[0] and "Traceback" not in proc.stderr, command


@pytest.mark.slow
def test_a_batch_on_a_site_folder_is_replayed_from_that_folder(tmp_path):
    folder = _copy(tmp_path)
    out = tmp_path / "run"
    proc = _run(
        "-m", "pedsafe_sumo.batch", "--scenario", "crossing", "--episodes", "1", "--workers", "1",
        "--site", str(folder), "--out", str(out),
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    run = json.loads((out / "run.json").read_text())
    assert run["site"] == "xueqing" and Path(run["site_path"]) == folder.resolve()
    assert run["site_files_sha256"]["xueqing.net.xml"]
    logged = load_logged_episode(out, 0, "sv")
    assert logged.site.directory.resolve() == folder.resolve()
    # A file of the folder changed after the run: replay refuses, in one line naming it.
    poly = folder / "xueqing.poly.xml"
    poly.write_text(poly.read_text() + "\n")
    with pytest.raises(ReplayError) as info:
        load_logged_episode(out, 0, "sv")
    assert "xueqing.poly.xml" in str(info.value) and "\n" not in str(info.value)
