"""The layers contract (pyproject.toml ``[tool.importlinter]``, docs/architecture.md): imports point down
only, from the command line to the sans-IO protocol, and no conformance test module imports another.
Checked with import-linter, whose report names each offending import and its line."""

from __future__ import annotations

import subprocess
import sys
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_imports_point_down_only():
    done = subprocess.run([sys.executable, "-c", "import sys; from importlinter.cli import lint_imports_command; "
                           "sys.argv = ['lint-imports', '--no-cache']; lint_imports_command()"],
                          cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, f"an import breaks the layers (pyproject.toml [tool.importlinter]):\n{done.stdout}{done.stderr}"
    assert "0 broken" in done.stdout, done.stdout


def test_every_conformance_module_is_in_the_independence_contract():
    contracts = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["importlinter"]["contracts"]
    listed = {m for c in contracts if c["type"] == "independence" for m in c["modules"]}
    modules = {f"conformance.{p.stem}" for p in (ROOT / "conformance").glob("test_*.py")}
    assert modules - listed == set(), "add these to the independence contract in pyproject.toml"
    assert listed - modules == set(), "these are listed but do not exist"


# ----------------------------------------------------------------------------------------- private names
#: Private names one module still takes from another, each (importer, "module.name"): none (the HTML kit and
#: compare's tables became public in issue #19). Nothing may be added to it.
PRIVATE_IMPORTS_LEFT: set[tuple[str, str]] = set()
PROJECT = ("ckesc", "conformance")


def _module_of(path: Path) -> tuple[str, str]:
    """(the module's dotted name, the package its relative imports start from)."""
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        return ".".join(parts[:-1]), ".".join(parts[:-1])
    return ".".join(parts), ".".join(parts[:-1])


def _private_uses(path: Path) -> list[tuple[int, str]]:
    """(line, "module.name") of each private name of another project module that ``path`` imports or reaches:
    ``from X import _name`` and ``X._name`` (X a project module, or a name imported from one)."""
    import ast

    me, package = _module_of(path)
    tree = ast.parse(path.read_text(encoding="utf-8"))
    bound: dict[str, str] = {}  # a local name -> the project module or name it is
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            base = package.split(".")[: len(package.split(".")) - (node.level - 1)] if node.level else []
            source = ".".join([*base, *([node.module] if node.module else [])])
            if source.split(".")[0] not in PROJECT:
                continue
            for alias in node.names:
                if alias.name.startswith("_") and not alias.name.startswith("__") and source != me:
                    found.append((node.lineno, f"{source}.{alias.name}"))
                bound[alias.asname or alias.name] = f"{source}.{alias.name}"
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.split(".")[0] in PROJECT:
                    local = alias.asname or alias.name.split(".")[0]  # ``import a.b`` binds ``a``
                    bound[local] = alias.name if alias.asname else local
    for node in ast.walk(tree):
        if (isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id in bound
                and node.attr.startswith("_") and not node.attr.startswith("__")):
            found.append((node.lineno, f"{bound[node.value.id]}.{node.attr}"))
    return found


def test_no_module_takes_another_modules_private_names():
    """A name starting with ``_`` is its module's own: no module of ckesc/ or conformance/ imports or reaches one of
    another's (make it public where it is shared), except the list above, which only shrinks."""
    uses = {(_module_of(p)[0], name, line) for base in PROJECT for p in sorted((ROOT / base).rglob("*.py"))
            for line, name in _private_uses(p)}
    unexpected = sorted(f"{m} line {line}: {name}" for m, name, line in uses if (m, name) not in PRIVATE_IMPORTS_LEFT)
    assert unexpected == [], "make these names public where they are defined:\n" + "\n".join(unexpected)
    gone = PRIVATE_IMPORTS_LEFT - {(m, name) for m, name, _ in uses}
    assert gone == set(), f"no longer imported: take them off PRIVATE_IMPORTS_LEFT: {sorted(gone)}"


def test_the_private_names_check_sees_both_forms(tmp_path, monkeypatch):
    """The check above finds ``from X import _name`` (relative too) and ``X._name``, and leaves a module's own alone."""
    pkg = tmp_path / "ckesc" / "demo"
    pkg.mkdir(parents=True)
    (pkg / "a.py").write_text("_own = 1\nprint(_own)\n")
    (pkg / "b.py").write_text("from .a import _own\nfrom ckesc.demo import a\nimport ckesc.demo.a as aa\n"
                              "print(a._own, aa._other, a.public)\n")
    monkeypatch.setattr(sys.modules[__name__], "ROOT", tmp_path)
    assert _private_uses(pkg / "a.py") == []
    assert sorted(_private_uses(pkg / "b.py")) == [(1, "ckesc.demo.a._own"), (4, "ckesc.demo.a._other"),
                                                  (4, "ckesc.demo.a._own")]


# ----------------------------------------------------------------------------------------- import circles
def _circles(graph) -> list[str]:
    """Each import circle of ``graph`` (a grimp graph) once, as ``a -> b -> a``: a module that imports another from
    which a chain of imports leads back to it. Every import counts, at the top of a module, inside a function and
    under ``TYPE_CHECKING`` alike: a circle hidden in a function is still two modules that cannot be read apart."""
    found: dict[frozenset[str], str] = {}
    for module in sorted(graph.modules):
        for imported in sorted(graph.find_modules_directly_imported_by(module)):
            if imported != module and graph.chain_exists(importer=imported, imported=module):
                chain = graph.find_shortest_chain(importer=imported, imported=module)
                found.setdefault(frozenset(chain), " -> ".join((module, *chain)))
    return sorted(found.values())


def test_no_import_circle_inside_ckesc():
    """No two modules of ckesc import each other, directly or through others (issue #35): what both need lives in a
    module below both. The layers contract cannot see a circle inside one layer; this does."""
    import grimp

    circles = _circles(grimp.build_graph("ckesc"))
    assert circles == [], "move what both modules need below both:\n" + "\n".join(circles)


def test_the_circle_check_sees_a_circle():
    """The check above finds a circle of two and of three modules (one per circle), and passes a chain."""
    import grimp

    graph = grimp.ImportGraph()
    for importer, imported in (("p.a", "p.b"), ("p.b", "p.a"), ("p.c", "p.d"), ("p.d", "p.e"), ("p.e", "p.c"),
                               ("p.f", "p.a"), ("p.f", "p.g")):
        graph.add_import(importer=importer, imported=imported)
    assert _circles(graph) == ["p.a -> p.b -> p.a", "p.c -> p.d -> p.e -> p.c"]
