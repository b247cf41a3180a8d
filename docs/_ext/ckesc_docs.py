"""Pages made from the code at build time, so that the documentation cannot drift from it.

A page asks for a generated block with a fence of its own directive name::

    ```{ckesc-generated} profile-keys
    ```

Before Sphinx parses the page (its ``source-read`` event) each such fence is replaced by the Markdown
that :data:`GENERATORS` makes for the name: tables, and for the catalogue whole sections with headings,
which a directive could not add. An unknown name is an error; a fence this extension did not replace
(the extension not loaded) is an unknown directive, which ``-W`` makes an error too.

A figure in prose is a role: ``{ckesc-figure}`suite.tests``` is the number of tests pytest collects now,
``{ckesc-figure}`run.PASS``` the PASS count of the recorded faultless run (``docs/recorded/faultless-run.json``,
refused when it is not a run of the suite the code has now), ``{ckesc-figure}`suite.json:simulated.overlap.protocol_s .0f```
a recorded benchmark's figure (``benchmarks/results/``), ``{ckesc-figure}`code:MODULE.NAME``` a constant of the code; a
line the suite prints (``sample.progress``) is made by the code that prints it. ``tests/test_docs.py`` fails a page
that writes such a figure by hand.
"""

from __future__ import annotations

import argparse
import ast
import functools
import json
import re
import subprocess
import sys
import tomllib
import types
import typing
from collections.abc import Callable
from pathlib import Path

from docutils import nodes
from sphinx.application import Sphinx
from sphinx.errors import ExtensionError

ROOT = Path(__file__).resolve().parents[2]
FENCE = re.compile(r"^```\{ckesc-generated\}\s+(?P<name>[\w-]+)\s*\n```[ \t]*$", re.MULTILINE)


def _cell(text: object) -> str:
    """A Markdown table cell: one line, pipes escaped."""
    return " ".join(str(text).split()).replace("|", "\\|")


def _table(head: tuple[str, ...], rows: list[tuple[object, ...]]) -> str:
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    lines += ["| " + " | ".join(_cell(c) for c in row) + " |" for row in rows]
    return "\n".join(lines)


# ------------------------------------------------------------------------------------ DUT profiles
def _type_text(annotation: object) -> str:
    if typing.get_origin(annotation) is typing.Literal:
        return " \\| ".join(f'`"{a}"`' for a in typing.get_args(annotation))
    if typing.get_origin(annotation) is list:
        return f"list of {typing.get_args(annotation)[0].__name__}"
    if typing.get_origin(annotation) in (typing.Union, types.UnionType):
        return " or ".join(a.__name__ for a in typing.get_args(annotation) if a is not type(None))
    return getattr(annotation, "__name__", str(annotation))


def _range_text(field) -> str:
    bounds = {type(m).__name__: m for m in field.metadata}
    lo = bounds.get("Ge")
    hi = bounds.get("Le")
    if lo is not None and hi is not None:
        return f"{lo.ge:g} .. {hi.le:g}"
    return ""


def profile_keys() -> str:
    """Every section and key of a DUT profile, from the schema the loader checks files against."""
    from ckesc.bench.profile import PROFILE_SCHEMA

    rows = []
    for section, sfield in PROFILE_SCHEMA.model_fields.items():
        for key, field in sfield.annotation.model_fields.items():
            default = field.default
            default_text = "the file's name" if default is None else (
                f"`{str(default).lower()}`" if isinstance(default, bool) else f"`{default!r}`".replace("'", '"'))
            assert field.description, f"profile key [{section}] {key} has no description (profile.py)"
            rows.append((f"`[{section}] {key}`", _type_text(field.annotation), default_text, _range_text(field),
                         field.description))
    return _table(("key", "type", "default", "range", "what"), rows)


def optional_functions() -> str:
    """The functions a profile may declare absent (R9b) and what each covers."""
    from ckesc.protocol.functions import CORE, OPTIONAL

    rows = [(f"`{f.name}`", f"{f.title} ({', '.join(f.sections)})", ", ".join(f.requirements)) for f in OPTIONAL.values()]
    core = ", ".join(f"`{name}` ({section})" for name, section in CORE.items())
    return (_table(("function", "what it is", "requirements it covers"), rows)
            + f"\n\nNever absent (R9b keeps them in every claim; naming one is a preflight error): {core}.")


