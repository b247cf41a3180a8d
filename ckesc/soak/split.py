"""A simulated soak on two cores (``ckesc soak --processes 2``): the simulated world in a process of its own, the
reading of its frames in this one.

The world (the simulated bus, the emulated ESCs, the flight controller's :class:`~.player.Player`) does not depend on
what the reader concludes: the host's frames come from the flight plan and the lane's clock alone. The reader (the
:class:`~.monitor.Monitor` with the bus reader and the watches, the trace, the live line, the report) takes the
world's frames in order. So once the DUT is found and its settings read, the soak forks (:func:`start`): the child
runs the world (:func:`run_world`), this process reads (:func:`read_world`).

* **What crosses**: per stream tick, what the host sent (id, bytes, the lane's time at the send, the stream frame's
  lateness), every frame heard (id, bytes, stamp, extended), the lane's time after the tick and the player's counts;
  in batches of :data:`BATCH_FRAMES` frames, each ``marshal``'d plain values through a pipe. The pipe holds less
  than a batch: the world waits while the reader is a batch behind, so memory stays bounded.
* **Where it stops**: the reader judges every tick as the one-process soak does (findings written, the stop at the
  first finding once it settled, the live line) and decides the stop; the world may be up to a batch or two ahead,
  and what it did past the reader's stop is read by no one: the findings, the trace, the statement and the exit
  status are the one-process soak's. The world's own figures at its end (the foreign traffic it played) count to
  where it stopped.
* **Signals**: the world ignores SIGINT (a terminal's Ctrl-C reaches both; the reader stops it) and stops at SIGTERM;
  the reader takes SIGINT and SIGTERM as "stop" between two batches (a read of the pipe is never cut), tells the world,
  reads to its last message and waits for it: the world zeroes the throttle and closes the bench itself. A reader
  that goes away closes the pipe, and the world ends at its next batch (a broken pipe).
"""

from __future__ import annotations

import gc
import marshal
import os
import pickle
import signal
import sys
from itertools import islice
from multiprocessing.connection import Connection, Pipe
from typing import Any, Callable

import can

from ..bench.lanes import BenchGone, BusFault
from ..emulator.sim_frames import Heard

#: frames handed over at a time (about 100 kB marshal'd; the pipe between the processes holds less)
BATCH_FRAMES = 4096
#: the world's cyclic garbage collector: its frames are tuples freed as they go (no cycle), so a collection every
#: 700 of them (Python's default) is work for nothing
GC_THRESHOLDS = (100_000, 50, 50)
#: the choices of ``--processes``: ``auto`` is 2 for a simulated soak on a machine with two cores or more
CHOICES = ("auto", "1", "2")
COMPLETED, INTERRUPTED, STOPPED, ABORTED = "COMPLETED", "INTERRUPTED", "STOPPED", "ABORTED"
_BATCH, _END = b"B", b"E"


def cores() -> int:
    """The cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # (not on Linux)
        return os.cpu_count() or 1


def processes(choice: str, simulated: bool) -> int:
    """How many processes a soak runs in: ``choice`` of :data:`CHOICES`; 2 only for a simulated lane (a real bus
    is read as it comes) on a system that forks."""
    if choice not in CHOICES:
        raise ValueError(f"--processes {choice!r}: one of {', '.join(CHOICES)}")
    if not simulated or not hasattr(os, "fork") or choice == "1":
        return 1
    return 2 if choice == "2" or cores() >= 2 else 1


class World:
    """The world's process as the reader holds it: its pid and the two ends of the pipes."""

    def __init__(self, pid: int, frames: Connection, control: Connection) -> None:
        self.pid, self.frames, self.control = pid, frames, control


