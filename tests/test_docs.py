"""The documentation site (docs/): it builds with warnings as errors, its generated tables hold what the code
holds, its figures are made at build time (no count or run time written by hand, none from a stale record), angle
brackets outside code are not swallowed, every shell example says whether it runs here, and the ones that do are
run for real and checked.

A shell example (a fence of ``sh``, ``bash``, ``shell`` or ``console``) follows a MyST comment line, which the site
does not show:

    % example: run                           exit status 0
    % example: run; exit 1; prints "R2"      exit status 1, and "R2" in what it printed (stdout or stderr)
    % example: not run (a CAN adapter)       needs what this machine has not: the reason is required

The runnable ones of a page run in order, each with ``bash -e`` in one temporary directory per page (with the
repository's ``fixtures/*`` linked into it) and this interpreter's ``ckesc`` first on PATH. Cost: about 10 s for the
build (its figures collect the suite), 40-50 s for the examples (each a few sections of the suite in the simulated
lane) and about 20 s for the stand-in page's (a few tests in real time against ``ckesc emulate`` started in the
background, which the example stops on its way out).
"""

from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
PAGES = sorted(p for p in DOCS.rglob("*.md") if "_build" not in p.parts)
SHELL = {"sh", "bash", "shell", "console"}
FENCE = re.compile(r"^(?P<indent> *)```(?P<info>[\w{}-]*)[^\n]*$")
MARKER = re.compile(r'^ *% example: (?:(?P<run>run)(?:; exit (?P<exit>\d+))?(?:; prints "(?P<prints>[^"]+)")?'
                    r"|not run \((?P<why>[^)]+)\))\s*$")


@dataclass(frozen=True)
class Example:
    page: Path
    line: int
    code: str
    runs: bool
    exit: int = 0
    prints: str | None = None

    @property
    def where(self) -> str:
        return f"{self.page.relative_to(ROOT)}:{self.line}"


def examples(page: Path) -> tuple[list[Example], list[str]]:
    """A page's shell examples, and what is wrong with its markers (an example without one, a bad marker)."""
    lines = page.read_text(encoding="utf-8").split("\n")
    found: list[Example] = []
    problems: list[str] = []
    i = 0
    while i < len(lines):
        fence = FENCE.match(lines[i])
        if not fence:
            i += 1
            continue
        end = next((j for j in range(i + 1, len(lines)) if lines[j].strip() == "```"), len(lines))
        if fence["info"] in SHELL:
            indent = len(fence["indent"])
            code = "\n".join(line[indent:] for line in lines[i + 1:end])
            before = next((lines[j] for j in range(i - 1, -1, -1) if lines[j].strip()), "")
            marker = MARKER.match(before)
            if marker is None:
                problems.append(f"{page.relative_to(ROOT)}:{i + 1}: a shell example without a '% example: run' or "
                                f"'% example: not run (why)' line before it (found: {before.strip()!r})")
            else:
                found.append(Example(page, i + 1, code, runs=bool(marker["run"]), exit=int(marker["exit"] or 0),
                                     prints=marker["prints"]))
        i = end + 1
    return found, problems


def test_every_shell_example_says_whether_it_runs():
    problems = [p for page in PAGES for p in examples(page)[1]]
    assert not problems, "\n".join(problems)
    runnable = [e for page in PAGES for e in examples(page)[0] if e.runs]
    assert len(runnable) >= 10, f"only {len(runnable)} runnable examples found: the marker parser lost them?"


