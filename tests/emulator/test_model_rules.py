"""The emulated ESC against the document, rule by rule (ids of spec/INTERPRETATIONS.md), in simulated time.

The lane is deterministic, so times are asserted exactly (to float rounding): a frame of n data bytes
takes (67 + 8n) / bitrate s and is timestamped at its last bit. The numbers below are the document's,
written out here on purpose: these tests are the oracle for the emulator, not a copy of its tables.
"""

from __future__ import annotations

import math

import pytest

from ckesc.protocol import BY_NAME, Kind, Status, illegal_cases
from ckesc.protocol import catalogue as cat
from ckesc.protocol.catalogue import SELFTEST_ERROR_MASK

# --------------------------------------------------------------------------------------------------
# The document's numbers

MS = 0.001
MSG1_S, MSG2_S, MSG3_S = 10 * 2 * MS, 50 * 2 * MS, 250 * 2 * MS  # 4.4.22 clarification 4: defaults x 2 ms
SLOT_S = 2 * MS  # R2: answer after (node_id % 32) x 2 ms
COMM_LOSS_S = 200 * MS  # 4.4.4 clarification 3
WINDOW_S = 120.0  # 4.3.2: Set ID / Set Baud valid for 120 s after power-up
SUSPEND, RESUME, RESUME_EXP = 0x55555555, 0xAAAAAAAA, 0xEEEEEEEE  # 4.4.2
CAN_TEST_ON, CAN_TEST_OFF = 0xAA, 0x55  # 4.4.1
HIGHEST, MEDIUM, LOW, LOWEST = 0, 16, 24, 31  # 4.1.2
RED, GREEN, BLUE = 4, 2, 1  # 4.4.20: bit 2 R, bit 1 G, bit 0 B
BAUD = {0: 1_000_000, 1: 500_000, 2: 250_000, 3: 200_000, 4: 125_000, 5: 100_000, 6: 50_000}  # 4.4.19
REPORTS = cat.REPORT_FRAMES

#: Payload + tail bytes on the wire.
LEN = {"msg1": 7, "msg2": 6, "msg3": 8, "msg_control": 6, "get_esc_id?": 2, "get_esc_id": 3, "set_freq": 5,
       "can_test": 6, "raw": 8, "self_test?": 1, "self_test": 2, "expand_set_part": 4}

#: Three ESCs whose R2 answers never meet their own report bursts: 6, 58 and 16 ms (40 % 32 = 8).
STAGGERED = (3, 29, 40)


def tick_at_or_after(t: float, base: float, period: float = MSG1_S, phase: float = 0.0) -> float:
    """The first base + k * period + phase that is not before t."""
    k = math.ceil((t - base - phase) / period - 1e-9)
    return base + k * period + phase


def msg1_due(f, base: float) -> float:
    """MSG1's due time on its 20 ms grid, even when a host frame delayed it."""
    return base + MSG1_S * math.floor((f.timestamp - base) / MSG1_S + 1e-9)


def reports_after(frames, t: float, names=REPORTS):
    return [f for f in frames if f.name in names and f.timestamp > t]


def read_settings(host, node: int) -> dict:
    """Everything the services let a host read back (R10, R13)."""
    cfg = host.call("get_major_configuration", {"option": 0}, node).fields
    freq = host.call("set_freq", {"option": 0, "msg1_interval": 10, "msg2_interval": 10, "msg3_interval": 10}, node).fields
    rotation = host.call("set_rotation", {"rotation": 0xFF}, node).fields["rotation"]
    t = host.now
    host.send("get_esc_id", {"option": 0})
    ids = [f.fields for f in host.collect(t + 0.07) if f.name == "get_esc_id"]
    return {"config": cfg, "freq": {k: v for k, v in freq.items() if k != "option"}, "rotation": rotation, "ids": ids}


def nvm_settings(esc) -> dict:
    keys = ("node_id", "throttle_channel", "baud", "led_color", "led_blink", "rotation", "msg1_interval",
            "msg2_interval", "msg3_interval", "throttle_source", "active_freewheel", "prop_lock",
            "startup_acceleration", "lost_signal_reduction")
    return {k: esc.nvm[k] for k in keys}


# --------------------------------------------------------------------------------------------------
# Power-up (4.2.1, 4.4.24, 4.4.27)


def test_first_report_comes_one_boot_time_after_power_up(lane):
    host = lane([1])
    frames = host.collect(1.0)
    assert frames[0].name == "msg1"
    assert host.close(frames[0].timestamp, host.BOOT + host.tx(LEN["msg1"]))
    assert all(f.timestamp > host.BOOT for f in frames)

    host.bus.power_cycle(0.4)
    t_on = host.now
    frames = host.collect(t_on + 0.5)
    assert host.close(host.of(frames, "msg1")[0].timestamp, t_on + host.BOOT + host.tx(LEN["msg1"]))
    assert all(f.timestamp > t_on + host.BOOT for f in frames)


def test_the_esc_hears_nothing_while_it_boots(lane):
    host = lane([1])
    lane.join(host, source=0x10)  # another node (a flight controller) acknowledges: alone, the host's frames would wait
    host.wait_until(0.1)
    host.send("get_esc_id", {"option": 0})
    host.send("msg_control", {"option": 0, "command": SUSPEND})
    assert host.collect(host.BOOT) == []
    assert host.esc(1).counters["rx"] == 0
    frames = host.collect(host.BOOT + 0.1)
    assert host.of(frames, "msg1"), "the suspend sent while booting must not have been obeyed"
    assert not host.of(frames, "get_esc_id")


def test_power_up_counter_counts_power_ups(lane):
    host = lane([1])
    host.wait_until(0.3)
    counts = [host.call("maintenance_information", {"option": 2}).fields["power_ups"]]
    for _ in range(2):
        host.bus.power_cycle(0.2)
        host.wait(host.BOOT + 0.01)
        counts.append(host.call("maintenance_information", {"option": 2}).fields["power_ups"])
    assert counts == [1, 2, 3]


#: Fault code 1 -> MSG1 self-test bit: the reading the emulator plays, a protocol table (catalogue)
SELF_TEST_BITS = cat.FAULT_CODE_STATUS_BITS


@pytest.mark.parametrize("code", sorted(SELF_TEST_BITS), ids=lambda c: f"0x{c:02X}")
def test_self_test_fault_shows_in_msg1_self_test_and_maintenance(lane, code):
    host = lane([1], esc_config={"self_test_fault": code})
    frames = host.collect(0.3)
    status = host.of(frames, "msg1")[0].fields["status"]
    assert status & SELFTEST_ERROR_MASK == SELF_TEST_BITS[code]
    assert host.call("self_test").fields == {"status": int(code != 0)}  # 4.4.24: 0 passed, 1 failed
    assert host.call("maintenance_information", {"option": 2}).fields["fault_code"] == code
    host.send("msg_control", {"option": 0, "command": RESUME_EXP})
    exp9 = host.of(host.collect(host.now + 0.6), "msg_exp9")
    assert exp9 and exp9[0].fields["fault_code_1"] == code  # 4.4.11


# --------------------------------------------------------------------------------------------------
# F1-F3: ids, tail bytes and transfer ids of what the ESC sends; MSG1..3 contents (R7, 4.4.4-4.4.6)


