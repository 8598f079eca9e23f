"""The house's layout rules (issue 27), checked over the packages' modules.

- a module over 500 lines says why in the first line of its docstring ("Over 500 lines
  because ...");
- no folder holds five or more modules whose names share a first word (``field_*`` x 6
  became ``core/store/``): a family becomes a sub-package.
"""

from __future__ import annotations

import ast
from collections import Counter
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("core", "rig", "capture", "processing", "render", "sim", "app", "bench")
MAX_LINES = 500
FAMILY = 5


def _modules() -> list[Path]:
    return sorted(p for package in PACKAGES for p in (ROOT / package).rglob("*.py"))


def test_a_long_module_says_why() -> None:
    unexplained = []
    for path in _modules():
        text = path.read_text(encoding="utf-8")
        docstring = ast.get_docstring(ast.parse(text)) or ""
        if text.count("\n") > MAX_LINES and not docstring.startswith("Over 500 lines because"):
            unexplained.append(f"{path.relative_to(ROOT)} ({text.count(chr(10))} lines)")
    assert not unexplained, (
        f"split these along a seam, or say why in the docstring's first line: {unexplained}"
    )


def test_no_folder_holds_a_family_of_modules_by_name() -> None:
    folders = {p.parent for p in _modules()}
    crowded = []
    for folder in sorted(folders):
        words = Counter(p.stem.split("_")[0] for p in folder.glob("*.py") if p.stem != "__init__")
        crowded += [f"{folder.relative_to(ROOT)}/{w}_*: {n}" for w, n in words.items()
                    if n >= FAMILY]  # fmt: skip
    assert not crowded, f"make these families sub-packages: {crowded}"