def test_the_docs_build_with_warnings_as_errors(tmp_path):
    missing = [m for m in ("sphinx", "myst_parser", "furo") if _absent(m)]
    assert not missing, (f"the docs packages are not installed ({', '.join(missing)}): pip install -e '.[test]' "
                         "(the test extra includes docs)")
    out = tmp_path / "html"
    proc = subprocess.run([sys.executable, "-m", "sphinx", "-W", "--keep-going", "-q", "-b", "html",
                           "-d", str(tmp_path / "doctrees"), str(DOCS), str(out)],
                          capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert proc.returncode == 0, f"sphinx-build -W failed:\n{proc.stderr[-4000:]}"
    # the generated tables hold what the code holds
    from ckesc.bench.profile import PROFILE_SCHEMA
    from ckesc.emulator.faults import FAULTS
    from ckesc.emulator.variants import FREEDOMS
    from ckesc.protocol.requirements import REQUIREMENTS

    def cells(name: str) -> set[str]:
        """The text of every table cell of a built page."""
        html = (out / name).read_text(encoding="utf-8")
        return {" ".join(re.sub(r"<[^>]+>", "", c).split()) for c in re.findall(r"<td>(.*?)</td>", html, re.S)}

    keys = {f"[{s}] {k}" for s, f in PROFILE_SCHEMA.model_fields.items() for k in f.annotation.model_fields}
    assert not keys - cells("bench/profiles.html"), "profile keys missing from the docs"
    assert not (set(FAULTS) | set(FREEDOMS)) - cells("emulator.html"), "faults or variants missing from the docs"
    assert not set(REQUIREMENTS) - cells("catalogue.html"), "requirements missing from the catalogue"


def _absent(module: str) -> bool:
    import importlib.util

    return importlib.util.find_spec(module) is None


RUNNABLE = [e for page in PAGES for e in examples(page)[0] if e.runs]


@pytest.mark.realtime  # some pages run `ckesc emulate` and real-time benches
@pytest.mark.parametrize("page", sorted({e.page for e in RUNNABLE}), ids=lambda p: str(p.relative_to(DOCS)))
def test_runnable_examples_run(page, tmp_path):
    (tmp_path / "fixtures").mkdir()  # the repository's fixtures, read-only by way of links: an example writes beside them
    for item in (ROOT / "fixtures").iterdir():
        (tmp_path / "fixtures" / item.name).symlink_to(item)
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}",
           "COLUMNS": "100"}
    for example in (e for e in RUNNABLE if e.page == page):
        proc = subprocess.run(["bash", "-e", "-c", example.code], cwd=tmp_path, env=env, capture_output=True,
                              text=True, timeout=120)
        said = proc.stdout + proc.stderr
        assert proc.returncode == example.exit, (
            f"{example.where}: exit {proc.returncode}, the page says {example.exit}:\n"
            f"$ {shlex.quote(example.code)}\n{said[-3000:]}")
        if example.prints:
            assert example.prints in said, f"{example.where}: the page says it prints {example.prints!r}:\n{said[-3000:]}"


def _blocks(info: str) -> list[tuple[str, str]]:
    """Every fenced block of one kind in the pages: (where, text)."""
    out = []
    for page in PAGES:
        lines = page.read_text(encoding="utf-8").split("\n")
        for i, line in enumerate(lines):
            fence = FENCE.match(line)
            if fence and fence["info"] == info:
                end = next(j for j in range(i + 1, len(lines)) if lines[j].strip() == "```")
                indent = len(fence["indent"])
                out.append((f"{page.relative_to(ROOT)}:{i + 1}", "\n".join(x[indent:] for x in lines[i + 1:end])))
    return out


def test_the_rig_files_and_ci_recipes_shown_are_valid():
    """What cannot run here is still checked: a rig file shown is one the rig loader takes, a CI recipe is YAML and
    each ckesc command in it is one the command line takes."""
    import yaml

    from ckesc.cli import build_parser
    from ckesc.rigs.rig import parse

    rigs = [(where, text) for where, text in _blocks("toml") if "[bench." in text]
    assert rigs, "no rig file example found in the docs"
    for where, text in rigs:
        assert parse(text, ROOT / "fixtures" / "rigs" / "docs-example.toml").benches, where
    commands = []
    for where, text in _blocks("yaml"):
        doc = yaml.safe_load(text)
        assert doc, f"{where}: empty YAML"
        commands += [(where, c) for c in re.findall(r"(?:run: |- )(ckesc [^\n#]+)", text)]
    assert len(commands) >= 2, "the CI recipes run no ckesc command?"
    parser = build_parser()
    for where, command in commands:
        try:
            args = parser.parse_args(shlex.split(command)[1:])
        except SystemExit:
            raise AssertionError(f"{where}: '{command}' is not a valid ckesc command line") from None
        assert args.handler, where