def test_report_ids_tails_and_transfer_ids(lane):
    host = lane([5])
    msgs = host.collect_raw(host.BOOT + 0.02 * 40 + 0.01)
    msg1 = [m for m in msgs if (m.arbitration_id >> 8) & 0xFFFF == 20050]
    assert {m.arbitration_id for m in msg1} == {0b11111_0100111001010010_0_0000101}  # LOWEST, 20050, message, node 5
    assert {m.arbitration_id for m in msgs if (m.arbitration_id >> 8) & 0xFFFF == 20052} == {0x1F4E5405}  # MSG3
    assert {m.data[-1] & 0xE0 for m in msgs} == {0xC0}  # F2: start=1 end=1 toggle=0
    assert [m.data[-1] & 0x1F for m in msg1] == [k % 32 for k in range(41)]  # F3: +1 per transfer, modulo 32
    msg2 = [m.data[-1] & 0x1F for m in msgs if (m.arbitration_id >> 8) & 0xFFFF == 20051]
    assert msg2 == list(range(len(msg2)))  # one counter per frame type


def test_status_bits_and_report_contents(lane):
    host = lane([1])
    frames = host.collect(0.3)
    m1, m2, m3 = (host.of(frames, n)[0] for n in REPORTS)
    assert (m1.fields, len(m1.data)) == ({"speed": 0, "pwm": 0, "status": 0}, 7)
    assert 5030 <= m2.fields["voltage"] <= 5050 and m2.fields["current"] == 0 and len(m2.data) == 6  # 0.01 V: 50.4 V
    assert m2.fields["temperature"] == m3.fields["mos_t"] == 25 and len(m3.data) == 8
    assert m3.fields["motor_t"] == 0  # no motor sensor configured (4.4.6)
    host.call("set_rotation", {"rotation": 1})
    status = host.of(host.collect(host.now + 0.03), "msg1")[-1].fields["status"]
    assert status == Status.DIRECTION_CCW  # R7: bit 15, not DroneCAN's bit 14
    task = host.bus.send_periodic(host.message("raw_command_10b", {"channels": [500, 0, 0, 0, 0, 0]}), 0.01)
    frames = host.collect(host.now + 1.0)
    task.stop()
    last = host.of(frames, "msg1")[-1]
    assert last.fields["status"] == Status.DIRECTION_CCW | Status.RUNNING and last.fields["pwm"] == 1000
    assert 4400 < last.fields["speed"] < 4510  # the emulator's motor: half of 9000 rpm, first-order lag
    assert host.of(frames, "msg2")[-1].fields["current"] > 0


# --------------------------------------------------------------------------------------------------
# F7: the factory node id 0x7D reports nothing on its own, yet answers


def test_factory_default_node_is_silent_but_answers(lane):
    host = lane([0x7D])
    assert host.collect(1.5) == []

    t = host.now
    host.send("get_esc_id", {"option": 0})
    [reply] = host.collect(t + 0.1)
    assert (reply.source, reply.fields) == (0x7D, {"node_id": 0x7D, "throttle_channel": 1})
    assert host.close(reply.timestamp, t + host.tx(LEN["get_esc_id?"]) + (0x7D % 32) * SLOT_S + host.tx(LEN["get_esc_id"]))

    t = host.now
    host.send("msg_control", {"option": 0, "command": RESUME})
    [answer] = host.collect(t + 0.1)
    assert answer.name == "msg_control" and answer.fields == {"option": 0, "command": 0}
    assert host.close(answer.timestamp, t + host.tx(LEN["msg_control"]) + 29 * SLOT_S + host.tx(LEN["msg_control"]))

    assert host.call("self_test", destination=0x7D).fields == {"status": 0}
    # the document's defaults (4.4.20-4.4.23): forward, CAN throttle, green steady, 10/50/250
    assert host.call("get_major_configuration", {"option": 0}, 0x7D).fields == {
        "direction": 0, "throttle_source": 0, "throttle_channel": 1, "led_blink": 0, "led_color": GREEN,
        "msg1_interval": 10, "msg2_interval": 50, "msg3_interval": 250, "reserved": 0}
    assert host.collect(host.now + 1.0) == []

    # given a node id, it reports at once; back at 0x7D it is silent again
    reply = host.call("set_id", {"node_id": 5, "throttle_channel": 5}, 0x7D)
    assert reply.source == 5
    t = host.now
    frames = host.collect(t + 0.1)
    assert {f.source for f in frames} == {5} and len(host.of(frames, "msg1")) == 5
    host.call("set_id", {"node_id": 0x7D, "throttle_channel": 1}, 5)
    host.wait(0.01)
    assert host.collect(host.now + 1.0) == []


# --------------------------------------------------------------------------------------------------
# R9: report intervals


def test_default_report_intervals(lane):
    host = lane([1])
    frames = host.collect(host.BOOT + 1.2 + 2 * MS)
    tx1, tx2, tx3 = host.tx(LEN["msg1"]), host.tx(LEN["msg2"]), host.tx(LEN["msg3"])
    # the three share one grid, so MSG2 always follows an MSG1 and MSG3 an MSG2 (arbitration: lower id first)
    for name, period, delay in (("msg1", MSG1_S, tx1), ("msg2", MSG2_S, tx1 + tx2), ("msg3", MSG3_S, tx1 + tx2 + tx3)):
        stamps = [f.timestamp for f in host.of(frames, name)]
        expected = [host.BOOT + k * period + delay for k in range(int(1.2 / period + 1e-9) + 1)]
        assert len(stamps) == len(expected), name
        assert all(host.close(a, b) for a, b in zip(stamps, expected)), (name, stamps[:5], expected[:5])


def _check_set_freq(host, setting, frames_before) -> list:
    """Send Set Freq at a time 1 ms off the 2 ms report grid, then check every report's due time:
    the first new one at max(request, last report + new interval), then every new interval."""
    t_send = tick_at_or_after(host.now + 0.001, host.BOOT, 2 * MS, phase=MS)
    frames_before = frames_before + host.collect(t_send, own=True)
    fields = {"option": 1, "msg1_interval": setting[0], "msg2_interval": setting[1], "msg3_interval": setting[2]}
    host.send("set_freq", fields, destination=1)
    t_rx = t_send + host.tx(LEN["set_freq"])
    after = host.collect(t_rx + 2 * max(setting) * 2 * MS + 0.1, own=True)
    everything = frames_before + after
    dues = host.due_times(everything)
    [answer] = [f for f in after if f.name == "set_freq" and f.kind is Kind.RESPONSE]
    assert answer.fields == fields
    for name, n in zip(REPORTS, setting):
        period = n * 2 * MS
        old = [d for d, f in zip(dues, everything) if f.name == name and d < t_rx - 1e-9]
        new = [d for d, f in zip(dues, everything) if f.name == name and d >= t_rx - 1e-9]
        assert old and len(new) >= 2, name
        assert host.close(new[0], max(t_rx, old[-1] + period)), (name, new[0], t_rx, old[-1])
        gaps = [b - a for a, b in zip(new, new[1:])]
        assert all(host.close(g, period) for g in gaps), (name, period, gaps)
    return after


@pytest.mark.parametrize("setting", [(10, 10, 10), (15, 60, 100), (250, 250, 250), (11, 13, 17), (25, 50, 250)])
def test_report_intervals_after_set_freq(lane, setting):
    host = lane([1])
    before = host.collect(host.BOOT + 0.645, own=True)
    _check_set_freq(host, setting, before)


