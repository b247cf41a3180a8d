"""``ckesc soak --rig FILE [--benches a,b]``: a soak on every bench of a rig at once, as ``ckesc run --rig`` runs the
suite on them (issue #31 item 6: "in a rig batch one line per bench").

Each bench is a ``ckesc soak`` process of its own, given the bench's options from the rig file (the same as its
``ckesc run``; :meth:`ckesc.rigs.rig.Bench.argv`) and the soak's options of the command line, its report in
``<batch>/<bench>/``, its console in ``<batch>/<bench>/console.txt``. A soak has no pytest session to share, so
the processes are started here (not through pytest-xdist as ``ckesc run --rig`` does): each process is its own
process group, so that a Ctrl-C at the terminal reaches this process only, which passes SIGINT on to each bench
once (each zeroes its throttle and writes its report, as one soak does) and keeps waiting for them.

The console: one line per bench (elapsed, left, frames, findings; then its end), from the figures each bench writes
once a second to a status file (:class:`~.runner.StatusFile`); on a terminal the lines are rewritten in place once a
second, elsewhere (a CI log) printed as a block once a minute, and a line per bench as it ends. The batch's report,
``<batch>/batch.json`` and ``<batch>/summary.txt``: per bench its exit status, how its soak ended, its findings and
its statement. The batch's exit status is the worst bench's (:func:`ckesc.reporting.exits.worst`): 130 one was
interrupted, 1 a finding, 3 a bench could not be used, 2 a bench's set-up mistake, 0 nothing found on any bench.
"""

from __future__ import annotations

import json
import shlex
import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, TextIO

from ..reporting.durations import duration_text
from ..reporting.exits import ExitStatus, worst
from ..reporting.report import run_dir
from ..rigs import rig as rigs
from ..session import options
from . import report
from .runner import LIVE_LOG_S, LIVE_TTY_S, live_text

#: how often the benches' status files are read (s of wall time)
POLL_S = 0.2


class SoakBatchError(ValueError):
    """A batch that cannot start: the rig file, a bench's power, bench options given with --rig (exit 2)."""


