"""Files from others are data (docs/trust.md): a crafted manifest, site file, SUMO configuration or
run.json makes the command refuse in one line with exit status 2, and no file outside the run or site
directory changes (a victim folder's files, bytes and modification times, are the same after)."""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from pedsafe_sumo import NETWORKS_DIR, REPO_ROOT
from pedsafe_sumo.control.agent import AlgorithmLoadError
from pedsafe_sumo.control.stack_source import stack_to_replay
from pedsafe_sumo.network.sites import available_sites, content_digest, resolve_site
from pedsafe_sumo.network.sumo_inputs import SumoInputError, check_gui_site, config_inputs

TOOLS = REPO_ROOT / "tools"
#: A module that, once imported, leaves a file in the victim folder {victim}.
EVIL_MODULE = (
    "from pathlib import Path\nPath({victim!r}, 'imported.txt').write_text('ran')\nclass Stack:\n    pass\n"
)


def snapshot(folder: Path) -> dict[str, tuple[str, int]]:
    """Every file under `folder`: SHA-256 of its bytes and its modification time in ns."""
    return {
        str(p.relative_to(folder)): (hashlib.sha256(p.read_bytes()).hexdigest(), p.stat().st_mtime_ns)
        for p in sorted(folder.rglob("*"))
        if p.is_file()
    }


def victim(tmp_path: Path) -> Path:
    folder = tmp_path / "victim"
    folder.mkdir()
    (folder / "x").write_text("keep me\n")
    (folder / "important.txt").write_text("important\n")
    return folder


def command(*args: str, cwd: Path = REPO_ROOT) -> subprocess.CompletedProcess:
    """A command as a user runs it, with this checkout's package importable and nothing else named."""
    env = {**os.environ, "PYTHONPATH": str(REPO_ROOT)}
    return subprocess.run(
        [sys.executable, *args], capture_output=True, text=True, cwd=cwd, env=env, timeout=600
    )


def assert_refused(proc: subprocess.CompletedProcess, *phrases: str) -> None:
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2, proc.stderr[-3000:]
    assert len(lines) == 1 and "Traceback" not in proc.stderr, proc.stderr[-3000:]
    for phrase in phrases:
        assert phrase in lines[0], lines[0]


# ---------------------------------------------------------------------------------------- run directories
@pytest.fixture(scope="module")
def finished_run(tmp_path_factory) -> Path:
    """A finished batch run of one crossing pair with the reference stack."""
    out = tmp_path_factory.mktemp("trust") / "run"
    proc = command(
        "-m", "pedsafe_sumo.batch", "--scenario", "crossing", "--episodes", "1", "--workers", "1",
        "--out", str(out),
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-3000:]
    return out


def stopped_copy(finished_run: Path, tmp_path: Path) -> Path:
    """A copy of the run as a killed batch leaves it: state running, no episodes.parquet."""
    run = tmp_path / "received" / "run"
    shutil.copytree(finished_run, run)
    info = json.loads((run / "run.json").read_text())
    (run / "run.json").write_text(json.dumps({**info, "state": "running"}))
    (run / "episodes.parquet").unlink()
    return run


def _manifest_entry(run: Path, victim_dir: Path, how: str) -> None:
    manifest = json.loads((run / "manifest.json").read_text())
    key, entry = next(iter(manifest["chunks"].items()))
    if how == "dotdot":
        entry["file"] = "../../victim/x"
    elif how == "absolute":
        entry["file"] = str(victim_dir / "x")
    elif how == "link":
        (run / "parts" / "evil.parquet").symlink_to(victim_dir / "x")
        entry["file"] = "parts/evil.parquet"
    elif how == "steplog":
        entry["steplog_file"], entry["steplog_sha256"] = "../../victim/x", "0" * 64
    manifest["chunks"][key] = entry
    (run / "manifest.json").write_text(json.dumps(manifest))


def _linked_entry(run: Path, victim_dir: Path, name: str) -> None:
    target = run / name
    if target.is_dir():
        shutil.rmtree(target)
    else:
        target.unlink(missing_ok=True)
    target.symlink_to(victim_dir if name in ("parts", "cases") else victim_dir / "important.txt")


