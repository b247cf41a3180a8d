"""``ckesc bisect``: the first bad image of a build history (issue #37). Its arguments and exit status;
:mod:`ckesc.bisect` bisects, each step a real ``ckesc run --firmware IMAGE``.

Exit 0 with the first bad image named on the console's last lines; 1 when it cannot decide (a step without a
majority, or the canary, the known-good image, failing: the bench kept state); 2 for a mistake in the arguments
(before any run) or a bench error in a step (a flash that failed or hung, an image that is not the one running, a
bench that went away)."""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

from ..bisect import report, steps
from ..bisect.core import CANARY_CHOICES, Ending
from ..reporting.exits import ExitStatus
from ..reporting.report import run_dir
from ..session import options
from .common import UsageError, check_dir, check_images, positive_int

USAGE = ("%(prog)s [BENCH OPTION ...] --images LIST [--flash-cmd \"CMD {image}\"] [--tries N] [--canary every|end] "
         "(SELECTION ... | --regressed OLD_RUN NEW_RUN)")
#: the bench options a bisect does not take: it names each step's image itself, and each image says its own 240
NOT_PASSED = ("firmware", "expect_firmware")
#: each ending's exit status (the one exit table)
EXITS = {Ending.FOUND: ExitStatus.OK, Ending.UNDECIDED: ExitStatus.FAILED, Ending.STATE_KEPT: ExitStatus.FAILED,
         Ending.BENCH_ERROR: ExitStatus.USAGE}


def _bench_rows() -> list[options.Option]:
    return [o for o in options.bench_options() if o.dest not in NOT_PASSED and o.run_flags]


def run_args(args: argparse.Namespace) -> list[str]:
    """The bench options given to ``ckesc bisect``, as ``ckesc run`` takes them for each step (defaults left out)."""
    out: list[str] = []
    for o in _bench_rows():
        value: Any = getattr(args, o.dest)
        if value is None or value is False or value == [] or value == o.default_on(run=True):
            continue
        flag = o.run_flags[0]
        if o.action == "store_true":
            out.append(flag)
        elif o.action == "append":
            out += [f"{flag}={v}" for v in value]
        else:
            out.append(f"{flag}={value}")
    return out


def add_bisect_command(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "bisect", usage=USAGE, help="find the first bad firmware image between a known-good and a known-bad one",
        description=__doc__.split("\n\n")[0] if __doc__ else None,
        epilog="Each step flashes an image (--flash-cmd, {image} replaced by its path; with --dut emulator an emulator "
               "image needs none), proves it and runs the SELECTION as `ckesc run --firmware IMAGE ...` does. A step "
               "is retried --tries times and a majority decides; the known-good image is run again at the end (and, "
               "--canary every, after every step): failing, the bench kept state. Reports in DIR/<timestamp>-bisect/.")
    g = p.add_argument_group(options.DUT)
    for o in _bench_rows():
        g.add_argument(*o.run_flags, **o.arguments(run=True))
    b = p.add_argument_group("bisect")
    b.add_argument("--images", required=True, metavar="LIST",
                   help="a file of image paths, one a line, oldest first: the first known good, the last known bad "
                        "(or a directory, its images ordered by the firmware date 240 answers for each, else by name)")
    b.add_argument("--tries", type=positive_int, default=1, metavar="N",
                   help="runs of each step; more than half of them decide it (default 1)")
    b.add_argument("--canary", choices=CANARY_CHOICES, default="end",
                   help="run the known-good image again at the end (default) or after every step too")
    b.add_argument("--reports", default="reports", metavar="DIR",
                   help="write the bisect's report in DIR/<timestamp>-bisect/ (every step's run under its steps/)")
    b.add_argument("--regressed", nargs=2, metavar=("OLD_RUN", "NEW_RUN"),
                   help="what each step runs: whatever regressed from one run to the other (ckesc compare's "
                        "regressions: tests that passed in OLD_RUN and do not in NEW_RUN), instead of a SELECTION")
    b.add_argument("selection", nargs="*", metavar="SELECTION",
                   help="what each step runs: sections, test modules or test ids, as ckesc run takes them")

    def handler(args: argparse.Namespace) -> int:
        images = check_images(args.images, "--images")
        check_dir(args.reports, "--reports")
        if bool(args.selection) == bool(args.regressed):
            raise UsageError("give what each step runs: a SELECTION (sections, modules, test ids) or --regressed "
                             "OLD_RUN NEW_RUN, one of the two")
        if args.regressed:
            try:
                args.selection = steps.regressed_tests(*args.regressed)
            except ValueError as exc:
                raise UsageError(str(exc)) from None
        if any(s.startswith("-") for s in args.selection):
            raise UsageError(f"{next(s for s in args.selection if s.startswith('-'))} is not an option of ckesc bisect")
        where = run_dir(Path(args.reports), time.time(), "bisect")
        passed = run_args(args)
        print(f"bisect: {len(images)} images, {images[0].name} good .. {images[-1].name} bad, tries {args.tries}, "
              f"canary {args.canary}; reports {where}", flush=True)
        done = steps.bisect(images, args.selection,
                            lambda image, out: steps.run_once(image, passed, args.selection, out),
                            where / "steps", tries=args.tries, canary=args.canary,
                            say=lambda line: print(line, flush=True))
        report.write(done, where)
        for line in report.last_lines(done):
            print(line)
        print(f"report: {where / 'bisect.txt'}")
        return ExitStatus.INTERRUPTED if done.result is None else EXITS[done.result.ending]

    p.set_defaults(handler=handler)
