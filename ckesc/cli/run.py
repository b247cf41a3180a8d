"""``ckesc run``: its arguments; :mod:`ckesc.run` runs the suite with them.

The options are made from the run's option table (``ckesc/session/options.py``), as pytest's are. The
command line splits at the first ``--``: before it, ``ckesc run``'s options and the selection (sections, test
modules, paths); after it, pytest's arguments, handed on untouched."""

from __future__ import annotations

import argparse
import shlex
from typing import Any

from .. import run as run_lib
from ..session import options
from .common import UsageError, check_dir, check_readable, check_run

USAGE = "%(prog)s [OPTION ...] [SECTION | MODULE[::TEST] ...] [-- PYTEST_ARGUMENT ...]"


def add_bench_options(p: argparse.ArgumentParser) -> argparse._ArgumentGroup:
    """The bench options ``ckesc run`` and ``ckesc explore`` share (the device under test, its lane and power), from
    the one option table."""
    g = p.add_argument_group(options.DUT)
    for o in options.bench_options():
        g.add_argument(*o.run_flags, **o.arguments(run=True))
    return g


def add_run_command(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "run",
        usage=USAGE,
        split_at_dashes=True,
        help="run the conformance suite against a DUT and write reports",
        description=run_lib.__doc__.split("\n\n")[1] if run_lib.__doc__ else None,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="Before `--`: ckesc run's options and the selection, sections by number or test modules by name or "
               "path, with ::test (`ckesc run 4.4.22 4.4.3`, `ckesc run conformance/test_s4_4_22_set_freq.py`), or a test's "
               "id as the console and every report print it, from any directory "
               "(`ckesc run 'conformance/test_s4_1_framing.py::test_source_is_an_esc_node_id[provoked]'`); a "
               "selection that matches nothing is an error (exit 2). After `--`: pytest's options, handed on untouched "
               "(`ckesc run 4.4.22 -- -k read -x`); a selection there is an error that says where it goes.",
    )
    groups: dict[str, Any] = {}
    for o in options.run_options():
        if o.group not in groups:
            groups[o.group] = p.add_argument_group(o.group)
        groups[o.group].add_argument(*o.run_flags, **o.arguments(run=True))

    def handler(args: argparse.Namespace) -> int:
        unknown = next((i for i, t in enumerate(args.free) if t.startswith("-")), None)
        if unknown is not None:
            way_out = shlex.join(["ckesc", "run", *args.free[:unknown], "--", *args.free[unknown:], *args.after_dashes])
            raise UsageError(f"{args.free[unknown]} is not an option of ckesc run: pytest's options go after `--` ({way_out})")
        check_dir(args.ckesc_reports, "--reports")
        check_readable(args.ckesc_durations, "--time-from", "results.json")
        if args.rig and args.ckesc_baseline:
            raise UsageError("--baseline gates one bench's run against its own earlier run: run each bench of the rig "
                             "alone with it, or compare the batch's bench directories with ckesc compare")
        check_run(args.ckesc_baseline, "--baseline")
        args.selection, args.pytest_args = args.free, args.after_dashes
        return run_lib.run_command(args)

    p.set_defaults(handler=handler)