def test_report_intervals_after_every_set_freq_in_a_row(lane):
    host = lane([1])
    frames = host.collect(host.BOOT + 0.6, own=True)
    for setting in [(20, 30, 40), (10, 250, 10), (250, 10, 100), (12, 12, 12), (10, 50, 250)]:
        frames = _check_set_freq(host, setting, frames)


def test_set_freq_read_ignores_the_values_sent(lane):
    host = lane([1])
    host.wait_until(0.3)
    host.call("set_freq", {"option": 1, "msg1_interval": 20, "msg2_interval": 40, "msg3_interval": 80})
    read = host.call("set_freq", {"option": 0, "msg1_interval": 99, "msg2_interval": 99, "msg3_interval": 99})
    assert read.fields == {"option": 0, "msg1_interval": 20, "msg2_interval": 40, "msg3_interval": 80}


# --------------------------------------------------------------------------------------------------
# R2 and 4.4.2: MSG Control


def _answers(frames, name, t_rx, host, nbytes):
    got = sorted((f.source, f.timestamp) for f in frames if f.name == name and f.source != 0)
    want = sorted((n, t_rx + (n % 32) * SLOT_S + host.tx(nbytes)) for n in STAGGERED)
    assert [n for n, _ in got] == [n for n, _ in want]
    for (n, a), (_, b) in zip(got, want):
        assert host.close(a, b), (n, a - b)


def test_msg_control_suspend_resume_and_exp_mode(lane):
    host = lane(STAGGERED)
    base = host.BOOT

    # suspend: all three answer, staggered; no report after the command
    t_send = tick_at_or_after(base + 0.2, base, phase=5 * MS)
    host.wait_until(t_send)
    host.send("msg_control", {"option": 0, "command": SUSPEND})
    t_rx = t_send + host.tx(LEN["msg_control"])
    frames = host.collect(t_rx + 0.5)
    _answers(frames, "msg_control", t_rx, host, LEN["msg_control"])
    assert all(f.fields == {"option": 0, "command": 0} and f.priority == MEDIUM for f in host.of(frames, "msg_control"))
    assert reports_after(frames, t_rx) == []

    # resume: reports restart at once ("immediate recovery"), then every 20 ms
    t_send = host.now + 7 * MS
    host.wait_until(t_send)
    host.send("msg_control", {"option": 0, "command": RESUME})
    t_rx = t_send + host.tx(LEN["msg_control"])
    frames = host.collect(t_rx + 0.3)
    _answers(frames, "msg_control", t_rx, host, LEN["msg_control"])
    first = [f for f in frames if f.name == "msg1"][:3]
    assert [f.source for f in first] == list(STAGGERED)  # arbitration: lower node id first
    for i, f in enumerate(first):
        assert host.close(f.timestamp, t_rx + (i + 1) * host.tx(LEN["msg1"]))
    for node in STAGGERED:
        dues = [msg1_due(f, t_rx) for f in host.of(frames, "msg1", node)]
        assert all(host.close(b - a, MSG1_S) for a, b in zip(dues, dues[1:]))
    assert {f.source for f in host.of(frames, "msg2")} == set(STAGGERED)
    assert {f.source for f in host.of(frames, "msg3")} == set(STAGGERED)

    # EXP mode: MSG_EXP frames replace MSG1..3 (which ones and how often is OBSERVE: the emulator sends
    # EXP1 on MSG1's schedule and EXP7..EXP11 on MSG3's)
    t_send = tick_at_or_after(host.now, t_rx, phase=5 * MS)
    host.wait_until(t_send)
    host.send("msg_control", {"option": 0, "command": RESUME_EXP})
    t_rx2 = t_send + host.tx(LEN["msg_control"])
    frames = host.collect(t_rx2 + 1.1)
    _answers(frames, "msg_control", t_rx2, host, LEN["msg_control"])
    assert reports_after(frames, t_rx2) == []
    for node in STAGGERED:
        exp1 = host.of(frames, "msg_exp1", node)
        assert len(exp1) == 55
        dues = [msg1_due(f, t_rx) for f in exp1]
        assert all(host.close(b - a, MSG1_S) for a, b in zip(dues, dues[1:]))
        for n in range(7, 12):
            assert len(host.of(frames, f"msg_exp{n}", node)) == 2
    assert {f.name for f in frames} == {"msg_control", "msg_exp1", *(f"msg_exp{n}" for n in range(7, 12))}

    # back to MSG1..3
    t_send = tick_at_or_after(host.now, t_rx, phase=5 * MS)
    host.wait_until(t_send)
    host.send("msg_control", {"option": 0, "command": RESUME})
    t_rx3 = t_send + host.tx(LEN["msg_control"])
    frames = host.collect(t_rx3 + 0.1)
    _answers(frames, "msg_control", t_rx3, host, LEN["msg_control"])
    assert not [f for f in frames if f.name.startswith("msg_exp") and f.timestamp > t_rx3]
    assert {f.source for f in reports_after(frames, t_rx3, ("msg1",))} == set(STAGGERED)


def test_msg_control_ignores_other_options_and_unknown_commands(lane):
    host = lane([1])
    host.wait_until(0.3)
    host.send("msg_control", {"option": 1, "command": SUSPEND})
    host.send("msg_control", {"option": 0, "command": 0x12345678})  # not in 4.4.2: OBSERVE (ignored, unanswered)
    host.send("msg_control", {"option": 0, "command": 0})  # another ESC's answer: nothing to do
    frames = host.collect(host.now + 0.2)
    assert not host.of(frames, "msg_control")
    assert len(host.of(frames, "msg1")) == 10


# --------------------------------------------------------------------------------------------------
# R1, R2: FRAME_MSG_GET_ESC_ID


def test_get_esc_id_replies_staggered_by_node_id(lane):
    host = lane(STAGGERED)
    t_send = tick_at_or_after(host.BOOT + 0.3, host.BOOT, phase=5 * MS)
    host.wait_until(t_send)
    host.send("get_esc_id", {"option": 0})
    t_rx = t_send + host.tx(LEN["get_esc_id?"])
    frames = host.collect(t_rx + 0.1)
    _answers(frames, "get_esc_id", t_rx, host, LEN["get_esc_id"])
    replies = {f.source: f for f in host.of(frames, "get_esc_id")}
    for node, f in replies.items():
        channel = node if node <= 20 else 1  # the emulator's factory channel
        assert f.fields == {"node_id": node, "throttle_channel": channel}  # R1: exactly [node_id, channel]
        assert len(f.data) == 3 and f.kind is Kind.MESSAGE and f.priority == MEDIUM
        assert f.timestamp - t_rx <= 64 * MS + host.tx(LEN["get_esc_id"])  # 4.4.3 clarification 4
    # an unknown option is not answered (OBSERVE)
    host.send("get_esc_id", {"option": 1})
    assert not host.of(host.collect(host.now + 0.1), "get_esc_id")


# --------------------------------------------------------------------------------------------------
# R8: the comm-loss flag (MSG1 status bit 13)


def _flag(f) -> bool:
    return bool(f.fields["status"] & Status.COMM_FAULT)