@pytest.mark.slow
@pytest.mark.parametrize(
    ("attack", "phrase"),
    [
        (lambda run, v: _manifest_entry(run, v, "dotdot"), "climbs out of"),
        (lambda run, v: _manifest_entry(run, v, "absolute"), "is not a path relative to"),
        (lambda run, v: _manifest_entry(run, v, "link"), "leads out of"),
        (lambda run, v: _manifest_entry(run, v, "steplog"), "climbs out of"),
        (lambda run, v: _linked_entry(run, v, "parts"), "leads out of"),
        (lambda run, v: _linked_entry(run, v, "cases"), "leads out of"),
        (lambda run, v: _linked_entry(run, v, ".lock"), "leads out of"),
    ],
    ids=[
        "dotdot-entry",
        "absolute-entry",
        "linked-part",
        "steplog-entry",
        "parts-link",
        "cases-link",
        "lock-link",
    ],
)
def test_a_crafted_run_directory_cannot_make_resume_touch_other_files(finished_run, tmp_path, attack, phrase):
    victim_dir = victim(tmp_path)
    run = stopped_copy(finished_run, tmp_path)
    attack(run, victim_dir)
    before = snapshot(victim_dir)
    proc = command("-m", "pedsafe_sumo.batch", "--resume", "--out", str(run))
    assert_refused(proc, "cannot resume", phrase, "refused")
    assert snapshot(victim_dir) == before


@pytest.mark.slow
@pytest.mark.parametrize("entry", ["tables", "figures", "report.html"])
def test_a_link_in_a_run_directory_cannot_send_the_report_elsewhere(finished_run, tmp_path, entry):
    victim_dir = victim(tmp_path)
    run = tmp_path / "received" / "run"
    shutil.copytree(finished_run, run)
    shutil.rmtree(run / entry, ignore_errors=True)
    (run / entry).unlink(missing_ok=True)
    (run / entry).symlink_to(victim_dir / "important.txt" if entry.endswith(".html") else victim_dir)
    before = snapshot(victim_dir)
    proc = command("-m", "pedsafe_sumo.report", str(run))
    assert_refused(proc, "report", "leads out of", "refused")
    assert snapshot(victim_dir) == before


# ------------------------------------------------------------------------------------------ site folders
def site_copy(tmp_path: Path, edit) -> Path:
    """networks/xueqing copied to tmp_path/sites/xueqing, its site file edited by `edit(info, folder)`."""
    folder = tmp_path / "sites" / "xueqing"
    shutil.copytree(NETWORKS_DIR / "xueqing", folder)
    shutil.copyfile(REPO_ROOT / "osm" / "xueqing.osm", folder / "xueqing.osm")
    path = folder / "xueqing.site.json"
    info = json.loads(path.read_text())
    info["source_osm"], info["clip_osm"] = "xueqing.osm", "xueqing.osm"
    edit(info, folder)
    path.write_text(json.dumps(info, indent=2))
    return folder


def _clip(value: str):
    return lambda info, folder: info.update(clip_osm=value)


def _source(value: str):
    return lambda info, folder: info.update(source_osm=value)


BUILD = ("-m", "pedsafe_sumo.site", "--site")
BUILD_TOOL = (str(TOOLS / "build_network.py"), "--site")


@pytest.mark.parametrize(
    ("build", "edit", "phrases"),
    [
        (BUILD, _clip("../../victim/important.txt"), ("clip_osm", "outside the site folder")),
        (BUILD_TOOL, _clip("../../victim/important.txt"), ("clip_osm", "writes only there")),
        (BUILD, _clip("ABSOLUTE"), ("clip_osm", "outside the site folder")),
        (BUILD_TOOL, _source("../../victim/important.txt"), ("source_osm", "refused")),
        (BUILD_TOOL, _clip("LINK"), ("clip_osm", "writes only there")),
    ],
    ids=[
        "network-dotdot-clip",
        "tool-dotdot-clip",
        "network-absolute-clip",
        "tool-outside-source",
        "tool-linked-clip",
    ],
)
def test_a_crafted_site_file_cannot_make_a_build_write_elsewhere(tmp_path, build, edit, phrases):
    victim_dir = victim(tmp_path)

    def resolved_edit(info, folder):
        edit(info, folder)
        if info["clip_osm"] == "ABSOLUTE":
            info["clip_osm"] = str(victim_dir / "important.txt")
        if info["clip_osm"] == "LINK":
            (folder / "clip.osm").symlink_to(victim_dir / "important.txt")
            info["clip_osm"] = "clip.osm"

    folder = site_copy(tmp_path, resolved_edit)
    before = snapshot(victim_dir)
    proc = command(*build, str(folder))
    assert proc.returncode == 2, proc.stderr[-3000:]
    line = proc.stderr.strip().splitlines()[-1]
    assert len(proc.stderr.strip().splitlines()) == 1 and "Traceback" not in proc.stderr, proc.stderr
    for phrase in phrases:
        assert phrase in line, line
    assert snapshot(victim_dir) == before


def test_a_site_file_named_after_another_site_cannot_send_the_build_to_a_sibling(tmp_path):
    folder = site_copy(tmp_path, lambda info, folder: None)
    renamed = folder.with_name("received")
    folder.rename(renamed)
    (tmp_path / "sites" / "xueqing").mkdir()
    before = snapshot(tmp_path / "sites" / "xueqing")
    proc = command(*BUILD_TOOL, str(renamed))
    assert proc.returncode == 2 and "give --out" in proc.stderr, proc.stderr[-3000:]
    assert snapshot(tmp_path / "sites" / "xueqing") == before == {}


