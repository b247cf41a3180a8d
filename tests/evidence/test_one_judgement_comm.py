"""One trace, every consumer that judges the comm flag, one finding (issue #35): R8 over the frames of an emulated ESC
under the host's RawCommand stream that stops for half a second and starts again, while a flight controller queries
GET_ESC_ID every 50 ms and streams its standard DroneCAN ESC command (1030) every 10 ms throughout (R20: only RawCommand refreshes the comm watchdog, and comm loss is judged with
such traffic going on). The faultless ESC is R8 to none; one that raises the flag 400 ms or 100 ms after the last
command, never, or does not clear it on the next command (the emulator's ``comm_loss_*`` faults) is R8 to each:

* the suite's check (``conformance/test_s4_4_4_msg1.py``, as written there: no flag under the stream; the first MSG1
  with the flag against ``judgements.r8_onset`` from the last command, one MSG1 interval being the DUT's own; the
  flag clear on an MSG1 within an interval of the next command);
* the soak's comm-flag watch (:class:`~ckesc.soak.comm_watch.CommFlagWatch`: each MSG1 against
  ``judgements.r8_flag_due``);
* ``ckesc explore``'s judge (``judge._status``: each MSG1's bit 13 against ``r8_flag_due`` from the commands the reader says address the ESC's throttle channel).

Who does not judge it, and why: the live bus rules and ``ckesc check-log`` record the flag's changes with the time
since the last command (``summary()["nodes"][...]["comm_loss"]``) and judge nothing of them: a capture does not say
that the throttle source is CAN, nor which node's RawCommand channel is the ESC's. They must record the same
episodes on every trace, the flight controller's queries no command."""

from __future__ import annotations

import can
import pytest

from ckesc.evidence.events import EventLog
from ckesc.evidence.rules import BusRules
from ckesc.explore.judge import Params, judge
from ckesc.explore.oracle import Oracle
from ckesc.protocol import catalogue as cat
from ckesc.protocol.frame import frame_bits
from ckesc.protocol.judgements import r8_onset
from ckesc.soak.monitor import Monitor
from ckesc.soak.watch import WatchConfig
from conformance.telemetry import REACT_S

from .test_one_judgement import BOOT_S, NODE, decoded, play, request

FC = 10
HIGH_MINUS_1 = 3  # the flight controller's priority for 1030 (bench/foreign.py)
#: the host's stream: every 10 ms over these two spans (the gap between them: comm loss); the trace's end
STREAMS = ((0.30, 0.80), (1.30, 1.60))
END_S = 1.80
MSG1_S = 0.020
COMM = int(cat.Status.COMM_FAULT)


