"""What ``ckesc explore`` does with its arguments (the command line only parses them and maps the exit code)."""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path
from typing import Any, TextIO

from ..bench.dut import DutError
from ..bench.errors import PreflightError, RestoreFailed
from ..bench.lanes import BenchGone
from ..bench.station import BenchOptions
from ..reporting.durations import duration_text
from ..reporting.exits import ExitStatus
from ..reporting.report import run_dir
from .engine import Stats, explore
from .report import load_replay, summary_text, write_reports
from .runner import OPTION_NAMES, Session

BENCH_OPTIONS = OPTION_NAMES


class BenchProblem(RuntimeError):
    """The bench could not be used (exit 3): nothing was judged."""


def bench_options(args: argparse.Namespace) -> dict[str, Any]:
    """The bench options given on the command line (None: not given), as the reports and a replay file keep them;
    :class:`Session` makes its :class:`~ckesc.bench.station.BenchOptions` of them."""
    return {k: getattr(args, k) for k in BENCH_OPTIONS if getattr(args, k, None) is not None}


def open_session(options: BenchOptions | dict[str, Any], *, load: bool = False, bus: bool = False) -> Session:
    """The bench of ``options``, built and its DUT found (:class:`Session`; ``load``: draw foreign-load steps, ``bus``:
    R20's bus steps); a
    set-up mistake is a ``ValueError`` (exit 2), a bench that cannot be used a :class:`BenchProblem` (exit 3)."""
    try:
        return Session(options, load=load, bus=bus)
    except PreflightError as exc:  # a set-up mistake (options, fault names, profile): a usage error
        raise ValueError(str(exc)) from None
    except (DutError, BenchGone, OSError) as exc:
        raise BenchProblem(f"cannot use the bench: {exc}") from None


def _close(session: Session, out: TextIO) -> None:
    session.close()
    if session.left:
        print(f"WARNING: the DUT was not put back into the state the exploration found it in: {session.left}",
              file=out, flush=True)


def main(args: argparse.Namespace, given: set[str], out: TextIO) -> int:
    """``ckesc explore``: 0 nothing found, 1 a finding (or a replay that still shows one)."""
    if getattr(args, "selftest", None):
        return selftest_command(args, out)
    if args.replay:
        bench, program, finding = load_replay(args.replay)
        mine = bench_options(args)
        options = {**bench, **{k: v for k, v in mine.items() if k in given or k not in bench}}
        session = open_session(options)
        try:
            outcome = session.run(program)
        except (RestoreFailed, DutError, BenchGone) as exc:
            raise BenchProblem(str(exc)) from None
        finally:
            _close(session, out)
        print(f"replayed {len(program)} steps in {outcome.seconds:.3f} s of lane time", file=out)
        for line in outcome.skipped:  # (a step this lane cannot play: a foreign load in real time)
            print(line, file=out)
        for f in outcome.findings:
            print(f.text(), file=out)
        same = finding is not None and any(f.key == finding.get("key") for f in outcome.findings)
        if finding is not None:
            print(f"the finding of {os.path.basename(args.replay)} ({finding.get('key')}): "
                  f"{'reproduced' if same else 'NOT reproduced'}", file=out)
        return ExitStatus.FAILED if outcome.findings else ExitStatus.OK
    options = bench_options(args)
    session = open_session(options, load=bool(getattr(args, "load", False)), bus=bool(getattr(args, "bus", False)))
    database = None if args.database == "none" else (args.database or os.path.join(args.reports, "explore-db"))

    def progress(stats: Stats) -> None:
        if not args.quiet:
            print(stats.line(), file=out, flush=True)

    def say(line: str) -> None:
        print(line, file=out, flush=True)

    say(f"explore: a budget of {duration_text(args.budget)} wall time, shrinking what it finds included")
    for note in (session.load_note, session.bus_note):
        if note:
            say(note)
    try:
        found, stats = explore(session, budget_s=args.budget, seed=args.seed, database=database,
                               max_size=args.max_steps, stop_at_first=args.first, progress=progress,
                               max_programs=getattr(args, "max_programs", None), say=say)
    except (RestoreFailed, DutError, BenchGone) as exc:
        raise BenchProblem(str(exc)) from None
    finally:
        _close(session, out)
    where = run_dir(Path(args.reports), time.time(), "explore")  # named as every command's run
    info = {"bench": options, "seed": args.seed, "budget_s": args.budget, "lane": session.lane.name,
            "clock": session.lane.clock, "profile": session.profile.name, "faults": options.get("emulator_faults") or "",
            "emulator_variants": options.get("emulator_variants"), "emulator_option": options.get("emulator_option"),
            "load": session.bench.load, "bus": session.draw_bus}
    write_reports(where, found, stats, info)
    print(summary_text(found, stats, where), file=out)
    return ExitStatus.FAILED if found else ExitStatus.OK


def selftest_command(args: argparse.Namespace, out: TextIO) -> int:
    """``ckesc explore --selftest FAULTS``: 0 when exploration found every fault (citing one of its rules)."""
    from ..emulator.faults import FAULTS
    from .selftest import find_faults, table

    names = list(FAULTS) if args.selftest == "all" else [f for f in args.selftest.split(",") if f]
    unknown = set(names) - set(FAULTS)
    if unknown:
        raise ValueError(f"unknown fault(s) {', '.join(sorted(unknown))}")
    options = {k: v for k, v in bench_options(args).items() if k != "emulator_faults"}

    def progress(row) -> None:
        if not args.quiet:
            if row.programs is not None:
                print(f"{row.fault:<34} {'found' if row.found else 'NOT found (a finding citing other rules)'} after "
                      f"{row.programs} programs, {row.seconds} s", file=out, flush=True)
            else:
                print(f"{row.fault:<34} NOT found within the budget: {row.explored}", file=out, flush=True)

    rows = find_faults(names, budget_s=args.budget, seed=args.seed, max_programs=getattr(args, "max_programs", None),
                       options=options, progress=progress, load=True if getattr(args, "load", False) else None,
                       bus=True if getattr(args, "bus", False) else None)
    text = table(rows)
    print(text, file=out)
    if args.out:
        Path(args.out).write_text(text + "\n")
        Path(args.out).with_suffix(".json").write_text(json.dumps([r.to_json() for r in rows], indent=1) + "\n")
    return ExitStatus.OK if all(r.found for r in rows) else ExitStatus.FAILED
