"""A soak run, the IO part: the bench built as every command builds it (:func:`ckesc.bench.station.build`), the DUT
found and its settings read once (:class:`ckesc.bench.dut.Dut`), then the :class:`~.player.Player` driven on the
lane's clock and every frame read fed to the :class:`~.monitor.Monitor`, until the duration has passed, a finding
stops it (``stop_on_finding``) or the operator does (Ctrl-C, SIGTERM). On every way out the stream stops and zero
throttle goes out on every channel in every format (as the suite's exit paths do), then the reports are written.

In the simulated lane ``lane.recv`` advances the discrete-event clock, so hours cost minutes; in real time it
waits. The host's own timing is measured either way: how late each stream frame went out after it was due
(``host.send_lateness``), the stream's jitter as the host made it.
"""

from __future__ import annotations

import json
import os
import signal
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, TextIO

import can

from ..bench.dut import Dut
from ..bench.lanes import BenchGone, BusFault
from ..bench.station import BENCH_ROWS, BenchOptions, build
from ..protocol import catalogue as cat
from ..protocol.frame import WireFrame
from ..protocol.histogram import Histogram
from ..reporting.durations import duration_text
from . import report, split
from .monitor import Monitor
from .player import FORMATS, FlightPlan, Player
from .split import ABORTED, COMPLETED, INTERRUPTED, STOPPED
from .statement import Statement
from .trace import DEFAULT_BUDGET, Trace
from .watch import WatchConfig

#: lane time read after the closing zero throttle, so that its frames are on the bus before the lane closes
EXIT_READ_S = 0.01
#: the live line: at most once per this many seconds of wall time on a terminal; elsewhere (a CI log) this often
LIVE_TTY_S = 1.0
LIVE_LOG_S = 60.0
#: the host's send lateness histogram: bins of a tenth of a millisecond up to 20 ms
LATENESS_BIN_S = 0.0001
LATENESS_BINS = 200



@dataclass(frozen=True)
class SoakOptions:
    """What ``ckesc soak`` adds to the bench options."""

    duration_s: float
    rate_hz: float = 400.0
    format: str = "14b"
    channels: tuple[int, ...] | None = None  # None: every channel of one frame of the format
    throttle: tuple[tuple[float, int], ...] = ()
    stop_on_finding: bool = False
    reports: str = "reports"
    quiet: bool = False
    trace_budget: int = DEFAULT_BUDGET  # bytes of trace files on disk (0: no trace)
    #: a file the live line's figures go to as JSON once a second of wall time (a rig batch's console reads it)
    status_file: str | None = None
    #: ``--processes``: "1", "2" (a simulated soak's world in a process of its own, :mod:`.split`) or "auto"
    processes: str = "auto"


@dataclass
class SoakOutcome:
    status: str
    findings: int
    where: Path | None
    statements: list[Statement]


class Live:
    """The live console line: elapsed, left, frames, findings; at most once a second of wall time on a terminal
    (rewritten in place), once a minute elsewhere."""

    def __init__(self, out: TextIO, quiet: bool, clock: Callable[[], float]) -> None:
        self.out, self.quiet, self.clock = out, quiet, clock
        self.tty = bool(getattr(out, "isatty", lambda: False)())
        self.every = LIVE_TTY_S if self.tty else LIVE_LOG_S
        self.next = clock() + self.every
        self.shown = False

    def maybe(self, line: Callable[[], str]) -> None:
        if self.quiet:
            return
        now = self.clock()
        if now < self.next:
            return
        self.next = now + self.every
        self._show(line())

    def _show(self, text: str) -> None:
        if self.tty:
            self.out.write("\r\x1b[2K" + text)
            self.shown = True
        else:
            self.out.write(text + "\n")
        self.out.flush()

    def done(self) -> None:
        if self.tty and self.shown:
            self.out.write("\n")
            self.out.flush()


class StatusFile:
    """The live line's figures as JSON in a file, rewritten whole (a new file renamed over the old) at most once a
    second of wall time: how a rig batch (:mod:`.batch`) shows one line per bench without reading the benches'
    consoles."""

    def __init__(self, path: str | None, clock: Callable[[], float]) -> None:
        self.path, self.clock = (Path(path) if path else None), clock
        self.next = clock()

    def maybe(self, figures: Callable[[], dict[str, Any]], *, now: bool = False) -> None:
        if self.path is None or (not now and self.clock() < self.next):
            return
        self.next = self.clock() + LIVE_TTY_S
        tmp = self.path.with_name(self.path.name + ".tmp")
        try:
            tmp.write_text(json.dumps(figures()), encoding="utf-8")
            os.replace(tmp, self.path)
        except OSError:  # the console's figures only: the run goes on
            pass


