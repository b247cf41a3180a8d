"""Playing the explorer's R20 steps on the bench (the IO part of :mod:`ckesc.explore.actions`' ``short`` and ``alone``).

- **A bus short** (:func:`play_short`): the streams stopped (the commands cannot reach the ESC through a short), the
  bench's bus-fault control (:func:`~ckesc.bench.bus_fault.bus_fault_control`: the simulated lane's CAN model, the
  real-time emulator's ``ckesc control bus``, a real bench's ``--bus-fault-cmd``) shorts the bus for the step's
  seconds, then the bus is read until each report is back on its grid (R20's bound and the longest report interval
  twice, as the robustness section's test reads), the live reader leaving the reports' timing and transfer ids
  unjudged meanwhile (:data:`~ckesc.protocol.judgements.R20_UNJUDGED`); the oracle is told the short's start, its end
  and that moment (:data:`~.oracle.SHORT_MARKS`). A foreign load playing (R18) is taken off the bus for the short and
  put back once the reports settled: a load generator's backlog after the short would hold the ESC's reports back
  longer than R20's bound, which says nothing of a loaded bus. A DUT still bus-off then (no recovery of its own) is power-cycled
  back, as on a real bench, and the program goes on. A stream that ran before goes on after it: its next command clears
  the comm flag the short raised (R20). A lane without a control plays no short, and says so.
- **A power cycle with the host alone** (:func:`play_alone`): the power off, the step's frames sent (nobody
  acknowledges them: a real adapter, and the simulated lane's CAN model, hold them until the ESC's controller is up),
  the power on; the ESC meets them at its power-up and may take them or not (R20: OBSERVE; the live reader's report
  timing unjudged until each report came once more after it, :data:`~ckesc.protocol.judgements.R20_UNJUDGED`). Which it took, its answers
  tell (a read or a settings write is answered when taken): the oracle is given those only (:attr:`Session.unheld`
  keeps the others from it), and their answers are not judged (:attr:`~.oracle.Oracle.held`).
"""

from __future__ import annotations

from typing import Any, Callable

from ..protocol import catalogue as cat
from ..protocol.ids import Kind
from ..protocol.judgements import R20_UNJUDGED, r20_bound_s
from ..protocol.transfer import tail_transfer_id
from .actions import ANSWER_READ_S, Action, asks_only, stream_fields
from .oracle import SHORT_MARKS, Oracle


def play_short(session: Any, action: Action, oracle: Oracle, step: int, feed: Callable[[int], None]) -> None:
    """Short the bus for ``action.seconds`` (see the module docstring)."""
    control = session.bus_control()
    if control is None or not control.can("short"):
        session._skipped.append(f"step {step + 1}, {action.describe()}: skipped, the {session.lane.name} lane has no "
                                "bus-fault control (give --bus-fault-cmd)")
        return
    dut, lane = session.dut, session.lane
    stream = session.streaming
    dut.stop_throttle()
    dut.wait(STOP_S)  # (the last command of the stream on the bus before the short)
    feed(step)
    load = dict(session._current_load) if session._load is not None else {}
    if load:  # the foreign load off while the bus is shorted (its backlog would hold the reports back after it)
        session._set_load(None)
        oracle.load(lane.now(), 0.0, step)
    session.rules.excuse(R20_UNJUDGED)
    # the reader takes the ESC's first busy stretch after the short as what it held (evidence/rejoin.py: each frame
    # alone, its gap and transfer id OBSERVE, then every report again with R9a-gaps grace), as after the host's bus was
    # away; a reset across it is left to 241's counters and R20's bound (the judge's)
    session.rules.rules.rejoined(lane.bitrate)
    start = lane.now()
    oracle.mark(start, SHORT_MARKS[0], step)
    end = control.cause("short", action.seconds)
    end = lane.now() if end is None else end
    oracle.mark(end, SHORT_MARKS[1], step)
    intervals = oracle.state_at(end).intervals
    settled = end + r20_bound_s(intervals["msg1"], bitrate=lane.bitrate) + lane.timing_error + 2 * max(intervals.values())
    dut.read_until(settled)
    feed(step)
    oracle.mark(lane.now(), SHORT_MARKS[2], step)
    session.rules.excuse(frozenset())  # (what it excused: OBSERVE, not kept)
    if not control.settle() and lane.power.available:
        # a controller still bus-off (the DUT's: it did not recover by itself, which the judge finds): the power cycle
        # that brings it back on a real bench (as the robustness test's), so that the program goes on
        dut.switch_power(session.profile.off_s, session.profile.boot_s)
        control.settle()
        feed(step)
        stream = None
    if load:
        session._set_load(load, step)
        oracle.load(lane.now(), load.get("share", 0.0), step)
    if stream is not None:
        dut.throttle_stream(stream, stream_fields(stream), period=session.stream_period)
        session.streaming = stream


#: how long the step waits after stopping a stream before the short
STOP_S = 0.01


def play_alone(session: Any, action: Action, oracle: Oracle, step: int, feed: Callable[[int], None]) -> None:
    """A power cycle with the host alone on the bus sending ``action``'s frames while the ESC is off (see the module
    docstring). Where the lane has no power control, skipped and said so."""
    dut, lane, profile = session.dut, session.lane, session.profile
    if not lane.power.available:
        session._skipped.append(f"step {step + 1}, {action.describe()}: skipped, no power control")
        return
    session.streaming = None
    session.rules.excuse(R20_UNJUDGED)
    others = dut.supply.power_off()
    feed(step)
    off = lane.now()
    sent = []
    node = oracle.node_id
    for frame in action.fields.get("frames", ()):
        name, fields = frame["name"], frame.get("fields", {})
        if cat.spec(name).service:
            ex = dut.request(name, fields, destination=node, expect_response=False)
            sent.append((name, fields, Kind.RESPONSE, ex.sent.wire))
        else:
            s = dut.broadcast(name, fields, **({"layout": "query"} if name == "get_esc_id" else {}))
            sent.append((name, fields, Kind.MESSAGE, s.wire))
    lane.wait_power(max(0.0, off + profile.off_s - lane.now()))
    heard = len(dut.trace)
    dut.supply.power_on(others, profile.boot_s)
    dut.wait(ANSWER_READ_S)  # the answers to the frames held: they go out as the ESC's controller comes up
    # what the ESC did with them (a write taken at its boot restarts its reports from there, not from its send), until
    # each report came once more: the reader's report timing unjudged meanwhile (R20: OBSERVE)
    dut.wait(2 * cat.REPORT_INTERVAL_RANGE[1] * cat.INTERVAL_UNIT_S)
    session.rules.excuse(frozenset())
    for name, fields, kind, wire in sent:
        tid = tail_transfer_id(wire.data[-1]) if wire.data and cat.spec(name).has_tail else 0
        if kind is Kind.RESPONSE or name == "get_esc_id":
            oracle.held.add((name, tid))  # (its answer, or none: R20's OBSERVE)
        if kind is not Kind.RESPONSE or asks_only(name, fields):
            continue  # a read changes nothing: the model takes it either way
        taken = any(f.source != dut.host_node and f.name == name and f.kind is kind and f.transfer_id == tid
                    for f in dut.trace[heard:])
        if not taken:  # a write the ESC did not take at its power-up (R20 leaves it free): the model must not either
            session.unheld.append((wire.arbitration_id, bytes(wire.data)))

