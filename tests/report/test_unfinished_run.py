"""The report on a batch that has not finished: refused in one line, or with --partial reported on the
chunks recorded so far, flagged INCOMPLETE everywhere and written apart from the final report."""

from __future__ import annotations

import json

import pytest
from report_runs import standard_episodes

from pedsafe_sumo.io.episodes import to_table
from pedsafe_sumo.io.run_store import ChunkRecord, Manifest, parquet_bytes, sha256_bytes, write_bytes_atomic
from pedsafe_sumo.report.__main__ import main
from pedsafe_sumo.report.rundir import ReportError, load_run


def unfinished_run(directory, damaged_part: bool = False):
    """The standard episodes' crossing rows in two recorded chunks (episodes 0-4, 5-9) of a run of 4."""
    episodes = standard_episodes()
    crossing = episodes[episodes["scenario"] == "crossing"]
    (directory / "parts").mkdir(parents=True)
    manifest = Manifest(directory / "manifest.json")
    for first, last in ((0, 4), (5, 9)):
        rows = crossing[(crossing["episode"] >= first) & (crossing["episode"] <= last)]
        # Parts are written by the batch, whose rows state every flag (to_table refuses a missing one).
        rows = rows.assign(close_pass=False, contact_stationary=False, witness_collision=rows["collision"])
        data = parquet_bytes(to_table(rows.to_dict("records")))
        name = f"crossing-{first:06d}-{last:06d}.parquet"
        write_bytes_atomic(directory / "parts" / name, data)
        manifest.record(
            ChunkRecord(
                name[:-8],
                "crossing",
                first,
                last,
                f"parts/{name}",
                len(rows),
                sha256_bytes(data),
                0,
                0,
                "",
                1.0,
            )
        )
    if damaged_part:
        (directory / "parts" / "crossing-000005-000009.parquet").write_bytes(b"not a parquet file")
    run_info = {
        "state": "running",
        "chunks_total": 4,
        "episodes_total": 40,
        "run_seed": 1,
        "wall_time_s": None,
    }
    (directory / "run.json").write_text(json.dumps(run_info))
    return directory, crossing


def test_an_unfinished_run_is_refused_in_one_line(tmp_path, capsys):
    run, _ = unfinished_run(tmp_path / "run")
    assert main([str(run)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert "unfinished batch run (2 of 4 chunks, 20 of 40 episode rows done)" in err
    assert f"python -m pedsafe_sumo.batch --resume --out {run}" in err and "--partial" in err
    assert not (run / "tables").exists() and not (run / "partial").exists()


def test_partial_report_covers_the_recorded_chunks_and_says_so(tmp_path, capsys):
    run, crossing = unfinished_run(tmp_path / "run")
    assert main([str(run), "--partial"]) == 0
    lines = capsys.readouterr().out.rstrip().splitlines()
    banner = "INCOMPLETE RUN: 2 of 4 chunks, 20 of 40 episode rows; every number covers these episodes only"
    assert lines[0] == banner and lines[-1] == banner
    for name in ("table1.md", "paired.md"):
        assert (run / "partial" / "tables" / name).read_text().startswith(f"**{banner}**")
    assert (run / "partial" / "figures" / "first_detection_distance.png").is_file()
    assert not (run / "tables").exists() and not (run / "figures").exists()
    assert len(load_run(run, partial=True).episodes) == len(crossing) == 20


def test_a_damaged_part_is_left_out_of_a_partial_report(tmp_path):
    run, _ = unfinished_run(tmp_path / "run", damaged_part=True)
    loaded = load_run(run, partial=True)
    assert len(loaded.episodes) == 10 and loaded.incomplete.startswith("INCOMPLETE RUN: 1 of 4 chunks")
    with pytest.raises(ReportError, match="unfinished batch run"):
        load_run(run)