def test_comm_loss_flag_set_200ms_after_last_command_and_cleared_by_the_next(lane):
    host = lane([1])
    base = host.BOOT
    # no command since power-up: the emulator counts from the end of the boot
    frames = host.collect(base + 0.4)
    for f in host.of(frames, "msg1"):
        due = msg1_due(f, base)
        if due < base + COMM_LOSS_S - 1e-6:
            assert not _flag(f), due
        elif due > base + COMM_LOSS_S + 1e-6:
            assert _flag(f), due

    # commands every 10 ms: the first clears the flag, and it stays clear
    t_start = tick_at_or_after(host.now, base, phase=5 * MS)
    host.wait_until(t_start)
    task = host.bus.send_periodic(host.message("raw_command_14b", {"channels": [0, 0, 0, 0]}), 0.010)
    frames = host.collect(t_start + 0.495, own=True)
    task.stop()  # between two commands
    commands = [f.timestamp for f in frames if f.name == "raw_command_14b"]
    assert len(commands) == 50
    assert all(not _flag(f) for f in host.of(frames, "msg1") if f.timestamp > commands[0])

    # silence: set at the first MSG1 due at least 200 ms after the last command, never before
    last = commands[-1]
    frames = host.collect(last + 0.5)
    for f in host.of(frames, "msg1"):
        assert _flag(f) == (msg1_due(f, base) >= last + COMM_LOSS_S), (f.timestamp, last)
    first_set = next(msg1_due(f, base) for f in host.of(frames, "msg1") if _flag(f))
    assert host.close(first_set, tick_at_or_after(last + COMM_LOSS_S, base))
    assert first_set <= last + COMM_LOSS_S + MSG1_S  # R8's upper bound

    # the next command clears it: the first MSG1 after it is clear
    t_cmd = host.now + 3 * MS
    host.wait_until(t_cmd)
    host.send("raw_command_12b", {"channels": [0, 0, 0, 0], "group": 1})
    frames = host.collect(t_cmd + 0.1)
    after = [f for f in host.of(frames, "msg1") if f.timestamp > t_cmd + host.tx(LEN["raw"])]
    assert after and not _flag(after[0])


def test_only_commands_for_its_own_channel_keep_the_link_alive(lane):
    """The emulator's reading of "any command from the host": a RawCommand that carries its channel.
    12-bit frames for another group, or 14/10-bit frames when its channel is beyond them, do not count."""
    host = lane([1, 5, 9])
    host.wait_until(0.3)
    tasks = [host.bus.send_periodic(host.message("raw_command_12b", {"channels": [0, 0, 0, 0], "group": 2}), 0.01),
             host.bus.send_periodic(host.message("raw_command_10b", {"channels": [0] * 6}), 0.01)]
    frames = host.collect(host.now + 0.5)
    for task in tasks:
        task.stop()
    last = {f.source: _flag(f) for f in host.of(frames, "msg1")}
    assert last == {1: False, 5: False, 9: True}  # 1: 10-bit channel 1; 5: group 2; 9 (group 3): neither


def test_no_comm_loss_under_pwm_throttle_and_none_hang_when_back_to_can(lane):
    """PWM+CAN with a PWM signal present: no comm-loss flag (R8 applies under CAN throttle). Switching
    back to CAN throttle long after the last command sets it at once (this used to hang the lane)."""
    host = lane([1])
    host.wait_until(0.3)
    assert host.call("throttle_select", {"source": 1}).fields == {"source": 1}
    host.bench.set_pwm_input(0)
    frames = host.collect(host.now + 0.6)
    msg1 = host.of(frames, "msg1")[-10:]
    assert all(not _flag(f) and f.fields["status"] & Status.THROTTLE_PWM for f in msg1)
    assert host.call("throttle_select", {"source": 0}).fields == {"source": 0}
    frames = host.collect(host.now + 0.1)
    assert all(_flag(f) and not f.fields["status"] & Status.THROTTLE_PWM for f in host.of(frames, "msg1"))


# --------------------------------------------------------------------------------------------------
# R3-R5, 4.4.18 clarification 6: throttle channel selection


def _pwm_after(host, t_cmd, nodes):
    """Each ESC's MSG1 PWM in its first report after the commands."""
    frames = host.collect(t_cmd + 0.03)
    out = {}
    for f in frames:
        if f.name == "msg1" and f.source not in out:
            out[f.source] = f.fields["pwm"]
    assert set(out) == set(nodes)
    return out


def test_14bit_throttle_channels_1_to_4(lane):
    nodes = [1, 2, 3, 4, 5]
    host = lane(nodes, source=10)  # ArduPilot's node id (F6: OBSERVE, the emulator accepts any host)
    host.wait_until(tick_at_or_after(0.3, host.BOOT, phase=5 * MS))
    host.send("raw_command_14b", {"channels": [100, 700, 1300, 1900]})
    assert _pwm_after(host, host.now, nodes) == {1: 100, 2: 700, 3: 1300, 4: 1900, 5: 0}


def test_12bit_throttle_groups(lane):
    nodes = list(range(1, 10))
    host = lane(nodes)
    host.wait_until(tick_at_or_after(0.3, host.BOOT, phase=5 * MS))
    host.send("raw_command_12b", {"channels": [11, 222, 1333, 2000], "group": 1})
    host.send("raw_command_12b", {"channels": [5, 6, 7, 8], "group": 2})
    assert _pwm_after(host, host.now, nodes) == {1: 11, 2: 222, 3: 1333, 4: 2000, 5: 5, 6: 6, 7: 7, 8: 8, 9: 0}
    host.wait_until(tick_at_or_after(host.now, host.BOOT, phase=5 * MS))
    host.send("raw_command_12b", {"channels": [999, 1, 1, 1], "group": 3})  # channels 9..12
    assert _pwm_after(host, host.now, nodes)[9] == 999
    # the document's R4 vector: 0x123, 0x456, 0x789, 0xABC in group 1 -> 23 61 45 89 C7 AB 01
    wire = host.wire("raw_command_12b", {"channels": [0x123, 0x456, 0x789, 0xABC], "group": 1})
    assert wire.data[:7] == bytes.fromhex("23614589C7AB01")


def test_10bit_throttle_six_channels_doubled(lane):
    nodes = [1, 2, 3, 4, 5, 6, 7]
    host = lane(nodes)
    host.wait_until(tick_at_or_after(0.3, host.BOOT, phase=5 * MS))
    host.send("raw_command_10b", {"channels": [0, 1, 250, 500, 999, 1000]})
    assert _pwm_after(host, host.now, nodes) == {1: 0, 2: 2, 3: 500, 4: 1000, 5: 1998, 6: 2000, 7: 0}


def test_the_esc_follows_the_channel_set_by_set_id(lane):
    host = lane([1])
    host.wait_until(0.3)
    assert host.call("set_id", {"node_id": 1, "throttle_channel": 7}).fields == {"node_id": 1, "throttle_channel": 7}
    host.wait_until(tick_at_or_after(host.now, host.BOOT, phase=5 * MS))
    host.send("raw_command_12b", {"channels": [1, 2, 3, 4], "group": 1})
    host.send("raw_command_14b", {"channels": [1, 2, 3, 4]})  # channels 1..4 only
    host.send("raw_command_10b", {"channels": [1, 2, 3, 4, 5, 6]})  # channels 1..6 only
    assert _pwm_after(host, host.now, [1]) == {1: 0}
    host.send("raw_command_12b", {"channels": [5, 6, 777, 8], "group": 2})
    assert _pwm_after(host, host.now, [1]) == {1: 777}


