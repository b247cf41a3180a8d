"""A class's name says which (issue #35, item 6): no class name is defined at the top of two modules of ``ckesc/`` and
``conformance/``, so a reader (and an import) never has to ask which ``Heard`` or ``Stream`` is meant. The source is
read with ``ast``, as tests/test_outcome_forms.py reads it.

:data:`KNOWN` names the shared names still pending with the owners of ``ckesc/soak/`` and ``ckesc/explore/``; each
entry goes when its class is renamed (the second test fails on an entry whose class is gone, so the list cannot rot).
"""

from __future__ import annotations

import ast
from collections import defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PENDING_OWNERS = ("ckesc/soak/", "ckesc/explore/")
#: class name -> the modules that may define it while a soak/explore class of that name waits for its owner to rename
#: it; remove the entry when that class is renamed
KNOWN: dict[str, tuple[str, ...]] = {
    # the explorer's bench facts share a name with ckesc/rigs/rig.py's Bench (a rig file's bench, which
    # ckesc/soak/batch.py names too), so the explorer's owner renames theirs
    "Bench": ("ckesc/rigs/rig.py", "ckesc/explore/actions.py"),
}


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
    unexcused = {name: mods for name, mods in shared.items() if not set(mods) <= set(KNOWN.get(name, ()))}
    assert not unexcused, f"class names defined in more than one module (give each a name that says which): {unexcused}"


def test_known_lists_only_soak_and_explore_classes_still_there():
    where = _classes()
    pending = {(name, m) for name, mods in KNOWN.items() for m in mods if m.startswith(PENDING_OWNERS)}
    assert {name for name, _ in pending} == set(KNOWN), "every KNOWN entry waits on a class of soak/ or explore/"
    gone = {(name, m) for name, m in pending if m not in where.get(name, [])}
    assert not gone, f"renamed: remove these from KNOWN: {sorted(gone)}"
