"""The conflicts heat map: the site's network drawn by sumolib, conflicts counted in cells over it."""

from __future__ import annotations

import matplotlib.image
import numpy as np
import pandas as pd

from pedsafe_sumo import REPO_ROOT
from pedsafe_sumo.conflicts.heatmap import main

NET = REPO_ROOT / "networks" / "xueqing" / "xueqing.net.xml"


def table(path, rows):
    frame = pd.DataFrame(rows, columns=["x_m", "y_m", "conflict", "collision"])
    frame.to_csv(path, index=False)
    return path


def test_heatmap_draws_the_net_and_the_conflicts(tmp_path):
    # 20 conflicts in one spot, one contact elsewhere, 50 interactions without either (not counted)
    rows = (
        [(200.0, 200.0, True, False)] * 20
        + [(150.0, 250.0, False, True)]
        + [(100.0, 100.0, False, False)] * 50
    )
    out = tmp_path / "map.png"
    assert main([str(table(tmp_path / "t.csv", rows)), "--site", "xueqing", "--out", str(out)]) == 0
    image = matplotlib.image.imread(out)[..., :3]
    assert (np.abs(image - 1.0).max(axis=-1) > 0.05).mean() > 0.02  # lanes and cells drawn, not blank
    # the contact marker's blue (#0050d0) is there
    assert (np.abs(image - np.array([0x00, 0x50, 0xD0]) / 255).max(axis=-1) < 0.03).sum() > 5


def test_heatmap_bad_input_exit_2(tmp_path, capsys):
    good = table(tmp_path / "t.csv", [(1.0, 1.0, True, False)])
    bad = tmp_path / "bad.csv"
    bad.write_text("a,b\n1,2\n")
    for args, words in (
        ([str(tmp_path / "none.csv"), "--net", str(NET), "--out", str(tmp_path / "m.png")], "not found"),
        ([str(bad), "--net", str(NET), "--out", str(tmp_path / "m.png")], "not a conflicts table"),
        ([str(good), "--net", str(tmp_path / "no.net.xml"), "--out", str(tmp_path / "m.png")], "network"),
        ([str(good), "--net", str(NET), "--out", str(tmp_path / "m.txt")], "--out"),
        ([str(good), "--out", str(tmp_path / "m.png")], "--net NET.xml or --site"),
        ([str(good), "--site", str(tmp_path / "nosite"), "--out", str(tmp_path / "m.png")], "nosite"),
    ):
        assert main(args) == 2
        err = capsys.readouterr().err
        assert err.startswith("error: ") and err.count("\n") == 1 and words in err, err
