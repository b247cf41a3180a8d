"""The protocol core is sans-IO: it never imports ``can``, ``time``, ``threading`` or ``socket``
(ckesc/protocol/__init__.py). Checked twice: statically (every import statement of the package) and at
run time (what ``import ckesc.protocol`` pulls in, in a fresh interpreter)."""

from __future__ import annotations

import ast
import json
import subprocess
import sys
from pathlib import Path

import ckesc.protocol

FORBIDDEN = ("can", "time", "threading", "socket", "asyncio", "select", "selectors", "serial")
PACKAGE_DIR = Path(ckesc.protocol.__file__).parent


def _top(name: str) -> str:
    return name.split(".")[0]


def test_no_forbidden_import_statements():
    offenders = []
    files = sorted(PACKAGE_DIR.rglob("*.py"))
    assert len(files) >= 8
    for path in files:
        tree = ast.parse(path.read_text(), filename=str(path))
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names = [node.module]
            elif isinstance(node, ast.Call) and getattr(node.func, "id", getattr(node.func, "attr", None)) in (
                "__import__",
                "import_module",
            ):
                names = [a.value for a in node.args[:1] if isinstance(a, ast.Constant) and isinstance(a.value, str)]
            else:
                continue
            offenders += [f"{path.name}:{node.lineno}: {n}" for n in names if _top(n) in FORBIDDEN]
    assert not offenders, "ckesc.protocol must stay sans-IO: " + ", ".join(offenders)


def test_importing_the_package_loads_no_io_module():
    # `time` is loaded by the interpreter's own start-up, so drop the forbidden modules from sys.modules first
    # and see whether importing ckesc.protocol brings any of them back
    code = f"""
import json, sys
forbidden = {FORBIDDEN!r}
for name in list(sys.modules):
    if name.split(".")[0] in forbidden:
        del sys.modules[name]
import ckesc.protocol
print(json.dumps(sorted(n for n in sys.modules if n.split(".")[0] in forbidden)))
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, check=True)
    loaded = json.loads(out.stdout.strip().splitlines()[-1])
    assert loaded == [], f"import ckesc.protocol loaded {loaded}"
