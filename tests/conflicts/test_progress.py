"""The progress of a run: read_fcd reports the bytes of the file read so far, up to the file's size (the
compressed size for .xml.gz), and the command draws a tqdm bar from it on stderr, none with --quiet."""

from __future__ import annotations

import gzip

from fcd_files import walker, write_fcd

import pedsafe_sumo.conflicts.__main__ as command
from pedsafe_sumo.conflicts.fcd import read_fcd


def test_progress_reaches_the_file_size(tmp_path):
    plain = write_fcd(tmp_path / "a.fcd.xml", 200, [("walker", walker)])
    packed = tmp_path / "a.fcd.xml.gz"
    packed.write_bytes(gzip.compress(plain.read_bytes()))
    for path in (plain, packed):
        seen: list[int] = []
        steps = sum(1 for _ in read_fcd(path, progress=seen.append))
        assert steps == 200 and len(seen) == 200
        assert seen == sorted(seen) and seen[0] > 0
        assert seen[-1] == path.stat().st_size


def test_bar_on_stderr_unless_quiet(tmp_path, monkeypatch, capsys):
    fcd = write_fcd(tmp_path / "a.fcd.xml", 20, [("walker", walker)])
    monkeypatch.setattr(command, "PROGRESS_DELAY_S", 0.0)
    assert command.main([str(fcd), "--out", str(tmp_path / "a.csv")]) == 0
    err = capsys.readouterr().err
    # The bar counts the file's bytes: a few thousand, shown by tqdm to three digits ("5.19k"); the rate
    # after it may be kB/s or MB/s depending on the machine, so it is not what is asserted.
    size_k = f"{fcd.stat().st_size / 1000:.2f}k"
    assert "a.fcd.xml" in err and "100%" in err and f"{size_k}/{size_k}" in err, (size_k, err)
    assert command.main([str(fcd), "--out", str(tmp_path / "b.csv"), "--quiet"]) == 0
    assert capsys.readouterr().err == ""
