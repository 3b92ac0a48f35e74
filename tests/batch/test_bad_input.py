"""Bad input to the batch: one line "error: ..." on stderr, exit code 2, no traceback, nothing written,
and an earlier run in the output directory left byte for byte as it was.

Most cases call the CLI's main() in this process (the checks run before any worker starts, and one
import of the package serves them all); a few run the real command line."""

from __future__ import annotations

import shutil

import pytest
from batch_cli import SMALL_RUN_ARGS, batch, tree_digest

from pedsafe_sumo import NETWORKS_DIR, REPO_ROOT
from pedsafe_sumo.batch.__main__ import main
from pedsafe_sumo.network.sites import NETWORKS_DIR_ENV

CROSSING = ("--scenario", "crossing", "--episodes", "2")


@pytest.fixture(autouse=True)
def plugins_importable(monkeypatch):
    """--algorithm tests.batch.plugin_agents:... imports from the repository root, as the CLI does."""
    monkeypatch.syspath_prepend(str(REPO_ROOT))


def assert_refused(capsys, argv: list[str], message: str) -> str:
    """main(argv) refuses with exit 2 and one line on stderr containing `message`."""
    try:
        code = main(argv)
    except SystemExit as exc:  # argparse's own errors
        code = exc.code
    err = capsys.readouterr().err
    assert code == 2, err
    assert err.startswith("error: ") and err.count("\n") == 1, err
    assert message in err and "Traceback" not in err, err
    return err


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--scenario", "parking"], "unknown scenario 'parking'"),
        (["--episodes", "3"], "--scenario is required"),
        ([*CROSSING, "--condition", "v3i"], "unknown condition 'v3i'"),
        (["--scenario", "crossing", "--episodes", "0"], "--episodes must be at least 1"),
        (["--scenario", "crossing", "--episodes", "many"], "invalid int value: 'many'"),
        ([*CROSSING, "--chunk-size", "0"], "--chunk-size must be at least 1"),
        ([*CROSSING, "--set", "lane_count=3"], "unknown scenario parameter 'lane_count'"),
        (
            [*CROSSING, "--set", "perception.v2i.bandwidth_hz=3"],
            "unknown parameter 'perception.v2i.bandwidth_hz'",
        ),
        ([*CROSSING, "--set", "ego_speed_min_mps=-2"], "ego_speed_min_mps"),
        ([*CROSSING, "--set", "pedestrians.hasten_max_speed_mps=-1"], "hasten_max_speed_mps' must be > 0"),
        ([*CROSSING, "--set", "perception.v2i.packet_loss_probability=1.5"], "packet_loss_probability"),
        ([*CROSSING, "--set", "novalue"], "--set needs key=value"),
        ([*CROSSING, "--site", "atlantis"], "unknown site 'atlantis'"),
        ([*CROSSING, "--algorithm", "nowhere:Agent"], "cannot import module 'nowhere'"),
        ([*CROSSING, "--algorithm", "tests.batch.plugin_agents:Missing"], "has no class 'Missing'"),
        ([*CROSSING, "--algorithm", "tests.batch.plugin_agents:NoRunStep"], "missing run_step"),
        ([*CROSSING, "--algorithm", "no_colon"], "must look like package.module:ClassName"),
        ([*CROSSING, "--cluster", "local:0"], "local:N needs a number of workers"),
        ([*CROSSING, "--cluster", "scheduler:8786"], "must be a Dask scheduler address"),
        ([*CROSSING, "--cluster", "local:2", "--workers", "2"], "exclude each other"),
        ([*CROSSING, "--workers", "0"], "--workers must be at least 1"),
        ([*CROSSING, "--resume"], "--resume needs --out DIR"),
        # Upper bounds: values that would make a batch run for ever are refused up front.
        ([*CROSSING, "--set", "queue_vehicles=1e9"], "queue_vehicles must be at most 20"),
        ([*CROSSING, "--set", "time_limit_s=1e12"], "time_limit_s must be at most 600"),
        ([*CROSSING, "--set", "traffic.headway_rate_per_s=1e9"], "headway_rate_per_s' must be at most 1 "),
        (
            [*CROSSING, "--set", "perception.lidar.horizontal_resolution_deg=0.000001"],
            "horizontal_resolution_deg' must be at least 0.05",
        ),
        (
            [*CROSSING, "--set", "perception.occluders.tree_row_spacing_m=0.000000001"],
            "tree_row_spacing_m' must be at least 1",
        ),
        ([*CROSSING, "--set", "algorithm.max_decel_mps2=1e9"], "max_decel_mps2' must be at most 15"),
        (["--scenario", "crossing", "--episodes", "10000000"], "--episodes must be at most 1,000,000"),
        ([*CROSSING, "--seed", str(2**64)], "--seed must be at most 2**63 - 1"),
        ([*CROSSING, "--workers", "100000"], "--workers must be at most 256"),
        ([*CROSSING, "--chunk-size", "1000000"], "--chunk-size must be at most 10,000"),
        ([*CROSSING, "--cluster", "local:100000"], "starts at most 256 local workers"),
        ([*CROSSING, "--agent-timeout", "0"], "--agent-timeout must be > 0 and at most 3600"),
        ([*CROSSING, "--agent-timeout", "1e9"], "--agent-timeout must be > 0 and at most 3600"),
        ([*CROSSING, "--agent-timeout", "nan"], "--agent-timeout must be > 0 and at most 3600"),
        ([*CROSSING, "--agent-timeout", "soon"], "invalid float value: 'soon'"),
    ],
)
def test_bad_command_line(capsys, tmp_path, args, message):
    out = tmp_path / "out"
    assert_refused(capsys, [*args, "--out", str(out)] if "--resume" not in args else args, message)
    assert not out.exists()


