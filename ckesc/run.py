"""``ckesc run``: the whole conformance suite against a DUT, with reports.

    ckesc run                                   # the emulator, simulated time (exact timing)
    ckesc run --lane realtime                   # `ckesc emulate` in its own process, through socketcand
    ckesc run --dut bus --can-interface socketcan --can-channel can0 --power manual
    ckesc run --dut bus ... --power labgrid --labgrid-env env.yaml --labgrid-target esc   # power by labgrid
    ckesc run 4.4.22 4.4.3                      # some sections (numbers as in the document)
    ckesc run conformance/test_s4_4_22_set_freq.py   # a test module, by path (absolute or relative)
    ckesc run 4.4.22 -- -k read -x              # pytest's own arguments after `--`, handed on untouched
    ckesc run --rig fixtures/rigs/example.toml [--benches a,b] [4.4.3 ...]   # every bench of a rig at once


Runs pytest in this process over the installed ``conformance`` package with the ckesc plugin's
options, shows one progress line per test, writes ``reports/<timestamp>/`` (JUnit, JSON, summary)
with ``reports/latest`` pointing at it, and exits 0 only when no test FAILed or ERRORed and no bus rule
was broken while a SKIPPED test ran (INCONCLUSIVE and SKIPPED are reported, and ``--strict`` makes
INCONCLUSIVE fail the run too): the status the session's end decided (:func:`ckesc.reporting.exits.of_run`).

With ``--rig``, the same on every bench of a rig file at once (:func:`run_batch`): pytest-xdist, one worker
per bench (:mod:`ckesc.rigs.batch`), each bench's report in ``reports/<timestamp>/<bench>/`` and the
batch's own (``batch.html``, ``batch.json``, ``junit.xml``: :mod:`ckesc.rigs.batch_report`) beside them.
"""

from __future__ import annotations

import argparse
import re
import shlex
import shutil
import sys
import time
from pathlib import Path
from typing import Any

from .protocol.requirements import section_key
from .reporting.exits import ExitStatus
from .session import options


def _suite_root() -> str:
    """The directory holding the ``conformance`` package (a checkout, or site-packages of a wheel install):
    pytest's rootdir, so that test ids read ``conformance/test_s4_4_22_set_freq.py::...`` however the
    suite was installed and wherever it is run from."""
    from .session.collection import conformance_dir  # pytest with it: only when a run is about to start

    where = conformance_dir()
    return str(where.parent) if where else "."


class SelectionError(ValueError):
    """A section or test module on the command line that names nothing of the suite (one line)."""


#: a section number as the document numbers them ("4.4.22", "4.1"), the attachment, or a module name
_SECTION = re.compile(r"^(\d+(\.\d+)+|attachment|test_\w+)$")


def section_modules(where: Path) -> dict[str, list[Path]]:
    """Section number ("4.4.22", "4.1", "attachment", "robustness") -> its test modules (a section may have
    several: robustness has R17's and R18's), from the module names, in the document's order."""
    out: dict[str, list[Path]] = {}
    for path in sorted(where.glob("test_*.py")):
        m = re.match(r"test_s(\d+(?:_\d+)*)_", path.name)
        out.setdefault(m.group(1).replace("_", ".") if m else path.stem.removeprefix("test_").split("_")[0], []).append(path)
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
        if head in modules and not sep:
            out.extend(str(p) for p in modules[head])
            continue
        if head in modules and len(modules[head]) == 1:
            path = modules[head][0]
        elif head in {p.stem for ps in modules.values() for p in ps}:
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


def targets_of(args: argparse.Namespace) -> list[str]:
    """What pytest collects for ``args``' selection (the whole suite without one); raises :class:`SelectionError`
    for a selection of nothing. Always paths under :func:`_suite_root` (resolved, as the rootdir is): pytest names a
    test by its path relative to the rootdir only when it is under it, so the whole suite by ``--pyargs conformance``
    (found through ``sys.path``, e.g. a venv's ``lib64`` symlink) had ids ``test_s4_1_framing.py::...`` that
    ``ckesc run`` cannot select."""
    return resolve_selection(list(args.selection)) or [str(Path(_suite_root()) / "conformance")]


def pytest_argv(args: argparse.Namespace) -> list[str]:
    """pytest's command line for ``args``; raises :class:`SelectionError` for a selection of nothing."""
    targets = targets_of(args)
    # labgrid (the rig extra) is a library here: its pytest plugin (step logging, LG_ENV) stays out of the run;
    # the run order is the plugin's (session/schedule.py): pytest-randomly, when installed, only on request
    # (`-- -p randomly`, which comes later on the command line and so wins)
    argv = [*targets, "-p", "no:cacheprovider", "-p", "no:labgrid", "-p", "no:randomly", "--rootdir", _suite_root(),
            "--ckesc-summary", *options.command_line({o.dest: getattr(args, o.dest) for o in options.run_options()}),
            "-o", "console_output_style=count",
            # ckesc itself is the plugin and is imported before pytest starts: nothing of it needs rewriting
            "-W", "ignore:Module already imported so cannot be rewritten:pytest.PytestAssertRewriteWarning",
            "-q" if args.quiet else "-v",
            # what a person reads first ends the console: the counts and the failures by cause (the plugin's summary);
            # each test's traceback and pytest's short summary only with --verbose (the reports hold them all), and
            # pytest's header, whose rootdir is the installed package's, not the user's
            "--no-header", *(("--tb=short", "-rfE") if getattr(args, "verbose", False) else ("--tb=no", "-rN"))]
    return argv + list(args.pytest_args)  # last: pytest's own word wins


