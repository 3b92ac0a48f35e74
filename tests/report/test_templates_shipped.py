"""The page's templates are package data: every file of pedsafe_sumo/report/templates/ matches a pattern of
pyproject.toml's [tool.setuptools.package-data], so a wheel carries it (a wheel without them cannot render
the page)."""

from __future__ import annotations

import fnmatch
import sys

from pedsafe_sumo import REPO_ROOT

if sys.version_info >= (3, 11):
    import tomllib
else:  # Python 3.10: the backport of the same parser
    import tomli as tomllib


def test_every_template_is_package_data():
    config = tomllib.loads((REPO_ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    patterns = config["tool"]["setuptools"]["package-data"]["pedsafe_sumo"]
    package = REPO_ROOT / "pedsafe_sumo"
    templates = sorted((package / "report" / "templates").iterdir())
    assert {t.name for t in templates} >= {"report.html.j2", "style.css", "filter.js"}
    for template in templates:
        relative = template.relative_to(package).as_posix()
        assert any(fnmatch.fnmatch(relative, pattern) for pattern in patterns), relative
    dependencies = [d.split(">")[0].split("=")[0].strip().lower() for d in config["project"]["dependencies"]]
    assert "jinja2" in dependencies
