"""Outcomes travel typed (issue #35, item 3): the source of ``ckesc/`` and ``conformance/`` is read with ``ast`` for the
old forms, as tests/protocol/test_no_tolerance_literals.py reads it for tolerances.

* **No "harness:" decision**: a harness failure is an exception type (``ckesc.bench.errors.HarnessError``); no string
  of the code says ``harness:`` (neither a message that would ask for a word to decide, nor a test of one).
* **No regular expression reading a verdict back**: the modules that read outcomes (results, causes, compare, the
  record of measurements, the verdicts, the batches) use no ``re`` but where :data:`RE_ALLOWED` says why it reads no
  verdict; and no pattern anywhere names a strength or a verdict (``SHALL``, ``INCONCLUSIVE``, ...).
* **One exit-status table**: ``ckesc.reporting.exits.ExitStatus``. No ``EXIT_*`` number, no 130 or 141, no
  ``returncode=`` / ``sys.exit`` / ``SystemExit`` number, no number compared with an exit status and no number returned
  by a command's handler, anywhere else.
"""

from __future__ import annotations

import ast
import re
from collections import Counter
from pathlib import Path

from ckesc.protocol.requirements import STRENGTHS, Verdict

ROOT = Path(__file__).resolve().parents[1]
TABLE = "ckesc/reporting/exits.py"
#: modules whose functions annotated ``-> int`` are a command's handlers: what they return is an exit status
COMMANDS = ("ckesc/cli/", "ckesc/run.py", "ckesc/explore/command.py", "ckesc/soak/batch.py", "ckesc/rigs/batch_report.py")
#: modules that read outcomes back (results.json, a failure message, a measurement)
READERS = ("ckesc/reporting/", "ckesc/bench/outcomes.py", "ckesc/session/verdicts.py", "ckesc/session/finish.py",
           "ckesc/rigs/batch_report.py", "ckesc/soak/batch.py")
#: (file, how many ``re`` calls) -> why they read no verdict
RE_ALLOWED: dict[tuple[str, int], str] = {
    ("ckesc/reporting/report.py", 2): "a section's slug for a file name, and a git revision's hex digits",
}
#: file -> why a pattern naming a verdict decides none
PATTERNS_ALLOWED: dict[str, str] = {
    "ckesc/selftest.py": "strips an exception's class and INCONCLUSIVE's own word from a message shown in a line; the "
                         "run's bucket is its typed outcome",
}
#: what a pattern that reads a verdict or a strength back would name
VERDICT_WORDS = re.compile("|".join(sorted({*STRENGTHS, *(v.value for v in Verdict)}, key=len, reverse=True)))
EXIT_NUMBERS = {130, 141}
#: where 130 and 141 may be other things than exit statuses (a throttle value, a frame's field)
NOT_STATUSES = ("conformance/", "ckesc/protocol/", "ckesc/emulator/")


def _sources() -> list[tuple[str, ast.Module]]:
    return [(p.relative_to(ROOT).as_posix(), ast.parse(p.read_text(encoding="utf-8"), str(p)))
            for base in ("ckesc", "conformance") for p in sorted((ROOT / base).rglob("*.py"))]


def _strings(tree: ast.Module) -> list[tuple[int, str]]:
    return [(n.lineno, n.value) for n in ast.walk(tree) if isinstance(n, ast.Constant) and isinstance(n.value, str)]


def _int(node: ast.AST | None) -> bool:
    return isinstance(node, ast.Constant) and type(node.value) is int


def _is_re_call(node: ast.AST) -> bool:
    return isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and isinstance(node.func.value, ast.Name) \
        and node.func.value.id == "re"


def _names_exit(node: ast.AST) -> bool:
    """``node`` reads an exit status: a name, attribute or key that says exit / returncode."""
    text = ast.unparse(node).lower()
    return any(w in text for w in ("exit", "returncode"))


def _another_process_succeeded(node: ast.Compare) -> bool:
    """``proc.returncode == 0`` / ``!= 0``: whether a process the code ran (git, a power command) succeeded, POSIX's
    convention, not one of ckesc's statuses."""
    sides = [node.left, *node.comparators]
    return len(sides) == 2 and any(_int(c) and c.value == 0 for c in sides) \
        and any(isinstance(c, ast.Attribute) and c.attr == "returncode" for c in sides)