class _AfterDashes:
    """What pytest made of the arguments after ``--``, read by pytest's own parser: a free argument there (not an
    option's value) would be a path for pytest to collect, beside the selection (``ckesc run -- --no-header 4.4.22``:
    "file not found: 4.4.22"). It is a usage error that names the way out: the selection goes before ``--``."""

    def __init__(self, targets: list[str], args: argparse.Namespace) -> None:
        self.targets, self.args = targets, args

    def pytest_cmdline_main(self, config) -> int | None:  # (registered after pytest's own: before its session)
        extra = [a for a in config.args if a not in self.targets]  # (targets: the paths)
        if not extra:
            return None
        rest = [a for a in self.args.pytest_args if a not in extra]
        way_out = shlex.join(["ckesc", "run", *self.args.selection, *extra, "--", *rest])
        print(f"ckesc run: error: {extra[0]} after `--` would be a path for pytest to collect: the selection goes before "
              f"`--` ({way_out})", file=sys.stderr)
        return ExitStatus.PYTEST_USAGE


def run_command(args: argparse.Namespace) -> int:
    import pytest

    if args.rig:
        return run_batch(args)
    if args.benches:
        print("ckesc run: error: --benches chooses benches of a rig: it needs --rig FILE", file=sys.stderr)
        return ExitStatus.USAGE

    collector = _Collector()
    try:
        argv, targets = pytest_argv(args), targets_of(args)
    except SelectionError as exc:
        print(f"ckesc run: error: {exc}", file=sys.stderr)
        return ExitStatus.USAGE
    code = pytest.main(argv, plugins=[collector, _AfterDashes(targets, args)])
    status = collector.status  # the session's end decided it from the run's results
    if status in (ExitStatus.ABORTED, ExitStatus.INTERRUPTED):  # the DUT did not answer, the bench went away; Ctrl-C
        return status
    if code in (pytest.ExitCode.USAGE_ERROR, pytest.ExitCode.INTERNAL_ERROR):
        return ExitStatus.USAGE
    if code == pytest.ExitCode.NO_TESTS_COLLECTED:  # -k / -m / ::name that match nothing: never the whole suite
        print("ckesc run: error: the selection matches no conformance test", file=sys.stderr)
        return ExitStatus.USAGE
    if status is None and code == pytest.ExitCode.INTERRUPTED:  # before any test (collecting)
        return ExitStatus.INTERRUPTED
    if status is None or not collector.ran:
        print("ckesc run: no conformance test ran", file=sys.stderr)
        return ExitStatus.FAILED
    return status


class _Collector:
    """Keeps what the session's end decided: the run's exit status, and whether any conformance test ran."""

    status: ExitStatus | None = None
    ran: bool = False

    def pytest_unconfigure(self, config):  # (after every pytest_sessionfinish)
        from .session.state import state

        st = state(config)
        self.status, self.ran = st.exit_status, bool(st.results)


# ----------------------------------------------------------------------------------------- batches
class RunBatchError(ValueError):
    """A batch that cannot start: the rig file, a bench's set-up, the options (one line, exit 2)."""


def _static_preflight(bench) -> None:
    """The bench's preflight without its bus (that is opened by its own worker: a bench that is not there is
    ABSENT, not a set-up mistake of the batch)."""
    from .bench import checks
    from .bench.errors import PreflightError
    from .bench.station import BenchOptions

    opts = {**options.BENCH_OPTIONS, **bench.options()}
    if opts.get("power") == "manual":
        raise RunBatchError(f"bench {bench.name}: power 'manual' prompts an operator at the console, which a batch cannot; "
                         f"run that bench alone: {bench.command_line()}")
    try:
        checks.check(BenchOptions.of(opts.get))
    except PreflightError as exc:
        raise RunBatchError(f"bench {bench.name}: {exc}") from None


def batch_plan(args: argparse.Namespace) -> tuple[Any, list]:
    """The rig and its chosen benches, each checked (:class:`RunBatchError`)."""
    from .rigs import rig as rigs

    given = [o for o in map(options.BY_DEST.get, options.BENCH_OPTIONS)
             if getattr(args, o.dest, None) not in (o.default_on(run=True), None, [], "")]
    if given:
        raise RunBatchError(f"{given[0].run_flags[0]} is set per bench in the rig file ({given[0].rig}; with --rig, the rig "
                         "says it)")
    try:
        rig = rigs.load(args.rig)
        benches = rig.select([b.strip() for b in (args.benches or "").split(",") if b.strip()])
    except rigs.RigError as exc:
        raise RunBatchError(str(exc)) from None
    for bench in benches:
        _static_preflight(bench)
    return rig, benches