def shipped_profiles() -> str:
    """The profiles the package ships, each in full."""
    from ckesc.bench.profile import SHIPPED

    out = []
    for path in sorted(SHIPPED.iterdir(), key=lambda p: p.name):
        if path.name.endswith(".toml"):
            out += [f"`{path.name.removesuffix('.toml')}`", "", "```toml", path.read_text(encoding="utf-8").rstrip(), "```", ""]
    return "\n".join(out)


# ------------------------------------------------------------------------------------ requirements
def _requirement_rows(reqs, cited) -> list[tuple[object, ...]]:
    rows = []
    for req in reqs:
        tests = sorted(cited.get(req.id, ()))
        names = ", ".join(f"`{t.split('::')[1]}`" for t in tests) if tests else "none"
        quote = req.quote + (f" *({req.note})*" if req.note else "")
        capability = f" (needs `{req.capability}`)" if req.capability else ""
        rows.append((f"**{req.id}**", req.strength + capability, quote, names))
    return rows


def catalogue() -> str:
    """Every requirement of ``requirements.toml``, section by section, with the tests citing it."""
    from ckesc.protocol.requirements import REQUIREMENTS, section_heading, section_key
    from ckesc.selftest import citations

    cited = citations()
    sections: dict[str, list] = {}
    for req in REQUIREMENTS.values():
        sections.setdefault(req.section, []).append(req)
    out = []
    for section in sorted(sections, key=section_key):
        modules = sorted({t.split("::")[0] for r in sections[section] for t in cited.get(r.id, ())})
        where = f"Tests in {', '.join(f'`{m}`' for m in modules)}." if modules else "No test cites this section."
        out += [f"## {section_heading(section)}", "", where, "",
                _table(("id", "strength", "the document says", "tests"), _requirement_rows(sections[section], cited)), ""]
    return "\n".join(out)


def interpretation_rules() -> str:
    """The rules of INTERPRETATIONS.md (F1.., R1..) as the requirement table carries them."""
    from ckesc.protocol.requirements import REQUIREMENTS
    from ckesc.selftest import citations

    reqs = [r for r in REQUIREMENTS.values() if re.fullmatch(r"[FR]\d+\w*(-[\w-]+)?", r.id)]
    return _table(("id", "strength", "the reading", "tests"), _requirement_rows(reqs, citations()))


# ------------------------------------------------------------------------------------ the emulator
def faults() -> str:
    from ckesc.emulator.faults import FAULTS

    return _table(("fault", "breaks", "what the emulated ESC does"),
                  [(f"`{f.name}`", ", ".join(f.rules), f.description) for f in FAULTS.values()])


def variants() -> str:
    from ckesc.emulator.variants import FREEDOMS

    return _table(("variant", "values (first: the default)", "left open by", "what the emulated ESC does"),
                  [(f"`{f.name}`", f"`{f.values_text()}`", ", ".join(f.allowed_by), f.description)
                   for f in FREEDOMS.values()])


# ------------------------------------------------------------------------------------ architecture
def layers() -> str:
    """The import contract's layers, top to bottom, as pyproject.toml declares them."""
    doc = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    contract = next(c for c in doc["tool"]["importlinter"]["contracts"] if c["type"] == "layers")
    return "\n".join(f"{i}. " + " \\| ".join(f"`{m.strip()}`" for m in layer.split("|"))
                     for i, layer in enumerate(contract["layers"], 1))


def _docstring(path: Path) -> str:
    """A module's docstring, its first paragraph, on one line."""
    doc = ast.get_docstring(ast.parse(path.read_text(encoding="utf-8"))) or ""
    doc = re.sub(r":\w+:`~?([^`]+)`", r"``\1``", doc)  # Sphinx roles (:mod:, :func:, ...): as code here
    return " ".join(doc.split("\n\n")[0].split())


