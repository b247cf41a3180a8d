"""``ckesc run``: the whole conformance suite against a DUT, with reports.

    ckesc run                                   # the emulator, simulated time (exact timing)
    ckesc run --lane realtime                   # `ckesc emulate` in its own process, through socketcand
    ckesc run --dut bus --can-interface socketcan --can-channel can0 --power manual
    ckesc run --dut bus ... --power labgrid --labgrid-env env.yaml --labgrid-target esc   # power by labgrid
    ckesc run 4.4.22 4.4.3                      # some sections (numbers as in the document)
    ckesc run conformance/test_s4_4_22_set_freq.py   # a test module, by path (absolute or relative)

Runs pytest in this process over the installed ``conformance`` package with the ckesc plugin's
options, shows one progress line per test, writes ``reports/<timestamp>/`` (JUnit, JSON, summary)
with ``reports/latest`` pointing at it, and exits 0 only when no test FAILed or ERRORed
(INCONCLUSIVE and SKIPPED are reported, and ``--strict`` makes INCONCLUSIVE fail the run too).
"""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

from .protocol.requirements import section_key

EXIT_OK, EXIT_FAILED, EXIT_USAGE, EXIT_ABORTED, EXIT_INTERRUPTED = 0, 1, 2, 3, 130


def _suite_root() -> str:
    """The directory holding the ``conformance`` package (a checkout, or site-packages of a wheel install):
    pytest's rootdir, so that test ids read ``conformance/test_s4_4_22_set_freq.py::...`` however the
    suite was installed and wherever it is run from."""
    from .harness.plugin import conformance_dir  # pytest with it: only when a run is about to start

    where = conformance_dir()
    return str(where.parent) if where else "."


class SelectionError(ValueError):
    """A section or test module on the command line that names nothing of the suite (one line)."""


#: a section number as the document numbers them ("4.4.22", "4.1"), the attachment, or a module name
_SECTION = re.compile(r"^(\d+(\.\d+)+|attachment|test_\w+)$")
#: pytest flags that take no value: a section number after one of them is a selection, after any other
#: option (``--maxfail 4.4``? ``--timeout 2.5``) it is that option's value
_FLAGS = frozenset({"-x", "--exitfirst", "-v", "-vv", "-vvv", "--verbose", "-q", "-qq", "--quiet", "-s", "-l", "--showlocals",
                    "--lf", "--last-failed", "--ff", "--failed-first", "--nf", "--new-first", "--sw", "--stepwise",
                    "--pdb", "--co", "--collect-only", "--strict-markers", "--runxfail", "--strict", "--allow-motor-spin"})


def is_selector(token: str, previous: str | None = None) -> bool:
    """Whether ``token`` selects part of the suite: a section number, a test module's name or a path
    to one (``.py``, with or without ``::test``), and not the value of the option before it."""
    if token.startswith("-") or (previous is not None and previous.startswith("-") and "=" not in previous
                                 and previous not in _FLAGS):
        return False
    return bool(_SECTION.match(token)) or ".py" in token or "/" in token


def split_selection(tokens: list[str]) -> tuple[list[str], list[str]]:
    """``ckesc run``'s free arguments -> (selectors, the rest for pytest, without the ``--``)."""
    selectors, rest = [], []
    previous, dashes = None, False
    for token in tokens:
        if token == "--" and not dashes:  # ckesc's own arguments end here
            previous, dashes = None, True
            continue
        (selectors if is_selector(token, previous) else rest).append(token)
        previous = token
    return selectors, rest


def section_modules(where: Path) -> dict[str, Path]:
    """Section number ("4.4.22", "4.1", "attachment") -> its test module, from the module names, in the
    document's order."""
    out: dict[str, Path] = {}
    for path in where.glob("test_*.py"):
        m = re.match(r"test_s(\d+(?:_\d+)*)_", path.name)
        out[m.group(1).replace("_", ".") if m else path.stem.removeprefix("test_").split("_")[0]] = path
    return dict(sorted(out.items(), key=lambda kv: section_key(kv[0])))