def start(body: Callable[[Connection, Connection], None]) -> World:
    """Fork: ``body(frames, control)`` runs in the child (it must not return: :func:`run_world` ends the process);
    the parent gets the :class:`World`."""
    theirs, ours = Pipe(duplex=False)  # (receiving end, sending end)
    control_in, control_out = Pipe(duplex=False)
    sys.stdout.flush()
    sys.stderr.flush()
    pid = os.fork()
    if pid == 0:  # the world
        code = 0
        try:
            theirs.close()
            control_out.close()
            body(ours, control_in)
        except BaseException:  # noqa: BLE001 - the reader sees the pipe close and says so
            code = 1
        finally:
            os._exit(code)
    ours.close()
    control_in.close()
    return World(pid, theirs, control_out)


def run_world(out: Connection, control: Connection, lane: Any, player: Any, end: float,
              finish: Callable[[], dict[str, Any]]) -> None:
    """The world's side: the player's frames sent on ``lane`` and every frame heard sent to the reader (``out``), tick
    by tick, until ``end``, a stop from the reader (``control``), SIGTERM or the bench's failure; then ``finish()``
    (the zero throttle on the way out, the lane closed; it never raises) and the last message with the figures it
    returns (the foreign traffic's, the process's CPU time and memory)."""
    stop: list[str] = []
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, lambda signum, frame: stop.append(INTERRUPTED))
    gc.freeze()  # (the bench as built stays: the collector looks only at what the run makes, and less often)
    gc.set_threshold(*GC_THRESHOLDS)
    # (bound once: the loop runs once per stream tick, hours of them; the world's clock read as its attribute: the
    # lane's now and peek_now are it)
    world = lane.sim.world
    send, frames_into = lane.send_wire, lane.frames_into
    due_by, next_deadline = player.due, player.next_deadline
    ticks: list[tuple[Any, ...]] = []
    frames: list[Any] = []
    tick, limit = ticks.append, 4 * BATCH_FRAMES
    status, problem = COMPLETED, ""
    n = 0
    sends: list[tuple[int, bytes, float, float | None]] = []
    try:
        while True:
            now = world.now
            if now >= end:
                break
            n, sends = len(frames), []
            for planned in due_by(now):
                wire = planned.wire
                t = world.now
                try:
                    send(wire)
                except BaseException:
                    sends.append((wire.arbitration_id, wire.data, t, None))  # (sent as far as the reader knows)
                    raise
                late = None
                if planned.what == "stream":
                    late = now - planned.due
                    if late < 0.0:
                        late = 0.0
                sends.append((wire.arbitration_id, wire.data, t, late))
            deadline = next_deadline()
            if deadline > end:
                deadline = end
            frames_into(deadline, frames)
            tick((world.now, (len(frames) - n) >> 2, sends, player.sent_stream, player.skipped))
            if len(frames) >= limit:
                out.send_bytes(_BATCH + marshal.dumps((ticks, frames)))
                ticks.clear()
                frames.clear()
                if control.poll():
                    stop.append(control.recv())
            if stop:
                status = stop[0]
                break
    except (BenchGone, BusFault) as exc:  # the bench failed under the run: the reader reads the tick's frames so far
        status, problem = ABORTED, str(exc)
        tick((world.now, (len(frames) - n) >> 2, sends, player.sent_stream, player.skipped))
    stopped_at = world.now
    figures = finish()
    out.send_bytes(_END + pickle.dumps({**figures, "status": status, "problem": problem, "stopped_at": stopped_at,
                                        "ticks": ticks, "frames": frames}))
    out.close()
    os._exit(0)


