"""Every switchable fault changes exactly the behaviour it names.

For each fault in ``ckesc.emulator.faults.FAULTS`` a scenario observes one behaviour on a fresh
bench twice: without the fault (the conforming value) and with it (the named deviation). A fault
with no scenario fails ``test_every_fault_has_a_scenario``, so a new fault cannot go untested; and
every SHALL/READING rule the suite checks must be broken by some fault, so the suite's self-test
can show that each of its rules can fail. (The interaction faults, ``kind="interaction"``, have theirs in
test_interaction_faults.py, the soak faults, ``kind="soak"``, in test_soak_faults.py.)
"""

from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import pytest

from ckesc.emulator import FAULTS
from ckesc.emulator.faults import SINGLE, SOAK
from ckesc.protocol import Status, service_id
from ckesc.protocol.catalogue import BY_NAME
from ckesc.protocol.load import LoadSource

#: The vendor document and INTERPRETATIONS.md (not in the repository): $CKESC_SPEC_DIR, else the shared copy.
SPEC_DIR = Path(os.environ.get("CKESC_SPEC_DIR", "/work/shared/spec"))
MS = 0.001
BOOT = 0.25
SUSPEND, RESUME, RESUME_EXP = 0x55555555, 0xAAAAAAAA, 0xEEEEEEEE
LOW = 24
RED, GREEN = 4, 2
READ = {"option": 0, "msg1_interval": 10, "msg2_interval": 10, "msg3_interval": 10}
SINGLE_FAULTS = sorted(n for n, f in FAULTS.items() if f.kind == SINGLE)


@dataclass
class Case:
    observe: Callable[[Any], Any]  # host -> observation
    off: Any  # what a conforming ESC shows (a value, or a predicate)
    on: Any  # what the fault makes it show
    nodes: tuple[int, ...] = (1,)
    bus: dict = field(default_factory=dict)  # extra can.Bus arguments (esc_config, ...)


CASES: dict[str, Case] = {}


def case(fault: str, observe, off, on, *, nodes=(1,), **bus) -> None:
    assert fault not in CASES, f"two scenarios for {fault}"
    CASES[fault] = Case(observe, off, on, tuple(nodes), bus)


def _matches(expected, value) -> bool:
    return expected(value) if callable(expected) else value == expected


# --------------------------------------------------------------------------------------------------
# observation helpers (raw frames where a fault makes them undecodable)


def msg_type(m) -> int | None:
    return None if m.arbitration_id & 0x80 else (m.arbitration_id >> 8) & 0xFFFF


def service_type(m) -> int | None:
    return (m.arbitration_id >> 16) & 0xFF if m.arbitration_id & 0x80 else None


def booted(observe):
    """``observe`` once the ESC has booted (first report at 250 ms)."""
    def run(host):
        host.wait_until(0.3)
        return observe(host)
    return run


def quiet(host, after: float = 0.3, phase: float = 5 * MS) -> float:
    """Wait for a time ``phase`` after an MSG1 tick (default intervals), clear of report bursts."""
    k = math.ceil((max(after, host.now) - BOOT - phase) / 0.02 - 1e-9)
    t = BOOT + k * 0.02 + phase
    host.wait_until(t)
    return t


def raw_msgs(host, type_id: int, seconds: float) -> list:
    return [m for m in host.collect_raw(host.now + seconds) if msg_type(m) == type_id]


def msg1(host, seconds: float = 0.2) -> list:
    return host.of(host.collect(host.now + seconds), "msg1")


def first_pwm(host) -> int:
    quiet(host, host.now)
    return host.of(host.collect(host.now + 0.03), "msg1")[0].fields["pwm"]


def throttle(host, name, fields) -> int:
    quiet(host)
    host.send(name, fields)
    return first_pwm(host)


def intervals(host) -> tuple:
    f = host.call("set_freq", READ).fields
    return f["msg1_interval"], f["msg2_interval"], f["msg3_interval"]


def gaps(frames) -> list[float]:
    return [round(b.timestamp - a.timestamp, 6) for a, b in zip(frames, frames[1:])]


def power_cycle(host) -> None:
    host.bus.power_cycle(0.5)
    host.wait(BOOT + 0.01)


def run_motor(host, value=500):
    host.wait_until(0.3)
    task = host.bus.send_periodic(host.message("raw_command_14b", {"channels": [value, 0, 0, 0]}), 0.01)
    host.wait(0.2)
    return task


def service_responses(host, type_id: int, seconds: float = 0.02) -> list:
    return [m for m in host.collect_raw(host.now + seconds) if service_type(m) == type_id and m.arbitration_id & 0x7F]


def self_test_response(host, tid: int = 7):
    """(request bit, destination, transfer id) of the answer to a Self Test."""
    host.wait_until(0.3)
    host.send("self_test", destination=1, transfer_id=tid)
    [m] = service_responses(host, 216)
    return (m.arbitration_id >> 15) & 1, (m.arbitration_id >> 8) & 0x7F, m.data[-1] & 0x1F


def answer_delays(host, name, fields, nbytes) -> tuple:
    """Delay from the request to each ESC's answer (MSG Control or GET_ESC_ID), by node id."""
    t = quiet(host)
    host.send(name, fields)
    t_rx = t + host.tx(len(host.wire(name, fields).data))
    frames = [f for f in host.collect(t_rx + 0.1) if f.name == name and f.source]
    return tuple(round(f.timestamp - t_rx - host.tx(nbytes), 6) for f in sorted(frames, key=lambda f: f.source))


