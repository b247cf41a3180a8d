"""The conformance package's own layout (issue #15): a test module holds one section's tests and is
nobody's library. What several modules share lives in the package's non-test modules
(``conformance/telemetry.py``, ``throttle.py``, ...), so no module there imports a ``test_*`` module.
Read with ``ast`` from the source, without importing the modules."""

from __future__ import annotations

import ast
from pathlib import Path

import conformance

PACKAGE = "conformance"
ROOT = Path(conformance.__file__).parent
WHY = "a test module is no library: move what is shared to a non-test module of conformance/ (conformance/README.md)"


def imported(node: ast.stmt, package: str = PACKAGE) -> list[str]:
    """The dotted names an import statement may bring in, relative imports resolved against
    ``package``: ``from X import name`` gives X and X.name (``name`` may be a module)."""
    if isinstance(node, ast.Import):
        return [a.name for a in node.names]
    if isinstance(node, ast.ImportFrom) and node.level <= 1:  # level 2+: above the package, none of its modules
        base = node.module or "" if node.level == 0 else ".".join(filter(None, (package, node.module)))
        return [base] + [f"{base}.{a.name}" for a in node.names]
    return []


def test_module_imports(root: Path, package: str = PACKAGE) -> list[str]:
    """``file:line: imports test_x - why`` for every import of a test module by a module of the package."""
    test_modules = sorted(f"{package}.{p.stem}" for p in root.glob("test_*.py"))
    problems = []
    for path in sorted(root.glob("*.py")):
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        for node in ast.walk(tree):
            names = imported(node, package)
            for m in test_modules:
                if any(n == m or n.startswith(m + ".") for n in names):
                    problems.append(f"{path.name}:{node.lineno}: imports {m.removeprefix(package + '.')} - {WHY}")
    return sorted(problems, key=lambda p: (p.split(":")[0], int(p.split(":")[1])))


test_module_imports.__test__ = False  # the check itself, not a test


def test_no_conformance_module_imports_a_test_module():
    problems = test_module_imports(ROOT)
    assert not problems, "\n".join(problems)


def test_the_check_names_file_and_line(tmp_path):
    (tmp_path / "test_s9_1_a.py").write_text("X = 1\n")
    (tmp_path / "test_s9_2_b.py").write_text('"""b"""\nimport pytest\n\nfrom .test_s9_1_a import X\n')
    (tmp_path / "helper.py").write_text("from .other import thing\nfrom . import test_s9_1_a\n")
    (tmp_path / "test_s9_3_c.py").write_text("from conformance.helper import y\n\n\ndef f():\n    import conformance.test_s9_2_b as b\n")
    (tmp_path / "test_s9_4_d.py").write_text("from ..test_s9_1_a import X\nfrom .test_s9_1_ab import Y\n")  # neither
    assert test_module_imports(tmp_path) == [
        f"helper.py:2: imports test_s9_1_a - {WHY}",
        f"test_s9_2_b.py:4: imports test_s9_1_a - {WHY}",
        f"test_s9_3_c.py:5: imports test_s9_2_b - {WHY}",
    ]