def read_world(body: Callable[[Connection, Connection], None], feed: Callable[[Any], None],
               keep: Callable[[float, int, bytes], None] | None, sent: Callable[[int, bytes, float], None],
               lateness: Callable[[float], None], tick_done: Callable[[float, int, int], bool], *,
               signals: bool = True) -> dict[str, Any]:
    """The world's process started (:func:`start`: ``body`` runs there, :func:`run_world`) and read to its end: each
    tick's sends (``sent``, ``lateness``) and frames (``feed``, ``keep``) in order, then
    ``tick_done(now, sent_stream, skipped)``, which says whether the soak stops there (its first finding). Returns
    how it ended: ``status``, ``problem``, ``stopped_at`` (the lane's time where the reading stopped) and the figures
    of :func:`run_world`'s ``finish``. ``signals``: SIGINT and SIGTERM taken as "stop" (in the main thread only); a
    second one while the world has not stopped ends the world's process at once (a world that no longer answers)."""
    stopping: list[str] = []
    pid: list[int] = []

    def handler(signum: int, frame: Any) -> None:
        if stopping and pid:
            os.kill(pid[0], signal.SIGKILL)  # (its pipe closes: the read below ends)
        stopping.append(INTERRUPTED)

    old = {s: signal.signal(s, handler) for s in (signal.SIGINT, signal.SIGTERM)} if signals else {}
    try:
        world = start(body)  # (after the handlers: a Ctrl-C from here on stops both processes the same way)
        pid.append(world.pid)
    except BaseException:
        for s, h in old.items():
            signal.signal(s, h)
        raise
    status: str | None = None
    stopped_at = None
    end: dict[str, Any] | None = None
    try:
        while True:
            try:
                raw = world.frames.recv_bytes()
            except EOFError:
                break
            last = raw[:1] == _END
            if last:
                end = pickle.loads(memoryview(raw)[1:])
                ticks, frames = end["ticks"], end["frames"]
            else:
                ticks, frames = marshal.loads(memoryview(raw)[1:])
            if status is None:
                partial = last and end["status"] == ABORTED  # (its last tick cut where the bench failed)
                at = _read(ticks, frames, feed, keep, sent, lateness, tick_done, partial)
                if at is not None:
                    status, stopped_at = STOPPED, at
                elif ticks:
                    stopped_at = ticks[-1][0]
                if status is None and stopping:
                    status = stopping[0]
                if status is not None and not last:
                    try:
                        world.control.send(status)  # (the world stops at its next batch; what it sends until then
                    except OSError:  # is drained unread)
                        pass  # (it ended meanwhile: the read below says how)
            if last:
                break
    finally:
        for s, h in old.items():
            signal.signal(s, h)
        world.frames.close()
        world.control.close()
        _, code = os.waitpid(world.pid, 0)
    if end is None:
        if stopping:  # (stopped twice: the world's process ended by the second)
            return {"status": INTERRUPTED, "stopped_at": stopped_at, "problem": ""}
        return {"status": ABORTED, "stopped_at": stopped_at,
                "problem": f"the simulated world's process ended without its last message (wait status {code})"}
    out = dict(end)
    if status is not None:
        out.update(status=status, stopped_at=stopped_at, problem="")
    return out


def _read(ticks: list[Any], frames: list[Any], feed: Callable[[Any], None],
          keep: Callable[[float, int, bytes], None] | None, sent: Callable[[int, bytes, float], None],
          lateness: Callable[[float], None], tick_done: Callable[[float, int, int], bool], partial: bool) -> float | None:
    """One batch read; the lane's time of the tick where the soak stops (None: it goes on)."""
    it = iter(frames)
    quads = zip(it, it, it, it)
    new, heard = tuple.__new__, Heard
    last = len(ticks) - 1
    for i, (now, n, sends, sent_stream, skipped) in enumerate(ticks):
        for can_id, data, t, late in sends:
            sent(can_id, data, t)
            if late is not None:
                lateness(late)
        for x in islice(quads, n):
            flags = x[3]
            msg = new(heard, x) if flags.__class__ is bool else _message(x)
            feed(msg)
            if keep is not None:
                keep(x[2], x[0], x[1])
        if partial and i == last:
            return None
        if tick_done(now, sent_stream, skipped):
            return now
    return None


def _message(x: tuple[Any, ...]) -> can.Message:
    """A remote or error frame as the world's lane handed it."""
    extended, remote, error, dlc = x[3]
    return can.Message(arbitration_id=x[0], data=x[1], timestamp=x[2], is_extended_id=extended,
                       is_remote_frame=remote, is_error_frame=error, dlc=dlc)