def test_readme_is_one_screen_and_points_at_the_docs():
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    assert len(readme.splitlines()) <= 70, f"README.md has {len(readme.splitlines())} lines: the rest goes in docs/"
    assert "docs/" in readme and "sphinx" in readme
    # the two commands for a fresh machine, and the project's tests as .ci/run runs them
    assert 'pip install . && ckesc run' in readme
    ci = (ROOT / ".ci" / "run").read_text(encoding="utf-8")
    installs = re.findall(r'pip install --quiet -e "(\.\[[\w,]+\])"', ci)
    assert installs and f'pip install -e "{installs[0]}" && python -m pytest' in readme, (
        f"README's test command does not install what .ci/run installs ({installs})")
    (command,) = re.findall(r'&& (python -m pytest[^\n`]*)\n', readme)
    assert command in ci, f"README's test command {command!r} is not the one .ci/run runs"


# ----------------------------------------------------------------------------------------- figures that cannot go stale
#: a figure written through the role: ``{ckesc-figure}`NAME``` (docs/_ext/ckesc_docs.py)
FIGURE_ROLE = re.compile(r"\{ckesc-figure\}`[^`]*`")
#: a count of tests or verdicts, and a time in seconds, written by hand
COUNT = re.compile(r"(?<![\w.])\d[\d,.]*\s*(?:tests?|PASS|FAIL|ERROR|OBSERVED|INCONCLUSIVE|SKIPPED|passed|failed|observed)\b")
SECONDS = re.compile(r"(?<![\w.:])~?\d[\d,.]*(?: s\b| ?s wall\b)")
#: what is written by hand on purpose, each with why it is no figure a generator owns
BY_HAND = {
    ("docs/reports.md", "301 tests"): "an invented card's heading, showing how a cause is grouped",
    ("docs/explore.md", "291 PASS"): "the suite against the clean-room ESC, a run of which no record is kept",
    ("docs/explore.md", "0 FAIL"): "the same run",
    ("docs/explore.md", "0 ERROR"): "the same run",
    ("docs/benchmarks.md", "291 PASS"): "the same run",
    ("docs/benchmarks.md", "0 FAIL"): "the same run",
    ("docs/benchmarks.md", "0 ERROR"): "the same run",
    ("docs/benchmarks.md", "120 s"): "the explorer's self-test budget, a setting of the measurement",
    ("docs/benchmarks.md", "58 s"): "history: a figure before a change, not measured again",
    ("docs/benchmarks.md", "30 s"): "history: measured in the morning of 2026-11-26, before the changes measured since",
    ("docs/emulator.md", "37 s"): "54 min 37 s: 65536 ticks of 50 ms, the arithmetic of a fault's definition",
    ("docs/emulator.md", "122 s"): "the suite's shape measured on a date the sentence says, an argument, not a figure of a run",
    ("docs/emulator.md", "4 s"): "the same measurement",
    ("docs/emulator.md", "80 s"): "the same measurement",
    ("docs/emulator.md", "603 s"): "the same measurement",
    ("docs/soak.md", "532 s"): "one event of a diagnosis told as a story (when it happened), no figure a generator owns",
    ("docs/soak.md", "1.2 s"): "the same event",
    ("docs/cli.md", "30 s"): "examples of how a duration is written (1 min 30 s), not a figure of anything",
    ("docs/cli.md", "37 s"): "the same examples",
    ("docs/cli.md", "42.5 s"): "the same examples",
}


def hand_written_figures(where: str, text: str) -> list[str]:
    """Counts of tests or verdicts and times in seconds, on any page, not written through the ``{ckesc-figure}`` role:
    the figures a generator owns (a run's, a benchmark's, a setting's in the code), copied by hand, which go stale."""
    text = FIGURE_ROLE.sub("FIGURE", text)
    text = re.sub(r"^ *% example: .*$", "", text, flags=re.M)  # what an example prints: checked by running it
    text = re.sub(r"^ *```.*?^ *```", lambda m: "\n" * m.group().count("\n"), text, flags=re.S | re.M)  # code blocks
    found = [m for m in COUNT.finditer(text)] + [m for m in SECONDS.finditer(text)]
    return [f"{where}:{text[:m.start()].count(chr(10)) + 1}: {m.group().strip()!r} written by hand (write it as "
            "{ckesc-figure}`NAME`: docs/_ext/ckesc_docs.py)" for m in found
            if (where, m.group().strip().lstrip("~")) not in BY_HAND]


