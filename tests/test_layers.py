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