def resolve_selection(selectors: list[str], cwd: Path | None = None) -> list[str]:
    """Each selector -> the test module path (with its ``::test`` part) pytest is given; one that names
    nothing of the suite raises :class:`SelectionError`."""
    root = Path(_suite_root())
    where = root / "conformance"
    modules = section_modules(where)
    cwd = cwd or Path.cwd()
    out: list[str] = []
    for sel in selectors:
        head, sep, tail = sel.partition("::")
        if head in modules:
            path = modules[head]
        elif head in {p.stem for p in modules.values()}:
            path = where / f"{head}.py"
        elif _SECTION.match(head) and ".py" not in head:
            what = "test module" if head.startswith("test_") else "section"
            raise SelectionError(f"no conformance {what} {head!r} (sections: {', '.join(modules)})")
        else:
            given = Path(head).expanduser()
            tries = [given] if given.is_absolute() else [cwd / given, root / given]
            path = next((p for p in tries if p.exists()), tries[0]).resolve()
            if not path.exists():
                raise SelectionError(f"{head}: no such file (a section number, a test module's name, or the path of "
                                     f"one in {where})")
            if path != where.resolve() and where.resolve() not in path.parents:
                raise SelectionError(f"{head}: not part of the conformance suite (it is in {where})")
        out.append(f"{path}{sep}{tail}")
    return list(dict.fromkeys(out))


def pytest_argv(args: argparse.Namespace) -> list[str]:
    """pytest's command line for ``args``; raises :class:`SelectionError` for a selection of nothing."""
    selectors, extra = split_selection(list(args.pytest_args))
    targets = resolve_selection(selectors) or ["--pyargs", "conformance"]
    # labgrid (the rig extra) is a library here: its pytest plugin (step logging, LG_ENV) stays out of the run;
    # the run order is the plugin's (harness/schedule.py): pytest-randomly, when installed, only on request
    # (`-- -p randomly`, which comes later on the command line and so wins)
    argv = [*targets, "-p", "no:cacheprovider", "-p", "no:labgrid", "-p", "no:randomly", "--rootdir", _suite_root(), "--ckesc-summary", "--ckesc-reports", args.reports,
            "--dut", args.dut, "--lane", args.lane, "--ckesc-trace-format", args.trace_format,
            "--ckesc-order", getattr(args, "order", "overlap"),
            "-o", "console_output_style=count",
            # ckesc itself is the plugin and is imported before pytest starts: nothing of it needs rewriting
            "-W", "ignore:Module already imported so cannot be rewritten:pytest.PytestAssertRewriteWarning"]
    for opt in ("can_interface", "can_channel", "can_bitrate", "node_id", "nodes", "profile", "power", "power_off_cmd",
                "power_on_cmd", "emulator_faults", "can_bitrate_cmd", "host_send_error", "labgrid_env", "labgrid_target",
                "labgrid_place", "labgrid_coordinator"):
        value = getattr(args, opt)
        if value not in (None, ""):
            argv += [f"--{opt.replace('_', '-')}", str(value)]
    for kv in args.can_config:
        argv += ["--can-config", kv]
    for kv in getattr(args, "emulator_option", []):
        argv += ["--emulator-option", kv]
    if args.emulator_seed:
        argv += ["--emulator-seed", str(args.emulator_seed)]
    if args.allow_motor_spin:
        argv.append("--allow-motor-spin")
    argv.append("-q" if args.quiet else "-v")
    return argv + extra


def run_command(args: argparse.Namespace) -> int:
    import pytest

    collector = _Collector()
    try:
        argv = pytest_argv(args)
    except SelectionError as exc:
        print(f"ckesc run: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    code = pytest.main(argv, plugins=[collector])
    stopped = collector.stopped or ""
    if stopped.startswith("aborted"):  # the DUT did not answer, or the bench went away
        return EXIT_ABORTED
    if stopped.startswith("interrupted") or code == pytest.ExitCode.INTERRUPTED:
        return EXIT_INTERRUPTED
    if code in (pytest.ExitCode.USAGE_ERROR, pytest.ExitCode.INTERNAL_ERROR):
        return EXIT_USAGE
    if code == pytest.ExitCode.NO_TESTS_COLLECTED:  # -k / -m / ::name that match nothing: never the whole suite
        print("ckesc run: error: the selection matches no conformance test", file=sys.stderr)
        return EXIT_USAGE
    results = collector.results
    if not results:
        print("ckesc run: no conformance test ran", file=sys.stderr)
        return EXIT_FAILED
    failed = [r for r in results if r.outcome in ("FAIL", "ERROR")]
    inconclusive = [r for r in results if r.outcome == "INCONCLUSIVE"]
    if failed or (args.strict and inconclusive):
        return EXIT_FAILED
    return EXIT_OK


class _Collector:
    """Keeps the plugin's results once the session ends."""

    results: list = []
    stopped: str | None = None

    def pytest_sessionfinish(self, session):
        from .harness.plugin import state

        st = state(session.config)
        self.results = list(st.results.values())
        self.stopped = st.stopped