def test_throttle_above_the_document_range_is_clamped(lane):
    """R6 (OBSERVE): the emulator clamps 14/12-bit values to 2000 and 10-bit values to 1000 (x2)."""
    host = lane([1])
    host.wait_until(tick_at_or_after(0.3, host.BOOT, phase=5 * MS))
    host.send("raw_command_14b", {"channels": [16383, 0, 0, 0]})
    assert _pwm_after(host, host.now, [1]) == {1: 2000}
    host.send("raw_command_10b", {"channels": [1023, 0, 0, 0, 0, 0]})
    assert _pwm_after(host, host.now, [1]) == {1: 2000}
    host.send("raw_command_12b", {"channels": [4095, 0, 0, 0], "group": 1})
    assert _pwm_after(host, host.now, [1]) == {1: 2000}


# --------------------------------------------------------------------------------------------------
# F4, F5: service answers

SERVICE_CALLS = [
    ("set_id", {"node_id": 5, "throttle_channel": 5}, {"node_id": 5, "throttle_channel": 5}),
    ("set_baud", {"baud": 1}, {"baud": 1}),
    ("set_led", {"option": 0, "color": BLUE, "blink": 2}, {"option": 0, "color": BLUE, "blink": 2}),
    ("set_rotation", {"rotation": 0xFF}, {"rotation": 0}),
    ("set_freq", {"option": 1, "msg1_interval": 10, "msg2_interval": 50, "msg3_interval": 250},
     {"option": 1, "msg1_interval": 10, "msg2_interval": 50, "msg3_interval": 250}),
    ("throttle_select", {"source": 0}, {"source": 0}),
    ("self_test", {}, {"status": 0}),
    ("esc_information", {"option": 0}, {"max_cells": 12, "max_current": 8, "hardware_version": 3, "protocol_version": 21,
                                        "firmware_year": 24, "firmware_month": 10, "firmware_day": 11}),
    ("maintenance_information", {"option": 1}, {"run_time": 0, "runs": 0, "info_7": 1}),
    ("maintenance_information", {"option": 2}, {"power_ups": 1, "stops": 0, "fault_code": 0, "option": 2}),
    ("get_major_configuration", {"option": 0}, {"direction": 0, "throttle_source": 0, "throttle_channel": 5, "led_blink": 0,
                                                "led_color": GREEN, "msg1_interval": 10, "msg2_interval": 50,
                                                "msg3_interval": 250, "reserved": 0}),
]


@pytest.mark.parametrize("host_node,tid", [(0, 0), (10, 31)], ids=["host0", "ardupilot10"])
@pytest.mark.parametrize("name,fields,answer", SERVICE_CALLS, ids=[f"{c[0]}{c[1].get('option', '')}" for c in SERVICE_CALLS])
def test_service_answer_framing(lane, name, fields, answer, host_node, tid):
    host = lane([5], source=host_node)
    t_send = tick_at_or_after(0.3, host.BOOT, phase=5 * MS)
    host.wait_until(t_send)
    request = host.send(name, fields, destination=5, transfer_id=tid)
    t_rx = t_send + host.tx(len(request.data))
    frames = host.collect(t_rx + 0.01)
    [resp] = [f for f in frames if f.kind is not Kind.MESSAGE]
    spec = BY_NAME[name]
    assert resp.kind is Kind.RESPONSE and not resp.can_id & 0x8000  # F4: request bit 0
    assert resp.type_id == spec.type_id and resp.transfer_id == tid  # F4: same service, same transfer id
    assert (resp.source, resp.destination) == (5, host_node)  # F4: from the ESC to the requester
    assert resp.priority == (spec.priority if spec.priority is not None else MEDIUM)  # F5 (240..242: OBSERVE)
    assert resp.fields == answer
    assert host.close(resp.timestamp, t_rx + host.SERVICE_DELAY + host.tx(len(resp.data)))


def test_maintenance_option_0_and_responses_at_the_request_priority_when_the_table_has_none(lane):
    host = lane([1])
    host.wait_until(0.3)
    resp = host.call("maintenance_information", {"option": 0}, priority=LOW)
    assert resp.priority == LOW  # F5 OBSERVE for 240..242: the emulator answers at the request's priority
    assert set(resp.fields) == {"total_run_time", "mos_t_max", "cap_t_max", "info_7"} and resp.fields["info_7"] == 0
    assert host.call("get_major_configuration", {"option": 0}, priority=HIGHEST).priority == HIGHEST
    assert host.call("set_freq", {"option": 0, "msg1_interval": 10, "msg2_interval": 50, "msg3_interval": 250},
                     priority=LOWEST).priority == MEDIUM  # the table's priority wins where it has one


def test_services_to_another_node_and_never_answered_services(lane):
    host = lane([1, 2])
    host.wait_until(0.3)
    for name, fields in [("self_test", {}), ("set_rotation", {"rotation": 1}), ("get_major_configuration", {"option": 0})]:
        host.send(name, fields, destination=9)
    host.send("expand_set_part", {"set_cmd": 0xFFF8, "part": 1}, destination=1)  # R14: never answered
    host.send("clear_rec", {"payload": []}, destination=1)  # R15 OBSERVE: the emulator does not answer
    frames = host.collect(host.now + 0.1)
    assert [f for f in frames if f.kind is not Kind.MESSAGE] == []
    assert host.call("set_rotation", {"rotation": 0xFF}, 2).fields == {"rotation": 0}  # the one to 9 did nothing


# --------------------------------------------------------------------------------------------------
# R10: illegal values are ignored, never partly applied

#: A legal request for each service that changes every field from its default, so that any partial
#: application shows.
LEGAL_CHANGE = {
    "set_freq": {"option": 1, "msg1_interval": 30, "msg2_interval": 70, "msg3_interval": 110},
    "set_id": {"node_id": 9, "throttle_channel": 9},
    "set_baud": {"baud": 3},
    "set_rotation": {"rotation": 1},
    "throttle_select": {"source": 1},
}
UNCHANGED_ANSWER = {
    "set_freq": {"option": 1, "msg1_interval": 10, "msg2_interval": 50, "msg3_interval": 250},
    "set_id": {"node_id": 1, "throttle_channel": 1},
    "set_baud": {"baud": 1},
    "set_rotation": {"rotation": 0},
    "throttle_select": {"source": 0},
}
ILLEGAL = [(name, case) for name in LEGAL_CHANGE for case in illegal_cases(BY_NAME[name])]


def test_every_enforced_field_has_illegal_cases():
    assert {name for name, _ in ILLEGAL} == set(LEGAL_CHANGE)
    assert {(n, c.field) for n, c in ILLEGAL} == {("set_freq", "msg1_interval"), ("set_freq", "msg2_interval"),
                                                  ("set_freq", "msg3_interval"), ("set_id", "node_id"),
                                                  ("set_baud", "baud"), ("set_rotation", "rotation"),
                                                  ("throttle_select", "source")}


@pytest.mark.parametrize("name,case", ILLEGAL, ids=[f"{n}-{c.id}" for n, c in ILLEGAL])
def test_illegal_values_change_nothing(lane, name, case):
    host = lane([1])
    host.wait_until(0.3)
    before = read_settings(host, 1)
    nvm_before = nvm_settings(host.esc(1))
    fields = {**LEGAL_CHANGE[name], case.field: case.value}
    resp = host.call(name, fields, 1)
    assert resp.fields == UNCHANGED_ANSWER[name]  # whether and how: OBSERVE; the emulator answers what it has
    assert read_settings(host, 1) == before
    assert nvm_settings(host.esc(1)) == nvm_before
    host.bus.power_cycle(0.3)
    host.wait(host.BOOT + 0.01)  # still at 500 kbit/s and node 1
    assert read_settings(host, 1) == before
    assert nvm_settings(host.esc(1)) == nvm_before


