"""``ckesc run``: the whole conformance suite against a DUT, with reports.

    ckesc run                                   # the emulator, simulated time (exact timing)
    ckesc run --lane realtime                   # `ckesc emulate` in its own process, through socketcand
    ckesc run --dut bus --can-interface socketcan --can-channel can0 --power manual

Runs pytest in this process over the installed ``conformance`` package with the ckesc plugin's
options, shows one progress line per test, writes ``reports/<timestamp>/`` (JUnit, JSON, summary)
with ``reports/latest`` pointing at it, and exits 0 only when no test FAILed or ERRORed
(INCONCLUSIVE and SKIPPED are reported, and ``--strict`` makes INCONCLUSIVE fail the run too).
"""

from __future__ import annotations

import argparse
import importlib.util
import sys
from pathlib import Path

EXIT_OK, EXIT_FAILED, EXIT_USAGE, EXIT_ABORTED, EXIT_INTERRUPTED = 0, 1, 2, 3, 130


def _suite_root() -> str:
    """The directory holding the ``conformance`` package (a checkout, or site-packages of a wheel install):
    pytest's rootdir, so that test ids read ``conformance/test_s4_4_22_set_freq.py::...`` however the
    suite was installed and wherever it is run from."""
    spec = importlib.util.find_spec("conformance")
    locations = list(spec.submodule_search_locations or []) if spec else []
    return str(Path(locations[0]).resolve().parent) if locations else "."


def pytest_argv(args: argparse.Namespace) -> list[str]:
    argv = ["--pyargs", "conformance", "-p", "no:cacheprovider", "--rootdir", _suite_root(), "--ckesc-summary", "--ckesc-reports", args.reports,
            "--dut", args.dut, "--lane", args.lane, "--ckesc-trace-format", args.trace_format,
            "-o", "console_output_style=count",
            # ckesc itself is the plugin and is imported before pytest starts: nothing of it needs rewriting
            "-W", "ignore:Module already imported so cannot be rewritten:pytest.PytestAssertRewriteWarning"]
    for opt in ("can_interface", "can_channel", "can_bitrate", "node_id", "nodes", "profile", "power", "power_off_cmd",
                "power_on_cmd", "emulator_faults"):
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
    extra = list(args.pytest_args)
    if extra and extra[0] == "--":
        extra = extra[1:]
    return argv + extra


def run_command(args: argparse.Namespace) -> int:
    import pytest

    collector = _Collector()
    code = pytest.main(pytest_argv(args), plugins=[collector])
    stopped = collector.stopped or ""
    if stopped.startswith("aborted"):  # the DUT did not answer, or the bench went away
        return EXIT_ABORTED
    if stopped.startswith("interrupted") or code == pytest.ExitCode.INTERRUPTED:
        return EXIT_INTERRUPTED
    if code in (pytest.ExitCode.USAGE_ERROR, pytest.ExitCode.INTERNAL_ERROR):
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
