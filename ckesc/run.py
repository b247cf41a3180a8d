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
import sys

from .harness.traces import TRACE_FORMATS

EXIT_OK, EXIT_FAILED, EXIT_USAGE, EXIT_ABORTED, EXIT_INTERRUPTED = 0, 1, 2, 3, 130


def add_run_command(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "run",
        help="run the conformance suite against a DUT and write reports",
        description=__doc__.split("\n\n")[1] if __doc__ else None,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="Any other pytest option can follow `--`, e.g. `ckesc run -- -k set_freq -x`.",
    )
    g = p.add_argument_group("device under test")
    g.add_argument("--dut", choices=("emulator", "bus"), default="emulator", help="default: emulator")
    g.add_argument("--lane", choices=("simulated", "realtime"), default="simulated",
                   help="for --dut emulator: simulated time (default) or a separate real-time process")
    g.add_argument("--can-interface", help="python-can interface for --dut bus (else can.conf / CAN_INTERFACE)")
    g.add_argument("--can-channel", help="python-can channel, e.g. can0")
    g.add_argument("--can-bitrate", type=int, help="bit rate of the host's bus")
    g.add_argument("--can-config", action="append", default=[], metavar="KEY=VALUE", help="extra bus argument (repeatable)")
    g.add_argument("--node-id", type=int, help="the DUT's node id (default: discovered with GET_ESC_ID)")
    g.add_argument("--nodes", help="emulator: node ids of the emulated bench (default 1)")
    g.add_argument("--profile", help="DUT profile name (fixtures/duts) or path")
    g.add_argument("--power", choices=("emulator", "command", "manual", "none"), help="power control")
    g.add_argument("--power-off-cmd", help="--power command: switches the DUT off")
    g.add_argument("--power-on-cmd", help="--power command: switches the DUT on")
    g.add_argument("--allow-motor-spin", action="store_true", default=None,
                   help="allow non-zero throttle on a real ESC (propellers off!)")
    g.add_argument("--emulator-faults", default="", help="emulator: comma-separated fault names to switch on")
    g.add_argument("--emulator-seed", type=int, default=0)
    o = p.add_argument_group("output")
    o.add_argument("--reports", default="reports", metavar="DIR", help="where reports go (default: reports/)")
    o.add_argument("--strict", action="store_true", help="INCONCLUSIVE results fail the run too")
    o.add_argument("--trace-format", choices=TRACE_FORMATS, default="blf",
                   help="each test's CAN traffic under <run>/traces/: blf (default), asc, log (candump), none")
    o.add_argument("-q", "--quiet", action="store_true", help="no per-test progress lines")
    p.add_argument("pytest_args", nargs=argparse.REMAINDER, help="after --: passed to pytest")
    p.set_defaults(handler=run_command)


def pytest_argv(args: argparse.Namespace) -> list[str]:
    argv = ["--pyargs", "conformance", "-p", "no:cacheprovider", "--ckesc-summary", "--ckesc-reports", args.reports,
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
