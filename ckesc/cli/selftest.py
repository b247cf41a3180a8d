"""``ckesc selftest``: its arguments, progress lines, output files and exit code; :mod:`ckesc.selftest` runs it."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from .. import selftest as selftest_lib
from ..emulator.faults import FAULTS
from ..selftest import SCOPES, FaultRun, selftest, table


def add_selftest_command(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("selftest", help="show that the suite passes the emulator and fails each of its faults",
                       description=selftest_lib.__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--faults", help="comma-separated fault names (default: all)")
    p.add_argument("--jobs", type=int, help="parallel suite runs (default: CPU count)")
    p.add_argument("--out", help="write the fault -> failing tests table (Markdown) and JSON beside it")
    p.add_argument("--scope", choices=SCOPES, default="full",
                   help="full (default): the whole suite per fault; cited: per fault only the modules with a test "
                   "citing its rules (fast: CI's check that every fault is caught there, by the right tests)")
    p.set_defaults(handler=selftest_command)


def selftest_command(args: argparse.Namespace) -> int:
    faults = [f for f in args.faults.split(",") if f] if args.faults else None
    unknown = set(faults or ()) - set(FAULTS)
    if unknown:
        print(f"ckesc selftest: unknown fault(s) {', '.join(sorted(unknown))}", file=sys.stderr)
        return 2

    def progress(run: FaultRun, i: int, n: int) -> None:
        status = "ok" if run.ok else "PROBLEM"
        print(f"[{i:>3}/{n}] {run.fault or '(faultless)':<34} {len(run.failing):>3} failing  {status}", flush=True)

    runs = selftest(faults, args.jobs, progress=progress, scope=args.scope)
    text = table(runs)
    if args.out:
        Path(args.out).write_text(text + "\n")
        Path(args.out).with_suffix(".json").write_text(json.dumps([r.__dict__ for r in runs], indent=1))
    bad = [r for r in runs if not r.ok]
    for r in bad:
        print(f"PROBLEM {r.fault or '(faultless)'}: {r.problem}", file=sys.stderr)
    print(f"{len(runs) - len(bad)} of {len(runs)} runs as expected")
    return 1 if bad else 0
