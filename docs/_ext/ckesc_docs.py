"""Pages made from the code at build time, so that the documentation cannot drift from it.

A page asks for a generated block with a fence of its own directive name::

    ```{ckesc-generated} profile-keys
    ```

Before Sphinx parses the page (its ``source-read`` event) each such fence is replaced by the Markdown
that :data:`GENERATORS` makes for the name: tables, and for the catalogue whole sections with headings,
which a directive could not add. An unknown name is an error; a fence this extension did not replace
(the extension not loaded) is an unknown directive, which ``-W`` makes an error too.
"""

from __future__ import annotations

import argparse
import ast
import re
import tomllib
import types
import typing
from collections.abc import Callable
from pathlib import Path

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
    return {"version": "1", "parallel_read_safe": True, "parallel_write_safe": True}
