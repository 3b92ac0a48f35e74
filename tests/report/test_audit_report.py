"""The collision witness and the staging diagnostics in the printed report, its files and report.html."""

from __future__ import annotations

import pandas as pd
from report_runs import write_standard_run

from pedsafe_sumo.report.__main__ import main


def test_the_audit_is_printed_written_and_on_the_page(tmp_path, capsys):
    run = write_standard_run(tmp_path / "run")
    assert main([str(run)]) == 0
    out = capsys.readouterr().out
    assert "Collision witness: the loop's collision against an independent check" in out
    assert "Staging diagnostics (targets:" in out
    # The standard run's rows carry no witness verdict (written without it) and the report holds case
    # logs of a few episodes only: the others are "not recorded".
    witness = pd.read_csv(run / "tables" / "witness.csv")
    assert (witness["not_recorded"] > 0).any()
    assert (witness["compared"] + witness["not_recorded"] == witness["n"]).all()
    staging = pd.read_csv(run / "tables" / "staging.csv")
    assert staging[["scenario", "condition"]].values.tolist() == [
        ["crossing", "sv"],
        ["crossing", "v2i"],
        ["jaywalking", "sv"],
        ["jaywalking", "v2i"],
    ]
    # crossing V2I: every first detection at 1.0 s, inside the first second.
    assert staging.loc[1, "first_second_share"] == 1.0 and not staging.loc[1, "first_second_target_met"]
    page = (run / "report.html").read_text(encoding="utf-8")
    for table_id in ("witness", "staging"):
        assert f'<table class="data" id="{table_id}">' in page
    assert "Collision witness" in page and "Staging diagnostics" in page
