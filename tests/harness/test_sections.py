"""The tables of the TOML files a user writes (a DUT profile, a rig file) share one pydantic base,
:class:`ckesc.bench.sections.Section` (issue #35): strict and closed, declared once. Read from the models themselves."""

from __future__ import annotations

import ast
import importlib
from pathlib import Path

from pydantic import BaseModel

import ckesc
from ckesc.bench.sections import Section

ROOT = Path(ckesc.__file__).parent


def _models() -> list[type[BaseModel]]:
    """Every pydantic model of ckesc: each module that uses pydantic imported, then BaseModel's subclasses."""
    for path in sorted(ROOT.rglob("*.py")):
        if "pydantic" in path.read_text(encoding="utf-8") and path.name != "__main__.py":
            importlib.import_module(".".join(("ckesc", *path.relative_to(ROOT).with_suffix("").parts)))
    seen: list[type[BaseModel]] = []
    todo = [BaseModel]
    while todo:
        for sub in todo.pop().__subclasses__():
            if sub not in seen:
                seen.append(sub)
                todo.append(sub)
    return [m for m in seen if m.__module__.startswith("ckesc.")]


def _strict_closed_bases() -> list[str]:
    """Where a class body of ckesc writes ``model_config = ConfigDict(extra="forbid", strict=True)`` (read with
    ``ast``: pydantic gives every subclass the merged config, so the classes cannot tell who declared it)."""
    found = []
    for path in sorted(ROOT.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if not isinstance(node, ast.ClassDef):
                continue
            for stmt in node.body:
                if (isinstance(stmt, ast.Assign) and [getattr(t, "id", None) for t in stmt.targets] == ["model_config"]
                        and isinstance(stmt.value, ast.Call)
                        and {k.arg: getattr(k.value, "value", None) for k in stmt.value.keywords}
                        == {"extra": "forbid", "strict": True}):
                    found.append(f"{path.relative_to(ROOT.parent).as_posix()}:{node.name}")
    return found


def test_one_base_declares_the_strict_closed_table():
    """Only :class:`Section` declares ``extra="forbid", strict=True``: a second base written beside it (as the
    profile and the rig file each had one) fails here; a table that loosens it (``[timing]``: not strict) is its own."""
    assert _strict_closed_bases() == ["ckesc/bench/sections.py:Section"]


def test_the_profile_and_the_rig_file_read_their_tables_with_it():
    by_module: dict[str, int] = {}
    for m in _models():
        if issubclass(m, Section) and m is not Section:
            by_module[m.__module__] = by_module.get(m.__module__, 0) + 1
    assert set(by_module) == {"ckesc.bench.profile", "ckesc.rigs.rig"}, by_module