def comm_loss_delay(host):
    """From the last command to the first MSG1 with the comm-loss bit, in whole MSG1 intervals
    (R8: 200 ms, so 10), or None if it never comes."""
    t = quiet(host)
    host.send("raw_command_14b", {"channels": [0, 0, 0, 0]})
    t_rx = t + host.tx(8)
    for f in host.of(host.collect(t_rx + 1.0), "msg1"):
        if f.fields["status"] & Status.COMM_FAULT:
            due = BOOT + 0.02 * math.floor((f.timestamp - BOOT) / 0.02 + 1e-9)
            return math.floor((due - t_rx) / 0.02 + 1e-9)
    return None


def comm_loss_after_next_command(host) -> bool:
    host.wait_until(0.7)  # set 200 ms after boot, no command since
    quiet(host, host.now)
    host.send("raw_command_14b", {"channels": [0, 0, 0, 0]})
    return bool(host.of(host.collect(host.now + 0.03), "msg1")[0].fields["status"] & Status.COMM_FAULT)


def comm_flag_under_queries(host) -> bool:
    """Whether the comm-loss flag rises after the last command while a GET_ESC_ID query and a 242 read go on every
    50 ms (R20: they do not refresh the comm watchdog)."""
    quiet(host)
    host.send("raw_command_14b", {"channels": [0, 0, 0, 0]})
    flagged = []
    for _ in range(10):
        host.send("get_esc_id", {"option": 0}, layout="query")
        host.send("get_major_configuration", {"option": 0}, destination=1)
        flagged += [f for f in host.of(host.collect(host.now + 0.05), "msg1") if f.fields["status"] & Status.COMM_FAULT]
    return bool(flagged)


def mcu_records_tail(host) -> list:
    host.wait_until(0.3)
    host.send("get_rec", {"payload": []}, destination=1)
    return [m.data[-1] for m in raw_msgs(host, 20064, 0.01)]


def can_test_frames(host, seconds=0.1) -> list:
    return [f for f in host.collect(host.now + seconds) if f.name == "can_test" and f.source]


def after_power_cycle_hears(host, setup) -> bool:
    host.wait_until(0.3)
    setup(host)
    host.wait(0.01)
    power_cycle(host)
    return bool(msg1(host))


# --------------------------------------------------------------------------------------------------
# framing (F1..F5, F7)

case("tail_toggle_set", lambda h: {m.data[-1] & 0xE0 for m in raw_msgs(h, 20050, 0.35)}, {0xC0}, {0xE0})
case("tail_not_single_frame", lambda h: {m.data[-1] & 0xE0 for m in raw_msgs(h, 20050, 0.35)}, {0xC0}, {0x80})
case("transfer_id_stuck", lambda h: [m.data[-1] & 0x1F for m in raw_msgs(h, 20050, 0.33)], [0, 1, 2, 3], [0, 0, 0, 0])
case("response_transfer_id_wrong", lambda h: self_test_response(h, 7)[2], 7, 8)
case("response_to_broadcast", lambda h: self_test_response(h)[1], 0, 127)
case("response_as_request", lambda h: self_test_response(h)[0], 0, 1)
case("wrong_priority", lambda h: {m.arbitration_id >> 24 for m in h.collect_raw(0.6)}, {31}, {16})
case("response_wrong_priority",
     booted(lambda h: (h.call("set_freq", READ).priority, h.call("self_test").priority)),
     (16, 31), (31, 16))
case("reports_at_default_id", lambda h: len(h.of(h.collect(1.0), "msg1")), 0, 38, nodes=(0x7D,))

# --------------------------------------------------------------------------------------------------
# answers to broadcasts (R1, R2, 4.4.2)

case("answer_late", lambda h: answer_delays(h, "get_esc_id", {"option": 0}, 3), (0.002,), (0.080,))
# with the fault both answers are due at 10 ms: node 3's waits for node 1's (230 us at 500 kbit/s)
case("answer_not_staggered", lambda h: answer_delays(h, "msg_control", {"option": 0, "command": RESUME}, 6),
     (0.002, 0.006), (0.010, 0.01023), nodes=(1, 3))
# both due at 1 ms: node 3's reply (3 bytes) waits for node 1's (182 us)
case("answer_at_once", lambda h: answer_delays(h, "get_esc_id", {"option": 0}, 3), (0.002, 0.006), (0.001, 0.001182),
     nodes=(1, 3))


def get_esc_id_reply(host):
    quiet(host)
    host.send("get_esc_id", {"option": 0})
    [m] = raw_msgs(host, 20013, 0.05)
    return m.arbitration_id & 0x7F, list(m.data[:-1])


case("get_esc_id_with_option", lambda h: get_esc_id_reply(h)[1], [1, 1], [0, 1, 1])
case("get_esc_id_wrong_node", get_esc_id_reply, (1, [1, 1]), (1, [2, 1]))


def suspend_answers(host):
    quiet(host)
    host.send("msg_control", {"option": 0, "command": SUSPEND})
    return [f.fields["command"] for f in host.collect(host.now + 0.05) if f.name == "msg_control" and f.source]


case("msg_control_answer_echo", suspend_answers, [0], [SUSPEND])
case("msg_control_no_answer", suspend_answers, [0], [])
case("suspend_ignored", lambda h: (suspend_answers(h), len(msg1(h)))[1], 0, 10)