def _raise_interrupt(signum: int, frame: Any) -> None:
    raise KeyboardInterrupt


def run(bench: BenchOptions, soak: SoakOptions, *, out: TextIO = sys.stdout, given: dict[str, Any] | None = None,
        wall: Callable[[], float] = time.monotonic) -> SoakOutcome:
    """One soak of ``bench`` (a set-up mistake raises :class:`~ckesc.bench.errors.PreflightError` before anything
    is opened; a DUT that cannot be found raises :class:`~ckesc.bench.dut.DutError`)."""
    station = build(bench)
    old_term = signal.getsignal(signal.SIGTERM)
    in_main = _in_main_thread()
    if in_main:
        signal.signal(signal.SIGTERM, _raise_interrupt)
    try:
        return _run(station, bench, soak, out, given or {}, wall)
    finally:
        station.close()
        if in_main:
            signal.signal(signal.SIGTERM, old_term)


def _in_main_thread() -> bool:
    import threading

    return threading.current_thread() is threading.main_thread()


def _run(station, bench: BenchOptions, soak: SoakOptions, out: TextIO, given: dict[str, Any],
         wall: Callable[[], float]) -> SoakOutcome:
    started_utc = report.utc_now()
    wall0 = wall()
    lane = station.open_lane()  # (on a real bus the echo found first, then any foreign traffic)
    profile = station.profile
    dut = Dut(lane, profile, node_id=bench.node_id, allow_motor_spin=bool(bench.allow_motor_spin))
    settings = dut.settings()
    intervals = {name: settings[field] * cat.INTERVAL_UNIT_S for name, field in cat.REPORT_INTERVAL_FIELDS.items()}
    per = FORMATS[soak.format][1] if soak.format in FORMATS else 4
    plan = FlightPlan(host_node=dut.host_node, node_id=dut.node_id, format=soak.format, rate_hz=soak.rate_hz,
                      channels=soak.channels or tuple(range(1, per + 1)), throttle=soak.throttle,
                      allow_motor_spin=bool(bench.allow_motor_spin), nibble_order=profile.nibble_order)
    plan.check()
    t0 = lane.now()
    player = Player(plan, t0)
    monitor = Monitor(WatchConfig(node_id=dut.node_id, host_node=dut.host_node, intervals=intervals,
                                  error=lane.timing_error, own_error=lane.own_error, jitter=profile.jitter_s,
                                  bitrate=lane.bitrate, nibble_order=profile.nibble_order,
                                  stream_frames=player.frames_per_tick), t0)
    lateness = Histogram(LATENESS_BIN_S, LATENESS_BINS)
    where = report.new_dir(soak.reports) if soak.trace_budget else None
    trace = Trace(where, soak.trace_budget, t0) if where is not None else None
    written = 0  # findings whose frames are in their trace file

    watch, keep = monitor.feed, (trace.frame if trace is not None else None)

    def write_findings(final: bool = False) -> None:
        nonlocal written
        if trace is None:
            return
        kept = monitor.findings
        while written < len(kept) and (final or written < len(kept) - monitor.open_findings):
            trace.finding(kept[written])
            written += 1
    rss_start = _rss_kb()
    cpu0, cpu_wall0 = _cpu_s(), wall()
    end = t0 + soak.duration_s
    live = Live(out, soak.quiet, wall)
    status_file = StatusFile(soak.status_file, wall)
    status = COMPLETED
    problem = ""
    say = (lambda text: None) if soak.quiet else (lambda text: print(text, file=out, flush=True))

    procs = split.processes(soak.processes, lane.clock == "simulated")
    at = [t0]  # (two processes: the lane's time of the last tick read)
    lane_now = lane.peek_now if procs == 1 else (lambda: at[0])

    def figures(state: str = "running") -> dict[str, Any]:
        now = lane_now()
        return {"state": state, "elapsed_s": round(max(now - t0, 0), 3), "left_s": round(max(end - now, 0), 3),
                "frames": monitor.frames, "findings": monitor.count}

    def line() -> str:
        return live_text(figures())

    # (bound once: the loop below runs once per stream tick, hours of them)
    send, now_of, peek, frames_until, sent, add_lateness = (lane.send_wire, lane.now, lane.peek_now,
                                                            lane.frames_until, monitor.sent, lateness.add)
    due_by, next_deadline = player.due, player.next_deadline
    show = not soak.quiet or soak.status_file is not None
    stopped_at = t0
    world: dict[str, Any] = {}

    def after_tick() -> bool:
        """A tick's frames read: its findings written, the live line; whether the soak stops here."""
        if written < len(monitor.findings):
            write_findings()
        if soak.stop_on_finding and monitor.count and monitor.settled:  # (the frames after it read)
            return True
        if show:
            live.maybe(line)
            status_file.maybe(figures)
        return False

    def tick_done(now: float, sent_stream: int, skipped: int) -> bool:
        """Two processes: a tick read (:func:`.split.read_world`), with the lane's time and the player's counts after it."""
        at[0] = now
        player.sent_stream, player.skipped = sent_stream, skipped
        return after_tick()

    try:
        say(f"soak: {duration_text(soak.duration_s)} of flight-like running on {lane.name} ({lane.clock} clock), node "
            f"{dut.node_id}: RawCommand_{plan.format} at {plan.rate_hz:g} Hz on channels "
            f"{','.join(map(str, plan.channels))} ({'throttle profile' if plan.throttle and plan.allow_motor_spin else 'zero throttle'}), "
            "GET_ESC_ID every second, 241 and 242 read"
            + (f"; foreign traffic: {station.foreign.name} (other nodes' frames, not judged as the ESC's)"
               if station.foreign is not None else "")
            + ("; the simulated world in a process of its own" if procs == 2 else ""))
        if procs == 2:
            world = split.read_world(lambda frames, control: split.run_world(
                frames, control, lane, player, end, lambda: _finish_world(station, lane, player, dut)),
                watch, keep, sent, add_lateness, tick_done, signals=_in_main_thread())
            lane.sim.world.bench.flash = None  # (the world's process closed the bench: this copy writes no flash)
            status, problem = world["status"], world["problem"]
            stopped_at = world["stopped_at"] if world["stopped_at"] is not None else at[0]  # (None: no tick read)
        else:
            while True:
                now = now_of()
                if now >= end:
                    break
                for planned in due_by(now):
                    wire = planned.wire
                    sent(wire.arbitration_id, wire.data, peek())  # its echo's stamp: how late the bench stamped it
                    send(wire)
                    if planned.what == "stream":
                        late = now - planned.due
                        add_lateness(late if late > 0.0 else 0.0)
                deadline = next_deadline()
                if deadline > end:
                    deadline = end
                for msg in frames_until(deadline):
                    watch(msg)
                    if keep is not None:
                        keep(msg.timestamp, msg.arbitration_id, msg.data)
                if after_tick():
                    status = STOPPED
                    break
    except KeyboardInterrupt:
        status = INTERRUPTED
    except (BenchGone, BusFault) as exc:  # the bench failed, not the DUT: the run stops, its report says why
        status, problem = ABORTED, str(exc)
    finally:
        ignore = _ignore_interrupts()
        try:
            if procs == 1:
                stopped_at = lane.peek_now()
                _zero(lane, player, dut)
                if station.foreign is not None:
                    station.foreign.stop()  # its figures final for the report (the lane closes after it)
            live.done()
        finally:
            ignore()
    ignore = _ignore_interrupts()
    try:
        monitor.close(stopped_at)
        write_findings(final=True)
        if trace is not None:
            trace.close()
        ran = stopped_at - t0
        cpu_s, cpu_wall = _cpu_s() - cpu0 + world.get("cpu_s", 0.0), wall() - cpu_wall0
        statements = [Statement(w.name, w.rules, w.what, w.one, w.events, ran, w.statement_unit, w.trials)
                      for w in monitor.watches]
        record = {
            "kind": "soak", "status": status, "problem": problem, "started_utc": started_utc,
            "bench": {k: _plain(v) for k, v in (given or {}).items()},
            "lane": lane.name, "clock": lane.clock, "timing_error_s": lane.timing_error, "profile": profile.name,
            "faults": bench.emulator_faults or "",
            "foreign_traffic": world.get("foreign") if procs == 2 else station.foreign.report() if station.foreign is not None else None,
            "node_id": dut.node_id, "host_node": dut.host_node,
            "plan": {"format": plan.format, "rate_hz": plan.rate_hz, "channels": list(plan.channels),
                     "throttle": [list(s) for s in plan.throttle] if plan.allow_motor_spin else [],
                     "allow_motor_spin": plan.allow_motor_spin},
            "settings_at_start": settings,
            "duration_s": soak.duration_s, "ran_s": round(ran, 6), "wall_s": round(wall() - wall0, 3),
            "frames": {"total": monitor.frames, "dut": monitor.dut_frames, "host": monitor.own_frames,
                       "other": monitor.other_frames},
            "host": {"stream_frames": player.sent_stream, "stream_skipped": player.skipped,
                     "send_lateness": lateness.to_json(), "bench_stamp_lag": monitor.bench_lag.to_json(), "cpu_s": round(cpu_s, 3),
                     "cpu_percent": round(100 * cpu_s / cpu_wall, 1) if cpu_wall > 0 else None, "processes": procs,
                     "world_cpu_s": round(world["cpu_s"], 3) if "cpu_s" in world else None},
            "memory": {"rss_start_kb": rss_start, "rss_end_kb": _rss_kb(), "peak_rss_kb": _peak_rss_kb(),
                       "world_peak_rss_kb": world.get("peak_rss_kb")},
            "watches": {w.name: {"rules": list(w.rules), "events": w.events, "trials": w.trials,
                                 "statistics": w.statistics()} for w in monitor.watches},
            "r9_per_minute_ms": monitor.intervals.series,
            # what the bus reader the watches take their events from kept (its own violations are the suite's per-frame
            # reading, not the soak's findings: the soak judges the properties above)
            "bus_reader": monitor.rules.summary(),
            "trace": trace.to_json() if trace is not None else None,
            "findings": [f.to_json() for f in monitor.findings], "findings_not_kept": monitor.dropped,
            "statement": [s.to_json() for s in statements],
        }
        where = report.write(soak.reports, record, where)
        status_file.maybe(lambda: {**figures(status), "report": str(where)}, now=True)
        if not soak.quiet:
            out.write(report.summary_text(record, where))
            out.flush()
    finally:
        ignore()
    return SoakOutcome(status, monitor.count, where, statements)