def _trace(faults: tuple[str, ...], echo: bool = True) -> list:
    """The host's stream (its frames stamped at their end on the bus by their echo, or without one at the host's send,
    one frame's time before) and the flight controller's queries, and everything the ESC sends."""
    events = [(t / 1000, request("raw_command_14b", {"channels": [0] * 4}, t / 1000, destination=None,
                                 transfer_id=(t // 10) % 32))
              for lo, hi in STREAMS for t in range(round(lo * 1000), round(hi * 1000) + 1, 10)]
    events += [(t / 1000 + 0.003, request("get_esc_id", {"option": 0}, t / 1000 + 0.003, source=FC, layout="query",
                                          transfer_id=(t // 50) % 32)) for t in range(250, 1750, 50)]
    events += [(t / 1000 + 0.005, _foreign_esc_command(t / 1000 + 0.005, (t // 10) % 32)) for t in range(250, 1750, 10)]
    frames = play(sorted(events, key=lambda e: e[0]), END_S, faults=faults, throttle_channel=1)
    for m in frames:
        if not echo and not m.is_rx:
            m.timestamp -= frame_bits(len(m.data)) / cat.DEFAULT_BITRATE
    return sorted(frames, key=lambda m: m.timestamp)


def _foreign_esc_command(t: float, tid: int) -> can.Message:
    """The flight controller's standard DroneCAN ESC command (``uavcan.equipment.esc.RawCommand``, 1030), ZERO, as
    ``bench/foreign.ardupilot`` plays it: not one of the ESC's frames (R17), no comm refresh (R20)."""
    return can.Message(arbitration_id=(HIGH_MINUS_1 << 24) | (1030 << 8) | FC, data=bytes([0] * 7 + [0xC0 | tid]),
                       is_extended_id=True, timestamp=t)


def _flag(f) -> bool:
    return bool(f.fields["status"] & COMM)


def _suite(frames) -> set[str]:
    """As ``test_comm_fault_flag`` judges: no flag under the stream, the first flag's onset, cleared again."""
    msg1 = [f for f in decoded(frames) if f.name == "msg1" and f.source == NODE]
    commands = [m.timestamp for m in frames if not m.is_rx]
    last = max(t for t in commands if t <= STREAMS[0][1] + 0.001)
    again = min(t for t in commands if t > last)

    def start(f) -> float:
        return f.timestamp - frame_bits(len(f.data)) / cat.DEFAULT_BITRATE

    under = [f for f in msg1 if STREAMS[0][0] + MSG1_S < f.timestamp <= last]
    if any(map(_flag, under)):
        return {"R8"}  # "bit13 (comm fault) set in MSG1 under a command stream"
    interval = max([MSG1_S] + [start(b) - start(a) for a, b in zip(under, under[1:])])
    first = next((f for f in msg1 if last < f.timestamp < again and _flag(f)), None)
    if first is None:
        return {"R8"}  # "no MSG1 with bit13 (comm fault) within ... of the last command"
    before = [f for f in msg1 if last < f.timestamp < first.timestamp]
    if before:
        interval = max(interval, start(first) - start(before[-1]))
    broken = {j.rule for j in r8_onset(start(first) - last, interval) if not j.ok}
    cleared = next((f for f in msg1 if again < f.timestamp and not _flag(f)), None)
    if cleared is None or start(cleared) - again > interval + REACT_S:
        broken.add("R8")  # "bit13 still set ... after a new command (4.4.4-3: cleared)"
    return broken


def _soak(frames) -> set[str]:
    monitor = Monitor(WatchConfig(node_id=NODE, host_node=0, intervals={"msg1": MSG1_S}), t0=0.0)
    for m in frames:
        monitor.feed(m)
    monitor.close(END_S)
    return {r for f in monitor.findings if f.watch == monitor.comm.name for r in f.rules}


def _judged(frames, *, channel: int = 1, heard=None) -> tuple[Oracle, list]:
    """The explorer's oracle fed the host's frames of ``frames`` (the ESC at throttle ``channel``), and its judge's
    findings on the ESC's frames (``heard``: the reader's log, when the test gives it)."""
    baseline = {"node_id": NODE, "throttle_channel": channel, **cat.DEFAULT_REPORT_INTERVALS}
    oracle = Oracle(baseline, powered_at=0.0, start=BOOT_S)
    for m in frames:
        if not m.is_rx:
            oracle.host_frame(m)
    oracle.finish(END_S)
    found = judge(oracle, decoded(m for m in frames if m.is_rx and m.timestamp >= BOOT_S), BOOT_S, END_S,
                  Params(boot_s=BOOT_S), **({} if heard is None else {"heard": heard}))
    return oracle, found


def _explorer(frames) -> set[str]:
    return {r for f in _judged(frames)[1] for r in f.requirements}


def _recorded(frames) -> list[tuple[str, float]]:
    """The bus rules' (and check-log's) record of the flag: each change and its time since the last command (ms)."""
    rules = BusRules(tolerance=0.0, complete=True, power_known=True)
    for m in frames:
        rules.feed_message(m)
    assert not [v for v in rules.findings() if v.fails]
    return [(e["event"], e.get("since_last_throttle_ms")) for e in rules.summary()["nodes"][str(NODE)]["comm_loss"]]


@pytest.mark.parametrize("faults, expected", [((), set()), (("comm_loss_late",), {"R8"}), (("comm_loss_early",), {"R8"}),
                                              (("comm_loss_never",), {"R8"}), (("comm_loss_sticky",), {"R8"})],
                         ids=["faultless", "late", "early", "never", "sticky"])
@pytest.mark.parametrize("echo", [True, False], ids=["echo", "no echo"])
def test_one_trace_the_same_r8_finding_from_the_suite_the_soak_and_the_explorer(faults, expected, echo):
    frames = _trace(faults, echo)
    soak, explorer = _soak(frames), _explorer(frames)
    got = {"suite": _suite(frames), "soak": soak & {"R8"}, "explorer": explorer & {"R8"}}
    assert got == dict.fromkeys(got, expected)
    assert soak <= {"R8", "R19"} and explorer <= {"R8", "R7"}  # nothing else found on the flight controller's traffic


def test_the_bus_rules_record_the_comm_loss_episode_and_no_command_in_the_flight_controllers_queries():
    """The faultless ESC's flag set once, 200 ms to one MSG1 interval after the last command however many queries
    came meanwhile, and cleared once after the next command."""
    (set_, since_set), (cleared, since_cleared) = _recorded(_trace(()))
    assert (set_, cleared) == ("set", "cleared")
    assert 200 <= since_set <= 200 + MSG1_S * 1000 + frame_bits(8) / cat.DEFAULT_BITRATE * 1000
    assert since_cleared <= MSG1_S * 1000 + 1


def _set_id_trace(faults: tuple[str, ...]) -> list:
    """The ESC at node NODE, throttle channel NODE (5), under a RawCommand_10b stream (channels 1..6) every 10 ms from
    0.3 s to the end; the host reads GET_ESC_ID at 0.35 s and sends Set ID (node NODE, channel 20) at 0.6 s: from then on no
    frame of the stream carries the ESC's channel, and R8's flag is due 200 ms after the last one that did."""
    events = [(t / 1000, request("raw_command_10b", {"channels": [0] * 6}, t / 1000, destination=None))
              for t in range(300, round(END_S * 1000) + 1, 10)]
    events += [(0.355, request("get_esc_id", {"option": 0}, 0.355, layout="query", destination=None)),
               (0.605, request("set_id", {"node_id": NODE, "throttle_channel": 20}, 0.605, transfer_id=1))]
    return play(sorted(events, key=lambda e: e[0]), END_S, faults=faults)


@pytest.mark.parametrize("faults, expected", [((), set()), (("comm_loss_never",), {"R8"}), (("comm_loss_late",), {"R8"})],
                         ids=["faultless", "never", "late"])
def test_r8_counts_from_the_commands_that_address_the_esc_s_channel_in_every_consumer(faults, expected):
    """Where the readings disagreed (issue #35): the reader's last command was the last RawCommand of any channel; the
    explorer's model counted R8 from the commands that carry its ESC's channel (a RawCommand for other channels is no
    command for it: 4.4.4-3 "does not receive any command", R8 "no RawCommand has arrived", as the emulator's ESC
    reads it). The model's reading won, and is now the reader's (``evidence/commands.py``: the channel from the
    GET_ESC_ID reply, then the Set ID answer), which the explorer's judge and the soak's comm watch take: after Set ID
    to channel 20 under a 10-bit stream the flag is due, the faultless ESC raises it and nobody finds anything; an ESC
    that never raises it, or late, is R8 to both. On the losing reading (any channel's command) a stream frame came
    within 10 ms of every MSG1: the flag would be due nowhere, the faultless ESC would be R8 and the faulty ones not."""
    frames = _set_id_trace(faults)
    rules = BusRules(tolerance=0.0, complete=True, power_known=True)
    rules.power_switched(0.0)  # (the ESC's power-up: Set ID's window, R11, known to the reader)
    log = rules.events = EventLog()
    for m in frames:
        rules.feed_message(m)
    assert rules.clock.channel(NODE) == 20
    streamed = [m.timestamp for m in frames if not m.is_rx and m.dlc == 8]
    assert all(t - max(s for s in streamed if s <= t) <= 0.010 for t, _, _ in log.flags[NODE] if t > 0.35)
    due = [(t, flag) for t, flag, last in log.flags[NODE] if last is not None and t - last > 0.2 + MSG1_S + 0.001]
    assert len(due) > 20  # the reader's clock: the flag due, 200 ms after the last frame that carried channel 5
    assert max(last for t, _, last in log.flags[NODE] if last is not None) < 0.605 + 0.001
    if not faults:
        assert all(flag for _, flag in due)
    explorer = {r for f in _judged(frames, channel=NODE)[1] for r in f.requirements}
    _, with_its_log = _judged(frames, channel=NODE, heard=log)
    monitor = Monitor(WatchConfig(node_id=NODE, host_node=0, intervals={"msg1": MSG1_S}), t0=0.0)
    monitor.rules.power_switched(0.0)
    for m in frames:
        monitor.feed(m)
    monitor.close(END_S)
    soak = {r for f in monitor.findings if f.watch == monitor.comm.name for r in f.rules}
    assert {"explorer": explorer & {"R8"}, "explorer on the reader's log": {r for f in with_its_log for r in f.requirements}
            & {"R8"}, "soak": soak & {"R8"}} == dict.fromkeys(("explorer", "explorer on the reader's log", "soak"), expected)
    assert monitor.comm.trials > 20  # the soak judged the flag through the Set ID (never: not judged at all)