def test_legal_changes_used_by_the_illegal_cases_do_apply(lane):
    host = lane([1])
    host.wait_until(0.3)
    before = read_settings(host, 1)
    for name, fields in LEGAL_CHANGE.items():
        if name not in ("set_id", "set_baud"):
            host.call(name, fields, 1)
    after = read_settings(host, 1)
    assert after["freq"] == {"msg1_interval": 30, "msg2_interval": 70, "msg3_interval": 110}
    assert after["rotation"] == 1 and after["config"]["throttle_source"] == 1
    assert after != before


# --------------------------------------------------------------------------------------------------
# R11: Set ID and Set Baud within 120 s of power-up; Set Baud at the next power-up; Set ID pseudo-broadcast


def test_set_id_only_within_120s_of_power_up_and_ignoring_the_destination(lane):
    host = lane([1])
    host.wait_until(0.3)
    host.call("set_freq", {"option": 1, "msg1_interval": 250, "msg2_interval": 250, "msg3_interval": 250})  # a quiet bus
    host.wait_until(WINDOW_S - 1.0)
    resp = host.call("set_id", {"node_id": 7, "throttle_channel": 8}, destination=0x55)  # pseudo-broadcast
    assert (resp.source, resp.destination, resp.fields) == (7, 0, {"node_id": 7, "throttle_channel": 8})
    host.wait_until(WINDOW_S + 0.5)
    resp = host.call("set_id", {"node_id": 9, "throttle_channel": 9}, destination=7)
    assert (resp.source, resp.fields) == (7, {"node_id": 7, "throttle_channel": 8})
    assert {f.source for f in host.collect(host.now + 1.1)} == {7}
    # the window opens again at the next power-up
    host.bus.power_cycle(0.5)
    host.wait(host.BOOT + 0.01)
    resp = host.call("set_id", {"node_id": 9, "throttle_channel": 9}, destination=7)
    assert (resp.source, resp.fields) == (9, {"node_id": 9, "throttle_channel": 9})


def test_set_id_is_obeyed_by_every_esc_on_the_bus(lane):
    """4.4.18 clarification 2: with several ESCs connected they are all set to the same id."""
    host = lane([1, 2])
    host.wait_until(0.3)
    host.send("set_id", {"node_id": 6, "throttle_channel": 6}, destination=1)
    frames = host.collect(host.now + 0.01)
    assert [(f.source, f.fields) for f in frames if f.name == "set_id"] == [(6, {"node_id": 6, "throttle_channel": 6})] * 2
    assert [esc.node_id for esc in host.bench.escs] == [6, 6]


@pytest.mark.parametrize("code", [0, 2, 3, 4, 5, 6])
def test_set_baud_takes_effect_at_the_next_power_up(lane, code):
    host = lane([1])
    host.wait_until(0.3)
    assert host.call("set_baud", {"baud": code}).fields == {"baud": code}
    assert len(host.of(host.collect(host.now + 0.2), "msg1")) == 10  # still at 500 kbit/s
    host.bus.power_cycle(0.5)
    t_on = host.now
    other = lane.join(host, bitrate=BAUD[code])
    host.send("self_test", destination=1)  # not heard at the old rate
    assert host.collect(t_on + 1.0) == []
    frames = other.collect(t_on + 1.0)
    first = host.of(frames, "msg1")[0]
    assert first.source == 1 and other.close(first.timestamp, t_on + other.BOOT + other.tx(LEN["msg1"]))
    assert not [f for f in frames if f.kind is Kind.RESPONSE]
    assert other.call("set_baud", {"baud": 1}).fields == {"baud": 1}  # and back, for the next power-up
    other.bus.power_cycle(0.5)
    other.wait(other.BOOT + 0.05)
    assert host.of(host.collect(host.now + 0.1), "msg1")


def test_set_baud_after_the_window_is_ignored(lane):
    host = lane([1])
    host.wait_until(0.3)
    host.call("set_freq", {"option": 1, "msg1_interval": 250, "msg2_interval": 250, "msg3_interval": 250})
    host.wait_until(WINDOW_S + 0.5)
    assert host.call("set_baud", {"baud": 2}).fields == {"baud": 1}
    host.bus.power_cycle(0.5)
    assert host.of(host.collect(host.now + host.BOOT + 0.1), "msg1")


# --------------------------------------------------------------------------------------------------
# R12: nothing changes while reporting is suspended, nor while the motor runs

CHANGES = [
    ("set_led", {"option": 1, "color": RED, "blink": 5}),
    ("set_rotation", {"rotation": 1}),
    ("set_freq", {"option": 1, "msg1_interval": 40, "msg2_interval": 60, "msg3_interval": 80}),
    ("throttle_select", {"source": 1}),
    ("expand_set_part", {"set_cmd": 0xFFF8, "part": 3}),  # prop lock strong
    ("set_id", {"node_id": 1, "throttle_channel": 4}),
    ("set_baud", {"baud": 4}),
]


def test_no_parameter_change_while_reporting_is_suspended(lane):
    host = lane([1])
    host.wait_until(0.3)
    before, nvm_before = read_settings(host, 1), nvm_settings(host.esc(1))
    host.send("msg_control", {"option": 0, "command": SUSPEND})
    host.wait(0.01)
    for name, fields in CHANGES:
        host.send(name, fields, destination=1)
        host.wait(0.01)
    assert nvm_settings(host.esc(1)) == nvm_before
    host.send("msg_control", {"option": 0, "command": RESUME})
    host.wait(0.01)
    assert read_settings(host, 1) == before
    # resumed, the same requests apply
    for name, fields in CHANGES:
        host.send(name, fields, destination=1)
        host.wait(0.01)
    after = nvm_settings(host.esc(1))
    assert after == {**nvm_before, "led_color": RED, "led_blink": 5, "rotation": 1, "msg1_interval": 40,
                     "msg2_interval": 60, "msg3_interval": 80, "throttle_source": 1, "prop_lock": 3,
                     "throttle_channel": 4, "baud": 4}


def test_rotation_throttle_select_and_expand_set_need_the_motor_stopped(lane):
    host = lane([1])
    host.wait_until(0.3)
    nvm_before = nvm_settings(host.esc(1))
    task = host.bus.send_periodic(host.message("raw_command_14b", {"channels": [1000, 0, 0, 0]}), 0.01)
    frames = host.collect(host.now + 0.3)
    assert host.of(frames, "msg1")[-1].fields["status"] & Status.RUNNING
    assert host.call("set_rotation", {"rotation": 1}).fields == {"rotation": 0}
    assert host.call("throttle_select", {"source": 1}).fields == {"source": 0}
    host.send("expand_set_part", {"set_cmd": 0xFFF0, "part": 2}, destination=1)  # reverse
    host.send("expand_set_part", {"set_cmd": 0xFFF9, "part": 3}, destination=1)  # startup acceleration
    host.wait(0.01)
    assert nvm_settings(host.esc(1)) == nvm_before
    # throttle 0, and the motor spins down
    task.modify_data(host.message("raw_command_14b", {"channels": [0, 0, 0, 0]}))
    frames = host.collect(host.now + 3.0)
    task.stop()
    last = host.of(frames, "msg1")[-1]
    assert last.fields["speed"] == 0 and not last.fields["status"] & Status.RUNNING
    assert host.call("set_rotation", {"rotation": 1}).fields == {"rotation": 1}
    assert host.call("throttle_select", {"source": 1}).fields == {"source": 1}
    host.send("expand_set_part", {"set_cmd": 0xFFF9, "part": 3}, destination=1)
    host.wait(0.01)
    assert host.esc(1).nvm["startup_acceleration"] == 3


