"""The house rules of the package, checked on its source (docs/architecture.md):

- imports run one way: no import cycle between the package's sub-packages, counting imports inside functions;
- an import inside a function says why, in a comment on its line or in the three lines above;
- no module over 600 lines;
- the package never imports the research folder or the tools;
- nothing outside research/ names a numbered step of the project's development or an issue number, and
  nothing reads or cites a path outside the repository.
"""

from __future__ import annotations

import ast
import re
import subprocess
from collections import defaultdict
from pathlib import Path

import pytest

REPOSITORY = Path(__file__).resolve().parents[1]
PACKAGE = REPOSITORY / "pedsafe_sumo"
MAX_MODULE_LINES = 600


def _modules() -> list[Path]:
    return sorted(PACKAGE.rglob("*.py"))


def _sub_package(module: Path) -> str:
    """The first level below pedsafe_sumo: a sub-package (`sim`) or a top-level module (`sweep`)."""
    first = module.relative_to(PACKAGE).parts[0]
    return first.removesuffix(".py")


def _imported_modules(node: ast.AST) -> list[str]:
    if isinstance(node, ast.Import):
        return [alias.name for alias in node.names]
    if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
        return [node.module]
    return []


def package_import_graph(modules: list[Path]) -> dict[str, set[str]]:
    """Sub-package -> the sub-packages it imports (anywhere in its modules, inside functions too)."""
    graph: dict[str, set[str]] = defaultdict(set)
    for module in modules:
        source = _sub_package(module)
        for node in ast.walk(ast.parse(module.read_text(encoding="utf-8"))):
            for name in _imported_modules(node):
                parts = name.split(".")
                if parts[0] == "pedsafe_sumo" and len(parts) > 1 and parts[1] != source:
                    graph[source].add(parts[1])
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Every strongly connected component of more than one node (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []
    counter = [0]

    def visit(node: str) -> None:
        index[node] = low[node] = counter[0]
        counter[0] += 1
        stack.append(node)
        on_stack.add(node)
        for target in sorted(graph.get(node, ())):
            if target not in index:
                visit(target)
                low[node] = min(low[node], low[target])
            elif target in on_stack:
                low[node] = min(low[node], index[target])
        if low[node] == index[node]:
            component = []
            while True:
                member = stack.pop()
                on_stack.discard(member)
                component.append(member)
                if member == node:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for node in sorted(set(graph) | {t for targets in graph.values() for t in targets}):
        if node not in index:
            visit(node)
    return found


def test_cycle_finder_finds_a_cycle_and_only_cycles() -> None:
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert cycles({"a": {"b"}, "b": {"c"}}) == []


def test_no_import_cycle_between_sub_packages() -> None:
    found = cycles(package_import_graph(_modules()))
    assert found == [], f"sub-packages that import each other: {found}"


def _imports_inside_functions(tree: ast.AST) -> list[ast.Import | ast.ImportFrom]:
    """The import statements in a function's body (a module-level `try` or `if` is not a function)."""
    found: list[ast.Import | ast.ImportFrom] = []
    for function in ast.walk(tree):
        if isinstance(function, (ast.FunctionDef, ast.AsyncFunctionDef)):
            for node in ast.walk(function):
                if isinstance(node, (ast.Import, ast.ImportFrom)) and node not in found:
                    found.append(node)
    return found


def _unexplained_inner_imports(module: Path) -> list[str]:
    lines = module.read_text(encoding="utf-8").splitlines()
    out = []
    for node in _imports_inside_functions(ast.parse("\n".join(lines))):
        here, above = lines[node.lineno - 1], lines[max(0, node.lineno - 4) : node.lineno - 1]
        if "#" in here or any("#" in line for line in above):  # the reason, on its line or just above
            continue
        out.append(f"{module.relative_to(REPOSITORY)}:{node.lineno}: {here.strip()}")
    return out


def test_inner_import_finder_sees_functions_only() -> None:
    tree = ast.parse("try:\n    import a\nexcept ImportError:\n    a = None\ndef f():\n    import b\n")
    assert [alias.name for node in _imports_inside_functions(tree) for alias in node.names] == ["b"]


def test_imports_inside_functions_say_why() -> None:
    unexplained = [line for module in _modules() for line in _unexplained_inner_imports(module)]
    message = "imports inside functions without a comment saying why:\n" + "\n".join(unexplained)
    assert unexplained == [], message


def test_no_module_over_the_size_limit() -> None:
    sizes = {m: len(m.read_text(encoding="utf-8").splitlines()) for m in _modules()}
    large = {str(m.relative_to(REPOSITORY)): n for m, n in sizes.items() if n > MAX_MODULE_LINES}
    assert large == {}, f"modules over {MAX_MODULE_LINES} lines: {large}"


def test_package_never_imports_research_or_tools() -> None:
    offenders = []
    for module in _modules():
        for node in ast.walk(ast.parse(module.read_text(encoding="utf-8"))):
            if any(name.split(".")[0] in {"research", "tools"} for name in _imported_modules(node)):
                offenders.append(str(module.relative_to(REPOSITORY)))
    assert offenders == []


def _tracked_files() -> list[Path]:
    try:
        listed = subprocess.run(
            ["git", "ls-files"], cwd=REPOSITORY, capture_output=True, text=True, check=True
        ).stdout.splitlines()
    except (OSError, subprocess.CalledProcessError):
        pytest.skip("not a git checkout: the tracked files are unknown")
    return [REPOSITORY / name for name in listed]


HISTORY = re.compile(r"\bsessions? [0-9]+|\bissues? #?[0-9]+\b", re.IGNORECASE)
OUTSIDE_PATHS = re.compile(r"\.\./shared|/work/|/home/[a-z]|shared/DESIGN|DESIGN\.md")


@pytest.mark.parametrize(
    ("pattern", "what"), [(HISTORY, "development history"), (OUTSIDE_PATHS, "paths outside the repository")]
)
def test_the_product_speaks_of_itself(pattern: re.Pattern[str], what: str) -> None:
    hits = []
    for path in _tracked_files():
        relative = path.relative_to(REPOSITORY)
        if relative.parts[0] == "research" or relative == Path(__file__).relative_to(REPOSITORY):
            continue
        try:
            text = path.read_text(encoding="utf-8")
        except (UnicodeDecodeError, FileNotFoundError, IsADirectoryError):
            continue
        for number, line in enumerate(text.splitlines(), start=1):
            if pattern.search(line):
                hits.append(f"{relative}:{number}: {line.strip()[:100]}")
    assert hits == [], f"{len(hits)} lines name {what}:\n" + "\n".join(hits[:40])
