"""The validation page keeps one measured block per site: validating a site replaces its own block and
never another's (before, any site run without --docs replaced Xueqing's numbers)."""

from __future__ import annotations

from pedsafe_sumo.demand.validation_page import measured_markers, write_report


def _block(site: str, body: str) -> str:
    begin, end = measured_markers(site)
    return f"{begin}\n{body}\n{end}"


def test_a_new_site_gets_its_own_block_and_the_others_stay(tmp_path):
    page = tmp_path / "demand_validation.md"
    xueqing = _block("xueqing", "xueqing numbers")
    page.write_text(f"# Demand validation\n\nexplanation\n\n{xueqing}\n\nmore\n")
    write_report(page, _block("dual", "dual numbers, first"), "dual")
    text = page.read_text()
    assert "xueqing numbers" in text and "dual numbers, first" in text
    assert text.index("more") < text.index("## Measured: dual")
    write_report(page, _block("dual", "dual numbers, second"), "dual")
    text = page.read_text()
    assert "dual numbers, first" not in text and text.count("dual numbers, second") == 1
    assert "xueqing numbers" in text and text.count("## Measured: dual") == 1
    write_report(page, _block("xueqing", "xueqing again"), "xueqing")
    text = page.read_text()
    assert "xueqing numbers" not in text and "xueqing again" in text and "dual numbers, second" in text
    assert text.startswith("# Demand validation\n\nexplanation\n\n")


def test_the_shipped_page_holds_xueqing_block():
    from pedsafe_sumo import REPO_ROOT

    begin, end = measured_markers("xueqing")
    text = (REPO_ROOT / "docs" / "demand_validation.md").read_text(encoding="utf-8")
    assert text.count(begin) == 1 and text.count(end) == 1