# --------------------------------------------------------------------------------------------------
# R13: what survives a power cycle (and a new process, through the flash file)


def _change_everything(host):
    host.call("set_id", {"node_id": 9, "throttle_channel": 5}, 1)
    host.call("set_led", {"option": 1, "color": RED, "blink": 2}, 9)
    host.call("set_rotation", {"rotation": 1}, 9)
    host.call("set_freq", {"option": 1, "msg1_interval": 20, "msg2_interval": 60, "msg3_interval": 200}, 9)
    host.call("throttle_select", {"source": 1}, 9)
    for cmd, part in ((0xFFF4, 0), (0xFFF8, 2), (0xFFF9, 11), (0xFFFA, 3)):
        host.send("expand_set_part", {"set_cmd": cmd, "part": part}, destination=9)
    host.wait(0.01)


def _check_everything(host):
    assert read_settings(host, 9) == {
        "config": {"direction": 1, "throttle_source": 1, "throttle_channel": 5, "led_blink": 2, "led_color": RED,
                   "msg1_interval": 20, "msg2_interval": 60, "msg3_interval": 200, "reserved": 0},
        "freq": {"msg1_interval": 20, "msg2_interval": 60, "msg3_interval": 200},
        "rotation": 1,
        "ids": [{"node_id": 9, "throttle_channel": 5}],
    }
    # the intervals are in force: MSG1 every 40 ms
    t = host.now
    msg1 = host.of(host.collect(t + 0.5), "msg1")
    assert all(host.close(b.timestamp - a.timestamp, 0.040) for a, b in zip(msg1, msg1[1:])) and len(msg1) >= 11
    host.send("msg_control", {"option": 0, "command": RESUME_EXP})
    [exp7] = host.of(host.collect(host.now + 0.41), "msg_exp7")
    assert exp7.fields == {"direction": 2, "led": 1, "comm_interface": 2, "reserved_1": 0, "active_freewheel": 0,
                           "entry_angle_1": 0, "entry_angle_2": 0, "load_type": 0, "prop_lock": 2,
                           "startup_acceleration": 11, "lost_signal_protection": 3, "reserved_2": 0}
    host.send("msg_control", {"option": 0, "command": RESUME})
    host.wait(0.1)


def test_settings_survive_a_power_cycle(lane):
    host = lane([1])
    host.wait_until(0.3)
    _change_everything(host)
    _check_everything(host)
    host.bus.power_cycle(1.0)
    host.wait(host.BOOT + 0.01)
    _check_everything(host)


def test_settings_survive_in_the_flash_file(lane, tmp_path):
    flash = tmp_path / "esc-flash.json"
    host = lane([1], flash_path=str(flash))
    host.wait_until(0.3)
    _change_everything(host)
    host.bus.power_off()
    assert flash.exists()
    later = lane([1], flash_path=str(flash))  # a new channel: a new world reading the same flash
    assert later.channel != host.channel
    later.wait_until(0.3)
    _check_everything(later)
    assert later.call("maintenance_information", {"option": 2}, 9).fields["power_ups"] == 2


def test_can_test_suspension_and_unsaved_led_do_not_survive(lane):
    host = lane([1])
    host.wait_until(0.3)
    host.call("set_led", {"option": 1, "color": BLUE, "blink": 1})
    host.call("set_led", {"option": 0, "color": RED, "blink": 5})
    assert host.call("get_major_configuration", {"option": 0}).fields["led_color"] == RED
    host.send("msg_control", {"option": 0, "command": SUSPEND})
    host.send("can_test", {"option": CAN_TEST_ON, "count": 0})
    frames = host.collect(host.now + 0.2)
    assert host.of(frames, "can_test", 1) and not reports_after(frames, host.now - 0.15)
    host.bus.power_cycle(0.5)
    frames = host.collect(host.now + host.BOOT + 0.1)
    assert host.of(frames, "msg1") and not host.of(frames, "can_test", 1)
    cfg = host.call("get_major_configuration", {"option": 0}).fields
    assert (cfg["led_color"], cfg["led_blink"]) == (BLUE, 1)


# --------------------------------------------------------------------------------------------------
# R14: Expand Set Part


@pytest.mark.parametrize("cmd,part,key,value", [
    (0xFFF0, 2, "rotation", 1), (0xFFF1, 1, "led_color", RED), (0xFFF1, 3, "led_color", BLUE),
    (0xFFF2, 5, "throttle_source", 1), (0xFFF4, 0, "active_freewheel", 0), (0xFFF8, 3, "prop_lock", 3),
    (0xFFF9, 15, "startup_acceleration", 15), (0xFFFA, 0, "lost_signal_reduction", 0), (0xFFFC, 4, "baud", 4),
], ids=lambda v: f"{v:X}" if isinstance(v, int) and v > 255 else None)
def test_expand_set_part_applies_without_answer(lane, cmd, part, key, value):
    host = lane([1])
    host.wait_until(0.3)
    request = host.send("expand_set_part", {"set_cmd": cmd, "part": part}, destination=1)
    assert request.data[:3] == bytes([cmd & 0xFF, cmd >> 8, part])  # Set_cmd little-endian
    frames = host.collect(host.now + 0.1)
    assert {f.name for f in frames} <= set(REPORTS)  # no answer of any kind
    assert host.esc(1).nvm[key] == value


def test_expand_set_part_ignores_reserved_and_unknown_codes(lane):
    host = lane([1])
    host.wait_until(0.3)
    before = nvm_settings(host.esc(1))
    for cmd, part in ((0xFFF5, 1), (0xFFF0, 3), (0xFFF2, 1), (0xFFF3, 1), (0xF0FF, 2), (0xFFFE, 0)):
        host.send("expand_set_part", {"set_cmd": cmd, "part": part}, destination=1)
    frames = host.collect(host.now + 0.1)
    assert {f.name for f in frames} <= set(REPORTS)
    assert nvm_settings(host.esc(1)) == before


# --------------------------------------------------------------------------------------------------
# R15: Get Rec / Clear Rec


def _records(frames):
    recs = [f for f in frames if f.name == "msg_exp12"]
    assert [f.data[-1] for f in recs] == [0xC1, 0xC2, 0xC3, 0xC4]  # MCU, MOS, CAP, motor
    return {f.fields["record"]: f.fields for f in recs}