@dataclass
class BenchRun:
    """One bench's ``ckesc soak`` process and what is known of it."""

    name: str
    description: str
    argv: list[str]
    where: Path  # <batch>/<bench>/
    proc: subprocess.Popen | None = None
    exit: int | None = None
    figures: dict[str, Any] = field(default_factory=dict)
    started: float = 0.0
    seconds: float | None = None
    #: Ctrl-C passed on while the bench was in its soak's loop (a bench still starting may not have heard it)
    stopped_in_loop: bool = False

    @property
    def status_path(self) -> Path:
        return self.where / "status.json"

    def read_status(self) -> None:
        try:
            self.figures = json.loads(self.status_path.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            pass

    def line(self) -> str:
        """The bench's console line: its live figures while it runs, its end once it has ended."""
        if self.exit is None:
            f = self.figures
            return f"{self.name}: " + (live_text(f).removeprefix("soak: ") if f else "starting")
        return f"{self.name}: {end_text(self.exit, self.figures)}"


def end_text(code: int, figures: dict[str, Any]) -> str:
    state = figures.get("state", "")
    what = {ExitStatus.OK: "nothing found", ExitStatus.FAILED: "FINDINGS", ExitStatus.USAGE: "set-up mistake",
            ExitStatus.ABORTED: "the bench could not be used",
            ExitStatus.INTERRUPTED: "interrupted"}.get(code, f"ended with status {code}")
    done = (f" ({state.lower()}, {duration_text(figures['elapsed_s'])}, {figures['frames']} frames, "
            f"{figures['findings']} findings)" if state and state != "running" else "")
    return f"exit {code}, {what}{done}"


def plan(rig_file: str, names: str | None, given: dict[str, Any]) -> tuple[rigs.Rig, list[rigs.Bench]]:
    """The rig and its chosen benches (:class:`SoakBatchError`: the rig file's mistake, a bench option given on the
    command line, a bench whose power asks an operator)."""
    for dest, value in given.items():
        o = options.BY_DEST[dest]
        if value not in (o.default_on(run=True), None, [], "", False):
            raise SoakBatchError(f"{o.run_flags[0]} is set per bench in the rig file ({o.rig}; with --rig, the rig says it)")
    try:
        rig = rigs.load(rig_file)
        benches = rig.select([b.strip() for b in (names or "").split(",") if b.strip()])
    except rigs.RigError as exc:
        raise SoakBatchError(str(exc)) from None
    for b in benches:
        if b.power == "manual":
            raise SoakBatchError(f"bench {b.name}: power 'manual' prompts an operator at the console, which a batch cannot; "
                             f"soak that bench alone: {shlex.join(['ckesc', 'soak', *b.argv()])}")
    return rig, benches


class Console:
    """One line per bench: rewritten in place on a terminal (at most once a second), a block once a minute
    elsewhere; a bench's end is printed as it ends either way (elsewhere)."""

    def __init__(self, out: TextIO, quiet: bool, clock: Callable[[], float]) -> None:
        self.out, self.quiet, self.clock = out, quiet, clock
        self.tty = bool(getattr(out, "isatty", lambda: False)())
        self.every = LIVE_TTY_S if self.tty else LIVE_LOG_S
        self.next = clock() + self.every
        self.drawn = 0  # lines drawn on the terminal last time

    def refresh(self, runs: list[BenchRun], *, force: bool = False) -> None:
        if self.quiet or (not force and self.clock() < self.next):
            return
        self.next = self.clock() + self.every
        lines = [f"soak {r.line()}" for r in runs]
        if self.tty:
            up = f"\x1b[{self.drawn}F" if self.drawn else ""
            self.out.write(up + "".join(f"\x1b[2K{text}\n" for text in lines))
            self.drawn = len(lines)
        else:
            self.out.write("".join(f"{text}\n" for text in lines))
        self.out.flush()

    def ended(self, run: BenchRun) -> None:
        if self.quiet:
            return
        if self.tty:  # its line is redrawn at once (run_batch)
            return
        self.out.write(f"soak {run.line()}  {run.where}/\n")
        self.out.flush()


def run_batch(rig_file: str, names: str | None, soak_argv: list[str], reports: str, *, given: dict[str, Any],
              quiet: bool = False, out: TextIO = sys.stdout, wall: Callable[[], float] = time.monotonic) -> int:
    """Soak every chosen bench of ``rig_file`` at once; ``soak_argv``: the soak's own options for each bench (not its
    bench options nor ``--reports``). The batch's exit status (a :class:`SoakBatchError` before anything started)."""
    rig, benches = plan(rig_file, names, given)
    batch_dir = run_dir(Path(reports), time.time(), "soak-batch")
    runs = [BenchRun(b.name, b.description, [*b.argv(), *soak_argv], batch_dir / b.name) for b in benches]
    started_utc, t0 = report.utc_now(), wall()
    if not quiet:
        print(f"ckesc soak: batch of {len(runs)} benches ({', '.join(r.name for r in runs)}) from {rig.path}; "
              f"reports in {batch_dir}/", file=out, flush=True)
    console = Console(out, quiet, wall)
    interrupted = False
    wake = threading.Event()  # the batch's pace: set by a signal, else it waits POLL_S between looks

    def stop(signum: int, frame: Any) -> None:  # noqa: ARG001
        nonlocal interrupted
        if interrupted:
            return
        interrupted = True
        wake.set()
        print(f"ckesc soak: {signal.Signals(signum).name}: stopping every bench (zero throttle, then its report)",
              file=sys.stderr, flush=True)
        for r in runs:
            _interrupt(r)

    previous = {sig: signal.signal(sig, stop) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        for r in runs:
            r.where.mkdir(parents=True, exist_ok=True)
            cmd = [sys.executable, "-m", "ckesc", "soak", *r.argv, "--reports", str(r.where),
                   "--status-file", str(r.status_path)]
            with open(r.where / "console.txt", "w", encoding="utf-8") as console_file:
                r.proc = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=console_file, stderr=subprocess.STDOUT,
                                          start_new_session=True)
            r.started = wall()
        console.refresh(runs, force=True)
        while any(r.exit is None for r in runs):
            wake.wait(POLL_S)  # (the benches do the protocol's timing; this only looks at them)
            wake.clear()
            for r in runs:
                r.read_status()
                if interrupted and r.exit is None and not r.stopped_in_loop and r.figures:
                    _interrupt(r)  # it was starting when Ctrl-C came: now its loop stops it as one soak stops
                if r.exit is None and r.proc is not None and (code := r.proc.poll()) is not None:
                    r.exit, r.seconds = code, wall() - r.started
                    r.read_status()
                    console.ended(r)
                    if console.tty:
                        console.refresh(runs, force=True)
            console.refresh(runs)
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    if console.tty:
        console.refresh(runs, force=True)
    doc = batch_record(rig.path, runs, started_utc, wall() - t0, interrupted)
    (batch_dir / "batch.json").write_text(json.dumps(doc, indent=1) + "\n", encoding="utf-8")
    text = summary(doc, batch_dir)
    (batch_dir / "summary.txt").write_text(text, encoding="utf-8")
    if not quiet:
        out.write(text)
        out.flush()
    return doc["exit_status"]


def _interrupt(r: BenchRun) -> None:
    """SIGINT to a bench's soak still running (once in its loop; a bench starting gets it again once it soaks)."""
    if r.proc is None or r.proc.poll() is not None:
        return
    r.stopped_in_loop = bool(r.figures)
    try:
        r.proc.send_signal(signal.SIGINT)
    except ProcessLookupError:
        pass


def _bench_doc(r: BenchRun) -> dict[str, Any]:
    found = sorted(r.where.glob("*-soak/results.json"))
    doc: dict[str, Any] = {"name": r.name, "description": r.description,
                           "command": shlex.join(["ckesc", "soak", *r.argv]), "exit": r.exit,
                           "seconds": round(r.seconds or 0.0, 3), "console": f"{r.name}/console.txt"}
    if not found:
        doc.update(status=None, findings=None, statement=[],
                   why=_tail(r.where / "console.txt") or "its soak ended without a report")
        return doc
    rec = json.loads(found[-1].read_text(encoding="utf-8"))
    doc.update(status=rec["status"], problem=rec.get("problem", ""), ran_s=rec["ran_s"],
               report_dir=found[-1].parent.relative_to(r.where.parent).as_posix(),
               findings=len(rec["findings"]) + rec["findings_not_kept"],
               first_findings=[f"{f['t_s']:.3f} s [{' '.join(f['rules'])}] {f['watch']}: {f['message']}"
                               for f in rec["findings"][:3]],
               statement=[{"watch": s["watch"], "text": s["text"]} for s in rec["statement"]])
    return doc


def _tail(path: Path, lines: int = 3) -> str:
    try:
        return " / ".join(path.read_text(encoding="utf-8", errors="replace").strip().splitlines()[-lines:])
    except OSError:
        return ""


def batch_record(rig: str, runs: list[BenchRun], started_utc: str, seconds: float, interrupted: bool) -> dict[str, Any]:
    benches = [_bench_doc(r) for r in runs]
    codes = [b["exit"] if b["exit"] is not None else ExitStatus.ABORTED for b in benches]
    code = ExitStatus.INTERRUPTED if interrupted else worst(codes)
    return {"kind": "soak-batch", "rig": rig, "started_utc": started_utc, "seconds": round(seconds, 3),
            "interrupted": interrupted, "exit_status": code, "benches": benches}


def summary(doc: dict[str, Any], batch_dir: Path) -> str:
    """The batch's end, for the console and ``summary.txt``: per bench its end and its statement."""
    lines = [f"soak batch: {len(doc['benches'])} benches in {duration_text(doc['seconds'])} of wall time, exit {doc['exit_status']}"
             + (" (interrupted)" if doc["interrupted"] else "")]
    for b in doc["benches"]:
        lines.append(f"bench {b['name']}: exit {b['exit']}, " + (
            f"{b['status'].lower()}, {b['findings']} findings" if b["status"] else f"no report: {b['why']}")
            + (f"  {batch_dir / b['report_dir']}/" if b.get("report_dir") else ""))
        lines += [f"  {s['watch']:<20} {s['text']}" for s in b["statement"]]
        lines += [f"  finding: {f}" for f in b.get("first_findings", [])]
    lines.append(f"batch report: {batch_dir / 'batch.json'}")
    return "\n".join(lines) + "\n"
