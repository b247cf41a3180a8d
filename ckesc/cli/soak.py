"""``ckesc soak``: hours of flight-like running, watched (:mod:`ckesc.soak`), with ``ckesc run``'s bench options.

Exit 0 nothing found, 1 a finding, 2 a set-up mistake (as ``ckesc run``), 3 the bench could not be used (the DUT
did not answer, the bench went away: as ``ckesc run``'s aborted run), 130 interrupted (the report written, marked
INTERRUPTED)."""

from __future__ import annotations

import argparse
import re
import sys

from ..reporting.exits import ExitStatus
from ..soak import split, trace
from .common import UsageError, check_dir, check_file, duration_arg, positive_float, seconds_of
from .run import add_bench_options


def parse_channels(text: str) -> tuple[int, ...]:
    """``1-4``, ``1,3``, ``1-4,7`` -> the channels."""
    out: list[int] = []
    for part in text.split(","):
        m = re.fullmatch(r"\s*(\d+)\s*(?:-\s*(\d+))?\s*", part)
        if not m:
            raise argparse.ArgumentTypeError(f"channels like 1-4 or 1,3, not {text!r}")
        lo, hi = int(m.group(1)), int(m.group(2) or m.group(1))
        out.extend(range(lo, hi + 1))
    return tuple(dict.fromkeys(out))


def parse_throttle(text: str) -> tuple[tuple[float, int], ...]:
    """``0:0,10m:200,1h:0`` -> ((0, 0), (600, 200), (3600, 0)): from each time on, that throttle (0..2000)."""
    steps = []
    for part in text.split(","):
        at, _, value = part.partition(":")
        if not value.strip().isdigit():
            raise argparse.ArgumentTypeError(f"a throttle profile like 0:0,10m:200,1h:0, not {text!r}")
        try:
            steps.append((seconds_of(at), int(value)))
        except ValueError as exc:
            raise argparse.ArgumentTypeError(f"{exc} (in the throttle profile {text!r})") from None
    return tuple(sorted(steps))