def run_batch(args: argparse.Namespace) -> int:
    """``ckesc run --rig FILE [--benches a,b]``: the selected sections on every chosen bench at once."""
    import pytest

    try:
        import xdist  # noqa: F401 - the batch's engine
    except ImportError:
        print("ckesc run: error: --rig runs its benches through pytest-xdist, which is not installed: "
              "pip install 'ckesc-conformance[rig]' (or pip install -e '.[rig]' in a checkout)", file=sys.stderr)
        return ExitStatus.USAGE
    from .reporting import report as reports
    from .rigs import batch, batch_report
    from .session import preflight

    try:
        rig, benches = batch_plan(args)
        targets = targets_of(args)
        preflight.reports_writable(args.ckesc_reports)
    except (RunBatchError, SelectionError, preflight.PreflightError) as exc:
        print(f"ckesc run: error: {exc}", file=sys.stderr)
        return ExitStatus.USAGE
    started = time.time()
    batch_dir = reports.run_dir(Path(args.ckesc_reports), started)
    plans = [{"name": b.name, "options": b.options(), "report_dir": str((batch_dir / b.name).resolve())} for b in benches]
    records: dict[str, dict[str, Any]] = {}

    def record(name: str, said: dict[str, Any]) -> dict[str, Any]:
        bench = rig.benches[name]
        if said.get("setup_error"):
            (batch_dir / name).mkdir(exist_ok=True)
            (batch_dir / name / "setup-error.txt").write_text(said["setup_error"] + "\n", encoding="utf-8")
        rec = batch_report.bench_record(name, batch_dir / name, batch_dir, description=bench.description,
                                        command=bench.command_line(), setup_error=said.get("setup_error"),
                                        crash=said.get("crash"), strict=args.ckesc_strict)
        if said.get("setup_error"):
            rec.setdefault("files", {})["setup-error.txt"] = f"{name}/setup-error.txt"
        rec["seconds"] = round(said.get("seconds") or (time.time() - started), 3)
        return rec

    def finished(name: str, said: dict[str, Any]) -> None:
        records[name] = record(name, said)
        print(batch_report.progress_line(records[name], records[name]["seconds"], batch_dir), flush=True)

    controller = batch.Controller(plans, on_finished=finished)
    # no:tmpdir: xdist would make a pytest-of-<user> base directory for the workers' tmp_path, which no
    # conformance test uses (a one-bench run makes none either)
    # no:labgrid, no:randomly: as in a one-bench run (labgrid is a library here; the run order is the plugin's)
    argv = [*targets, "-p", "no:cacheprovider", "-p", "no:terminal", "-p", "no:tmpdir", "-p", "no:labgrid",
            "-p", "no:randomly", "--rootdir", _suite_root(),
            "--ckesc-reports", str(batch_dir), "--ckesc-trace-format", args.ckesc_trace_format,
            "-p", "ckesc.rigs.batch", "-n", str(len(benches)), "--dist", "each", "--max-worker-restart", "0",
            "-W", "ignore:Module already imported so cannot be rewritten:pytest.PytestAssertRewriteWarning", *args.pytest_args]
    print(f"ckesc run: batch of {len(benches)} benches ({', '.join(b.name for b in benches)}) from {rig.path}; "
          f"reports in {batch_dir}/", flush=True)
    controller.install_signals()
    try:
        code = pytest.main(argv, plugins=[controller, _AfterDashes(targets, args)])
    finally:
        controller.restore_signals()
    if code in (pytest.ExitCode.USAGE_ERROR, pytest.ExitCode.INTERNAL_ERROR) and not records:
        print("ckesc run: error: the batch could not start (pytest's message above)", file=sys.stderr)
        shutil.rmtree(batch_dir, ignore_errors=True)
        return ExitStatus.USAGE
    for b in benches:
        if b.name not in records:  # its worker never reported back
            records[b.name] = record(b.name, {"crash": "its worker ended without reporting back"})
    latest = batch_dir / "latest"  # each bench's run pointed its base's latest at itself: the batch is the run here
    if latest.is_symlink():
        latest.unlink()
    doc = batch_report.write(batch_dir, [records[b.name] for b in benches], rig=str(rig.path), started=started,
                             finished=time.time(), interrupted=controller.interrupted)
    reports.point_latest(batch_dir)
    print(f"batch: {', '.join(f'{n} {s}' for s, n in doc['statuses'].items())} in {doc['seconds']:.1f} s; "
          f"{batch_dir / 'batch.html'}", flush=True)
    return doc["exit_status"]
