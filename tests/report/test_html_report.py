"""DIR/report.html: one self-contained page rendered from the package's Jinja2 templates, checked as text
and in a real headless Chromium.

The run is the hand-made standard run of report_runs.py (known Table I, 7 case logs). The verdict's
numbers are checked against rates and Wilson intervals computed here from episodes.parquet. The browser
tests open the page from disk with networking off: one takes a screenshot of the whole page and checks
its pixels (the table header colour of the page's style, a distinctive colour of every embedded figure);
one loads the page at a 1000 px wide window with a measuring script added to a copy of it, and reads
back from the DOM Chromium dumps the rendered width of every figure against the viewport's and what
the case filter shows once an outcome is chosen. Chromium is the Debian package `chromium` (.ci/run
installs it).
"""

from __future__ import annotations

import html
import json
import math
import re
import shutil
import subprocess
import sys
from html.parser import HTMLParser
from pathlib import Path

import matplotlib.image
import numpy as np
import pandas as pd
import pytest
from report_runs import RUN_INFO, standard_episodes, write_run, write_standard_run

from pedsafe_sumo import REPO_ROOT
from pedsafe_sumo.report.html import write_html_report
from pedsafe_sumo.report.rundir import load_run
from pedsafe_sumo.report.tables import paired_of_run, table_one_of_run

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
#: The table header background of the page's style (#e8eef6).
TABLE_HEADER_RGB = (0xE8, 0xEE, 0xF6)
#: The ego's path colour of the case pictures (#c0208a).
EGO_PATH_RGB = (0xC0, 0x20, 0x8A)
#: The protocol named in the run.json of the reported run.
PROTOCOL = {"name": "crossing-check-v3", "file": "protocols/crossing-check-v3.toml", "date": "2026-01-02"}
Z_95 = 1.959963984540054  # the 97.5% quantile of the standard normal