def _size(text: str) -> int:
    try:
        size = trace.parse_size(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    if 0 < size < trace.MIN_BUDGET:
        raise argparse.ArgumentTypeError(f"{text}: at least {trace.MIN_BUDGET} bytes (room for the findings' frames "
                                         "and the rolling files), or 0 for no trace")
    return size


def add_soak_command(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "soak",
        help="hours of flight-like running (a RawCommand stream, GET_ESC_ID once a second, 241 and 242 read), "
             "watched for resets, interval drift, comm flag glitches, late answers and changed settings",
        description="Play a flight controller for --duration (R19) and watch, continuously and with one owner each: "
                    "resets (241's power-up count and run time, report gaps with a transfer id restart), R9 over every "
                    "minute, the comm flag while the stream runs, GET_ESC_ID's answer delays (R2, 64 ms), the settings "
                    "(242), frames the ESC should not send. The end: a statement per property (with none found, the "
                    "rule of three). In the simulated lane hours cost minutes. Exit 0 nothing found, 1 a finding, 2 a "
                    "set-up mistake, 3 the bench could not be used, 130 interrupted (the report written, marked "
                    "INTERRUPTED). Throttle is zero unless --allow-motor-spin and --throttle-profile.",
    )
    add_bench_options(p)
    s = p.add_argument_group("soak")
    s.add_argument("--duration", type=duration_arg, default=600.0, metavar="DURATION",
                   help="how long to run, lane time (8h, 30m, 90s, 1h30m; default 10m)")
    s.add_argument("--rate", type=positive_float, default=400.0, metavar="HZ", help="RawCommand rate, 50-500 Hz (default 400)")
    s.add_argument("--format", choices=("14b", "12b", "10b"), default="14b", help="RawCommand format (default 14b)")
    s.add_argument("--channels", type=parse_channels, metavar="LIST",
                   help="throttle channels the stream commands, e.g. 1-4 (default: every channel of one frame)")
    s.add_argument("--throttle-profile", type=parse_throttle, default=(), metavar="T:V,...",
                   help="throttle (0..2000) from each time on, e.g. 0:0,1m:200,2h:0; needs --allow-motor-spin "
                        "(PROPELLERS OFF); default zero throttle")
    s.add_argument("--trace-budget", type=_size, default=trace.DEFAULT_BUDGET, metavar="SIZE",
                   help="disk the run's trace may take in its report directory: a rolling candump log of every frame "
                        "(the oldest file deleted as a new one starts) and each finding's frames in a file of its own, "
                        f"never deleted (200MB, 1GB, 500kB; at least {trace.MIN_BUDGET // 1000}kB; 0: no trace; default "
                        f"{trace.DEFAULT_BUDGET // 10**6}MB)")
    s.add_argument("--processes", choices=split.CHOICES, default="auto",
                   help="a simulated soak's world in a process of its own beside the reader's (2: two cores busy), "
                        "or not (1); auto: 2 where the machine has two cores or more (default)")
    s.add_argument("--stop-on-finding", action="store_true", help="stop at the first finding (the report written)")
    s.add_argument("--reports", default="reports", metavar="DIR", help="where reports go (default: reports/)")
    s.add_argument("-q", "--quiet", action="store_true", help="no console lines")
    s.add_argument("--status-file", metavar="FILE", help=argparse.SUPPRESS)  # a rig batch's bench: its live figures
    r = p.add_argument_group("several benches at once")
    r.add_argument("--rig", metavar="FILE",
                   help="a rig file (fixtures/rigs/*.toml): soak every bench of it at once, each a ckesc soak process of "
                        "its own with the bench's options from the file and the soak options given here; one console "
                        "line per bench; each bench's report in reports/<UTC>-soak-batch/<bench>/, batch.json and "
                        "summary.txt beside them; the exit status the worst bench's")
    r.add_argument("--benches", metavar="A,B", help="--rig: only these benches (default: every bench of the rig)")

    def handler(args: argparse.Namespace) -> int:
        from ..bench.dut import DutError
        from ..bench.errors import BenchError, PreflightError
        from ..bench.lanes import BenchGone
        from ..bench.station import BenchOptions
        from ..soak import runner

        check_dir(args.reports, "--reports")
        check_file(args.status_file, "--status-file", "status file")
        spin = bool(args.allow_motor_spin) or bool(args.rig)  # (a rig's bench says whether its motor may spin)
        if args.throttle_profile and any(v for _, v in args.throttle_profile) and not spin:
            raise UsageError("--throttle-profile spins the motor: give --allow-motor-spin too (PROPELLERS OFF)")
        from ..soak.player import FlightPlan

        try:  # the stream's own options, checked before the bench is opened
            FlightPlan(0, 1, format=args.format, rate_hz=args.rate, channels=args.channels or (1,),
                       throttle=args.throttle_profile, allow_motor_spin=spin).check()
        except ValueError as exc:
            raise UsageError(str(exc)) from None
        given = {k: getattr(args, k) for k in runner.OPTION_NAMES if getattr(args, k, None) not in (None, [], "")}
        if args.rig:
            return _batch(args, given)
        if args.benches:
            raise UsageError("--benches chooses benches of a rig: it needs --rig FILE")
        soak = runner.SoakOptions(duration_s=args.duration, rate_hz=args.rate, format=args.format,
                                  channels=args.channels, throttle=args.throttle_profile,
                                  stop_on_finding=args.stop_on_finding, reports=args.reports, quiet=args.quiet,
                                  trace_budget=args.trace_budget, status_file=args.status_file,
                                  processes=args.processes)
        try:
            outcome = runner.run(BenchOptions.of(vars(args).get), soak, out=sys.stdout, given=given)
        except (PreflightError, BenchError, ValueError) as exc:
            raise UsageError(str(exc)) from None
        except (DutError, BenchGone, OSError) as exc:
            print(f"ckesc soak: cannot use the bench: {exc}", file=sys.stderr)
            return ExitStatus.ABORTED
        if outcome.status == runner.INTERRUPTED:
            return ExitStatus.INTERRUPTED
        if outcome.status == runner.ABORTED:
            return ExitStatus.ABORTED
        return ExitStatus.FAILED if outcome.findings else ExitStatus.OK

    p.set_defaults(handler=handler)


def _batch(args: argparse.Namespace, given: dict) -> int:
    """``ckesc soak --rig``: the soak's own options passed on to every bench's ``ckesc soak``."""
    from ..soak import batch

    soak = ["--duration", f"{args.duration:g}s", "--rate", f"{args.rate:g}", "--format", args.format,
            "--trace-budget", str(args.trace_budget), "-q"]
    if args.channels:
        soak += ["--channels", ",".join(map(str, args.channels))]
    if args.throttle_profile:
        soak += ["--throttle-profile", ",".join(f"{at:g}s:{v}" for at, v in args.throttle_profile)]
    if args.stop_on_finding:
        soak.append("--stop-on-finding")
    try:
        return batch.run_batch(args.rig, args.benches, soak, args.reports, given=given, quiet=args.quiet)
    except batch.SoakBatchError as exc:
        raise UsageError(str(exc)) from None