def test_no_page_writes_a_figure_by_hand():
    """Test counts, verdict counts and run times come from the code or a recorded run when the site is built; the
    README, which Sphinx does not build, writes none."""
    problems = []
    for path in [*PAGES, ROOT / "README.md"]:
        problems += hand_written_figures(str(path.relative_to(ROOT)), path.read_text(encoding="utf-8"))
    assert not problems, "\n".join(problems)
    # the check sees what it is for: the figures this issue found stale, in prose and in a sample line
    stale = ("the whole suite, 327 tests; 299 PASS, 28 OBSERVED (566 s)\n"
             "`time: [4.4.22 Set/Get Freq] protocol time 212 s of ~566 s, 3:32 elapsed, ~5:54 left (180 of 327 tests)`\n")
    assert len(hand_written_figures("docs/reports.md", stale)) == 7
    assert hand_written_figures("docs/reports.md", "the {ckesc-figure}`suite.tests` tests, {ckesc-figure}`run.protocol_s` s") == []


def test_a_record_of_another_suite_fails_the_build(tmp_path, monkeypatch):
    """The recorded faultless run is refused, with the command that re-records it, when it is not a run of the suite
    the code has now: the pages would cite a stale run."""
    import json

    sys.path.insert(0, str(DOCS / "_ext"))
    try:
        import ckesc_docs
    finally:
        sys.path.remove(str(DOCS / "_ext"))
    from sphinx.errors import ExtensionError

    ckesc_docs.recorded_run.cache_clear()
    assert ckesc_docs.figure("run.tests")[0] == ckesc_docs.figure("suite.tests")[0]  # the committed record is current
    stale = json.loads(ckesc_docs.RECORD.read_text(encoding="utf-8"))
    stale.update(tests=327, test_ids_sha256="0" * 16)
    record = tmp_path / "faultless-run.json"
    record.write_text(json.dumps(stale), encoding="utf-8")
    monkeypatch.setattr(ckesc_docs, "RECORD", record)
    ckesc_docs.recorded_run.cache_clear()
    try:
        with pytest.raises(ExtensionError, match=r"327 tests.*record_run\.py"):
            ckesc_docs.figure("run.PASS")
    finally:
        ckesc_docs.recorded_run.cache_clear()


# ----------------------------------------------------------------------------------------- angle brackets survive
_CODE_SPAN = re.compile(r"(?<!`)(`+)(?!`).+?(?<!`)\1(?!`)", re.S)  # closed by a run of as many backticks, no more
_PLACEHOLDER = re.compile(r"<(?![a-z]+://)[A-Za-z/][^<>\n]*>")


def swallowed_placeholders(where: str, text: str) -> list[str]:
    """``<test>``, ``<name>=<value>`` outside code: MyST takes them for raw HTML and the built page drops them."""
    text = re.sub(r"^ *(```|~~~).*?^ *\1", lambda m: "\n" * m.group().count("\n"), text, flags=re.S | re.M)
    text = _CODE_SPAN.sub(lambda m: "x" * len(m.group()), text)
    return [f"{where}:{text[:m.start()].count(chr(10)) + 1}: {m.group()} outside code is swallowed as HTML: write it "
            "in backticks" for m in _PLACEHOLDER.finditer(text)]


def test_angle_bracket_text_is_in_code():
    problems = [p for page in PAGES for p in swallowed_placeholders(str(page.relative_to(ROOT)), page.read_text(encoding="utf-8"))]
    assert not problems, "\n".join(problems)
    assert swallowed_placeholders("x.md", 'SKIPPED as "not claimed: <function> (R9b)", `<test>` and <https://a.b>') == [
        'x.md:1: <function> outside code is swallowed as HTML: write it in backticks']
    assert swallowed_placeholders("x.md", "a fence ` ```{x} NAME ` and `` a`b <c> ``, then `<test>`") == []
