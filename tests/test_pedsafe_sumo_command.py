"""The command pedsafe-sumo (pedsafe_sumo.command) in the checkout: its subcommands are the modules' commands,
its version names the checkout's commit; the search path of site names; shipped protocols by name."""

from __future__ import annotations

import hashlib
import importlib
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from pedsafe_sumo import NETWORKS_DIR, REPO_ROOT, __version__
from pedsafe_sumo.command import COMMANDS, SITE_BUILD_MODULE
from pedsafe_sumo.network.sites import NETWORKS_DIR_ENV, SiteError, resolve_site
from pedsafe_sumo.protocol import ProtocolError, load_protocol


def cli(*args: str, cwd: Path = REPO_ROOT) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(REPO_ROOT)}
    return subprocess.run(
        [sys.executable, "-m", "pedsafe_sumo", *args],
        capture_output=True,
        text=True,
        cwd=cwd,
        env=env,
        timeout=120,
    )


def test_every_subcommand_is_a_module_with_main():
    for module_name in [*(module for module, _ in COMMANDS.values()), SITE_BUILD_MODULE]:
        assert callable(importlib.import_module(module_name).main), module_name


def test_version_in_a_checkout_names_its_commit(tmp_path):
    head = subprocess.run(["git", "rev-parse", "HEAD"], capture_output=True, text=True, cwd=REPO_ROOT)
    proc = cli("--version", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.splitlines()
    assert lines[0] == f"pedsafe-sumo {__version__}" and lines[1].startswith("SUMO 1.")
    assert lines[2].startswith(f"commit {head.stdout.strip()}")


def test_a_subcommand_runs_the_module_command():
    proc = cli("site", "build", "--radius", "0", "--site", "xueqing")
    assert proc.returncode == 2 and "radius must be positive" in proc.stderr, proc.stderr


def test_an_unknown_command_is_one_line():
    proc = cli("batchh")
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1 and "unknown command 'batchh'" in proc.stderr


def test_the_search_path_takes_the_first_folder_that_holds_the_name(tmp_path, monkeypatch):
    first, second = tmp_path / "first", tmp_path / "second"
    for root in (first, second):
        shutil.copytree(NETWORKS_DIR / "xueqing", root / "xueqing")
    monkeypatch.setenv(NETWORKS_DIR_ENV, os.pathsep.join([str(tmp_path / "empty"), str(first), str(second)]))
    assert resolve_site("xueqing").directory == first / "xueqing"
    assert resolve_site("xueqing_two_phase").directory == NETWORKS_DIR / "xueqing_two_phase"  # shipped, last
    with pytest.raises(SiteError) as info:
        resolve_site("atlantis")
    message = str(info.value)
    assert "\n" not in message and all(str(p) in message for p in (first, second, NETWORKS_DIR))
    assert NETWORKS_DIR_ENV in message


def test_a_bare_protocol_name_is_a_shipped_protocol(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    shipped = REPO_ROOT / "protocols" / "paper-v7.toml"
    for name in ("paper-v7", "paper-v7.toml"):
        protocol = load_protocol(Path(name))
        assert protocol.sha256 == hashlib.sha256(shipped.read_bytes()).hexdigest()
    with pytest.raises(ProtocolError, match=r"not found: paper-v99 .*paper-v7"):
        load_protocol(Path("paper-v99"))