@pytest.mark.parametrize(
    ("content", "message"),
    [
        (None, "parameter file not found"),
        ("[traffic\nheadway_rate_per_s = 0.2\n", "is not valid TOML"),
        ("[traffic]\nheadway_rate_s = 0.2\n", "unknown parameter 'traffic.headway_rate_s'"),
        ("[traffic]\nheadway_rate_per_s = -0.2\n", "headway_rate_per_s' must be > 0"),
        ("[perception.v2i]\npacket_loss_probability = 2.0\n", "packet_loss_probability"),
    ],
    ids=["missing", "malformed", "unknown-key", "negative-rate", "probability-above-1"],
)
def test_bad_parameter_file(capsys, tmp_path, content, message):
    params = tmp_path / "params.toml"
    if content is not None:
        params.write_text(content)
    out = tmp_path / "out"
    assert_refused(capsys, [*CROSSING, "--params", str(params), "--out", str(out)], message)
    assert not out.exists()


def broken_site(tmp_path, suffix: str, damage) -> None:
    """networks/ copied to tmp_path/networks with one file of the xueqing site damaged."""
    shutil.copytree(NETWORKS_DIR, tmp_path / "networks")
    damage(tmp_path / "networks" / "xueqing" / f"xueqing.{suffix}")


def truncate(path) -> None:
    path.write_bytes(path.read_bytes()[: len(path.read_bytes()) // 2])


@pytest.mark.parametrize(
    ("suffix", "damage", "message"),
    [
        ("net.xml", truncate, "cannot parse {path}: "),
        ("net.xml", lambda p: p.write_text("<net/>"), "site xueqing:"),
        ("poly.xml", lambda p: p.unlink(), "{path} is missing"),
        ("rsu.add.xml", truncate, "cannot parse {path}"),
        ("site.json", lambda p: p.write_text("{not json"), "cannot parse {path}"),
    ],
    ids=["net-truncated", "net-empty", "poly-missing", "rsu-truncated", "site-json-malformed"],
)
def test_missing_or_broken_site_file(capsys, tmp_path, monkeypatch, suffix, damage, message):
    broken_site(tmp_path, suffix, damage)
    monkeypatch.setenv(NETWORKS_DIR_ENV, str(tmp_path / "networks"))
    out = tmp_path / "out"
    path = tmp_path / "networks" / "xueqing" / f"xueqing.{suffix}"
    assert_refused(capsys, [*CROSSING, "--out", str(out)], message.format(path=path))
    assert not out.exists()


def test_broken_network_through_the_real_command_line(tmp_path):
    broken_site(tmp_path, "net.xml", truncate)
    out = tmp_path / "out"
    proc = batch(
        *CROSSING, "--out", str(out), env={NETWORKS_DIR_ENV: str(tmp_path / "networks")}, timeout=120
    )
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1, proc.stderr
    assert (
        "cannot parse" in proc.stderr
        and "xueqing.net.xml: " in proc.stderr
        and "Traceback" not in proc.stderr
    )
    assert not out.exists()


@pytest.mark.slow
@pytest.mark.parametrize(
    ("args", "message"),
    [
        (SMALL_RUN_ARGS, "already holds a run (complete); continue it with --resume"),
        (("--scenario", "jaywalking"), "already holds a run"),
        ((*SMALL_RUN_ARGS[:-1], "2", "--resume"), "chunk_size_pairs is 1 there, 2 here"),
        (("--resume", "--episodes", "5"), "episodes_per_scenario is 4 there, 5 here"),
        (("--resume", "--seed", "6"), "run_seed is 5 there, 6 here"),
        (("--resume", "--set", "perception.v2i.latency_s=0.3"), "parameters.perception.v2i.latency_s"),
        (("--resume", "--set", "time_limit_s=20"), "scenarios.crossing.time_limit_s"),
        (("--resume", "--algorithm", "tests.sim.plugin_agents:NeverBrakes"), "algorithm is"),
        (("--resume", "--set", "perception.v2i.packet_loss_probability=1.5"), "packet_loss_probability"),
        (("--resume", "--algorithm", "nowhere:Agent"), "cannot import module 'nowhere'"),
    ],
)
def test_an_earlier_run_is_never_damaged(small_run, capsys, args, message):
    out, _ = small_run
    before = tree_digest(out)
    assert_refused(capsys, [*args, "--out", str(out)], message)
    assert tree_digest(out) == before


@pytest.mark.slow
def test_an_earlier_run_is_never_damaged_by_the_real_command_line(small_run):
    out, _ = small_run
    before = tree_digest(out)
    proc = batch("--scenario", "crossing", "--episodes", "1", "--out", str(out), timeout=120)
    assert proc.returncode == 2 and "already holds a run" in proc.stderr and proc.stderr.count("\n") == 1
    assert tree_digest(out) == before


def test_output_that_is_a_file(capsys, tmp_path):
    (tmp_path / "out").write_text("my notes")
    assert_refused(capsys, [*CROSSING, "--out", str(tmp_path / "out")], "is a file, not a run directory")
    assert (tmp_path / "out").read_text() == "my notes"


def test_resume_needs_a_run_to_resume(capsys, tmp_path):
    assert_refused(capsys, ["--resume", "--out", str(tmp_path / "nothing")], "holds no run to resume")
    assert not (tmp_path / "nothing").exists()
    (tmp_path / "other").mkdir()
    (tmp_path / "other" / "notes.txt").write_text("mine")
    assert_refused(capsys, ["--resume", "--out", str(tmp_path / "other")], "holds no run to resume")
    (tmp_path / "other" / "run.json").write_text("{broken")
    assert_refused(capsys, ["--resume", "--out", str(tmp_path / "other")], "run.json is unreadable")
    assert sorted(p.name for p in (tmp_path / "other").iterdir()) == ["notes.txt", "run.json"]


def test_a_huge_queue_is_refused_by_the_real_command_line_not_run(tmp_path):
    """`--set queue_vehicles=1e9` would stage a billion vehicles (the batch would hang): refused up front."""
    out = tmp_path / "out"
    proc = batch(*CROSSING, "--set", "queue_vehicles=1e9", "--out", str(out), timeout=120)
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1, proc.stderr
    assert "queue_vehicles must be at most 20" in proc.stderr and "Traceback" not in proc.stderr
    assert not out.exists()


def foreign_directory(path):
    """A user's directory with files of their own (and a sub-folder), no run of ours."""
    (path / "photos").mkdir(parents=True)
    (path / "notes.txt").write_text("mine")
    (path / "photos" / "cat.jpg").write_bytes(bytes(range(256)))
    (path / "data.csv").write_text("a,b\n1,2\n")
    return path


def test_out_refuses_a_foreign_directory_and_leaves_it_byte_identical(capsys, tmp_path):
    out = foreign_directory(tmp_path / "mine")
    before = tree_digest(out)
    names_before = sorted(p.relative_to(out) for p in out.rglob("*"))
    assert_refused(
        capsys, [*CROSSING, "--out", str(out)], "is a directory that is not empty and holds no run"
    )
    assert tree_digest(out) == before
    assert sorted(p.relative_to(out) for p in out.rglob("*")) == names_before  # nothing added, no .lock


def test_out_refuses_the_root_directory(capsys):
    assert_refused(capsys, [*CROSSING, "--out", "/"], "--out / is a directory that is not empty")


def test_out_refuses_a_directory_with_only_a_hidden_file(capsys, tmp_path):
    (tmp_path / "hidden").mkdir()
    (tmp_path / "hidden" / ".keep").write_text("")
    assert_refused(capsys, [*CROSSING, "--out", str(tmp_path / "hidden")], "holds no run")
    assert [p.name for p in (tmp_path / "hidden").iterdir()] == [".keep"]


def test_out_accepts_an_empty_directory(tmp_path):
    from pedsafe_sumo.batch.__main__ import parse_args
    from pedsafe_sumo.batch.plan import prepare

    (tmp_path / "empty").mkdir()
    plan = prepare(parse_args([*CROSSING, "--out", str(tmp_path / "empty")]))
    assert plan.out == tmp_path / "empty" and plan.config.agent_timeout_s == 10.0


@pytest.mark.slow
def test_out_refuses_a_foreign_directory_through_the_real_command_line(tmp_path):
    out = foreign_directory(tmp_path / "mine")
    before = tree_digest(out)
    proc = batch(*CROSSING, "--out", str(out), timeout=120)
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1, proc.stderr
    assert "holds no run" in proc.stderr and "Traceback" not in proc.stderr
    assert tree_digest(out) == before