# ---------------------------------------------------------------------------------- SUMO files of a site
CFG_OUTPUT = '    <output>\n        <{option} value="{value}"/>\n    </output>\n</configuration>'


def _cfg_option(option: str, value: str = "../../victim/out.xml"):
    def edit(folder: Path) -> None:
        cfg = folder / "xueqing.sumocfg"
        cfg.write_text(
            cfg.read_text().replace("</configuration>", CFG_OUTPUT.format(option=option, value=value))
        )

    return edit


def _cfg_additional(element: str):
    def edit(folder: Path) -> None:
        (folder / "extra.add.xml").write_text(f"<additional>\n    {element}\n</additional>\n")
        cfg = folder / "xueqing.sumocfg"
        cfg.write_text(cfg.read_text().replace("xueqing.rsu.add.xml", "xueqing.rsu.add.xml,extra.add.xml"))

    return edit


def _cfg_names(value: str):
    def edit(folder: Path) -> None:
        cfg = folder / "xueqing.sumocfg"
        cfg.write_text(cfg.read_text().replace("xueqing.rsu.add.xml", f"xueqing.rsu.add.xml,{value}"))

    return edit


def _rsu_element(element: str):
    """An element added to rsu.add.xml, with the site file's digest of it made to match."""

    def edit(folder: Path) -> None:
        rsu = folder / "xueqing.rsu.add.xml"
        rsu.write_text(rsu.read_text().replace("</additional>", f"    {element}\n</additional>"))
        info = json.loads((folder / "xueqing.site.json").read_text())
        info["derived_sha256"][rsu.name] = content_digest(rsu)
        (folder / "xueqing.site.json").write_text(json.dumps(info, indent=2))

    return edit


def _view_snapshot(folder: Path) -> None:
    view = folder / "xueqing.view.xml"
    view.write_text(
        view.read_text().replace(
            "</viewsettings>", '<snapshot file="../../victim/shot.png" time="0"/></viewsettings>'
        )
    )


VALIDATE = ("-m", "pedsafe_sumo.demand.validate", "--duration", "20", "--warmup", "0")
EPISODE_GUI = ("-m", "pedsafe_sumo.episode", "--scenario", "crossing", "--gui")


@pytest.mark.parametrize(
    ("cli", "edit", "phrase"),
    [
        (VALIDATE, _cfg_option("fcd-output"), "sets fcd-output"),
        (VALIDATE, _cfg_option("summary-output"), "sets summary-output"),
        (VALIDATE, _cfg_option("output-prefix", "../../victim/"), "sets output-prefix"),
        (
            VALIDATE,
            _cfg_additional('<edgeData id="e" file="../../victim/edges.xml"/>'),
            "names a file in <edgeData",
        ),
        (VALIDATE, _cfg_names("../../victim/x"), "climbs out of"),
        (
            EPISODE_GUI,
            _rsu_element('<e1Detector id="d" lane="x_0" pos="1" file="../../victim/e1.xml"/>'),
            "<e1Detector",
        ),
        (EPISODE_GUI, _view_snapshot, "names a file in <snapshot"),
    ],
    ids=[
        "cfg-fcd",
        "cfg-summary",
        "cfg-prefix",
        "additional-edgedata",
        "cfg-outside-file",
        "gui-detector",
        "gui-snapshot",
    ],
)
def test_a_site_with_sumo_outputs_is_refused_before_sumo_starts(tmp_path, cli, edit, phrase):
    victim_dir = victim(tmp_path)
    folder = site_copy(tmp_path, lambda info, folder: None)
    edit(folder)
    before = snapshot(victim_dir)
    extra = ("--docs", str(tmp_path / "docs"), "--work", str(tmp_path / "work")) if cli is VALIDATE else ()
    proc = command(*cli, "--site", str(folder), *extra)
    assert proc.returncode == 2, proc.stderr[-3000:]
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and phrase in lines[0] and "Traceback" not in proc.stderr, proc.stderr[-3000:]
    assert snapshot(victim_dir) == before


# ---------------------------------------------------------------------------------- AD stacks in run.json
def _recorded_stack(run: Path, spec: str) -> None:
    info = json.loads((run / "run.json").read_text())
    info["algorithm"] = info["arguments"]["algorithm"] = spec
    (run / "run.json").write_text(json.dumps(info))


def _protocol_naming(run: Path, module: str) -> None:
    """A copy of the paper-v7 protocol in `run` whose [protocol] algorithm is `module`:Stack."""
    text = (REPO_ROOT / "protocols" / "paper-v7.toml").read_text()
    (run / "received.toml").write_text(
        text.replace(
            'algorithm = "pedsafe_sumo.control.reference:ReferenceStack"', f'algorithm = "{module}:Stack"', 1
        )
    )


