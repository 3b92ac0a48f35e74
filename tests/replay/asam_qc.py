"""ASAM's quality checkers (asam-qc-openscenarioxml, asam-qc-opendrive from PyPI), run as their own CLIs
from their own virtualenv (.venv-qc: they need numpy<2, the project pins numpy 2). `make test` builds
it; a test run without it builds it here the same way (`make .venv-qc/.installed`), never skips."""

from __future__ import annotations

import fcntl
import hashlib
import subprocess
import tempfile
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

from pedsafe_sumo import REPO_ROOT

QC_VENV = REPO_ROOT / ".venv-qc"
#: Held while .venv-qc is checked or built: test workers that ask for it at once build it once.
QC_VENV_LOCK = (
    Path(tempfile.gettempdir()) / f"pedsafe-qc-venv-{hashlib.sha256(bytes(QC_VENV)).hexdigest()[:12]}.lock"
)
BUNDLES = {"xosc": ("xoscBundle", "qc_openscenario"), "xodr": ("xodrBundle", "qc_opendrive")}


@dataclass(frozen=True)
class CheckerResult:
    checker_id: str
    status: str
    summary: str
    issues: tuple[str, ...]


def qc_venv() -> Path:
    with QC_VENV_LOCK.open("w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not (QC_VENV / ".installed").is_file():
            proc = subprocess.run(
                ["make", "-s", ".venv-qc/.installed"],
                cwd=REPO_ROOT,
                capture_output=True,
                text=True,
                timeout=600,
            )
            assert proc.returncode == 0, f"could not build .venv-qc: {proc.stderr[-2000:]}"
    return QC_VENV


def run_checker(kind: str, input_file: Path, workdir: Path) -> list[CheckerResult]:
    """Every checker of the bundle for `kind` ('xosc' or 'xodr') on `input_file`, from its result file."""
    bundle, command = BUNDLES[kind]
    result_file = workdir / f"{input_file.name}.xqar"
    config = workdir / f"{input_file.name}.qc-config.xml"
    config.write_text(
        '<?xml version="1.0" encoding="UTF-8"?>\n<Config>\n'
        f'    <Param name="InputFile" value="{input_file}"/>\n'
        f'    <CheckerBundle application="{bundle}">\n'
        f'        <Param name="resultFile" value="{result_file}"/>\n'
        "    </CheckerBundle>\n</Config>\n",
        encoding="utf-8",
    )
    proc = subprocess.run(
        [str(qc_venv() / "bin" / command), "-c", str(config)],
        cwd=workdir,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    results = []
    for checker in ET.parse(result_file).getroot().iter("Checker"):
        issues = tuple(
            " / ".join(loc.get("description", "") for loc in issue.iter("Locations"))
            or issue.get("description")
            for issue in checker.iter("Issue")
        )
        results.append(
            CheckerResult(checker.get("checkerId"), checker.get("status"), checker.get("summary", ""), issues)
        )
    assert results, f"no checker ran on {input_file}"
    return results
