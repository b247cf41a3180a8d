"""What made a simulated soak fast (issue #31: 8 h in under two minutes) changes nothing it judges: the trace's
remembered and batched lines are candump's own, the simulated lane's ``recv_until`` reads the frames and leaves the
clock where ``recv`` did, and the emulator's remembered throttle decodings and report payloads act and encode as
fresh ones. Each test would fail with its shortcut wrong; together they take well under a second."""

from __future__ import annotations

import can
import pytest

from ckesc.bench.sim_lane import SimLane
from ckesc.emulator.emulated_bench import EmulatedBench
from ckesc.protocol.errors import EncodeError
from ckesc.protocol.frame import Decoder, WireFrame, encode
from ckesc.soak.player import FORMATS, FlightPlan, Player
from ckesc.soak.trace import BATCH_LINES, MIN_BUDGET, ROLL_FILES, Trace, candump_line


def test_the_trace_writes_candumps_lines_in_order_across_its_rolls_and_at_its_close(tmp_path):
    t0 = 1000.0
    frames = [(t0 + i * 0.001 + 1e-7, 0x0C4E5201 + (i % 3), bytes(((i * 7) % 256, i % 2, 0xC0 | i % 32)))
              for i in range(7 * BATCH_LINES + 5)]  # not a whole number of batches: the last ones wait for close
    frames.append((t0 + 9.0, 0x1F, bytearray(b"\x01\x02")))  # a python-can frame's data is a bytearray
    line = len(candump_line(0.0, frames[0][1], frames[0][2]))
    trace = Trace(tmp_path, MIN_BUDGET, t0)
    trace.file_limit = 300 * line  # a few batches a file: it rolls mid-batch
    for t, can_id, data in frames:
        trace.frame(t, can_id, data)
    trace.close()
    kept = "".join((tmp_path / name).read_text() for name in (p.name for p in trace.files))
    assert trace.rolled_away > 0 and len(trace.files) == ROLL_FILES
    expected = "".join(candump_line(t - t0, can_id, bytes(data)) for t, can_id, data in frames)
    assert expected.endswith(kept) and kept.count("\n") >= 3 * 300 - 1  # the newest files, whole and in order
    assert sum((tmp_path / p.name).stat().st_size for p in trace.files) == len(kept)


def test_the_simulated_lanes_recv_until_and_frames_until_read_what_recv_did(tmp_path):
    """Three lanes of the same seed side by side, one read with ``recv(deadline - now())``, one with
    ``recv_until(deadline)``, one with ``frames_until(deadline)`` (and a listener on it), the last two sent to with
    ``send_wire`` (no ``can.Message``): the same frames at the same times, the clock at the same place after each
    frame read one by one and after each read up to a deadline (``frames_until`` runs the world to the deadline in
    one go: its clock is there at each frame), and the listener handed every frame as a ``can.Message``."""
    lanes = [SimLane(seed=3), SimLane(seed=3), SimLane(seed=3)]
    heard: list[can.Message] = []
    lanes[2].listeners.append(type("L", (can.Listener,), {"on_message_received": lambda self, m: heard.append(m)})())
    try:
        seen: list[list[tuple]] = [[], [], []]
        for step in range(1, 200):
            deadline = step * 0.0123
            for i, lane in enumerate(lanes):
                if step % 10 == 0:  # a command now and then: the ESC acts on it, its answers and echo read too
                    wire = throttle(100 * (step % 3), step % 32, node=100)
                    if i == 0:
                        lane.bus.send(can.Message(arbitration_id=wire.arbitration_id, data=wire.data, is_extended_id=True))
                    else:
                        lane.send_wire(wire)
                for msg in read(i, lane, deadline):
                    seen[i].append((msg.timestamp, msg.arbitration_id, bytes(msg.data), msg.is_rx, lane.now()))
                seen[i].append((None, None, None, None, lane.now()))
        assert seen[0] == seen[1] and sum(1 for s in seen[0] if s[0] is not None) > 100
        without_the_clock_at_each_frame = [[s if s[0] is None else s[:4] for s in seen[i]] for i in (0, 2)]
        assert without_the_clock_at_each_frame[0] == without_the_clock_at_each_frame[1]
        assert all(type(m) is can.Message for m in heard)
        assert [(m.timestamp, m.arbitration_id) for m in heard] == [s[:2] for s in seen[2] if s[0] is not None]
    finally:
        for lane in lanes:
            lane.close()


def test_a_soaks_reads_make_no_can_message_and_recv_makes_the_same_one():
    """Without a listener the simulated lane's ``frames_until`` hands each data frame as the bus heard it (no
    ``can.Message`` made: the soak's hours of frames); ``recv`` on a lane of the same seed gives python-can's
    ``Message`` of each, the host's own frames ``is_rx`` False in both."""
    lanes = [SimLane(seed=5), SimLane(seed=5)]
    try:
        for lane in lanes:  # (the ESC's controller up: the lane's acknowledgement holds the host's frames till then)
            lane.wait_power(0.5)
        got: list[list[tuple]] = [[], []]
        for step in range(1, 40):
            deadline = 0.5 + step * 0.0125
            for i, lane in enumerate(lanes):
                lane.send_wire(throttle(100, step % 32))
                msgs = list(lane.frames_until(deadline)) if i == 0 else list(read(1, lane, deadline))
                assert all(type(m) is not can.Message for m in msgs) if i == 0 else \
                    all(type(m) is can.Message and m.channel == lane.channel for m in msgs)
                got[i] += [(m.timestamp, m.arbitration_id, bytes(m.data), m.is_extended_id, m.is_rx,
                            m.is_remote_frame, m.is_error_frame) for m in msgs]
        assert got[0] == got[1]
        assert {f[4] for f in got[0]} == {True, False}  # the ESC's frames and the host's own, heard back
    finally:
        for lane in lanes:
            lane.close()


