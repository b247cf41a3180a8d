"""A class's name says which (issue #35, item 6): no class name is defined at the top of two modules of ``ckesc/`` and
``conformance/``, so a reader (and an import) never has to ask which ``Heard`` or ``Stream`` is meant. The source is
read with ``ast``, as tests/test_outcome_forms.py reads it."""

from __future__ import annotations

import ast
from collections import defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _classes() -> dict[str, list[str]]:
    where: dict[str, list[str]] = defaultdict(list)
    for base in ("ckesc", "conformance"):
        for p in sorted((ROOT / base).rglob("*.py")):
            tree = ast.parse(p.read_text(encoding="utf-8"), str(p))
            for node in tree.body:
                if isinstance(node, ast.ClassDef):
                    where[node.name].append(p.relative_to(ROOT).as_posix())
    return where


def test_no_class_name_is_defined_in_two_modules():
    shared = {name: mods for name, mods in _classes().items() if len(mods) > 1}
    assert not shared, f"class names defined in more than one module (give each a name that says which): {shared}"