def live_text(f: dict[str, Any]) -> str:
    """The live line from its figures (:class:`StatusFile`'s JSON)."""
    return (f"soak: {duration_text(f['elapsed_s'])} elapsed, {duration_text(f['left_s'])} left, "
            f"{f['frames']} frames, {f['findings']} findings")


def _message(wire: WireFrame) -> can.Message:
    return can.Message(arbitration_id=wire.arbitration_id, data=wire.data, is_extended_id=wire.is_extended_id)


def _zero(lane, player: Player, dut: Dut) -> None:
    """Zero throttle on the way out: the stream's own format first, then every format on every channel (the
    suite's :meth:`~ckesc.bench.link.Link.zero_throttle`), then the lane read until the frames are out. Best
    effort: a bench that went away cannot be zeroed, and the run says why it ended."""
    try:
        for wire in player.zero():
            lane.bus.send(_message(wire))
        dut.zero_throttle()
        until = lane.now() + EXIT_READ_S
        while (left := until - lane.now()) > 0:
            lane.recv(left)
    except Exception:  # noqa: BLE001 - best effort on the way out (the bench may be gone)
        pass


def _finish_world(station: Any, lane: Any, player: Player, dut: Dut) -> dict[str, Any]:
    """The world's process on its way out (:func:`.split.run_world`): zero throttle, the foreign traffic stopped, the
    lane closed (the emulator's flash written, as the one-process soak's close does); its figures for the report."""
    foreign = None
    try:
        _zero(lane, player, dut)
        if station.foreign is not None:
            station.foreign.stop()
            foreign = station.foreign.report()
        station.close()
    except Exception:  # noqa: BLE001 - best effort on the way out, as the one-process soak's
        pass
    return {"foreign": foreign, "cpu_s": _cpu_s(), "peak_rss_kb": _peak_rss_kb()}


