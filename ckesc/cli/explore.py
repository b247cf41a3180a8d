"""``ckesc explore``: model-based exploration of a DUT (:mod:`ckesc.explore`), with ``ckesc run``'s bench options."""

from __future__ import annotations

import argparse
import sys

from ..reporting.exits import ExitStatus
from .common import UsageError, check_dir, check_faults, check_file, check_readable, duration_arg, positive_int
from .run import add_bench_options

#: ``--budget``'s type: ``90``, ``90s``, ``10m``, ``1h``, ``1h30m`` -> seconds, more than zero
parse_budget = duration_arg


def add_explore_command(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "explore",
        help="generate programs of host actions, run them on the DUT and the ESC model in lockstep, shrink every "
             "disagreement to a replayable test",
        description="Model-based exploration (issue #22): programs of host actions drawn from the frame catalogue run "
                    "on the DUT, a faultless ESC model fed the same frames at the same bus times predicts what the "
                    "document requires, and every disagreement is shrunk on the DUT to the shortest program that shows "
                    "it, written as a replay file and a standalone pytest test. Exit 1 when something was found.",
    )
    add_bench_options(p)
    x = p.add_argument_group("exploration")
    x.add_argument("--budget", type=parse_budget, default=600.0, metavar="DURATION",
                   help="how long the exploration takes, wall time, shrinking what it finds included (90s, 10m, 1h; "
                        "default 10m): a finding shown late is shrunk for what is left, and says so")
    x.add_argument("--seed", type=int, default=0, help="same seed, same programs (default 0)")
    x.add_argument("--replay", metavar="FILE", help="run the program of a replay file once (a finding's "
                   "findings/finding_N.replay.json) on the bench it names, or on the bench options given")
    x.add_argument("--max-steps", type=positive_int, default=12, help="the longest program generated (default 12)")
    x.add_argument("--database", metavar="DIR", help="where every finding's program is kept: the next exploration runs them first "
                   "(default: <reports>/explore-db; 'none' for none)")
    x.add_argument("--load", action="store_true", help="also draw foreign-load steps (R18: the suite's load generator at "
                   "10, 30 or 50 %% of the bus from then on, or 70 %% for a while, OBSERVE); the simulated lane only "
                   "(--selftest: for a fault that breaks R18 always)")
    x.add_argument("--bus", action="store_true", help="also draw R20's steps: a bus short (CANH-CANL) for 20 ms to 0.8 s "
                   "where the bench can cause one (the simulated lane, ckesc emulate, --bus-fault-cmd), and a power cycle "
                   "with the host alone on the bus sending while the ESC is off (--selftest: for a fault that breaks R20 "
                   "always)")
    x.add_argument("--first", action="store_true", help="stop at the first finding (once shrunk)")
    x.add_argument("--selftest", metavar="FAULTS", help="the self-test: for each emulator fault (comma-separated, or "
                   "'all'), explore a fresh emulated bench from --seed until it is found or --budget is spent, and "
                   "say within how many programs, steps and seconds (a Markdown table; --out writes it and its JSON)")
    x.add_argument("--max-programs", type=positive_int, help="also stop after this many programs (per fault with --selftest)")
    x.add_argument("--out", metavar="FILE", help="--selftest: write the table here and its JSON beside it")
    o = p.add_argument_group("output")
    o.add_argument("--reports", default="reports", metavar="DIR", help="where reports go (default: reports/)")
    o.add_argument("-q", "--quiet", action="store_true", help="no progress lines")

    def handler(args: argparse.Namespace) -> int:
        from ..explore import command

        if not args.replay:  # (a replay writes no report)
            check_dir(args.reports, "--reports")
        if args.database not in (None, "none"):
            check_dir(args.database, "--database", "database directory")
        check_file(args.out, "--out")
        check_readable(args.replay, "--replay", "replay file")
        check_faults(args.selftest, "--selftest")
        given = {k for k in command.BENCH_OPTIONS if getattr(args, k) != p.get_default(k)}
        try:
            return command.main(args, given, out=sys.stdout)
        except command.BenchProblem as exc:
            print(f"ckesc explore: {exc}", file=sys.stderr)
            return ExitStatus.ABORTED
        except ValueError as exc:
            raise UsageError(str(exc)) from None

    p.set_defaults(handler=handler)
