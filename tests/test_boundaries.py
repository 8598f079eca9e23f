"""Every package imports only the floors below it, as ``docs/architecture.md`` draws them.

The table is the one in ``docs/architecture.md`` (the test reads it from there, so the document
and the check cannot drift apart), and there are no exemptions by file name.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
ARCHITECTURE = ROOT / "docs" / "architecture.md"


def _allowed() -> dict[str, set[str]]:
    """The ``| `package/` | owns | may import |`` rows of the architecture table."""
    table: dict[str, set[str]] = {}
    row = re.compile(r"^\| `(\w+)/` \|[^|]*\| ([^|]*) \|$")
    for line in ARCHITECTURE.read_text(encoding="utf-8").splitlines():
        match = row.match(line.strip())
        if match:
            names = set(re.findall(r"`(\w+)`", match.group(2)))
            table[match.group(1)] = names | {match.group(1)}
    return {package: names & set(table) for package, names in table.items()}


ALLOWED = _allowed()


def _project_imports(path: Path) -> set[str]:
    names: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            names.update(alias.name.split(".")[0] for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module.split(".")[0])
    return names & set(ALLOWED)


def test_the_table_names_every_package() -> None:
    packages = {p.parent.name for p in ROOT.glob("*/__init__.py")} - {"tests"}
    assert packages == set(ALLOWED), "docs/architecture.md and the packages disagree"


@pytest.mark.parametrize("package", sorted(ALLOWED))
def test_package_boundaries(package: str) -> None:
    for path in sorted((ROOT / package).rglob("*.py")):
        extra = _project_imports(path) - ALLOWED[package]
        assert not extra, f"{path.relative_to(ROOT)} imports {sorted(extra)}"


def test_no_cycle_between_packages() -> None:
    def reach(start: str) -> set[str]:
        seen: set[str] = set()
        todo = [start]
        while todo:
            for name in ALLOWED[todo.pop()] - {start} - seen:
                seen.add(name)
                todo.append(name)
        return seen

    for package in ALLOWED:
        below = ALLOWED[package] - {package}
        assert all(package not in reach(b) for b in below), f"{package} is in a cycle"


def _module_graph() -> dict[str, set[str]]:
    """Each project module's imports of other project modules (``from a import b`` counts as
    ``a.b`` when that is a module, else ``a``); type-checking imports included."""
    modules = {
        ".".join(p.relative_to(ROOT).with_suffix("").parts).removesuffix(".__init__"): p
        for package in ALLOWED
        for p in (ROOT / package).rglob("*.py")
    }
    graph: dict[str, set[str]] = {}
    for name, path in modules.items():
        targets: set[str] = set()
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Import):
                targets.update(a.name for a in node.names if a.name in modules)
            elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                for alias in node.names:
                    full = f"{node.module}.{alias.name}"
                    if full in modules:
                        targets.add(full)
                    elif node.module in modules:
                        targets.add(node.module)
        graph[name] = targets - {name}
    return graph


def test_no_cycle_between_modules() -> None:
    graph = _module_graph()
    state: dict[str, int] = {}  # 1: on the current path, 2: done

    def visit(name: str, path: list[str]) -> None:
        state[name] = 1
        for target in sorted(graph[name]):
            if state.get(target) == 1:
                cycle = [*path[path.index(target) :], target]
                raise AssertionError(f"import cycle: {' -> '.join(cycle)}")
            if target not in state:
                visit(target, [*path, target])
        state[name] = 2

    for name in sorted(graph):
        if name not in state:
            visit(name, [name])
