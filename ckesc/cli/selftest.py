"""``ckesc selftest``: its arguments, progress lines, output files and exit code; :mod:`ckesc.selftest` runs it."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from .. import selftest as selftest_lib
from ..reporting.exits import ExitStatus
from ..selftest import SCOPES, VARIANT_SETS, FaultRun, VariantRun, selftest, table
from .common import UsageError, check_faults, check_file, positive_int


def add_selftest_command(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("selftest", help="show that the suite passes the emulator and fails each of its faults",
                       description=selftest_lib.__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--faults", help="comma-separated fault names (default: all; none: only the faultless emulator)")
    p.add_argument("--jobs", type=positive_int, help="parallel suite runs (default: CPU count)")
    p.add_argument("--out", help="write the fault -> failing tests table (Markdown) and JSON beside it")
    p.add_argument("--scope", choices=SCOPES, default="full",
                   help="full (default): the whole suite per fault; cited: per fault only the modules with a test "
                   "citing its rules (fast: CI's check that every fault is caught there, by the right tests)")
    p.add_argument("--variants", choices=VARIANT_SETS,
                   help="also run the whole suite against conforming variants, each of which must have no FAIL and no "
                   "ERROR: each (every alternative of every freedom alone), covering (the few combinations that play "
                   "them all), drawn (the combinations --seeds draw), all")
    p.add_argument("--seeds", default="1-8", metavar="LIST",
                   help="the seeds --variants drawn/all draws combinations from: 1,5,9 or 1-8 (default 1-8)")
    p.set_defaults(handler=selftest_command)


def _seeds(text: str) -> list[int]:
    out: list[int] = []
    for part in filter(None, text.split(",")):
        lo, _, hi = part.partition("-")
        out += list(range(int(lo), int(hi or lo) + 1))
    return out


def selftest_command(args: argparse.Namespace) -> int:
    faults = [f for f in args.faults.split(",") if f and f != "none"] if args.faults else None
    check_faults(args.faults, "--faults")
    check_file(args.out, "--out")
    if args.out:
        check_file(str(Path(args.out).with_suffix(".json")), "--out", "output file (the JSON beside it)")

    def progress(run: FaultRun, i: int, n: int) -> None:
        status = "ok" if run.ok else "PROBLEM"
        if run.kind == "interaction" and run.ok:
            status += " (interaction: caught)" if run.caught else " (interaction: left to ckesc explore)"
        elif run.kind == "soak" and run.ok:
            status += " (soak: missed by the suite, found only by soak)"
        print(f"[{i:>3}/{n}] {run.fault or '(faultless)':<34} {len(run.failing):>3} failing  {status}", flush=True)

    try:
        matrix = selftest_lib.variant_matrix(args.variants, _seeds(args.seeds)) if args.variants else []
    except ValueError:
        raise UsageError(f"--seeds takes 1,5,9 or 1-8, not {args.seeds!r}") from None

    def variant_progress(run: VariantRun, i: int, n: int) -> None:
        print(f"[{i:>3}/{n}] {run.label[:60]:<60} {len(run.inconclusive):>3} inconclusive  "
              f"{'ok' if run.ok else 'PROBLEM'}", flush=True)

    runs = selftest(faults, args.jobs, progress=progress, scope=args.scope)
    variant_runs = selftest_lib.variant_selftest(matrix, args.jobs, progress=variant_progress)
    line = selftest_lib.headline(runs, variant_runs)
    text = table(runs) + (f"\n\n{line}\n\n{selftest_lib.variant_table(variant_runs)}" if variant_runs else "")
    if args.out:
        Path(args.out).write_text(text + "\n")
        Path(args.out).with_suffix(".json").write_text(json.dumps(
            [r.__dict__ for r in runs] + [{**r.__dict__, "allowed_by": r.allowed_by} for r in variant_runs], indent=1))
    bad = [r for r in runs if not r.ok]
    for r in bad:
        print(f"PROBLEM {r.fault or '(faultless)'}: {r.problem}", file=sys.stderr)
    bad_variants = [r for r in variant_runs if not r.ok]
    for v in bad_variants:
        print(f"PROBLEM {v.problem}", file=sys.stderr)
    total = len(runs) + len(variant_runs)
    print(f"{total - len(bad) - len(bad_variants)} of {total} runs as expected: {line}")
    return ExitStatus.FAILED if bad or bad_variants else ExitStatus.OK
