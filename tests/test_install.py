"""The package as a user who is not a developer gets it: a wheel built from the checkout, installed into a
fresh virtual environment, run from an empty folder. The heavy dependencies come from the environment the
tests run in (a .pth file and --system-site-packages), pedsafe_sumo itself only from the wheel."""

from __future__ import annotations

import hashlib
import importlib.metadata
import json
import os
import subprocess
import sys
import sysconfig
from pathlib import Path

import pandas as pd
import pytest

from pedsafe_sumo import REPO_ROOT

pytestmark = pytest.mark.slow


def _run(
    args: list[str], cwd: Path, env: dict[str, str], timeout: float = 900
) -> subprocess.CompletedProcess:
    return subprocess.run(args, cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    """(venv folder, wheel version, environment for its commands, an empty working folder)."""
    root = tmp_path_factory.mktemp("install")
    dist, venv, work = root / "dist", root / "venv", root / "work"
    work.mkdir()
    built = _run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "--quiet", "-w", str(dist), str(REPO_ROOT)],
        root,
        dict(os.environ),
    )
    assert built.returncode == 0, built.stderr
    (wheel,) = dist.glob("pedsafe_sumo-*.whl")
    version = wheel.name.split("-")[1]
    made = _run([sys.executable, "-m", "venv", "--system-site-packages", str(venv)], root, dict(os.environ))
    assert made.returncode == 0, made.stderr
    python = venv / "bin" / "python"
    purelib = _run([str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"], root, {})
    # The dependencies of this environment (a .pth file adds its site-packages; its own .pth files, the
    # editable install of the checkout among them, are not read).
    ours = {sysconfig.get_paths()["purelib"], sysconfig.get_paths()["platlib"]}
    Path(purelib.stdout.strip(), "_test_dependencies.pth").write_text("\n".join(sorted(ours)) + "\n")
    pip = _run(
        [str(python), "-m", "pip", "install", "--no-index", "--no-deps", "--quiet", str(wheel)], root, {}
    )
    assert pip.returncode == 0, pip.stderr
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH" and not k.startswith("PEDSAFE_")}
    env["NUMBA_CACHE_DIR"] = str(root / "numba-cache")  # a first run: it compiles, and says so
    return venv, version, env, work


def test_the_package_comes_from_the_wheel(installed):
    venv, _, env, work = installed
    proc = _run(
        [str(venv / "bin" / "python"), "-c", "import pedsafe_sumo; print(pedsafe_sumo.__file__)"], work, env
    )
    assert Path(proc.stdout.strip()).is_relative_to(venv), proc.stdout + proc.stderr


def test_version_names_the_package_and_sumo(installed):
    venv, version, env, work = installed
    proc = _run([str(venv / "bin" / "pedsafe-sumo"), "--version"], work, env)
    assert proc.returncode == 0, proc.stderr
    sumo = importlib.metadata.version("eclipse-sumo")
    # Installed from a wheel: no checkout, so no commit line.
    assert proc.stdout.splitlines() == [f"pedsafe-sumo {version}", f"SUMO {sumo}"]
    as_module = _run([str(venv / "bin" / "python"), "-m", "pedsafe_sumo", "--version"], work, env)
    assert as_module.stdout == proc.stdout


def test_a_bare_protocol_name_is_the_shipped_protocol(installed):
    venv, _, env, work = installed
    code = "from pathlib import Path; from pedsafe_sumo.protocol import load_protocol; "
    code += "p = load_protocol(Path('paper-v7'))"
    proc = _run([str(venv / "bin" / "python"), "-c", f"{code}; print(p.path); print(p.sha256)"], work, env)
    path, sha256 = proc.stdout.split()
    assert Path(path).is_relative_to(venv)
    assert sha256 == hashlib.sha256((REPO_ROOT / "protocols" / "paper-v7.toml").read_bytes()).hexdigest()


def test_the_main_job_runs_from_an_empty_folder(installed):
    venv, version, env, work = installed
    command = [str(venv / "bin" / "pedsafe-sumo"), "batch", "--scenario", "crossing", "--episodes", "1"]
    first = _run([*command, "--workers", "1", "--out", "r1"], work, env)
    assert first.returncode == 0, first.stderr
    rows = pd.read_parquet(work / "r1" / "episodes.parquet")
    assert sorted(rows["condition"]) == ["sv", "v2i"]  # one pair
    assert first.stderr.count("compiling the perception kernels") == 1
    run_info = json.loads((work / "r1" / "run.json").read_text())
    assert run_info["versions"]["pedsafe_sumo"] == version and "commit" not in run_info
    second = _run([*command, "--workers", "1", "--out", "r2"], work, env)
    assert second.returncode == 0 and "compiling" not in second.stderr, second.stderr


def test_an_unknown_site_says_where_it_looked_in_one_line(installed, tmp_path):
    venv, _, env, work = installed
    mine = [tmp_path / "a", tmp_path / "b"]
    env = {**env, "PEDSAFE_NETWORKS_DIR": os.pathsep.join(map(str, mine))}
    command = [str(venv / "bin" / "pedsafe-sumo"), "batch", "--scenario", "crossing", "--site", "atlantis"]
    proc = _run([*command, "--out", "r3"], work, env)
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1, proc.stderr
    shipped = next(venv.rglob("pedsafe_sumo/_shipped/networks"))
    for folder in (*mine, shipped):
        assert str(folder) in proc.stderr
    assert "unknown site 'atlantis'" in proc.stderr and "PEDSAFE_NETWORKS_DIR" in proc.stderr
    assert not (work / "r3").exists()