def packages() -> str:
    """Each layer's packages and modules, with what their docstrings say they hold (read, not imported)."""
    doc = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    contract = next(c for c in doc["tool"]["importlinter"]["contracts"] if c["type"] == "layers")
    out = []
    for layer in contract["layers"]:
        for name in (m.strip() for m in layer.split("|")):
            path = ROOT / name.replace(".", "/")
            if path.is_dir():
                out += [f"### `{path.relative_to(ROOT)}/`", "", _docstring(path / "__init__.py"), ""]
                modules = [m for m in sorted(path.glob("*.py")) if m.name != "__init__.py"]
                tests = [m for m in modules if m.name.startswith("test_")]
                rows = [(f"`{m.name}`", _docstring(m)) for m in modules if m not in tests]
                out += [_table(("module", "what it holds"), rows), ""]
                if tests:
                    out += [f"And {len(tests)} test modules, one per section of the document: [](catalogue.md).", ""]
                for sub in sorted(d for d in path.iterdir() if (d / "__init__.py").is_file()):
                    out += [f"`{sub.relative_to(ROOT)}/`: {_docstring(sub / '__init__.py')}", ""]
            else:
                out += [f"### `{path.relative_to(ROOT)}.py`", "", _docstring(path.with_suffix(".py")), ""]
    return "\n".join(out)


def cli() -> str:
    """Every ``ckesc`` command's ``--help`` (and its own commands', e.g. ``ckesc profile init``), as argparse prints
    it on an 100-column terminal."""
    import os

    from ckesc.cli import build_parser

    columns = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = "100"
    try:
        parser = build_parser()
        sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
        out = []
        for name, command in sub.choices.items():
            out += [f"## ckesc {name}", "", "```text", command.format_help().rstrip(), "```", ""]
            actions = next((a for a in command._actions if isinstance(a, argparse._SubParsersAction)), None)
            for action, parser in (actions.choices.items() if actions else ()):  # a command of its own commands
                out += [f"### ckesc {name} {action}", "", "```text", parser.format_help().rstrip(), "```", ""]
    finally:
        if columns is None:
            del os.environ["COLUMNS"]
        else:
            os.environ["COLUMNS"] = columns
    return "\n".join(out)


# ------------------------------------------------------------------------------------ figures in prose
#: the faultless simulated run the pages cite (``python docs/recorded/record_run.py`` re-records it)
RECORD = ROOT / "docs" / "recorded" / "faultless-run.json"
#: the benchmarks' recorded results (``python benchmarks/<name>.py`` writes them)
BENCH_RESULTS = ROOT / "benchmarks" / "results"
ROLE = "ckesc-figure"


@functools.cache
def collected() -> tuple[str, ...]:
    """The conformance suite's test ids, as pytest collects them now (about 2 s)."""
    proc = subprocess.run([sys.executable, "-m", "pytest", "--pyargs", "conformance", "-p", "no:cacheprovider",
                           "--collect-only", "-q"], cwd=ROOT, capture_output=True, text=True, timeout=300,
                          stdin=subprocess.DEVNULL)
    ids = tuple(line for line in proc.stdout.splitlines() if "::" in line)
    if proc.returncode != 0 or not ids:
        raise ExtensionError(f"{ROLE}: collecting the conformance tests failed (exit {proc.returncode}):\n"
                             f"{proc.stdout[-2000:]}{proc.stderr[-2000:]}")
    return ids


@functools.cache
def recorded_run() -> dict:
    """The recorded faultless run, refused when it is not a run of the suite the code has now."""
    recorder = ROOT / "docs" / "recorded"
    sys.path.insert(0, str(recorder))
    try:
        from record_run import ids_digest
    finally:
        sys.path.remove(str(recorder))
    doc = json.loads(RECORD.read_text(encoding="utf-8"))
    ids = collected()
    if doc["test_ids_sha256"] != ids_digest(list(ids)):
        raise ExtensionError(
            f"{ROLE}: {RECORD} (recorded {doc['recorded']}, {doc['tests']} tests) is not a run of the "
            f"suite the code has now ({len(ids)} tests collected, other test ids): the pages would cite a stale run. "
            f"Re-record it: python docs/recorded/record_run.py")
    return doc