def reports_after_resume(host) -> int:
    suspend_answers(host)
    host.send("msg_control", {"option": 0, "command": RESUME})
    return len(msg1(host))


case("resume_ignored", reports_after_resume, 10, 0)


def msg1_dues_after_resume(host) -> list[float]:
    """When the MSG1s after a resume were due, from the resume (R9a: the first within one interval)."""
    suspend_answers(host)
    host.send("msg_control", {"option": 0, "command": RESUME})
    sent = host.now
    frames = host.collect(sent + 0.1)
    return [round(d - sent, 4) for d, f in zip(host.due_times(frames), frames) if f.name == "msg1"][:3]


case("report_restart_late", msg1_dues_after_resume, lambda d: d[0] <= 0.0005, lambda d: 0.0295 <= d[0] <= 0.0305)


def test_a_grid_keeping_report_timer_sends_at_once_then_on_its_old_grid(lane):
    """EscConfig.report_timer "grid" (R9a leaves it open): one MSG1 at the resume, then the grid of before."""
    restart = msg1_dues_after_resume(lane())
    grid = msg1_dues_after_resume(lane(esc_config={"report_timer": "grid"}))
    assert restart[0] <= 0.0005 and grid[0] <= 0.0005
    assert abs(restart[1] - restart[0] - 0.02) < 1e-4  # the timer restarted
    assert grid[1] - grid[0] < 0.0195 and abs(grid[2] - grid[1] - 0.02) < 1e-4  # the old grid: sooner, then 20 ms


def exp_reports(host, name: str | tuple, seconds: float = 0.5) -> list:
    """The ``name`` frames heard after MSG Control 0xEEEEEEEE (MSG_EXP mode) at 300 ms: MSG_EXP1 every
    20 ms, MSG_EXP7..11 every 500 ms (MSG3's interval; the next due at 750 ms)."""
    host.wait_until(0.3)
    host.send("msg_control", {"option": 0, "command": RESUME_EXP})
    names = (name,) if isinstance(name, str) else name
    return [f for f in host.collect(host.now + seconds) if f.name in names]


case("resume_exp_ignored", lambda h: len(exp_reports(h, "msg_exp1", 0.1)), 5, 0)

# --------------------------------------------------------------------------------------------------
# reports (R7, R9, 4.4.4-4.4.6)

case("report_interval_wrong", lambda h: set(gaps(h.of(h.collect(1.0), "msg1"))), {0.02}, {0.03})
case("report_jitter", lambda h: gaps(h.of(h.collect(1.0), "msg1")),
     lambda g: set(g) == {0.02}, lambda g: len(set(g)) > 5 and all(0.014 <= x <= 0.026 for x in g))


def msg2_gaps_after_set_freq(host):
    quiet(host)  # so that MSG2's new schedule never overlaps an MSG1
    host.call("set_freq", {"option": 1, "msg1_interval": 10, "msg2_interval": 25, "msg3_interval": 250})
    frames = host.collect(host.now + 1.0)
    dues = [round(d, 6) for d, f in zip(host.due_times(frames), frames) if f.name == "msg2"]
    return {round(b - a, 6) for a, b in zip(dues[1:], dues[2:])}


case("msg2_interval_ignores_setting", msg2_gaps_after_set_freq, {0.05}, {0.1})


def direction_bits(host):
    host.wait_until(0.3)
    host.call("set_rotation", {"rotation": 1})
    status = msg1(host, 0.05)[-1].fields["status"]
    return bool(status & Status.DIRECTION_CCW), bool(status & Status.THROTTLE_PWM)


case("status_direction_bit14", direction_bits, (True, False), (False, True))


def running_bit(host) -> bool:
    task = run_motor(host)
    status = msg1(host, 0.05)[-1].fields["status"]
    task.stop()
    return bool(status & Status.RUNNING)


