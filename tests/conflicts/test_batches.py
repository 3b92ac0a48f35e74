"""The tracker measures the interactions that have ended a batch at a time: the rows must not depend on the
batch (each interaction measured alone gives the same bytes), they come in the order the interactions
end (those ending at one timestep in the order they began), and a pair that parts and meets again is two
interactions. A road user twice in one timestep is bad input (one line, exit 2)."""

from __future__ import annotations

import csv

import pytest

from pedsafe_sumo.conflicts import interactions
from pedsafe_sumo.conflicts.__main__ import main


def write_crowd_fcd(path, steps: int = 60):
    """Cars driving east on y = 0 and y = 20 (4 m ahead of each other, 8 m/s), walkers crossing north at
    x = 30, 60, 90 at 1 m/s; car c2 leaves the file after 3 s and comes back at 4.5 s (same id), walker w1
    leaves after 5 s and comes back at 6 s: their pairs end together and begin again. Steps of 0.5 s."""
    lines = ["<fcd-export>"]
    for k in range(steps):
        t = 0.5 * k
        lines.append(f'<timestep time="{t:.2f}">')
        for c in range(4):
            if c == 2 and 3.0 < t < 4.5:
                continue
            x = 8.0 * t + 4.0 * c
            lines.append(
                f'<vehicle id="c{c}" x="{x:.2f}" y="{20.0 * (c % 2):.2f}" angle="90.00" type="t" '
                'speed="8.00" lane="road_0"/>'
            )
        for w, wx in enumerate((30.0, 60.0, 90.0)):
            if w == 1 and 5.0 < t < 6.0:
                continue
            lines.append(
                f'<person id="w{w}" x="{wx:.2f}" y="{-10.0 + t:.2f}" angle="0.00" type="p" speed="1.00" '
                'edge="x"/>'
            )
        lines.append("</timestep>")
    lines.append("</fcd-export>")
    path.write_text("\n".join(lines) + "\n")
    return path


def rows_of(path):
    with open(path, newline="") as handle:
        return list(csv.DictReader(handle))


def test_rows_do_not_depend_on_the_batch(tmp_path, monkeypatch):
    fcd = write_crowd_fcd(tmp_path / "crowd.fcd.xml")
    outputs = []
    for flush_interactions, flush_rows in ((1, 1), (3, 10**9), (10**9, 7), (10**9, 10**9)):
        monkeypatch.setattr(interactions, "FLUSH_INTERACTIONS", flush_interactions)
        monkeypatch.setattr(interactions, "FLUSH_ROWS", flush_rows)
        # a table of held rows that starts small and grows many times, or hardly
        monkeypatch.setattr(interactions, "HELD_ROWS_AT_FIRST", 1 + flush_interactions % 5)
        out = tmp_path / f"c{flush_interactions}_{flush_rows}.csv"
        assert main([str(fcd), "--out", str(out), "--ssm", str(out.with_suffix(".xml")), "--quiet"]) == 0
        outputs.append((out.read_bytes(), out.with_suffix(".xml").read_bytes()))
    assert all(output == outputs[0] for output in outputs[1:])
    assert len(rows_of(tmp_path / "c1_1.csv")) > 10


def test_rows_in_the_order_the_interactions_end_then_begin(tmp_path):
    fcd = write_crowd_fcd(tmp_path / "crowd.fcd.xml")
    out = tmp_path / "c.csv"
    assert main([str(fcd), "--out", str(out), "--quiet", "--radius", "50"]) == 0
    rows = rows_of(out)
    ends = [float(r["end_s"]) for r in rows]
    assert ends == sorted(ends)
    # Within one end time, in the order they began: by begin time, then in the file's order of the pair
    # (vehicle, then person) at that first step.
    order = [(float(r["begin_s"]), int(r["vehicle_id"][1:]), int(r["person_id"][1:])) for r in rows]
    for k in range(1, len(rows)):
        if ends[k] == ends[k - 1]:
            assert order[k - 1] < order[k], (rows[k - 1], rows[k])
    assert len(set(ends)) < len(ends) - 3  # several end together
    # c2 leaves at 3.5 s and is back at 4.5 s: its pairs end at 3.0 s and begin again at 4.5 s.
    c2_w0 = [
        (float(r["begin_s"]), float(r["end_s"]))
        for r in rows
        if r["vehicle_id"] == "c2" and r["person_id"] == "w0"
    ]
    assert c2_w0[:2] == [(0.0, 3.0), (4.5, c2_w0[1][1])], c2_w0


@pytest.mark.parametrize("twice", ["vehicle", "person"])
def test_a_road_user_twice_in_a_timestep_is_bad_input(tmp_path, capsys, twice):
    car = '<vehicle id="c" x="10" y="0" angle="90" type="t" speed="5"/>'
    walker = '<person id="w" x="12" y="1" angle="0" type="p" speed="1"/>'
    doubled = car * 2 + walker if twice == "vehicle" else car + walker * 2
    fcd = tmp_path / "twice.fcd.xml"
    steps = f'<timestep time="0">{car}{walker}</timestep><timestep time="1">{doubled}</timestep>'
    fcd.write_text(f"<fcd-export>{steps}</fcd-export>")
    assert main([str(fcd), "--out", str(tmp_path / "t.csv"), "--quiet"]) == 2
    err = capsys.readouterr().err
    road_user = {"vehicle": "c", "person": "w"}[twice]
    assert err.count("\n") == 1 and f"{twice} '{road_user}' appears more than once at t=1 s" in err, err