REPLAY = (
    "-m",
    "pedsafe_sumo.replay",
    ".",
    "--episode",
    "0",
    "--condition",
    "sv",
    "--export-fcd",
    "x.fcd.xml",
)
RESUME = ("-m", "pedsafe_sumo.batch", "--resume", "--out", ".")
PROTOCOL = ("-m", "pedsafe_sumo.batch", "--protocol", "received.toml", "--episodes", "1", "--out", "new")


@pytest.mark.slow
@pytest.mark.parametrize(
    ("cli", "module", "phrase"),
    [
        (REPLAY, "evil_stack", "is not installed"),
        (RESUME, "evil_stack", "is not installed"),
        (REPLAY, "pytest", "the current directory holds a module 'pytest'"),
        (RESUME, "pytest", "the current directory holds a module 'pytest'"),
        (PROTOCOL, "evil_stack", "is not installed"),
    ],
    ids=[
        "replay-cwd-module",
        "resume-cwd-module",
        "replay-shadowing-module",
        "resume-shadowing-module",
        "protocol-cwd-module",
    ],
)
def test_a_stack_run_json_names_is_not_imported_from_the_current_directory(
    finished_run, tmp_path, cli, module, phrase
):
    victim_dir = victim(tmp_path)
    run = stopped_copy(finished_run, tmp_path) if cli is RESUME else tmp_path / "received" / "run"
    if cli is not RESUME:
        shutil.copytree(finished_run, run)
    if cli is PROTOCOL:
        _protocol_naming(run, module)
    (run / f"{module}.py").write_text(EVIL_MODULE.format(victim=str(victim_dir)))
    _recorded_stack(run, f"{module}:Stack")
    before_run = {name for name in os.listdir(run)}
    before = snapshot(victim_dir)
    proc = command(*cli, cwd=run)
    assert_refused(proc, phrase, "--algorithm")
    assert snapshot(victim_dir) == before and not (victim_dir / "imported.txt").exists()
    assert set(os.listdir(run)) == before_run  # nothing written (no new run either)


# --------------------------------------------------------------------------- the import rule, in-process
@pytest.mark.parametrize(
    ("spec", "named", "expected", "refusal"),
    [
        ("pedsafe_sumo.control.reference:ReferenceStack", None, "", None),
        ("pytest:Stack", None, "AD stack from run.json: pytest from", None),
        ("evil_stack:Stack", None, None, "is not installed"),
        ("pytest:Stack", None, None, "holds a module 'pytest'"),
        ("evil_stack:Stack", "evil_stack:Stack", "AD stack named by --algorithm: evil_stack:Stack", None),
        ("a:B", "c:D", "AD stack named by --algorithm: c:D; the run recorded a:B", None),
    ],
    ids=["shipped", "installed", "cwd-only", "shadowed", "named", "named-other"],
)
def test_which_stack_a_replay_imports(tmp_path, monkeypatch, spec, named, expected, refusal):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("PYTHONPATH", str(REPO_ROOT))
    (tmp_path / "evil_stack.py").write_text("raise SystemExit('imported')\n")
    if refusal and "pytest" in refusal:
        (tmp_path / "pytest.py").write_text("raise SystemExit('imported')\n")
    if refusal is None:
        chosen, note = stack_to_replay(spec, named, tmp_path / "run")
        assert chosen == (named or spec) and note.startswith(expected) and "\n" not in note
    else:
        with pytest.raises(AlgorithmLoadError, match=refusal) as info:
            stack_to_replay(spec, named, tmp_path / "run")
        assert "\n" not in str(info.value) and "--algorithm" in str(info.value)


@pytest.mark.parametrize(
    ("option", "value"),
    [
        ("tripinfo-output", "t.xml"),
        ("netstate-dump", "n.xml"),
        ("save-state.files", "s.xml"),
        ("log", "l.txt"),
        ("error-log", "e.txt"),
        ("device.ssm.file", "ssm.xml"),
        ("configuration-file", "other.sumocfg"),
        ("route-files", "r.rou.xml"),
    ],
)
def test_every_writing_option_of_a_site_configuration_is_refused(tmp_path, option, value):
    cfg = tmp_path / "x.sumocfg"
    cfg.write_text(
        '<configuration><input><net-file value="x.net.xml"/></input>'
        f'<{option} value="{value}"/></configuration>'
    )
    with pytest.raises(SumoInputError, match=f"sets {option}"):
        config_inputs(cfg)


def test_the_shipped_sites_pass_the_sumo_file_checks():
    for name in available_sites():
        site = resolve_site(name)
        found = config_inputs(site.file("sumocfg"))
        assert [p.name for p in found["additional"]] == [f"{name}.poly.xml", f"{name}.rsu.add.xml"]
        check_gui_site(site, site.file("view.xml"))