case("status_running_wrong", running_bit, True, False)
case("msg2_scale_tenths", lambda h: h.of(h.collect(0.3), "msg2")[0].fields["voltage"] // 100, 50, 5)
case("msg3_short", lambda h: {len(m.data) for m in raw_msgs(h, 20052, 0.3)}, {8}, {4})
case("reports_padded",
     lambda h: sorted({(msg_type(m), len(m.data)) for m in h.collect_raw(0.3) if msg_type(m) in (20050, 20051)}),
     [(20050, 7), (20051, 6)], [(20050, 8), (20051, 8)])
case("exp1_scale_tenths", lambda h: exp_reports(h, "msg_exp1", 0.1)[0].fields["voltage"] // 100, 50, 5)
case("exp7_direction_zero_based", lambda h: exp_reports(h, "msg_exp7")[0].fields["direction"], 1, 0)
case("exp8_power_ups_from_zero", lambda h: exp_reports(h, "msg_exp8")[0].fields["power_ups"], 1, 0)


def exp_run_times(host) -> tuple:
    host.wait_until(0.3)
    host.esc(1).nvm["total_run_time"] = 12.5  # an ESC with a past: 12.5 s in all, 3.25 s this session
    host.esc(1).state.run_time = 3.25
    exp9, exp10 = exp_reports(host, ("msg_exp9", "msg_exp10"))
    return exp9.fields["total_run_time"], exp10.fields["run_time"]


def exp11_temperatures(host) -> tuple:
    """MSG_EXP11 (MOS, MCU, CAP, motor) at rest: MOS and CAP 25 degC, MCU 30 degC, no motor sensor (0)."""
    f = exp_reports(host, "msg_exp11")[0].fields
    return f["mos_t"], f["mcu_t"], f["cap_t"], f["motor_t"]


case("exp_run_times_ms", exp_run_times, (12, 3), (12500, 3250))
case("exp11_msg3_order", exp11_temperatures, (25, 30, 25, 0), (25, 25, 0, 30))
case("speed_ignores_throttle", lambda h: throttle(h, "raw_command_14b", {"channels": [1000, 0, 0, 0]}), 1000, 0)

# --------------------------------------------------------------------------------------------------
# comm loss (R8)

case("comm_loss_late", comm_loss_delay, 10, 20)
case("comm_loss_early", comm_loss_delay, 10, 5)
case("comm_loss_never", comm_loss_delay, 10, None)
case("comm_loss_sticky", comm_loss_after_next_command, False, True)
case("comm_watchdog_kept_alive", comm_flag_under_queries, True, False)

# --------------------------------------------------------------------------------------------------
# the bus as CAN hardware makes it (R20)


def after_a_short(host) -> tuple[int, int]:
    """A 0.5 s bus short (the ESC reporting goes bus-off): MSG1s in the 50 ms after it ends, and how far 241's
    power-up count moved across it."""
    host.wait_until(0.3)
    ups = host.esc(1).nvm["power_ups"]
    host.bus.world.short(0.5)
    host.wait(0.5)
    back = len(host.of(host.collect(host.now + 0.05), "msg1"))
    return back, host.esc(1).nvm["power_ups"] - ups


case("no_busoff_recovery", lambda h: after_a_short(h)[0], lambda n: n >= 1, 0)
case("busoff_recovery_resets", lambda h: after_a_short(h)[1], 0, lambda n: n >= 1)


def rotation_sent_at_another_rate(host) -> int:
    """The ESC at 250 kbit/s (its stored Set Baud code 2), the host at 500 kbit/s: a Set Rotation 1 from the host; the
    rotation the ESC then keeps in flash."""
    host.wait_until(0.3)
    host.send_wire(host.wire("set_rotation", {"rotation": 1}, destination=1))
    host.wait(0.1)
    return host.esc(1).nvm["rotation"]


case("takes_other_bitrate", rotation_sent_at_another_rate, 0, 1, esc_config={"baud_code": 2})

# --------------------------------------------------------------------------------------------------
# throttle (R3-R5, 4.4.18)

case("throttle_channel_ignored", lambda h: throttle(h, "raw_command_14b", {"channels": [100, 200, 300, 400]}), 300, 100,
     nodes=(3,))
# A = 0x123, B = 0x456: p1 = 0x61; read with its nibbles swapped A's top nibble is 6: 0x623
case("twelve_bit_nibbles_swapped",
     lambda h: throttle(h, "raw_command_12b", {"channels": [0x123, 0x456, 0, 0], "group": 1}), 0x123, 0x623)
case("twelve_bit_group_ignored",
     lambda h: throttle(h, "raw_command_12b", {"channels": [500, 600, 700, 800], "group": 2}), 0, 500)
case("ten_bit_not_doubled", lambda h: throttle(h, "raw_command_10b", {"channels": [400, 0, 0, 0, 0, 0]}), 800, 400)
case("ten_bit_tail_checked",
     lambda h: throttle(h, "raw_command_10b", {"channels": [400, 0, 0, 0, 0, 0], "tail_bits": 0}), 800, 0)


def msg1_after_throttle(host) -> int:
    """MSG1 frames heard within 10 ms of a RawCommand, sent 5 ms after an MSG1 tick (the next is at 20 ms)."""
    quiet(host)
    host.send("raw_command_14b", {"channels": [100, 0, 0, 0]})
    return len(msg1(host, 0.01))


case("throttle_answered", msg1_after_throttle, 0, 1)


def fourteen_bit_little_endian(host):
    wire = host.wire("raw_command_14b", {"channels": [300, 0, 0, 0]})
    assert wire.data[:3] == bytes([0x2C, 0x04, 0x00])  # 300 = 0x12C: low byte 0x2C then 0b000001 (R3)
    return throttle(host, "raw_command_14b", {"channels": [300, 0, 0, 0]})


case("fourteen_bit_byte_order", fourteen_bit_little_endian, 300, 0x042C)  # 2C 04 read little-endian: 0x042C

# --------------------------------------------------------------------------------------------------
# rejects (R10)


def after(host, name, fields, destination=1, read=intervals):
    host.wait_until(0.3)
    host.send(name, fields, destination=destination)
    host.wait(0.01)
    return read(host)


case("set_freq_accepts_illegal",
     lambda h: after(h, "set_freq", {"option": 1, "msg1_interval": 5, "msg2_interval": 50, "msg3_interval": 250}),
     (10, 50, 250), (5, 50, 250))
case("set_freq_partial",
     lambda h: after(h, "set_freq", {"option": 1, "msg1_interval": 5, "msg2_interval": 60, "msg3_interval": 200}),
     (10, 50, 250), (10, 60, 200))
case("set_id_accepts_illegal",
     lambda h: after(h, "set_id", {"node_id": 0x7E, "throttle_channel": 1},
                     read=lambda h: {m.arbitration_id & 0x7F for m in raw_msgs(h, 20050, 0.1)}),
     {1}, {0x7E})
case("set_baud_accepts_illegal", booted(lambda h: h.call("set_baud", {"baud": 7}).fields["baud"]), 1, 7)
case("rotation_accepts_illegal",
     lambda h: after(h, "set_rotation", {"rotation": 2},
                     read=lambda h: h.call("get_major_configuration", {"option": 0}).fields["direction"]), 0, 1)
case("throttle_select_accepts_illegal",
     booted(lambda h: h.call("throttle_select", {"source": 2}).fields["source"]), 0, 2)
case("rotation_ignored",
     lambda h: after(h, "set_rotation", {"rotation": 1},
                     read=lambda h: h.call("get_major_configuration", {"option": 0}).fields["direction"]), 1, 0)
case("throttle_select_ignored",
     lambda h: after(h, "throttle_select", {"source": 1},
                     read=lambda h: h.call("get_major_configuration", {"option": 0}).fields["throttle_source"]), 1, 0)

# --------------------------------------------------------------------------------------------------
# the 120 s window, Set Baud at power-up, pseudo-broadcast (R11)


def late_set_id(host):
    host.wait_until(121.0)
    return host.call("set_id", {"node_id": 5, "throttle_channel": 5}, 0x7D).source


def late_set_baud(host):
    host.wait_until(121.0)
    return host.call("set_baud", {"baud": 2}, 0x7D).fields["baud"]


case("set_id_after_window", late_set_id, 0x7D, 5, nodes=(0x7D,))
case("set_baud_after_window", late_set_baud, 1, 2, nodes=(0x7D,))
case("config_window_short",
     lambda h: (h.wait_until(90.0), h.call("set_id", {"node_id": 5, "throttle_channel": 5}, 0x7D).source)[1],
     5, 0x7D, nodes=(0x7D,))
case("set_id_channel_ignored",
     booted(lambda h: h.call("set_id", {"node_id": 1, "throttle_channel": 6}).fields),
     {"node_id": 1, "throttle_channel": 6}, {"node_id": 1, "throttle_channel": 1})
case("set_baud_immediate",
     lambda h: after(h, "set_baud", {"baud": 2}, read=lambda h: len(msg1(h))), 10, 0)
case("set_id_needs_destination",
     lambda h: after(h, "set_id", {"node_id": 5, "throttle_channel": 5}, destination=99,
                     read=lambda h: [e.node_id for e in h.bench.escs]), [5], [1])

# --------------------------------------------------------------------------------------------------
# suspension and a running motor (R12)


def set_freq_while_suspended(host):
    suspend_answers(host)
    host.send("set_freq", {"option": 1, "msg1_interval": 20, "msg2_interval": 60, "msg3_interval": 80}, destination=1)
    host.wait(0.01)
    host.send("msg_control", {"option": 0, "command": RESUME})
    host.wait(0.01)
    return intervals(host)


def rotation_while_running(host):
    task = run_motor(host)
    rotation = host.call("set_rotation", {"rotation": 1}).fields["rotation"]
    task.stop()
    return rotation


def set_id_while_suspended(host):
    suspend_answers(host)
    host.send("set_id", {"node_id": 5, "throttle_channel": 6}, destination=1)
    host.wait(0.01)
    host.send("msg_control", {"option": 0, "command": RESUME})
    host.wait(0.01)
    return [(e.node_id, e.nvm["throttle_channel"]) for e in host.bench.escs]


def set_baud_while_suspended(host):
    suspend_answers(host)
    host.send("set_baud", {"baud": 2}, destination=1)
    host.wait(0.01)
    host.send("msg_control", {"option": 0, "command": RESUME})
    host.wait(0.01)
    return [e.nvm["baud"] for e in host.bench.escs]


case("settings_while_suspended", set_freq_while_suspended, (10, 50, 250), (20, 60, 80))
case("set_id_while_suspended", set_id_while_suspended, [(1, 1)], [(5, 6)])
case("set_baud_while_suspended", set_baud_while_suspended, [1], [2])
case("rotation_while_running", rotation_while_running, 0, 1)

# --------------------------------------------------------------------------------------------------
# persistence (R13)


def persisted(request, fields, read):
    def observe(host):
        host.wait_until(0.3)
        host.send(request, fields, destination=1)
        host.wait(0.01)
        power_cycle(host)
        return read(host)
    return observe


def ids_read(host):
    quiet(host, host.now)
    host.send("get_esc_id", {"option": 0})
    return [(f.fields["node_id"], f.fields["throttle_channel"]) for f in host.collect(host.now + 0.07) if f.name == "get_esc_id"
            and f.source]


def led_read(host):
    f = host.call("get_major_configuration", {"option": 0}).fields
    return f["led_color"], f["led_blink"]


def exp7_read(host):
    host.send("msg_control", {"option": 0, "command": RESUME_EXP})
    return host.of(host.collect(host.now + 0.6), "msg_exp7")[0].fields["prop_lock"]


def baud_after_power_cycle(host, lane):
    host.wait_until(0.3)
    host.call("set_baud", {"baud": 2})
    host.bus.power_cycle(0.5)
    slow = lane.join(host, bitrate=250_000)
    t = host.now
    return bool(host.of(host.collect(t + 0.5), "msg1")), bool(slow.of(slow.collect(t + 0.5), "msg1"))


FREQ = {"option": 1, "msg1_interval": 20, "msg2_interval": 60, "msg3_interval": 80}
case("intervals_not_persisted", persisted("set_freq", FREQ, intervals), (20, 60, 80), (10, 50, 250))
case("node_id_not_persisted", persisted("set_id", {"node_id": 1, "throttle_channel": 6}, ids_read), [(1, 6)], [(1, 1)])
case("rotation_not_persisted",
     persisted("set_rotation", {"rotation": 1}, lambda h: h.call("set_rotation", {"rotation": 0xFF}).fields["rotation"]), 1, 0)
case("led_save_not_persisted", persisted("set_led", {"option": 1, "color": RED, "blink": 1}, led_read), (RED, 1), (GREEN, 0))
case("led_unsaved_persisted", persisted("set_led", {"option": 0, "color": RED, "blink": 1}, led_read), (GREEN, 0), (RED, 1))
case("throttle_source_not_persisted",
     persisted("throttle_select", {"source": 1}, lambda h: h.call("throttle_select", {"source": 0xFF}).fields["source"]), 1, 0)
case("baud_not_persisted", "lane", (False, True), (True, False))  # observed with a second host: see _observe
case("expand_not_persisted", persisted("expand_set_part", {"set_cmd": 0xFFF8, "part": 2}, exp7_read), 2, 0)
case("suspend_persisted",
     lambda h: after_power_cycle_hears(h, lambda h: h.send("msg_control", {"option": 0, "command": SUSPEND})), True, False)
case("power_up_counter_stuck",
     booted(lambda h: (power_cycle(h), h.call("maintenance_information", {"option": 2}).fields["power_ups"])[1]), 2, 0)

# --------------------------------------------------------------------------------------------------
# other services (R14, R15, R16, 4.4.20-4.4.28)


def expand_answers(host) -> int:
    host.wait_until(0.3)
    host.send("expand_set_part", {"set_cmd": 0xFFF8, "part": 1}, destination=1)
    return len(service_responses(host, 222, 0.05))


def expand_little_endian(host) -> int:
    host.wait_until(0.3)
    request = host.send("expand_set_part", {"set_cmd": 0xFFF0, "part": 2}, destination=1)  # reverse
    assert bytes(request.data[:3]) == bytes([0xF0, 0xFF, 0x02])
    host.wait(0.01)
    return host.call("set_rotation", {"rotation": 0xFF}).fields["rotation"]


def record_kept_after_clear(host) -> bool:
    host.wait_until(0.3)
    host.esc(1).nvm["records"]["mos"].update(t_max=99, times=7, time=1234)  # an ESC with a hot past
    host.send("clear_rec", {"payload": []}, destination=1)
    host.wait(0.2)
    host.send("get_rec", {"payload": []}, destination=1)
    [mos] = [f for f in host.collect(host.now + 0.01) if f.name == "msg_exp12" and f.fields["record"] == 2]
    return mos.fields["t_max"] == 99


def can_test_counts(host) -> list:
    quiet(host)
    host.send("can_test", {"option": 0xAA, "count": 0})
    return [f.fields["count"] for f in can_test_frames(host, 0.07)]


def reports_in_can_test(host) -> int:
    quiet(host)
    host.send("can_test", {"option": 0xAA, "count": 0})
    return len(msg1(host))


def can_test_frames_after_off(host) -> int:
    quiet(host)
    host.send("can_test", {"option": 0xAA, "count": 0})
    host.wait(0.05)
    host.send("can_test", {"option": 0x55, "count": 0})
    host.wait(0.001)
    return len(can_test_frames(host))


def reports_after_can_test_while_suspended(host) -> int:
    suspend_answers(host)
    host.send("can_test", {"option": 0xAA, "count": 0})
    host.wait(0.05)
    host.send("can_test", {"option": 0x55, "count": 0})
    return len(msg1(host))


def can_test_after_power_cycle(host) -> bool:
    host.wait_until(0.3)
    host.send("can_test", {"option": 0xAA, "count": 0})
    host.wait(0.05)
    power_cycle(host)
    return bool(can_test_frames(host))


case("expand_set_answered", expand_answers, 0, 1)
case("expand_set_big_endian", expand_little_endian, 1, 0)
case("get_rec_untagged", mcu_records_tail, [0xC1, 0xC2, 0xC3, 0xC4], [0xC0] * 4)
case("get_rec_absent", mcu_records_tail, [0xC1, 0xC2, 0xC3, 0xC4], [])
case("expand_set_part_absent", expand_little_endian, 1, 0)
case("clear_rec_ignored", record_kept_after_clear, False, True)
case("can_test_count_skips", can_test_counts, [0, 1, 2, 3], [0, 2, 4, 6])
case("can_test_reports_continue", reports_in_can_test, 0, 10)
case("can_test_persisted", can_test_after_power_cycle, False, True)
case("can_test_off_ignored", can_test_frames_after_off, 0, 5)
case("can_test_off_resumes_reporting", reports_after_can_test_while_suspended, 0, 10)
case("self_test_always_passes", booted(lambda h: h.call("self_test").fields["status"]), 1, 0,
     esc_config={"self_test_fault": 0x11})
case("set_led_no_echo",
     booted(lambda h: h.call("set_led", {"option": 1, "color": RED, "blink": 5}).fields),
     {"option": 1, "color": RED, "blink": 5}, {"option": 0, "color": 0, "blink": 0})
case("set_freq_read_wrong", lambda h: after(h, "set_freq", FREQ), (20, 60, 80), (10, 50, 250))


def major_config_bits(host):
    host.wait_until(0.3)
    host.call("set_rotation", {"rotation": 1})
    f = host.call("get_major_configuration", {"option": 0}).fields
    return f["direction"], f["throttle_source"]


case("major_config_bits_swapped", major_config_bits, (1, 0), (0, 1))
case("maintenance_counts_wrong",
     booted(lambda h: h.call("maintenance_information", {"option": 2}).fields),
     lambda f: (f["power_ups"], f["stops"]) == (1, 0), lambda f: (f["power_ups"], f["stops"]) == (0, 1))


# --------------------------------------------------------------------------------------------------
# ids outside the protocol (F7, 4.1.2, 4.3.1), Self Test and the information services (4.2, 4.4.24-4.4.27)


def exp2_sources(host) -> set:
    host.wait_until(0.3)
    host.send("msg_control", {"option": 0, "command": RESUME_EXP})
    return {m.arbitration_id & 0x7F for m in raw_msgs(host, 20054, 0.6)}


def dronecan_answers(host) -> list:
    """What a DroneCAN GetNodeInfo request (service 1) to the ESC brings: frames outside the vendor ranges."""
    host.wait_until(0.3)
    host.send_raw(service_id(LOW, 1, True, 1, 0), [0xC0])
    out = []
    for m in host.collect_raw(host.now + 0.05):
        if m.arbitration_id & 0x80:
            out.append(("service", service_type(m), (m.arbitration_id >> 15) & 1, (m.arbitration_id >> 8) & 0x7F))
        elif msg_type(m) not in range(20000, 21000):
            out.append(("message", msg_type(m), m.arbitration_id & 0x7F))
    return sorted(out)


def self_test_answers(host) -> list:
    host.wait_until(0.3)
    host.send("self_test", destination=1)
    return [f.fields["status"] for f in host.collect(host.now + 0.02) if f.name == "self_test" and f.source]


def self_test_code(host):
    host.wait_until(0.3)
    return host.call("maintenance_information", {"option": 2}).fields["fault_code"], host.call("self_test").fields["status"]


def pwm_lost(host) -> tuple:
    """PWM+CAN with both inputs (PWM 800, CAN 600); then the PWM signal is lost (4.2: CAN takes over)."""
    host.wait_until(0.3)
    host.call("throttle_select", {"source": 1})
    host.bench.set_pwm_input(800)
    task = host.bus.send_periodic(host.message("raw_command_14b", {"channels": [600, 0, 0, 0]}), 0.01)
    with_pwm = msg1(host, 0.1)[-1].fields["pwm"]
    host.bench.set_pwm_input(None)
    without = msg1(host, 0.1)[-1].fields["pwm"]
    task.stop()
    return with_pwm, without


case("debug_frames_reserved_source", exp2_sources, set(), {0x7F})
case("dronecan_node_info", dronecan_answers, [], [("message", 341, 1), ("service", 1, 0, 0)])
case("self_test_unanswered", self_test_answers, [0], [])
case("self_test_inverted", self_test_answers, [0], [1])
case("self_test_undefined_code", self_test_code, (0, 0), (0x30, 1))
case("pwm_no_fallback", pwm_lost, (800, 600), (800, 0))
case("esc_information_bcd_date",
     booted(lambda h: h.call("esc_information", {"option": 0}).fields),
     lambda f: (f["firmware_year"], f["firmware_month"], f["firmware_day"]) == (24, 10, 11),
     lambda f: (f["firmware_year"], f["firmware_month"], f["firmware_day"]) == (0x24, 0x10, 0x11))
case("maintenance_info_7_missing",
     booted(lambda h: (h.send("maintenance_information", {"option": 2}, destination=1),
                       [len(m.data) for m in service_responses(h, 241)])[1]), [8], [7])


# --------------------------------------------------------------------------------------------------
# malformed and foreign frames (R17)


def answers_to(host, data, *, destination: int = 1, name: str = "set_rotation", fields=None) -> int:
    """Answers to ``name`` (Set Rotation 1 by default) sent with its data made ``data(wire data)``."""
    host.wait_until(0.3)
    wire = host.wire(name, {"rotation": 1} if fields is None else fields, destination=destination)
    host.send_raw(wire.arbitration_id, data(wire.data))
    return len(service_responses(host, BY_NAME[name].type_id))


def comm_fault_after_short_command(host) -> bool:
    """MSG1's comm-loss bit after a RawCommand_14b one byte short (the flag set: 200 ms after boot, no command)."""
    host.wait_until(0.7)
    quiet(host, host.now)
    wire = host.wire("raw_command_14b", {"channels": [0, 0, 0, 0]})
    host.send_raw(wire.arbitration_id, wire.data[:-2] + wire.data[-1:])
    return bool(host.of(host.collect(host.now + 0.03), "msg1")[0].fields["status"] & Status.COMM_FAULT)


def power_ups_after_start_frame(host) -> int:
    host.wait_until(0.3)
    wire = host.wire("self_test", destination=1)
    host.send_raw(wire.arbitration_id, wire.data[:-1] + bytes((wire.data[-1] & 0x1F | 0x80,)))
    host.wait(BOOT + 0.05)
    return host.call("maintenance_information", {"option": 2}).fields["power_ups"]


case("takes_multi_frame_start", lambda h: answers_to(h, lambda d: d[:-1] + bytes((d[-1] & 0x1F | 0x80,))), 0, 1)
case("short_raw_command_padded", comm_fault_after_short_command, True, False)
case("wrong_length_taken", lambda h: answers_to(h, lambda d: d[:-1] + bytes(1) + d[-1:]), 0, 1)
case("reset_on_multi_frame_start", power_ups_after_start_frame, 1, 2)
case("destination_low_bits", lambda h: answers_to(h, lambda d: d, destination=1 + 64), 0, 1)


# --------------------------------------------------------------------------------------------------
# a loaded bus (R18)


def msg1_under_load(host) -> int:
    """MSG1s from node 1 in 0.2 s of half load of foreign frames (R18's most), after boot."""
    host.wait_until(0.3)
    host.bus.world.add_source(LoadSource(0.5, host.bus.bitrate, priority="high", seed=0, exclude_nodes=[1]))
    return len([m for m in host.collect_raw(host.now + 0.2) if msg_type(m) == BY_NAME["msg1"].type_id])


case("drops_reports_under_load", msg1_under_load, 10, lambda n: n < 5)


# --------------------------------------------------------------------------------------------------
# the tests


def _observe(lane, name: str, c: Case, faults: list[str]):
    host = lane(c.nodes, faults=faults, **c.bus)
    if name == "baud_not_persisted":
        return baud_after_power_cycle(host, lane)
    return c.observe(host)


@pytest.mark.parametrize("name", SINGLE_FAULTS)
def test_fault_changes_the_behaviour_it_names(lane, name):
    c = CASES.get(name)
    if c is None:
        pytest.fail(f"fault {name!r} has no scenario in {__name__}")
    off = _observe(lane, name, c, [])
    assert _matches(c.off, off), f"{name} off: conforming behaviour expected {c.off!r}, got {off!r}"
    on = _observe(lane, name, c, [name])
    assert _matches(c.on, on), f"{name} on: {FAULTS[name].description}: expected {c.on!r}, got {on!r}"
    assert on != off


def test_every_fault_has_a_scenario():
    assert sorted(set(SINGLE_FAULTS) - set(CASES)) == [], "faults with no scenario"
    assert sorted(set(CASES) - set(SINGLE_FAULTS)) == [], "scenarios for faults that do not exist (or not single)"


def _spec_text(name: str) -> str:
    path = SPEC_DIR / name
    if not path.exists():
        pytest.skip(f"{path} not found (set CKESC_SPEC_DIR)")
    return path.read_text()


def _rule_ids() -> set[str]:
    return set(re.findall(r"^- ([FR]\d+) ", _spec_text("INTERPRETATIONS.md"), flags=re.M))


#: The SHALL/READING rules (F6 and R6 are OBSERVE: a device cannot break them).
CHECKED_RULES = {"F1", "F2", "F3", "F4", "F5", "F7", *(f"R{i}" for i in range(1, 19) if i != 6)}


def test_every_checked_rule_is_broken_by_some_fault():
    broken = {rule for f in FAULTS.values() for rule in f.rules}
    assert sorted(CHECKED_RULES - broken) == []


#: Rules the document now states that no fault breaks and no test checks yet, each with the issue that builds its
#: checks: a rule added to INTERPRETATIONS.md is either checked or listed here, never silently left out.
NOT_YET_CHECKED: dict[str, str] = {
    "R20": "issue #36: the bus as CAN hardware. Checked: R20-watchdog (only RawCommand refreshes the comm watchdog: "
           "4.4.4's comm-loss test with queries, reads and foreign frames going on; fault comm_watchdog_kept_alive), "
           "R20-recovery and R20-comm (the robustness section's bus-fault tests, a short and a node at another bit "
           "rate; faults no_busoff_recovery, busoff_recovery_resets), R20-bitrate (an ESC at another bit rate takes "
           "nothing: the robustness section; fault takes_other_bitrate). Not yet: error frames in normal operation (no "
           "fault, no test), the host alone on the bus judged with acknowledgement on in the simulated lane",
}
#: Rules of long runs: checked by ``ckesc soak``, not the ten-minute suite; broken by the soak faults (kind soak), which
#: the suite must miss (tests/emulator/test_soak_faults.py, the self-test).
SOAK_RULES = {"R19"}


def test_the_checked_rules_are_the_documents():
    ids = _rule_ids()
    assert CHECKED_RULES <= ids and ids - CHECKED_RULES - NOT_YET_CHECKED.keys() - SOAK_RULES == {"F6", "R6"}
    assert NOT_YET_CHECKED.keys() | SOAK_RULES <= ids, "a rule listed as pending or soak's is no longer in INTERPRETATIONS.md"


def test_every_soak_rule_is_broken_by_a_soak_fault():
    assert SOAK_RULES <= {rule for f in FAULTS.values() if f.kind == SOAK for rule in f.rules}


def test_faults_can_be_switched_on_a_running_bench(lane):
    """bus.set_fault: on and off again, for one node, while the lane runs."""
    host = lane([1, 2])
    host.wait_until(0.3)
    host.bus.set_fault("wrong_priority", True, node=2)
    prios = {(m.arbitration_id & 0x7F, m.arbitration_id >> 24) for m in host.collect_raw(host.now + 0.1)}
    assert prios == {(1, 31), (2, 16)}
    host.bus.set_fault("wrong_priority", False, node=2)
    host.wait(0.01)
    prios = {(m.arbitration_id & 0x7F, m.arbitration_id >> 24) for m in host.collect_raw(host.now + 0.1)}
    assert prios == {(1, 31), (2, 31)}
    with pytest.raises(ValueError, match="unknown fault"):
        host.bus.set_fault("no_such_fault")