def test_get_rec_reports_records_and_clear_rec_clears_them(lane):
    host = lane([1])
    host.wait_until(0.3)
    host.call("set_freq", {"option": 1, "msg1_interval": 10, "msg2_interval": 50, "msg3_interval": 10})
    task = host.bus.send_periodic(host.message("raw_command_14b", {"channels": [2000, 0, 0, 0]}), 0.02)
    frames = host.collect(host.now + 10.0)
    task.stop()
    hottest_mos = max(f.fields["mos_t"] for f in host.of(frames, "msg3"))
    assert hottest_mos > 40
    host.send("get_rec", {"payload": []}, destination=1)
    recs = _records(host.collect(host.now + 0.01))
    assert all(f.source == 1 for f in host.of(frames, "msg3"))
    assert recs[2]["t_max"] >= hottest_mos and recs[2]["times"] == 1 and recs[2]["time"] >= 9
    opt0 = host.call("maintenance_information", {"option": 0}).fields
    assert (opt0["mos_t_max"], opt0["cap_t_max"]) == (recs[2]["t_max"], recs[3]["t_max"])
    assert opt0["total_run_time"] >= 9
    opt1 = host.call("maintenance_information", {"option": 1}).fields
    assert opt1["runs"] == 1 and 9 <= opt1["run_time"] <= 12
    # Expand Set Part 0xFFFB reads them too
    host.send("expand_set_part", {"set_cmd": 0xFFFB, "part": 1}, destination=1)
    assert _records(host.collect(host.now + 0.01)) == recs
    # cleared: what is recorded afterwards is at most the temperature now
    host.wait(5.0)
    host.send("clear_rec", {"payload": []}, destination=1)
    host.wait(0.2)
    host.send("get_rec", {"payload": []}, destination=1)
    frames = host.collect(host.now + 0.01)
    cleared = _records(frames)
    now_mos = host.esc(1).state.temps["mos"]
    assert cleared[2]["t_max"] <= int(now_mos) < recs[2]["t_max"]


# --------------------------------------------------------------------------------------------------
# R16: CAN Test mode


def test_can_test_mode(lane):
    host = lane([1, 2])
    t_send = tick_at_or_after(0.4, host.BOOT, phase=5 * MS)
    host.wait_until(t_send)
    host.send("can_test", {"option": CAN_TEST_ON, "count": 0xDEADBEEF})
    t_rx = t_send + host.tx(LEN["can_test"])
    frames = first = host.collect(t_rx + 0.5)
    assert reports_after(frames, t_rx) == []
    for node in (1, 2):
        tests = host.of(frames, "can_test", node)
        assert [f.fields["count"] for f in tests] == list(range(len(tests))) and len(tests) == 25
        assert all(f.fields["option"] == 0 and f.priority == LOWEST for f in tests)
        # OBSERVE: the emulator sends them on MSG1's interval, starting at the command
        assert tests[0].timestamp - t_rx < 1 * MS
        assert all(host.close(b.timestamp - a.timestamp, MSG1_S) for a, b in zip(tests, tests[1:]))
    # off: back to reporting at once; the count continues next time (4.4.1: from the current count)
    host.send("can_test", {"option": CAN_TEST_OFF, "count": 0})
    t_off = host.now + host.tx(LEN["can_test"])
    frames = host.collect(t_off + 0.1)
    late = host.of(frames, "can_test", 1)  # on the bus as the command came
    assert all(f.timestamp <= t_off + 1 * MS for f in late) and len(late) <= 1
    assert {f.source for f in reports_after(frames, t_off, ("msg1",))} == {1, 2}
    last_count = (late or host.of(first, "can_test", 1))[-1].fields["count"]
    host.send("can_test", {"option": CAN_TEST_ON, "count": 0})
    frames = host.collect(host.now + 0.05)
    assert host.of(frames, "can_test", 1)[0].fields["count"] == last_count + 1
    # lost at power-off
    host.bus.power_cycle(0.5)
    frames = host.collect(host.now + host.BOOT + 0.2)
    assert host.of(frames, "msg1", 1) and not host.of(frames, "can_test", 1)


def test_can_test_off_returns_to_the_state_before(lane):
    host = lane([1])
    host.wait_until(0.3)
    host.send("msg_control", {"option": 0, "command": SUSPEND})
    host.wait(0.01)
    host.send("can_test", {"option": CAN_TEST_ON, "count": 0})
    assert host.of(host.collect(host.now + 0.1), "can_test", 1)
    host.send("can_test", {"option": CAN_TEST_OFF, "count": 0})
    host.wait(0.01)
    assert host.collect(host.now + 0.2) == []  # still suspended
    host.send("msg_control", {"option": 0, "command": RESUME_EXP})
    host.wait(0.01)
    host.send("can_test", {"option": CAN_TEST_ON, "count": 0})
    host.wait(0.01)
    host.send("can_test", {"option": CAN_TEST_OFF, "count": 0})
    host.wait(0.01)
    frames = host.collect(host.now + 0.1)
    assert host.of(frames, "msg_exp1") and not host.of(frames, "msg1")  # back in EXP mode


# --------------------------------------------------------------------------------------------------
# Foreign traffic: tolerated, counted, never acted on


def _foreign_frames():
    """(arbitration id, data, flags, counter it lands in)."""
    battery = 16 << 24 | 20010 << 8 | 10  # ArduPilot BatteryContinuous: a 3-frame transfer on MSG Control's id
    node_status = 16 << 24 | 341 << 8 | 10  # DroneCAN uavcan.protocol.NodeStatus
    vendor_unknown = 16 << 24 | 20500 << 8 | 10  # a CKESC-range message type the document does not define
    return [
        (0x184E200A, bytes([0x00, 0xC0]), {}, "rx_malformed"),  # ArduPilot SafetyState on CAN Test's id: 2 bytes
        (battery, bytes([0x55, 0x55, 0x55, 0x55, 0x55, 0x55, 0x55, 0x80 | 3]), {}, "rx_malformed"),
        (battery, bytes([0xAA, 0xAA, 0xAA, 0xAA, 0xAA, 0xAA, 0xAA, 0x20 | 3]), {}, "rx_malformed"),
        (battery, bytes([0x00, 0x00, 0x00, 0x00, 0x00, 0x40 | 3]), {}, "rx_malformed"),
        (node_status, bytes([1, 0, 0, 0, 0, 0, 0, 0xC0 | 4]), {}, "rx_foreign"),  # another protocol's type id
        (vendor_unknown, bytes([1, 2, 0xC0]), {}, "rx_foreign"),
        (0x123, bytes([1, 2, 3]), {"is_extended_id": False}, "rx_malformed"),
        (0x7FF, b"", {"is_extended_id": False}, "rx_malformed"),
        (0x1F4E2A0B, bytes(range(8)), {}, "rx_malformed"),  # garbage on MSG Control's id
        (0x1FFFFFFF, bytes([0xFF] * 8), {}, "rx_malformed"),  # from reserved node 0x7F
        (0x00000000, b"", {}, "rx_foreign"),  # type id 0: outside the CKESC ranges, another protocol's
    ]


def test_foreign_traffic_is_tolerated_and_counted(lane):
    host = lane([1])  # (the foreign burst at one instant is more than SocketCAN's queue of 10: it waits for room)
    host.wait_until(tick_at_or_after(0.4, host.BOOT, phase=3 * MS))
    esc = host.esc(1)
    before = dict(esc.counters)
    sent = _foreign_frames()
    for arbitration_id, data, flags, _ in sent:
        host.send_raw(arbitration_id, data, **flags)
    frames = host.collect(host.now + 0.3)
    after = esc.counters
    assert after["rx"] - before["rx"] == len(sent)
    for counter in ("rx_malformed", "rx_foreign", "rx_ignored"):
        assert after[counter] - before[counter] == sum(1 for *_, c in sent if c == counter), counter
    # still reporting on its 20 ms grid: neither suspended nor in CAN Test mode, and it answered nothing
    msg1 = host.of(frames, "msg1")
    assert len(msg1) == 15
    assert all(host.close(msg1_due(f, host.BOOT) + host.tx(LEN["msg1"]), f.timestamp) for f in msg1)
    assert {f.name for f in frames} <= set(REPORTS)