def _ignore_interrupts() -> Callable[[], None]:
    """SIGINT ignored while the run zeroes the throttle and writes its report (a second Ctrl-C must not lose it);
    returns the undo."""
    if not _in_main_thread():
        return lambda: None
    old = signal.signal(signal.SIGINT, signal.SIG_IGN)
    return lambda: signal.signal(signal.SIGINT, old)


def _rss_kb() -> int | None:
    """The process's resident memory now (kB; Linux's /proc), else None: a day's run must stay flat."""
    try:
        with open("/proc/self/statm", encoding="ascii") as f:
            pages = int(f.read().split()[1])
    except (OSError, ValueError, IndexError):
        return None
    return pages * os.sysconf("SC_PAGE_SIZE") // 1024


def _cpu_s() -> float:
    """The CPU time (user and system, s) this process has used so far, its own threads' and not its children's (a
    real-time bench's ``ckesc emulate`` is a process of its own): what the host's side of the run costs."""
    t = os.times()
    return t.user + t.system


def _peak_rss_kb() -> int | None:
    try:
        import resource
    except ImportError:  # not on Windows
        return None
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss


def _plain(value: Any) -> Any:
    return list(value) if isinstance(value, tuple) else value


#: the bench options by name (``ckesc run``'s), for the report's record of what was given
OPTION_NAMES = tuple(o.dest for o in BENCH_ROWS)