def _exit_literals(rel: str, tree: ast.Module) -> list[str]:
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Constant) and type(node.value) is int and node.value in EXIT_NUMBERS \
                and not rel.startswith(NOT_STATUSES):
            out.append(f"{rel}:{node.lineno}: {node.value}")
        elif isinstance(node, (ast.Assign, ast.AnnAssign)):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            values = node.value.elts if isinstance(node.value, ast.Tuple) else [node.value]
            names = [n.id for t in targets for n in ast.walk(t) if isinstance(n, ast.Name)]
            if any(n.startswith("EXIT_") for n in names) and any(_int(v) for v in values):
                out.append(f"{rel}:{node.lineno}: {', '.join(names)} = a number")
        elif isinstance(node, ast.keyword) and node.arg in ("returncode", "exitstatus") and _int(node.value):
            out.append(f"{rel}:{node.lineno}: {node.arg}={node.value.value}")
        elif isinstance(node, ast.Call) and ast.unparse(node.func) in ("sys.exit", "SystemExit", "exit") \
                and any(_int(a) for a in node.args):
            out.append(f"{rel}:{node.lineno}: {ast.unparse(node)}")
        elif isinstance(node, ast.Compare) and any(_int(c) for c in [node.left, *node.comparators]) \
                and any(_names_exit(c) for c in [node.left, *node.comparators] if not _int(c)) \
                and not _another_process_succeeded(node):
            out.append(f"{rel}:{node.lineno}: {ast.unparse(node)}")
        elif isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and rel.startswith(COMMANDS) \
                and node.returns is not None and ast.unparse(node.returns) in ("int", "'int'"):
            for r in ast.walk(node):
                if isinstance(r, ast.Return) and r.value is not None:
                    returned = [r.value.body, r.value.orelse] if isinstance(r.value, ast.IfExp) else [r.value]
                    out += [f"{rel}:{r.lineno}: {node.name} returns {v.value}" for v in returned if _int(v)]
    return out


def test_no_harness_prefix_decides_a_verdict():
    found = [f"{rel}:{line}: {text[:80]!r}" for rel, tree in _sources() for line, text in _strings(tree)
             if "harness:" in text]
    assert not found, f"raise ckesc.bench.errors.HarnessError instead of a 'harness:' message: {found}"


def test_no_regular_expression_reads_a_verdict_back():
    calls: Counter = Counter()
    patterns = []
    for rel, tree in _sources():
        for node in ast.walk(tree):
            if _is_re_call(node):
                if rel.startswith(READERS):
                    calls[rel] += 1
                pattern = node.args[0] if node.args else None
                if isinstance(pattern, ast.Constant) and isinstance(pattern.value, str) and VERDICT_WORDS.search(pattern.value) \
                        and rel not in PATTERNS_ALLOWED:
                    patterns.append(f"{rel}:{node.lineno}: {pattern.value[:80]!r}")
    allowed = {rel: n for (rel, n) in RE_ALLOWED}
    assert not patterns, f"a pattern that reads a verdict or a strength back from text (carry it as a field): {patterns}"
    assert dict(calls) == allowed, (f"regular expressions in the modules that read outcomes back (results carry their "
                                    f"fields; allow one in RE_ALLOWED with why it reads no verdict): {dict(calls)}")


def test_one_exit_status_table():
    found = [hit for rel, tree in _sources() if rel != TABLE for hit in _exit_literals(rel, tree)]
    assert not found, f"exit statuses written as numbers outside {TABLE} (use ExitStatus): {found}"


def test_the_scan_finds_the_old_forms():
    """The scan itself, on the forms it replaced (a scan that finds nothing could not fail)."""
    old = ast.parse("EXIT_BENCH = 3\nWORST_FIRST = (130, 1, 3, 2)\n"
                    "def exit_status(s) -> int:\n    return 1 if s else 0\n"
                    "def page(doc):\n    return doc['exit_status'] == 0\n"
                    "def abort():\n    pytest.exit('x', returncode=3)\n")
    hits = _exit_literals("ckesc/rigs/batch_report.py", old)
    assert len(hits) == 6, hits
    assert VERDICT_WORDS.search(r"^\[(?P<rules>[^\]]+?) (?P<strength>SHALL|READING|OBSERVE)\]\s*")