def _replay(section: str = "4.4.22"):
    """The run's time as a real-time run at the planned pace says it on entering ``section``: the suite's own
    table (``conformance/durations.json``, in the order of the run that made it) replayed through ``RunClock``."""
    from ckesc.session.progress import RunClock, expected_for, read_table, section_of_id

    ids = collected()
    table = read_table()
    order = [i for i in table if i in set(ids)] + [i for i in ids if i not in table]
    clock = RunClock(expected_for(list(ids)))
    clock.start(0.0, 0.0)
    now = 0.0
    for nodeid in order:
        heading = section_of_id(nodeid)
        if heading.split()[0] == section:
            return clock, heading
        now += clock.expected[nodeid]
        clock.finished(nodeid, now, now)
    raise ExtensionError(f"{ROLE}: no test of section {section} in the suite")


def _bench_line() -> str:
    from ckesc.rigs.batch_report import progress_line

    run = recorded_run()
    rec = {"name": "esc-17", "status": "PASS", "counts": run["verdicts"], "why": None, "report_dir": "esc-17"}
    return progress_line(rec, run["protocol_s"], Path("reports/2026-11-27T10-00-00Z"))


def _verdict_count(key: str) -> Callable[[], str]:
    return lambda: str(recorded_run()["verdicts"].get(key, 0))


#: figures by name: (what it is, its text)
FIGURES: dict[str, Callable[[], str]] = {
    "suite.tests": lambda: str(len(collected())),
    "plan.protocol_s": lambda: f"{_replay()[0].planned:.0f}",
    "run.tests": lambda: str(recorded_run()["tests"]),
    **{f"run.{v}": _verdict_count(v) for v in ("PASS", "OBSERVED", "INCONCLUSIVE", "SKIPPED", "FAIL", "ERROR")},
    "run.protocol_s": lambda: f"{recorded_run()['protocol_s']:.0f}",
    "run.wall_s": lambda: f"{recorded_run()['wall_s']:.0f}",
    "run.recorded": lambda: recorded_run()["recorded"],
}
def _plugtest(what: str) -> str:
    """The plugtest's figures (``benchmarks/results/plugtest-explore.json``): when each defect was first seen."""
    doc = json.loads((BENCH_RESULTS / "plugtest-explore.json").read_text(encoding="utf-8"))
    first = sorted((min(f["seconds_before"] for f in r["found"]), r["defect"]) for r in doc["runs"] if r["defect"] and r["found"])
    if what == "found":
        return ", ".join(f"`{name}` {seconds:.0f} s" for seconds, name in first)
    return f"{600 - first[-1][0]:.0f}"  # the slowest defect's time to spare of its 10-minute budget


FIGURES.update({
    "plugtest.found": lambda: _plugtest("found"),
    "plugtest.spare_s": lambda: _plugtest("spare"),
})
#: figures shown as code: a line the suite prints, made by the code that prints it
SAMPLES: dict[str, Callable[[], str]] = {
    "sample.progress": lambda: "time: " + _replay()[0].line(_replay()[1]),
    "sample.counter": lambda: f"[{len(_replay()[0].done) + 1}/{len(collected())}{_replay()[0].suffix()}]",
    "sample.batch-progress": lambda: f"time: esc-17: {_replay()[0].wall_line(_replay()[1])}",
    "sample.bench-done": _bench_line,
    "sample.closing": lambda: _closing_counts(),
}


def _closing_counts() -> str:
    """pytest's closing line's counts of the recorded run, in the words the suite gives pytest for each verdict."""
    from ckesc.session.verdicts import _CONSOLE

    words = {str(v): c[0] for v, c in _CONSOLE.items()}
    pytest_order = ("failed", "passed", "skipped", "error")  # pytest's known categories first, then the others
    counts = sorted(((n, words[v]) for v, n in recorded_run()["verdicts"].items()),
                    key=lambda nw: pytest_order.index(nw[1]) if nw[1] in pytest_order else len(pytest_order))
    return ", ".join(f"{n} {w}" for n, w in counts)


def _json_path(doc: object, path: str) -> object:
    for part in path.split("."):
        if isinstance(doc, list):
            doc = doc[int(part)]
        elif isinstance(doc, dict) and part in doc:
            doc = doc[part]
        else:
            raise KeyError(part)
    return doc