def _report(run: Path) -> None:
    proc = subprocess.run(
        [sys.executable, "-m", "pedsafe_sumo.report", str(run)],
        capture_output=True,
        text=True,
        cwd=REPO_ROOT,
        timeout=300,
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "report.html" in proc.stdout


@pytest.fixture(scope="module")
def reported(tmp_path_factory) -> Path:
    run = write_standard_run(tmp_path_factory.mktemp("html") / "run")
    (run / "run.json").write_text(json.dumps({**RUN_INFO, "protocol": PROTOCOL, "algorithm": "a.b:Stack"}))
    _report(run)
    return run


class Tables(HTMLParser):
    """The cells of every table of a page by the table's id, and the ids of the <section>s in order."""

    def __init__(self) -> None:
        super().__init__()
        self.tables: dict[str, list[list[str]]] = {}
        self.row_attributes: dict[str, list[dict[str, str]]] = {}
        self.sections: list[str] = []
        self._table: list[str] = []
        self._cell: list[str] | None = None
        self._in_body = False

    def handle_starttag(self, tag, attrs):
        attributes = {k: v or "" for k, v in attrs}
        if tag == "section":
            self.sections.append(attributes.get("id", ""))
        elif tag == "table":
            self._table.append(attributes.get("id", ""))
            self.tables[self._table[-1]] = []
            self.row_attributes[self._table[-1]] = []
        elif tag == "tbody":
            self._in_body = True
        elif tag == "tr" and self._table and self._in_body:
            self.tables[self._table[-1]].append([])
            self.row_attributes[self._table[-1]].append(attributes)
        elif tag == "td" and self._table and self._in_body:
            self._cell = []
        elif tag == "br" and self._cell is not None:
            self._cell.append(" ")

    def handle_endtag(self, tag):
        if tag == "td" and self._cell is not None:
            self.tables[self._table[-1]][-1].append(" ".join("".join(self._cell).split()))
            self._cell = None
        elif tag == "tbody":
            self._in_body = False
        elif tag == "table" and self._table:
            self._table.pop()

    def handle_data(self, data):
        if self._cell is not None:
            self._cell.append(data)


def parse(page: str) -> Tables:
    tables = Tables()
    tables.feed(page)
    return tables


def wilson(k: int, n: int) -> tuple[float, float]:
    """The Wilson score interval at 95%, from its formula."""
    centre = (k + Z_95**2 / 2) / (n + Z_95**2)
    half = Z_95 / (n + Z_95**2) * math.sqrt(k * (n - k) / n + Z_95**2 / 4)
    return max(0.0, centre - half), min(1.0, centre + half)


def cell_numbers(cell: str) -> list[float]:
    return [float(x) for x in re.findall(r"-?\d+\.\d+", cell)]


def test_page_is_self_contained_and_holds_tables_figures_cases_config(reported):
    page = (reported / "report.html").read_text(encoding="utf-8")
    # nothing is fetched: every image inline, no external scripts, links or styles
    sources = re.findall(r'src="([^"]*)"', page)
    assert sources and all(s.startswith("data:image/png;base64,") for s in sources)
    assert not re.search(r"<link\b|<script\b[^>]*\bsrc=", page)
    assert "http://" not in page.split("<pre>")[0] and "https://" not in page.split("<pre>")[0]
    # Table I as the CSV the report wrote: the collision cell of crossing SV
    table = pd.read_csv(reported / "tables" / "table1.csv")
    tables = parse(page)
    assert len(table) == len(tables.tables["table-one"]) == 4
    assert tables.tables["table-one"][0][4].startswith("0.3000 [")  # crossing SV: 3 of 10 collisions
    assert "0.2500" in [row[-1] for row in tables.tables["paired-tests"]]  # crossing collisions, p = 0.25
    figures = sorted((reported / "figures").glob("*.png"))
    assert figures and page.count("<figure>") == len(figures)
    # every diagnostic table of the text report is on the page, under a short heading
    for table_id in ("contacts", "agreement", "pet", "proximity", "first-detection", "witness", "staging"):
        assert tables.tables[table_id], table_id
        heading = re.search(rf'<h3 id="{table_id}-heading">([^<]*)</h3>', page).group(1)
        assert 0 < len(html.unescape(heading)) <= 40 and "\n" not in heading, heading


def test_every_case_is_listed_with_its_commands(reported):
    page = (reported / "report.html").read_text(encoding="utf-8")
    case_logs = sorted((reported / "cases").glob("*.parquet"))
    rows = parse(page).row_attributes["cases"]
    assert len(case_logs) == 7 and len(rows) == len(case_logs)
    listed = sorted(
        f"{r['data-scenario']}_{r['data-condition'].lower()}_{seed}.parquet"
        for r, seed in zip(rows, re.findall(r"<br>seed (\d+)</td>", page))
    )
    assert listed == [p.name for p in case_logs]
    assert page.count("--export-fcd") == 7 and page.count("--screenshot") == 7
    assert "Logged cases (7)" in page
    # collisions first: the crossing SV case of episode 1 and the jaywalking SV cases 0, 3 and 4 collide
    outcomes = [r["data-outcome"] for r in rows]
    assert outcomes == sorted(outcomes, key=["collision", "conflict", "none"].index)
    assert outcomes.count("collision") == 5  # crossing SV 1, jaywalking SV 0, 3, 4 and V2I 0


def test_verdict_is_first_and_its_rates_are_those_of_the_episodes(reported):
    page = (reported / "report.html").read_text(encoding="utf-8")
    tables = parse(page)
    assert tables.sections[0] == "verdict"
    assert page.index('<section id="verdict">') < page.index('id="table-one"')
    episodes = pd.read_parquet(reported / "episodes.parquet")
    rows = tables.tables["verdict-rates"]
    assert len(rows) == 4
    for scenario, condition, n_cell, collisions_cell, collision_cell, _, conflict_cell in rows:
        group = episodes[
            (episodes["scenario"] == scenario)
            & (episodes["condition"] == condition.lower())
            & (episodes["status"] == "ok")
        ]
        n = len(group)
        k = int(group["collision"].astype(bool).sum())
        conflicts = int((group["conflict"].astype(bool) & ~group["collision"].astype(bool)).sum())
        assert (int(n_cell), int(collisions_cell)) == (n, k)
        for cell, count in ((collision_cell, k), (conflict_cell, conflicts)):
            rate, low, high = cell_numbers(cell)
            assert rate == pytest.approx(count / n, abs=5e-5)
            assert (low, high) == pytest.approx(wilson(count, n), abs=5e-5)
    # the paired readings: crossing collisions 3 SV only, 0 V2I only, p = 2 / 2^3 = 0.25, no difference shown
    paired = {(r[0], r[1]): r for r in tables.tables["verdict-paired"]}
    crossing = paired[("crossing", "collision")]
    assert crossing[5] == "3 SV only, 0 V2I only" and crossing[6] == "0.2500"
    assert crossing[7].startswith("no difference shown")
    assert "a.b:Stack" in page.split('<section id="verdict">')[1].split("</section>")[0]


def test_configuration_table_and_folded_run_json(reported):
    page = (reported / "report.html").read_text(encoding="utf-8")
    config = dict((row[0], row[1]) for row in parse(page).tables["config"])
    assert PROTOCOL["name"] in config["protocol"] and config["run_seed"] == "100"
    folded = re.search(r"<details([^>]*)><summary>[^<]*</summary><pre>(.*?)</pre></details>", page, re.S)
    assert folded and "open" not in folded.group(1)
    assert json.loads(html.unescape(folded.group(2))) == json.loads((reported / "run.json").read_text())
    assert page.index('id="config"') < folded.start()


def test_no_template_syntax_is_left(reported):
    page = (reported / "report.html").read_text(encoding="utf-8")
    assert not re.search(r"\{\{|\}\}|\{%|%\}|\{#", page)


def test_names_from_the_run_are_escaped(tmp_path):
    episodes = standard_episodes()
    hostile = "<script>alert(1)</script>"
    episodes["scenario"] = episodes["scenario"].replace({"crossing": hostile})
    run = load_run(write_run(tmp_path / "run", episodes))
    out = write_html_report(
        run,
        table_one_of_run(run.episodes),
        paired_of_run(run.episodes),
        tmp_path / "none",
        tmp_path / "p.html",
    )
    page = out.read_text(encoding="utf-8")
    assert "<script>alert" not in page and "&lt;script&gt;alert(1)&lt;/script&gt;" in page
    assert hostile in [row[0] for row in parse(page).tables["verdict-rates"]]  # shown as text


def distinctive_rgb(png: Path) -> tuple[int, int, int]:
    """The most frequent saturated colour of an image (a line or bar colour of the figure)."""
    pixels = (matplotlib.image.imread(png)[..., :3] * 255).round().astype(int).reshape(-1, 3)
    saturation = pixels.max(axis=1) - pixels.min(axis=1)
    colours, counts = np.unique(pixels[saturation > 100], axis=0, return_counts=True)
    return tuple(int(v) for v in colours[np.argmax(counts)])


def has_colour(shot: np.ndarray, rgb: tuple[int, int, int], tolerance: int = 6, minimum: int = 30) -> bool:
    return int((np.abs(shot - np.array(rgb)).max(axis=-1) <= tolerance).sum()) >= minimum


def chromium(tmp_path: Path, *args: str) -> subprocess.CompletedProcess:
    proc = subprocess.run(
        [
            CHROMIUM,
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-quic",
            "--no-first-run",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            f"--user-data-dir={tmp_path / 'profile'}",
            "--hide-scrollbars",
            *args,
        ],
        capture_output=True,
        text=True,
        timeout=180,
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    # errors of the page itself (not Chromium's own D-Bus complaints on a machine without a session bus)
    page_errors = [line for line in proc.stderr.splitlines() if "CONSOLE" in line or "net::ERR" in line]
    assert not page_errors, page_errors
    return proc


needs_chromium = pytest.mark.skipif(
    CHROMIUM is None, reason="needs the Debian package chromium (installed by .ci/run)"
)


@pytest.mark.slow
@needs_chromium
def test_page_renders_in_headless_chromium(reported, tmp_path):
    shot_path = tmp_path / "page.png"
    chromium(
        tmp_path, "--window-size=1200,16000", f"--screenshot={shot_path}", (reported / "report.html").as_uri()
    )
    shot = (matplotlib.image.imread(shot_path)[..., :3] * 255).round().astype(int)
    assert (shot < 250).any(axis=-1).mean() > 0.05  # not blank
    assert has_colour(shot, TABLE_HEADER_RGB, tolerance=2, minimum=2000)  # the tables' headers
    assert has_colour(shot, EGO_PATH_RGB)  # the case pictures
    for figure in sorted((reported / "figures").glob("*.png")):
        assert has_colour(shot, distinctive_rgb(figure)), figure.name


#: Added to a copy of the page: measures the figures against the viewport, then picks the outcome
#: "collision" in the case filter, and writes what it found into the DOM as JSON.
MEASURE = """<script>
window.addEventListener("load", function () {
  var viewport = document.documentElement.clientWidth;
  var figures = Array.prototype.map.call(document.querySelectorAll("#figures img"), function (img) {
    var box = img.getBoundingClientRect();
    return {name: img.alt, left: box.left, right: box.right, width: box.width, natural: img.naturalWidth};
  });
  var pick = document.querySelector('#case-filters select[name="outcome"]');
  pick.value = "collision";
  pick.dispatchEvent(new Event("change"));
  var visible = Array.prototype.filter.call(document.querySelectorAll("#cases tbody tr"), function (row) {
    return !row.hidden && row.getBoundingClientRect().height > 0;
  });
  var out = document.createElement("pre");
  out.id = "measured";
  out.textContent = JSON.stringify({
    viewport: viewport,
    page: document.documentElement.scrollWidth,
    figures: figures,
    collisions_shown: visible.length,
    outcomes_shown: visible.map(function (row) { return row.dataset.outcome; }),
    counter: document.getElementById("cases-shown").textContent
  });
  document.body.appendChild(out);
});
</script>"""


@pytest.mark.slow
@needs_chromium
def test_figures_fit_a_1000_px_window_and_the_case_filter_works(reported, tmp_path):
    page = (reported / "report.html").read_text(encoding="utf-8")
    probe = reported / "probe.html"
    probe.write_text(page.replace("</body>", MEASURE + "</body>"), encoding="utf-8")
    try:
        proc = chromium(
            tmp_path, "--window-size=1000,800", "--virtual-time-budget=10000", "--dump-dom", probe.as_uri()
        )
    finally:
        probe.unlink()
    measured = json.loads(
        html.unescape(re.search(r'<pre id="measured">(.*?)</pre>', proc.stdout, re.S).group(1))
    )
    assert 900 <= measured["viewport"] <= 1000
    figures = sorted((reported / "figures").glob("*.png"))
    assert len(measured["figures"]) == len(figures)
    for figure in measured["figures"]:
        assert figure["width"] > 0.5 * measured["viewport"], figure  # shown large, not a thumbnail
        assert figure["left"] >= 0 and figure["right"] <= measured["viewport"], figure
    # the first-detection figure has several panels: shown no wider than the window, it is scaled down
    # by at most a factor 2, so its 10 pt legend (21 px in the PNG) stays at 10 px or more
    detection = next(f for f in measured["figures"] if f["name"] == "first_detection_distance.png")
    assert detection["width"] / detection["natural"] >= 0.5
    # the filter: outcome "collision" leaves the collision rows only, and the counter says how many
    episodes = pd.read_parquet(reported / "episodes.parquet")
    collided_cases = sum(
        bool(r.collision) and (reported / "cases" / f"{r.scenario}_{r.condition}_{r.seed}.parquet").is_file()
        for r in episodes.itertuples()
    )
    assert measured["collisions_shown"] == collided_cases == 5
    assert set(measured["outcomes_shown"]) == {"collision"} and measured["counter"] == "5"