def test_the_soak_worlds_frames_into_hands_over_what_frames_until_reads(tmp_path):
    """The simulated lane's ``frames_into`` (the soak's world in a process of its own, :mod:`ckesc.soak.split`)
    gives, four plain values a frame, the frames ``frames_until`` gives on a lane of the same seed, the clock at the
    same place after each read: the bus's queue taken whole, and one by one where a remote frame is among them (its
    flags in the fourth value)."""
    lanes = [SimLane(seed=7), SimLane(seed=7)]
    try:
        for lane in lanes:
            lane.wait_power(0.5)
        got: list[list[tuple]] = [[], []]
        for step in range(1, 60):
            deadline = 0.5 + step * 0.0125
            for i, lane in enumerate(lanes):
                lane.send_wire(throttle(100, step % 32))
                if step % 20 == 0:  # a remote frame (it is no data frame: the ESC ignores it, the bus carries it)
                    lane.bus.send(can.Message(arbitration_id=0x1234, is_remote_frame=True, dlc=2))
                if i == 0:
                    got[0] += [(m.arbitration_id, bytes(m.data), m.timestamp,
                                m.is_extended_id if type(m) is not can.Message else
                                (m.is_extended_id, m.is_remote_frame, m.is_error_frame, m.dlc))
                               for m in lane.frames_until(deadline)]
                else:
                    flat: list = []
                    lane.frames_into(deadline, flat)
                    got[1] += list(zip(flat[0::4], flat[1::4], flat[2::4], flat[3::4]))
                got[i].append(lane.now())
        assert got[0] == got[1] and len(got[0]) > 100
        assert sum(1 for f in got[1] if isinstance(f, tuple) and isinstance(f[3], tuple)) == 2  # the remote frames
    finally:
        for lane in lanes:
            lane.close()


def read(i: int, lane: SimLane, deadline: float):
    if i == 2:
        yield from lane.frames_until(deadline)
        return
    while (msg := lane.recv(deadline - lane.now()) if i == 0 else lane.recv_until(deadline)) is not None:
        yield msg


@pytest.mark.parametrize("fmt, channels", [("14b", (1, 2)), ("12b", (1, 5, 9)), ("10b", (1, 6))])
def test_the_players_stream_frames_are_a_fresh_encoding_with_the_counters_transfer_id(fmt, channels):
    """The player encodes each command once with every tail: each frame it plays is the command encoded anew with
    the transfer id its counter gives (R5: RawCommand_10b has none), the throttle changing on the way."""
    plan = FlightPlan(host_node=0, node_id=1, format=fmt, rate_hz=400.0, channels=channels,
                      throttle=((0.0, 0), (0.05, 300), (0.1, 0)), allow_motor_spin=True)
    player = Player(plan, 0.0)
    name, per = FORMATS[fmt]
    tid = played = 0
    while player.sent_stream < 80:  # 0.2 s: the transfer ids wrap, the command changes twice
        for planned in (p for p in player.due(player.next_deadline()) if p.what == "stream"):
            value = plan.throttle_at(planned.due)
            fields = Decoder().decode(planned.wire).fields
            if fmt == "12b":
                group = fields["group"]
                expected = {"group": group, "channels": [value if (group - 1) * per + i + 1 in channels else 0
                                                         for i in range(per)]}
            else:
                expected = {"channels": [value if i + 1 in channels else 0 for i in range(per)]}
            fresh = encode(name, expected, source=0, transfer_id=tid % 32)
            assert planned.wire == fresh
            tid += fmt != "10b"
            played += 1
    assert played == 80 * (3 if fmt == "12b" else 1) and player.sent_stream == 80


def throttle(value: int, tid: int, node: int = 0) -> WireFrame:
    return encode("raw_command_14b", {"channels": [value, 0, 0, 0]}, source=node, transfer_id=tid)


def test_a_throttle_frame_decoded_once_still_reaches_the_esc_each_time_with_its_own_value():
    bench = EmulatedBench([1])
    bench.power_on(0.0)
    esc = bench.escs[0]
    t = esc.state.ready_at + 0.01
    for i, value in enumerate([300, 300, 700, 300, 0] * 40):  # transfer ids cycle: the same bytes come again
        wire = throttle(value, i % 32)
        bench.deliver(wire._replace(timestamp=t), t, esc.state.bitrate)
        assert esc.state.can_throttle == value and esc.state.last_command == t
        t += 0.02
    assert 0 < len(bench._throttle_decoded) <= 3 * 32


def test_a_report_payload_remembered_for_1_is_not_taken_for_true():
    """The ESC's reports remember their payloads by field values; 1 and True are equal as keys, and only 1 encodes."""
    bench = EmulatedBench([1])
    bench.power_on(0.0)
    esc = bench.escs[0]
    esc._emit(1.0, "msg1", {"speed": 0, "pwm": 1, "status": 0})
    with pytest.raises(EncodeError):
        esc._emit(1.1, "msg1", {"speed": 0, "pwm": True, "status": 0})
    esc._emit(1.2, "msg1", {"speed": 0, "pwm": 2, "status": 0})
    sent = [w for _, _, w in sorted(esc.state.outbox)]
    assert [w.data[:-1] for w in sent] == [encode("msg1", {"speed": 0, "pwm": p, "status": 0}, source=1).data[:-1]
                                          for p in (1, 2)]
