"""``ckesc check-log``: its arguments, output files and exit code; :mod:`ckesc.evidence.checklog` checks the capture."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from ..evidence import checklog
from ..evidence.checklog import DEFAULT_TOLERANCE_S, check_capture, summary_html, summary_text
from ..protocol import catalogue as cat
from ..protocol.catalogue import BAUD_RATES
from ..reporting.exits import ExitStatus
from .common import check_file, check_readable, non_negative_float


def _bitrate_arg(text: str) -> int:
    try:
        value = int(text.lower().replace("k", "000").replace("m", "000000"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a bit rate: {text!r}") from None
    if value not in BAUD_RATES.values():
        raise argparse.ArgumentTypeError(f"{value} is not a CKESC bit rate ({', '.join(map(str, sorted(BAUD_RATES.values())))})")
    return value


def _run_check_log(args: argparse.Namespace) -> int:
    path = args.file
    check_readable(path, "FILE", "capture")
    check_file(args.json, "--json")
    check_file(args.html, "--html")
    jitter = 0.0
    if args.profile:
        from ..bench.profile import DutProfile, ProfileError

        try:
            jitter = DutProfile.load(args.profile).jitter_s
        except ProfileError as exc:
            print(f"ckesc check-log: error: --profile {args.profile}: {exc}", file=sys.stderr)
            return ExitStatus.USAGE
    summary = check_capture(path, bitrate=args.bitrate, tolerance=args.tolerance / 1000, complete=args.complete,
                            power_on=args.power_on, jitter=jitter)
    if summary["frames"] == 0:
        why = summary["damaged"]["first"][0]["reason"] if summary["damaged"]["count"] else "it holds no frame"
        print(f"ckesc check-log: error: nothing readable in {path}: {why}", file=sys.stderr)
        return ExitStatus.USAGE
    try:
        if args.json:
            Path(args.json).write_text(json.dumps(summary, indent=1) + "\n", encoding="utf-8")
        if args.html:
            Path(args.html).write_text(summary_html(summary), encoding="utf-8")
    except OSError as exc:
        print(f"ckesc check-log: error: cannot write {exc.filename}: {exc.strerror}", file=sys.stderr)
        return ExitStatus.USAGE
    print(summary_text(summary))
    if summary["truncated"]:
        cut = summary["truncated"]
        if not args.allow_truncated:
            print(f"ckesc check-log: error: {path} is truncated: {cut['detail']} (--allow-truncated judges what is there)",
                  file=sys.stderr)
            return ExitStatus.USAGE
        print(f"ckesc check-log: warning: {path} is truncated: {cut['detail']}", file=sys.stderr)
    return ExitStatus.FAILED if summary["violations"]["count"] else ExitStatus.OK


def add_check_log_command(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("check-log", help="check a capture (candump .log, .asc, .blf, ...) against the bus rules",
                       description=checklog.__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("file", metavar="FILE", help="the capture: candump -L .log, or any format python-can's LogReader reads")
    p.add_argument("--json", metavar="OUT", help="write the summary as JSON")
    p.add_argument("--html", metavar="OUT", help="write the summary as a self-contained HTML page")
    p.add_argument("--bitrate", type=_bitrate_arg, default=cat.DEFAULT_BITRATE,
                   help=f"the bus's bit rate, for frame durations (default {cat.DEFAULT_BITRATE}, the factory rate; a lower "
                        "value than the real one only makes the timing checks more lenient)")
    p.add_argument("--tolerance", type=non_negative_float, default=DEFAULT_TOLERANCE_S * 1000, metavar="MS",
                   help=f"timing error of the capture's timestamps in ms (default {DEFAULT_TOLERANCE_S * 1000:g})")
    p.add_argument("--complete", action="store_true",
                   help="the capture holds every frame on the bus (no drops): a missing frame is then the sender's fault")
    p.add_argument("--power-on", action="store_true",
                   help="the DUT's power stayed on for the whole capture (a flight): a reset (a power-up count that grew, "
                        "a report gap with a transfer id restart) is then a violation (R19, R17), not an observation, and "
                        "a late first report after a resume is judged")
    p.add_argument("--profile", metavar="NAME|PATH",
                   help="the DUT's profile (a shipped one by name, or a path, as ckesc run takes it): its [timing] jitter_s "
                        "widens each single report interval, as in a run or a soak of the same DUT (default: none, 0)")
    p.add_argument("--allow-truncated", action="store_true",
                   help="a capture shorter than its header declares (BLF) is judged on what it holds, with a warning, "
                        "instead of exit 2")
    p.set_defaults(handler=_run_check_log)