def figure(name: str) -> tuple[str, bool]:
    """A figure's text and whether it is shown as code. ``name``: one of :data:`FIGURES` / :data:`SAMPLES`; a
    recorded benchmark's ``FILE:PATH[ FORMAT]`` (``suite.json:simulated.overlap.protocol_s .0f``: that JSON file of
    ``benchmarks/results/``, a dotted path in it, list items by index); or a constant of the code,
    ``code:MODULE.NAME[ FORMAT]``. FORMAT: a Python format spec (``.0f``), ``verdicts`` (a {verdict: count} table
    as "291 PASS, 5 INCONCLUSIVE"), ``yes`` (a truth as yes / no), ``sum``
    (of a table's or a list's numbers) or ``ms`` and a format spec (microseconds shown in milliseconds: ``ms.1f``)."""
    name = name.strip()
    if name in FIGURES:
        return FIGURES[name](), False
    if name in SAMPLES:
        return SAMPLES[name](), True
    where, colon, rest = name.partition(":")
    if not colon:
        raise KeyError(f"unknown figure {name!r} (known: {', '.join([*FIGURES, *SAMPLES])}, FILE.json:PATH, code:MODULE.NAME)")
    path, _, fmt = rest.partition(" ")
    if where == "code":
        import importlib

        module, _, attr = path.rpartition(".")
        value = getattr(importlib.import_module(module), attr)
    else:
        file = BENCH_RESULTS / where
        if file.parent != BENCH_RESULTS or not file.is_file():
            raise KeyError(f"no recorded benchmark {where!r} in benchmarks/results/")
        value = _json_path(json.loads(file.read_text(encoding="utf-8")), path)
    if fmt == "verdicts":  # a {verdict: count} table, in the reports' order of verdicts
        order = ("PASS", "FAIL", "ERROR", "OBSERVED", "INCONCLUSIVE", "SKIPPED")
        return ", ".join(f"{value[v]} {v}" for v in sorted(value, key=lambda v: order.index(v) if v in order else 9)), False
    if fmt.startswith("ms"):  # microseconds shown in milliseconds: "ms.1f"
        value, fmt = float(value) / 1000, fmt[2:]
    if fmt == "yes":
        return ("yes" if value else "no"), False
    if fmt == "sum":
        return str(sum(value.values() if isinstance(value, dict) else value)), False
    return (format(value, fmt) if fmt else str(value)), False


def figure_role(name, rawtext, text, lineno, inliner, options=None, content=None):
    """``{ckesc-figure}`suite.tests```: the figure's text in the page, made at build time."""
    try:
        value, as_code = figure(text)
    except (KeyError, IndexError, ValueError, AttributeError, ImportError) as exc:
        msg = inliner.reporter.error(f"{ROLE} {text!r}: {exc}", line=lineno)
        return [inliner.problematic(rawtext, rawtext, msg)], [msg]
    if as_code:
        return [nodes.literal(rawtext, value)], []
    # a figure that names things (`name`) shows them as code, as a page would
    return [nodes.literal(part, part) if i % 2 else nodes.Text(part) for i, part in enumerate(value.split("`")) if part], []


GENERATORS: dict[str, Callable[[], str]] = {
    "profile-keys": profile_keys,
    "optional-functions": optional_functions,
    "shipped-profiles": shipped_profiles,
    "catalogue": catalogue,
    "interpretation-rules": interpretation_rules,
    "faults": faults,
    "variants": variants,
    "layers": layers,
    "packages": packages,
    "cli": cli,
}


def expand(text: str) -> str:
    def one(match: re.Match) -> str:
        name = match["name"]
        if name not in GENERATORS:
            raise ExtensionError(f"ckesc-generated: unknown block {name!r} (known: {', '.join(GENERATORS)})")
        return GENERATORS[name]()

    return FENCE.sub(one, text)


def _source_read(app: Sphinx, docname: str, source: list[str]) -> None:
    source[0] = expand(source[0])


def setup(app: Sphinx) -> dict:
    app.connect("source-read", _source_read)
    app.add_role(ROLE, figure_role)
    return {"version": "1", "parallel_read_safe": True, "parallel_write_safe": True}
