"""The library packages import only what docs/architecture.md allows."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
ALLOWED = {
    "rig": {"rig"},
    "capture": {"capture", "rig"},
    "processing": {"processing", "rig", "capture"},
    "render": {"render", "processing", "rig"},
    "sim": {"sim", "rig"},
}
#: The command line and the demo may import every package (``rig/cli*.py``, ``rig/demo*.py``).
APPLICATION_LAYER = {
    p.relative_to(ROOT).as_posix()
    for pattern in ("cli*.py", "demo*.py")
    for p in (ROOT / "rig").glob(pattern)
}


def _project_imports(path: Path) -> set[str]:
    names: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            names.update(alias.name.split(".")[0] for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module.split(".")[0])
    return names & set(ALLOWED)


@pytest.mark.parametrize("package", sorted(ALLOWED))
def test_package_boundaries(package: str) -> None:
    for path in sorted((ROOT / package).rglob("*.py")):
        if path.relative_to(ROOT).as_posix() in APPLICATION_LAYER:
            continue
        extra = _project_imports(path) - ALLOWED[package]
        assert not extra, f"{path.relative_to(ROOT)} imports {sorted(extra)}"
