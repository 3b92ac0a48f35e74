"""The run directory's files (pedsafe_sumo.io.run_store): atomic writes, the manifest, what a resume
must clean up. No SUMO here."""

from __future__ import annotations

import os

import pytest

from pedsafe_sumo.io import run_store
from pedsafe_sumo.io.run_store import (
    ChunkRecord,
    Manifest,
    RunStoreError,
    check_part,
    stray_files,
    write_bytes_atomic,
)


def record(key: str, data: bytes, session: int = 0) -> ChunkRecord:
    return ChunkRecord(
        key=key,
        scenario="crossing",
        first_episode=0,
        last_episode=0,
        file=f"parts/{key}.parquet",
        rows=2,
        sha256=run_store.sha256_bytes(data),
        n_error=0,
        session=session,
        completed_utc="2026-11-21T00:00:00+00:00",
        session_elapsed_s=1.5,
    )


def test_an_interrupted_write_leaves_the_old_file_whole(tmp_path, monkeypatch):
    target = tmp_path / "manifest.json"
    write_bytes_atomic(target, b"old and complete")

    def killed_before_rename(src, dst):
        raise KeyboardInterrupt  # the driver dies between writing the temporary file and renaming it

    monkeypatch.setattr(os, "replace", killed_before_rename)
    with pytest.raises(KeyboardInterrupt):
        write_bytes_atomic(target, b"new")
    assert target.read_bytes() == b"old and complete"
    assert (tmp_path / "manifest.json.tmp").exists()  # left for the resume to remove


def test_manifest_round_trip_and_bad_manifests(tmp_path):
    manifest = Manifest(tmp_path / "manifest.json")
    manifest.record(record("crossing-000000-000000", b"x"))
    loaded = Manifest.load(tmp_path / "manifest.json")
    assert loaded.chunks == manifest.chunks
    (tmp_path / "manifest.json").write_text('{"format": 99, "chunks": {}}')
    with pytest.raises(RunStoreError, match="not a manifest of format 1"):
        Manifest.load(tmp_path / "manifest.json")
    (tmp_path / "manifest.json").write_text("{half")
    with pytest.raises(RunStoreError, match="unreadable"):
        Manifest.load(tmp_path / "manifest.json")


def test_parts_are_checked_against_their_checksum_and_strays_are_found(tmp_path):
    parts = tmp_path / "parts"
    cases = tmp_path / "cases"
    parts.mkdir()
    cases.mkdir()
    good = record("crossing-000000-000000", b"good bytes")
    bad = record("crossing-000001-000001", b"what was written")
    gone = record("crossing-000002-000002", b"never there")
    (parts / "crossing-000000-000000.parquet").write_bytes(b"good bytes")
    (parts / "crossing-000001-000001.parquet").write_bytes(b"what is there now")
    (parts / "crossing-000003-000003.parquet").write_bytes(b"written, never recorded")
    (parts / "crossing-000004-000004.parquet.tmp").write_bytes(b"half")
    (cases / "crossing_sv_1.parquet.tmp").write_bytes(b"half")
    (cases / "crossing_sv_2.parquet").write_bytes(b"a whole case")
    assert check_part(tmp_path, good) == ""
    assert "does not match its recorded checksum" in check_part(tmp_path, bad)
    assert "is missing" in check_part(tmp_path, gone)
    manifest = Manifest(tmp_path / "manifest.json", {r.key: r for r in (good, bad, gone)})
    assert [p.relative_to(tmp_path).as_posix() for p in stray_files(tmp_path, manifest)] == [
        "parts/crossing-000003-000003.parquet",
        "parts/crossing-000004-000004.parquet.tmp",
        "cases/crossing_sv_1.parquet.tmp",
    ]
