"""The CKESC 2.1 ESC behaviour model: frames and a time in, frames and the next deadline out.

No sockets, threads, sleeps or clocks: the simulated-time bus and the real-time process drive the
same :class:`EscModel`. One model is one ESC; a bench of several shares a bus in the adapters.

    esc = EscModel(EscConfig(slot=0), nvm=None)     # nvm: what was in flash, or None for factory state
    esc.power_on(now=0.0)
    esc.receive(wire_frame, now)                    # a frame heard on the bus (already at the ESC's bitrate)
    out = esc.poll(now)                             # frames due at or before now, timestamped with their due time
    esc.next_deadline()                             # when to poll next (None: nothing scheduled)

Persistent settings and counters live in ``esc.nvm`` (a plain dict); ``esc.nvm_dirty`` tells the
adapter to write them to its flash store. Everything else is lost at power-off (R13).
"""

from __future__ import annotations

import copy
import heapq
import math
import random
from dataclasses import dataclass, field
from typing import Any

from ..protocol import catalogue as cat
from ..protocol.catalogue import (
    ANSWER_SLOT_S,
    BAUD_RATES,
    CAN_TEST_OFF,
    CAN_TEST_ON,
    COMM_LOSS_TIMEOUT_S,
    CONFIG_WINDOW_S,
    EXPAND_COMMANDS,
    INTERVAL_UNIT_S,
    MSG_CONTROL_RESUME,
    MSG_CONTROL_RESUME_EXP,
    MSG_CONTROL_SUSPEND,
    THROTTLE_10B_MAX,
    THROTTLE_MAX,
    Status,
)
from ..protocol.codecs import TAIL_BITS_10B, codec_for, unpack_throttle12
from ..protocol.errors import DecodeError, UnknownTypeError
from ..protocol.frame import Decoder, Frame, WireFrame, encode, frame_bits
from ..protocol.ids import DEFAULT_ESC_NODE_ID, Kind, Priority, message_id, service_id
from ..protocol.transfer import TransferIdCounter, tail_byte
from . import faults as _faults
from . import variants as _variants

# Reporting states (MSG Control, 4.4.2)
REPORTING = "normal"
SUSPENDED = "suspended"
EXP_MODE = "exp"

#: How the report timer may behave when reporting comes back (EscConfig.report_timer; R9a allows each)
REPORT_TIMERS = _variants.FREEDOMS["report_timer"].choices
_REPORT_NAMES = ("msg1", "msg2", "msg3")

#: Fault code 1 -> the MSG1 self-test error bit it lights (4.4.4 status bits 7..0).
_FAULT_BITS = {
    code: int(bit)
    for code, bit in {
        0x01: Status.SELFTEST_COM_INPUT_LOW,
        0x02: Status.SELFTEST_COM_INPUT_HIGH,
        0x11: Status.SELFTEST_A_OUTPUT_HIGH,
        0x12: Status.SELFTEST_B_OUTPUT_HIGH,
        0x13: Status.SELFTEST_C_OUTPUT_HIGH,
        0x21: Status.SELFTEST_A_OUTPUT_LOW,
        0x22: Status.SELFTEST_B_OUTPUT_LOW,
        0x23: Status.SELFTEST_C_OUTPUT_LOW,
    }.items()
}
_PWM, _CCW, _COMM_FAULT, _RUNNING = (int(Status.THROTTLE_PWM), int(Status.DIRECTION_CCW), int(Status.COMM_FAULT),
                                     int(Status.RUNNING))

_RECORD_SENSORS = ("mcu", "mos", "cap", "motor")  # MSG_EXP12 tail tags 0xC1..0xC4 (R15)

#: (sensor, time constant s, rise at full load degC, ambient degC): a plausible, not a measured, ESC.
_THERMAL = (("mos", 20.0, 60.0, 25.0), ("cap", 40.0, 35.0, 25.0), ("mcu", 30.0, 20.0, 30.0), ("motor", 60.0, 70.0, 25.0))


@dataclass
class EscConfig:
    """What is fixed in a given ESC: identity (240), capabilities and physical constants."""

    slot: int = 0  # position on the bench: the key of this ESC in the flash store (its node id can change)
    node_id: int = DEFAULT_ESC_NODE_ID  # node id of a factory-fresh ESC (no flash yet)
    throttle_channel: int | None = None  # factory channel; None: the node id if 1..20, else 1
    baud_code: int = cat.DEFAULT_BAUD_CODE  # factory Set Baud code (1: 500 kbit/s)
    max_cells: int = 12
    max_current_10a: int = 8  # 80 A
    hardware_version: int = 3
    protocol_version: int = 21
    firmware_date: tuple[int, int, int] = (24, 10, 11)
    self_test_fault: int = 0  # fault code 1 found by the power-up self-test (0: passed)
    has_led: bool = True
    has_motor_sensor: bool = False
    boot_time: float = 0.25  # power-on to first answer; the ESC hears nothing before
    report_delay: float = 0.0  # boot to first report: an ESC may answer services before it reports
    #: what the report timer does when reporting comes back (resume, leaving CAN Test or MSG_EXP mode) - R9a
    #: leaves it open: "restart" (the first report at once, the next ones one interval apart), "grid" (one report
    #: at once, "immediately", then the old grid goes on, as if the timer had never stopped), "next_tick" (nothing
    #: at once: the first report at the old grid's next point) or "one_interval" (the timer restarted at the
    #: event: the first report one full interval later)
    report_timer: str = "restart"
    #: when a report whose interval a Set Freq write changed comes next - R9a leaves it open: "last_report" (the
    #: new interval counted from the last report), "old_deadline" (the report already scheduled on the old
    #: interval first, the new interval from it), "restart" (one new interval after the write) or "at_once"
    #: (a report at the write, the new interval from it)
    set_freq_timer: str = "last_report"
    #: the ESC's own report timing jitter, as its profile would declare it (jitter_s, R9): each report goes out
    #: within +- half of it of its grid point (so one interval strays by at most this much), the grid itself exact
    report_jitter_s: float = 0.0
    #: when the comm-loss flag is raised (R8 leaves it open inside its window): "timer" (an exact 200 ms timer
    #: from the last command), "msg1" (checked when an MSG1 is due: the first one 200 ms or more after the last
    #: command carries it; an exact timer while nothing is reported) or "tick" (a periodic check on the report
    #: timer's 2 ms tick, which MSG1's grid is on)
    comm_loss_check: str = "timer"
    #: where in its 2 ms slot (R2) an answer to MSG Control / GET_ESC_ID goes: "start", "inside" (a random
    #: place, the frame ending inside the slot) or "late" (as late as leaves room for one longest frame on the
    #: bus ahead of it)
    answer_place: str = "start"
    service_delay: float = 0.0005  # request to response for services
    # the other freedoms the document leaves (ckesc/emulator/variants.py says what each value does)
    report_phase: str = "together"  # the first MSG1..3 after power-up together, or staggered
    transfer_id_start: str = "zero"  # message transfer-id counters' first value (F3)
    unlisted_priority: str = "request"  # 240/241/242 answers' priority (F5-unlisted)
    foreign_host: str = "accept"  # frames from a host node other than 0 (F6)
    rejected_answer: str = "current"  # the answer to an illegal or refused request (R10)
    over_max_throttle: str = "clamp"  # throttle above its maximum (R6)
    exp_frames: str = "msg3"  # which MSG_EXP frames, how often (R9-exp)
    value_rounding: str = "mixed"  # temperatures, run times, voltage, current to their units
    can_test_count: str = "from_zero"  # CAN Test's count's start (R16)
    led_blink_other: str = "no_blink"  # Set LED blink codes other than 0/1/2/5 (4.4.20)
    major_config_option: str = "answer"  # 242 with option != 0 (4.4.28-2)
    rec_answer: str = "none"  # Get Rec / Clear Rec answered (R15-payload)
    max_rpm: int = 9000
    motor_tau: float = 0.15  # rpm first-order lag
    supply_voltage: float = 50.4  # 12S full
    seed: int = 0
    faults: frozenset[str] = field(default_factory=frozenset)

    def __post_init__(self) -> None:
        self.faults = _faults.check(self.faults)
        # the freedoms the document leaves (conforming variants): each field only at a value that conforms
        _variants.check({name: getattr(self, name) for name in _variants.FREEDOMS})


def factory_nvm(config: EscConfig) -> dict[str, Any]:
    """Flash contents of a new ESC: the document's defaults."""
    channel = config.throttle_channel
    if channel is None:
        channel = config.node_id if 1 <= config.node_id <= 20 else 1
    return {
        "node_id": config.node_id,
        "throttle_channel": channel,
        "baud": config.baud_code,
        "led_color": int(cat.DEFAULT_LED_COLOR),
        "led_blink": 0,
        "rotation": 0,
        **dict(cat.DEFAULT_REPORT_INTERVALS),
        "throttle_source": 0,
        "active_freewheel": 1,
        "prop_lock": 0,
        "startup_acceleration": 8,
        "lost_signal_reduction": 8,
        "power_ups": 0,
        "starts": 0,
        "stops": 0,
        "total_run_time": 0.0,
        "records": {s: {"t_max": 0, "times": 0, "time": 0} for s in _RECORD_SENSORS},
        "can_test": False,  # only kept when the 'can_test_persisted' fault is on
        "suspended": False,  # only kept when the 'suspend_persisted' fault is on
    }


#: What R13 says survives a power cycle, and the fault that makes each item forget.
_PERSIST_FAULTS = {
    "msg1_interval": "intervals_not_persisted",
    "msg2_interval": "intervals_not_persisted",
    "msg3_interval": "intervals_not_persisted",
    "node_id": "node_id_not_persisted",
    "throttle_channel": "node_id_not_persisted",
    "rotation": "rotation_not_persisted",
    "led_color": "led_save_not_persisted",
    "led_blink": "led_save_not_persisted",
    "throttle_source": "throttle_source_not_persisted",
    "baud": "baud_not_persisted",
    "active_freewheel": "expand_not_persisted",
    "prop_lock": "expand_not_persisted",
    "startup_acceleration": "expand_not_persisted",
    "lost_signal_reduction": "expand_not_persisted",
}


class EscModel:
    """One emulated ESC. See the module docstring for the driving contract."""

    def __init__(self, config: EscConfig | None = None, nvm: dict[str, Any] | None = None) -> None:
        self.config = config or EscConfig()
        self.faults: set[str] = set(self.config.faults)
        self.nvm: dict[str, Any] = copy.deepcopy(nvm) if nvm is not None else factory_nvm(self.config)
        for key, value in factory_nvm(self.config).items():  # flash from an older emulator: fill gaps
            self.nvm.setdefault(key, value)
        self.nvm_dirty = nvm is None
        self._rng = random.Random(self.config.seed * 1_000_003 + self.config.slot)
        rounding = self.config.value_rounding
        #: temperatures and run times to whole units, voltage and current to 0.01 / 0.1 (value_rounding)
        self._whole = round if rounding == "round" else int
        self._fine = int if rounding == "truncate" else round
        self._decoder = Decoder()
        self.counters = {"rx": 0, "rx_ignored": 0, "rx_malformed": 0, "rx_foreign": 0, "tx": 0}
        self.pwm_input: int | None = None  # PWM throttle 0..2000 on the analog input; None: no signal
        self.powered = False
        self._power_epoch = 0
        self._reset_volatile(0.0)

    # ------------------------------------------------------------------------------------------
    # power

    def _reset_volatile(self, now: float) -> None:
        self.powered_at = now
        self.ready_at = now + self.config.boot_time
        self.bitrate = BAUD_RATES.get(self.nvm["baud"], cat.DEFAULT_BITRATE)
        self.reporting = REPORTING
        self.can_test = False
        self.can_test_prev = REPORTING
        self.can_test_count = self._rng.randrange(1 << 31) if self.config.can_test_count == "from_random" else 0
        self.led_color = self.nvm["led_color"]
        self.led_blink = self.nvm["led_blink"]
        self.throttle = 0  # 0..2000 in use
        self.can_throttle = 0
        self.last_command: float | None = None
        self.comm_fault = False
        self.rpm = 0.0
        self.running = False
        self.run_time = 0.0  # motor running seconds in this power session
        self.temps = {"mos": 25.0, "cap": 25.0, "mcu": 30.0, "motor": 25.0}
        self.current = 0.0
        self.self_test_fault = self.config.self_test_fault
        if "self_test_undefined_code" in self.faults:
            self.self_test_fault = 0x30  # a failed self-test whose code the attachment does not define
        self._pwm_seen = False  # a PWM signal was in use (fault 'pwm_no_fallback')
        self.test_mode = False
        self._outbox: list[tuple[float, int, WireFrame]] = []
        self._seq = 0
        self._tids = TransferIdCounter(
            (lambda: self._rng.randrange(32)) if self.config.transfer_id_start == "random" else None)
        self._last_update = now
        self._last_thermal = now
        self._next_report: dict[str, float] = {}
        self._regrid: dict[str, float] = {}  # report_timer "grid": the old grid's next point after a report sent at once
        # report_jitter_s: each report's offset from its grid point (empty without jitter: the hot path stays as it was),
        # and the earliest a jittered report may go out (not before the event that set its timer)
        self._offset: dict[str, float] = {k: self._jitter() for k in _REPORT_NAMES} if self.config.report_jitter_s else {}
        self._report_floor = now
        self._last_jittered: dict[str, float] = {}  # each report's last jittered time: the next never goes before it
        self._reports_were_active = True
        self._next_can_test = 0.0

    def power_on(self, now: float) -> None:
        if self.powered:
            return
        self.powered = True
        self._power_epoch += 1
        self._reset_volatile(now)
        if "can_test_persisted" in self.faults and self.nvm.get("can_test"):
            self.can_test = True
        if "suspend_persisted" in self.faults and self.nvm.get("suspended"):
            self.reporting = SUSPENDED
        if "power_up_counter_stuck" not in self.faults:
            self.nvm["power_ups"] = (self.nvm["power_ups"] + 1) & 0xFFFF
        self.nvm_dirty = True
        start = self.ready_at + self.config.report_delay
        stagger = (0.0, 0.007, 0.013) if self.config.report_phase == "staggered" else (0.0, 0.0, 0.0)
        self._next_report = {k: start + d for k, d in zip(_REPORT_NAMES, stagger)}
        self._report_floor = start
        self._next_can_test = start

    def power_off(self, now: float) -> None:
        if not self.powered:
            return
        self._update(now)
        for key, fault in _PERSIST_FAULTS.items():  # the faults that make a setting forget
            if fault in self.faults:
                self.nvm[key] = factory_nvm(self.config)[key]
        self.nvm["can_test"] = self.can_test
        self.nvm["suspended"] = self.reporting == SUSPENDED
        self.nvm_dirty = True
        self.powered = False
        self._outbox.clear()

    # ------------------------------------------------------------------------------------------
    # the driving contract

    @property
    def node_id(self) -> int:
        return self.nvm["node_id"]

    def next_deadline(self) -> float | None:
        if not self.powered:
            return None
        times = [self._outbox[0][0]] if self._outbox else []
        if self._reports_active():
            times.extend(self._next_report_times())
        if self.can_test:
            times.append(self._next_can_test)
        cl = self._comm_loss_deadline()
        if cl is not None:
            times.append(cl)
        if self.rpm > 0.5 or self.throttle:
            times.append(self._last_update + 0.05)  # motor and temperatures move
        return min(times) if times else None

    def handle(self, frame: Any | None, now: float) -> tuple[list[WireFrame], float | None]:
        """h11-style single entry point: feed one frame (or None for a timer), get what is due."""
        if frame is not None:
            self.receive(frame, now)
        return self.poll(now), self.next_deadline()

    def receive(self, msg: Any, now: float, *, decoded: Frame | DecodeError | None = None) -> bool:
        """A frame heard on the bus at ``now`` (the adapter has checked the bitrate matches).
        ``decoded``: the frame already decoded (or its DecodeError), when a bench decodes once for all.
        Returns whether the ESC acted on it (its next deadline may have moved)."""
        if not self.powered or now < self.ready_at:
            return False
        self.counters["rx"] += 1
        if decoded is None:
            try:
                decoded = self._decoder.decode(msg)
            except DecodeError as exc:
                decoded = exc
        if isinstance(decoded, DecodeError):
            # another protocol's type id (DroneCAN NodeStatus, ...) is foreign; anything else malformed
            self.counters["rx_foreign" if isinstance(decoded, UnknownTypeError) else "rx_malformed"] += 1
            return "dronecan_node_info" in self.faults and self._dronecan_node_info(msg, now)
        frame = decoded
        if frame.spec is None:
            self.counters["rx_foreign"] += 1
            return False
        handler = _HANDLERS.get((frame.kind, frame.name))
        if handler is None or (frame.source and self.config.foreign_host == "ignore"):
            self.counters["rx_ignored"] += 1
            return False
        if handler is not EscModel._on_throttle:
            self._update(now)  # throttle frames update only when addressed to this ESC's channel
        return handler(self, frame, now) is not False

    def poll(self, now: float) -> list[WireFrame]:
        """Everything due at or before ``now``, in due order, each stamped with its due time."""
        if not self.powered:
            return []
        self._update(now)
        if now >= self.ready_at:
            self._schedule_reports(now)
        out = []
        while self._outbox and self._outbox[0][0] <= now:
            out.append(heapq.heappop(self._outbox)[2])  # stamped with its due time when queued
        self.counters["tx"] += len(out)
        return out

    # ------------------------------------------------------------------------------------------
    # output helpers

    def _emit(self, due: float, name: str, fields: dict, *, kind: Kind = Kind.MESSAGE, destination: int | None = None,
              transfer_id: int | None = None, priority: int | None = None, layout: str | None = None,
              id_or: int = 0) -> None:
        spec = cat.BY_NAME[name]
        if transfer_id is None:
            transfer_id = self._tids.peek(name) if "transfer_id_stuck" in self.faults else self._tids.next(name)
        if priority is None:
            priority = spec.priority if spec.priority is not None else Priority.MEDIUM
        if kind is Kind.MESSAGE and layout is None and len(spec.layouts) == 1 and spec.has_tail:
            # reports, the bulk of what an ESC sends: the layout's compiled codec directly
            data = codec_for(spec.layouts[0]).encode(fields) + bytes((tail_byte(transfer_id),))
            wire = WireFrame(message_id(priority, spec.type_id, self.node_id), data, due)
        else:
            wire = encode(spec, fields, kind=kind, source=self.node_id, destination=destination,
                          transfer_id=transfer_id, priority=priority, layout=layout, timestamp=due)
        if self.faults & _TAIL_FAULTS:
            wire = self._mangle_tail(wire, spec)
        if id_or:
            wire = wire._replace(arbitration_id=wire.arbitration_id | id_or)
        self._push(due, wire)

    def _push(self, due: float, wire: WireFrame) -> None:
        self._seq += 1
        heapq.heappush(self._outbox, (due, self._seq, wire))

    def _mangle_tail(self, wire: WireFrame, spec) -> WireFrame:
        if not spec.has_tail:
            return wire
        data = bytearray(wire.data)
        if "tail_toggle_set" in self.faults:
            data[-1] |= 0x20
        if "tail_not_single_frame" in self.faults:
            data[-1] &= ~0x40 & 0xFF
        return wire._replace(data=bytes(data))

    def _respond(self, req: Frame, now: float, fields: dict, *, layout: str | None = None) -> None:
        spec = req.spec
        assert spec is not None
        priority = spec.priority if spec.priority is not None else _UNLISTED_PRIORITY.get(
            self.config.unlisted_priority, req.priority)  # F5: 240..242 list none
        if "response_wrong_priority" in self.faults:
            priority = Priority.LOWEST if priority != Priority.LOWEST else Priority.MEDIUM
        tid = req.transfer_id or 0
        if "response_transfer_id_wrong" in self.faults:
            tid = (tid + 1) % 32
        destination = 127 if "response_to_broadcast" in self.faults else req.source
        request_bit = 0x8000 if "response_as_request" in self.faults else 0
        self._emit(now + self.config.service_delay, spec.name, fields, kind=Kind.RESPONSE, destination=destination,
                   transfer_id=tid, priority=priority, layout=layout, id_or=request_bit)

    def _respond_rejected(self, req: Frame, now: float, current: dict) -> None:
        """The answer to a request that changed nothing (an illegal value, or refused: R10-R12 leave open
        whether, and with what, it is answered): the current values, none, or the request's values echoed."""
        how = self.config.rejected_answer
        if how == "current":
            self._respond(req, now, current)
        elif how == "echo":
            self._respond(req, now, {k: req.fields.get(k, v) for k, v in current.items()})

    def _answer_delay(self) -> float:
        if "answer_late" in self.faults:
            return 0.080
        if "answer_not_staggered" in self.faults:
            return 0.010
        if "answer_at_once" in self.faults:
            return 0.001
        start = (self.node_id % 32) * ANSWER_SLOT_S  # R2
        if self.config.answer_place == "start":
            return start
        # the latest start that still ends inside the slot with one longest frame on the bus ahead of it (the
        # answer frames are shorter than 8 data bytes); at a slow bit rate that may be the slot's start
        room = max(ANSWER_SLOT_S - 2 * frame_bits(8) / self.bitrate, 0.0)
        if self.config.answer_place == "late":
            return start + room
        return start + self._rng.uniform(0.0, room)

    # ------------------------------------------------------------------------------------------
    # physics and timers

    def _update(self, now: float) -> None:
        dt = now - self._last_update
        if dt <= 0:
            # no time passed, but a deadline may have come due without it (Throttle Select back to CAN
            # long after the last command): without this the comm-loss deadline stays in the past and
            # the lane polls at the same instant for ever
            self._refresh_throttle(now)
            return
        self._last_update = now
        self._refresh_throttle(now)
        target = self.throttle / THROTTLE_MAX * self.config.max_rpm
        self.rpm += (target - self.rpm) * (1 - math.exp(-dt / self.config.motor_tau))
        if target == 0 and self.rpm < 1:
            self.rpm = 0.0
        load = self.rpm / self.config.max_rpm
        self.current = 80.0 * load**3
        thermal_dt = now - self._last_thermal
        if thermal_dt >= 0.05:  # temperatures move in seconds: a coarser step costs less
            self._last_thermal = now
            for name, tau, gain, ambient in _THERMAL:
                goal = ambient + gain * load**2
                self.temps[name] += (goal - self.temps[name]) * (1 - math.exp(-thermal_dt / tau))
            self._record_temperatures()
        running = self.rpm >= 1 or self.throttle > 0
        if running:
            self.run_time += dt
            self.nvm["total_run_time"] += dt
        if running != self.running:
            self.running = running
            key = "starts" if running else "stops"
            self.nvm[key] = (self.nvm[key] + 1) & 0xFFFF
            self.nvm_dirty = True

    def _record_temperatures(self) -> None:
        for sensor in _RECORD_SENSORS:
            t = self._whole(self.temps[sensor])
            rec = self.nvm["records"][sensor]
            if t > rec["t_max"]:
                rec.update(t_max=min(t, 255), times=self.nvm["starts"], time=self._whole(self.nvm["total_run_time"]))
                self.nvm_dirty = True

    def _active_source_is_pwm(self) -> bool:
        return self.nvm["throttle_source"] == 1 and self.pwm_input is not None

    def _refresh_throttle(self, now: float) -> None:
        if self._active_source_is_pwm():
            self.throttle = min(max(self.pwm_input or 0, 0), THROTTLE_MAX)
            self.comm_fault = False
            self._pwm_seen = True
            return
        if self._comm_loss_due(now):
            self.comm_fault = True
            self.can_throttle = 0  # lost-signal protection: throttle to zero
        self.throttle = self.can_throttle
        if "pwm_no_fallback" in self.faults and self._pwm_seen and self.nvm["throttle_source"] == 1:
            self.throttle = 0  # the lost PWM signal is not replaced by the CAN throttle

    def _comm_loss_timeout(self) -> float | None:
        if "comm_loss_never" in self.faults:
            return None
        if "comm_loss_late" in self.faults:
            return 0.400
        if "comm_loss_early" in self.faults:
            return 0.100
        return COMM_LOSS_TIMEOUT_S

    def _comm_loss_deadline(self) -> float | None:
        if self.comm_fault or self._active_source_is_pwm():
            return None
        timeout = self._comm_loss_timeout()
        if timeout is None:
            return None
        since = self.last_command if self.last_command is not None else self.ready_at
        deadline = since + timeout
        check = self.config.comm_loss_check
        if check == "timer" or not self._reports_active() or "msg1" not in self._next_report:
            return deadline
        # checked on MSG1's grid (each MSG1 due) or on the report timer's 2 ms tick through it: the first
        # point of it at or after the deadline
        period = self._interval("msg1") if check == "msg1" else INTERVAL_UNIT_S
        grid = self._next_report["msg1"]
        if period <= 0:
            return deadline
        if check == "msg1" and self._offset:  # checked when the jittered MSG1 goes out (exactly then: no rounding)
            grid = self._jittered("msg1")
            return grid + max(0, math.ceil(round((deadline - grid) / period, 9))) * period
        return round(grid + math.ceil(round((deadline - grid) / period, 9)) * period, 9)

    def _comm_loss_due(self, now: float) -> bool:
        deadline = self._comm_loss_deadline()
        return deadline is not None and now >= deadline

    def _reports_active(self) -> bool:
        if self.can_test and "can_test_reports_continue" not in self.faults:
            return False
        if self.node_id == DEFAULT_ESC_NODE_ID and "reports_at_default_id" not in self.faults:
            return False  # F7: silent at 0x7D
        return self.reporting != SUSPENDED

    def _interval(self, which: str) -> float:
        n = self.nvm[f"{which}_interval"]
        if which == "msg2" and "msg2_interval_ignores_setting" in self.faults:
            n = cat.DEFAULT_REPORT_INTERVALS["msg2_interval"]
        unit = 0.003 if which == "msg1" and "report_interval_wrong" in self.faults else INTERVAL_UNIT_S
        period = n * unit
        if "report_jitter" in self.faults:
            period *= 1 + self._rng.uniform(-0.3, 0.3)
        return period

    def _restart_reports(self, now: float) -> None:
        """Reporting comes back (a resume, leaving CAN Test or MSG_EXP mode; R9a: the first report of each type
        within one interval plus a slack), as ``report_timer`` says: the first report at once, then every interval
        from it ("restart") or on the grid the timer kept ("grid"); the first at the kept grid's next point
        ("next_tick"); or one full interval after the event ("one_interval"). With the fault 'report_restart_late',
        one and a half intervals after the event."""
        self._regrid = {}
        self._report_floor = now
        timer = self.config.report_timer
        for k, due in self._next_report.items():
            period = self._interval(k)
            if "report_restart_late" in self.faults:
                self._next_report[k] = round(now + 1.5 * period, 9)
            elif timer == "one_interval":
                self._next_report[k] = round(now + period, 9)
            elif timer in ("grid", "next_tick") and period > 0:
                due = self._grid_point(due, now, period)
                self._next_report[k] = now if timer == "grid" else due
                if timer == "grid" and due > now:
                    self._regrid[k] = due
            else:
                self._next_report[k] = now

    @staticmethod
    def _grid_point(due: float, now: float, period: float) -> float:
        """The next point at or after ``now`` of the grid through ``due`` with spacing ``period``."""
        if due >= now:
            return due
        return round(due + math.ceil(round((now - due) / period, 9)) * period, 9)

    def _jittered(self, which: str) -> float:
        """When ``which`` goes out next with jitter: its grid point plus its offset, never before the event that set
        its timer nor before its own previous report (a report the old grid brings close behind one sent at once)."""
        return max(self._next_report[which] + self._offset[which], self._report_floor,
                   self._last_jittered.get(which, -math.inf))

    def _jitter(self) -> float:
        """A report's offset from its grid point (report_jitter_s: within +- half of it)."""
        half = self.config.report_jitter_s / 2
        return self._rng.uniform(-half, half)

    def _next_report_times(self) -> list[float]:
        if self._offset:
            return [self._jittered(k) for k in self._next_report]
        return list(self._next_report.values())

    def _schedule_reports(self, now: float) -> None:
        if self.can_test:
            while self._next_can_test <= now:
                self._emit_can_test(self._next_can_test)
                self._next_can_test = round(self._next_can_test + self._interval("msg1"), 9)
        if not self._reports_active():
            self._reports_were_active = False
            return
        if not self._reports_were_active:  # leaving 0x7D, suspension or CAN Test: start afresh, no catch-up burst
            self._reports_were_active = True
            for k in self._next_report:  # (a resume or CAN Test off has set it already: _restart_reports)
                if self._next_report[k] < now:
                    self._next_report[k] = self._report_floor = now
        offset = self._offset
        for which in _REPORT_NAMES:
            while (grid := self._next_report[which]) + (offset[which] if offset else 0.0) <= now:
                if offset:  # jitter: off the grid point by its offset (see _jittered)
                    self._emit_report(which, due := self._jittered(which))
                    self._last_jittered[which] = due
                    offset[which] = self._jitter()
                else:
                    self._emit_report(which, grid)
                self._next_report[which] = self._regrid.pop(which, None) or round(grid + self._interval(which), 9)  # no float drift

    # ------------------------------------------------------------------------------------------
    # reports

    def status_word(self) -> int:
        """MSG1 status (R7), with plain ints: IntFlag arithmetic is slow on this hot path."""
        s = _FAULT_BITS.get(self.self_test_fault, 0)
        if self.nvm["rotation"]:
            s |= _PWM if "status_direction_bit14" in self.faults else _CCW
        if self._active_source_is_pwm() and "status_direction_bit14" not in self.faults:
            s |= _PWM
        if self.comm_fault:
            s |= _COMM_FAULT
        if self.running and "status_running_wrong" not in self.faults:
            s |= _RUNNING
        return s

    def _emit_report(self, which: str, due: float) -> None:
        prio = Priority.MEDIUM if "wrong_priority" in self.faults else None
        if self.reporting == EXP_MODE:
            self._emit_exp(which, due)
            return
        if which == "msg1":
            pwm = 0 if "speed_ignores_throttle" in self.faults else self.throttle
            fields = {"speed": int(self.rpm), "pwm": pwm, "status": self.status_word()}
        elif which == "msg2":
            volts, amps = self._electrical()
            scale = 10 if "msg2_scale_tenths" in self.faults else 100
            fine, whole = self._fine, self._whole
            fields = {"voltage": fine(volts * scale), "current": fine(amps * scale), "temperature": whole(self.temps["mos"])}
        if which in ("msg1", "msg2"):
            if "reports_padded" in self.faults:  # the payload zero-padded to 7 bytes: a full 8-byte frame
                spec = cat.BY_NAME[which]
                self._emit_raw(due, spec.type_id, codec_for(spec.layouts[0]).encode(fields).ljust(7, b"\0"), prio or Priority.LOWEST)
            else:
                self._emit(due, which, fields, priority=prio)
        else:
            whole = self._whole
            fields = {"mos_t": whole(self.temps["mos"]), "cap_t": whole(self.temps["cap"]),
                      "motor_t": whole(self.temps["motor"]) if self.config.has_motor_sensor else 0,
                      "mcu_t": whole(self.temps["mcu"])}
            if "msg3_short" in self.faults:
                self._emit_raw(due, 20052, bytes([fields["mos_t"], fields["cap_t"], fields["motor_t"]]), prio or Priority.LOWEST)
                return
            self._emit(due, "msg3", fields, priority=prio)

    def _emit_raw(self, due: float, type_id: int, payload: bytes, priority: int) -> None:
        """A frame the catalogue's layouts cannot express (the faults that send wrong lengths)."""
        tid = self._tids.next(f"raw{type_id}")
        self._push(due, WireFrame(message_id(priority, type_id, self.node_id), payload + bytes([tail_byte(tid)]), due))

    def _electrical(self) -> tuple[float, float]:
        sag = 0.02 * self.current
        noise = self._rng.uniform(-0.02, 0.02)
        return max(self.config.supply_voltage - sag + noise, 0.0), max(self.current + (noise if self.current else 0), 0.0)

    def _emit_exp(self, which: str, due: float) -> None:
        """MSG_EXP mode (R9: which frames and how often is OBSERVE): EXP1 at MSG1's interval,
        EXP7..EXP11 at MSG3's (or all at MSG2's, or one of the two only: exp_frames)."""
        plays = self.config.exp_frames
        if which == ("msg2" if plays == "msg2" else "msg1") and plays != "no_exp1":
            volts, amps = self._electrical()
            scale = 10 if "exp1_scale_tenths" in self.faults else 100
            self._emit(due, "msg_exp1", {"speed": int(self.rpm), "voltage": self._fine(volts * scale),
                                         "current": self._fine(amps * scale)})
        if which == ("msg2" if plays == "msg2" else "msg3") and plays != "exp1_only":
            for name, fields in self.exp_frames():
                self._emit(due, name, fields)
            if "debug_frames_reserved_source" in self.faults:  # F7: a debug frame from a hard-coded node id
                spec = cat.BY_NAME["msg_exp2"]
                data = bytes(spec.layouts[0].size) + bytes((tail_byte(self._tids.next(spec.name)),))
                self._push(due, WireFrame(message_id(spec.priority, spec.type_id, 0x7F), data, due))

    def exp_frames(self) -> list[tuple[str, dict]]:
        n = self.nvm
        led_code = {0: 0, 4: 1, 2: 2, 1: 3}.get(self.led_color, 0)
        direction = (2 if n["rotation"] else 1) - ("exp7_direction_zero_based" in self.faults)
        power_ups = (n["power_ups"] - ("exp8_power_ups_from_zero" in self.faults)) & 0xFFFF
        unit = 1000 if "exp_run_times_ms" in self.faults else 1  # seconds, or milliseconds
        whole = self._whole
        temps = {k: whole(v) for k, v in self.temps.items()}
        if not self.config.has_motor_sensor:
            temps["motor"] = 0
        exp11 = (temps["mos"], temps["mcu"], temps["cap"], temps["motor"])
        if "exp11_msg3_order" in self.faults:
            exp11 = (temps["mos"], temps["cap"], temps["motor"], temps["mcu"])
        return [
            ("msg_exp7", {"direction": direction, "led": led_code,
                          "comm_interface": 2 if n["throttle_source"] else 3, "active_freewheel": n["active_freewheel"],
                          "prop_lock": n["prop_lock"], "startup_acceleration": n["startup_acceleration"],
                          "lost_signal_protection": n["lost_signal_reduction"]}),
            ("msg_exp8", {"power_ups": power_ups, "starts": n["starts"], "stops": n["stops"]}),
            ("msg_exp9", {"total_run_time": whole(n["total_run_time"] * unit) & 0xFFFFFFFF,
                          "fault_code_1": self.self_test_fault}),
            ("msg_exp10", {"run_time": whole(self.run_time * unit) & 0xFFFFFFFF, "fault_code_2": 0}),
            ("msg_exp11", dict(zip(("mos_t", "mcu_t", "cap_t", "motor_t"), exp11))),
        ]

    def _emit_can_test(self, due: float) -> None:
        self._emit(due, "can_test", {"option": 0x00, "count": self.can_test_count})
        step = 2 if "can_test_count_skips" in self.faults else 1
        self.can_test_count = (self.can_test_count + step) & 0xFFFFFFFF

    # ------------------------------------------------------------------------------------------
    # broadcast commands

    def _on_can_test(self, f: Frame, now: float) -> None:
        option = f.fields["option"]
        if option == CAN_TEST_ON and not self.can_test:
            self.can_test = True
            if self.config.can_test_count == "zero_each_session":
                self.can_test_count = 0
            self._next_can_test = now
        elif option == CAN_TEST_OFF and self.can_test and "can_test_off_ignored" not in self.faults:
            self.can_test = False  # R16: back to the state before; reporting state was kept
            if "can_test_off_resumes_reporting" in self.faults:
                self.reporting = REPORTING
            self._restart_reports(now)

    def _on_msg_control(self, f: Frame, now: float) -> None:
        if f.fields["option"] != 0:
            self.counters["rx_ignored"] += 1
            return
        command = f.fields["command"]
        was = self.reporting
        if command == MSG_CONTROL_SUSPEND and "suspend_ignored" not in self.faults:
            self.reporting = SUSPENDED
        elif command == MSG_CONTROL_RESUME and "resume_ignored" not in self.faults:
            self.reporting = REPORTING
        elif command == MSG_CONTROL_RESUME_EXP:
            if "resume_exp_ignored" not in self.faults:
                self.reporting = EXP_MODE
        elif command not in (MSG_CONTROL_SUSPEND, MSG_CONTROL_RESUME):
            self.counters["rx_ignored"] += 1
            return  # the answer packet (0) or an unknown command: nothing to do
        if was == SUSPENDED and self.reporting != SUSPENDED:
            self._restart_reports(now)  # "immediate recovery"
        elif was == EXP_MODE and self.reporting == REPORTING:
            self._restart_reports(now)  # leaving MSG_EXP mode: reporting comes back as after a resume (R9a)
        if "msg_control_no_answer" in self.faults:
            return
        answer = command if "msg_control_answer_echo" in self.faults else cat.MSG_CONTROL_ANSWER
        self._emit(now + self._answer_delay(), "msg_control", {"option": 0, "command": answer})

    def _on_get_esc_id(self, f: Frame, now: float) -> None:
        if f.layout is None or f.layout.name != "query" or f.fields["option"] != 0:
            self.counters["rx_ignored"] += 1  # a reply from another ESC, or an unknown option
            return
        due = now + self._answer_delay()
        node = self.node_id + 1 if "get_esc_id_wrong_node" in self.faults else self.node_id
        channel = self.nvm["throttle_channel"]
        if "get_esc_id_with_option" in self.faults:
            self._emit_raw(due, 20013, bytes([0, node, channel]), Priority.MEDIUM)
            return
        self._emit(due, "get_esc_id", {"node_id": node, "throttle_channel": channel}, layout="reply")

    def _over_max(self, maximum: int) -> int:
        """R6 (OBSERVE): a throttle above its maximum clamped, taken as zero, or (-1) ignored for the held one."""
        how = self.config.over_max_throttle
        return maximum if how == "clamp" else 0 if how == "zero" else -1

    def throttle_keys(self) -> set[tuple[str, int | None]] | None:
        """The throttle frames this ESC can be addressed by, as (frame name, 12-bit group or None);
        None: all of them (a fault changes how it reads them). Lets a bench route throttle frames
        to the ESCs they concern; must agree with :meth:`_on_throttle`."""
        if self.faults & _THROTTLE_READ_FAULTS:
            return None
        ch = self.nvm["throttle_channel"]
        keys: set[tuple[str, int | None]] = {("raw_command_12b", (ch + 3) // 4)}
        if 1 <= ch <= 4:
            keys.add(("raw_command_14b", None))
        if 1 <= ch <= 6:
            keys.add(("raw_command_10b", None))
        return keys

    def _on_throttle(self, f: Frame, now: float) -> None:
        channel = 1 if "throttle_channel_ignored" in self.faults else self.nvm["throttle_channel"]
        name = f.name
        value: int | None = None
        if name == "raw_command_14b":
            channels = f.fields["channels"]
            if "fourteen_bit_byte_order" in self.faults:
                v = int.from_bytes(f.data[:7], "little")
                channels = [(v >> (14 * i)) & 0x3FFF for i in range(4)]
            if 1 <= channel <= 4:
                value = channels[channel - 1]
        elif name == "raw_command_12b":
            channels, group = f.fields["channels"], f.fields["group"]
            if "twelve_bit_nibbles_swapped" in self.faults:
                channels, group = unpack_throttle12(f.data[:7], nibble_order="swapped")
            if "twelve_bit_group_ignored" in self.faults:
                value = channels[(channel - 1) % 4]
            elif 4 * group - 3 <= channel <= 4 * group:
                value = channels[channel - 4 * group + 3]
        else:  # raw_command_10b
            if "ten_bit_tail_checked" in self.faults and f.fields["tail_bits"] != TAIL_BITS_10B:
                return False  # the high nibble of payload[7] read as a tail byte, and this one refused
            if 1 <= channel <= 6:
                raw = f.fields["channels"][channel - 1]
                if raw > THROTTLE_10B_MAX:
                    raw = self._over_max(THROTTLE_10B_MAX)
                value = raw if "ten_bit_not_doubled" in self.faults or raw < 0 else raw * 2
        if value is None:
            return False  # not addressed to this ESC's channel: not a command for it
        if value > THROTTLE_MAX:
            value = self._over_max(THROTTLE_MAX)
        if value < 0:  # over_max_throttle "hold": the frame's value ignored, the command still heard
            value = self.can_throttle
        answered = "throttle_answered" in self.faults
        if answered:  # the broadcast taken for a request: a report at once, as its answer
            self._emit_report("msg1", now + self.config.service_delay)
        if value == self.can_throttle and not self.comm_fault:
            # the same command again: only the comm-loss deadline moves, and later, so nothing is due
            # earlier than before; the motor's first-order lag integrates exactly over the longer step
            self.last_command = now
            return answered  # an answer was queued: the ESC's next deadline moved
        self._update(now)
        self.can_throttle = value  # R6: above 2000 is OBSERVE (over_max_throttle)
        self.last_command = now
        if self.comm_fault and "comm_loss_sticky" not in self.faults:
            self.comm_fault = False
        self._refresh_throttle(now)

    # ------------------------------------------------------------------------------------------
    # services

    def _addressed(self, f: Frame) -> bool:
        return f.destination == self.node_id

    def _settings_locked(self) -> bool:
        """R12: parameter changes do not take effect while reporting is suspended."""
        return self.reporting == SUSPENDED and "settings_while_suspended" not in self.faults

    def _motor_busy(self) -> bool:
        return (self.running or self.throttle > 0) and "rotation_while_running" not in self.faults

    def _in_window(self, now: float, fault: str) -> bool:
        window = CONFIG_WINDOW_S / 2 if "config_window_short" in self.faults else CONFIG_WINDOW_S
        return now - self.powered_at <= window or fault in self.faults

    def _set_nvm(self, **values: Any) -> None:
        self.nvm.update(values)
        self.nvm_dirty = True

    def _on_set_id(self, f: Frame, now: float) -> None:
        if "set_id_needs_destination" in self.faults and not self._addressed(f):
            return
        node, channel = f.fields["node_id"], f.fields["throttle_channel"]
        legal = 1 <= node <= 0x7D or ("set_id_accepts_illegal" in self.faults and node <= 0x7F)
        legal = legal and 1 <= channel <= 20
        current = {"node_id": self.node_id, "throttle_channel": self.nvm["throttle_channel"]}
        if not (legal and self._in_window(now, "set_id_after_window") and not self._settings_locked()):
            self._respond_rejected(f, now, current)
            return
        if "set_id_channel_ignored" in self.faults:
            channel = self.nvm["throttle_channel"]
        self._set_nvm(node_id=node, throttle_channel=channel)
        self._respond(f, now, {"node_id": self.node_id, "throttle_channel": self.nvm["throttle_channel"]})

    def _on_set_baud(self, f: Frame, now: float) -> None:
        if not self._addressed(f):
            return
        code = f.fields["baud"]
        legal = code in BAUD_RATES or "set_baud_accepts_illegal" in self.faults
        if not (legal and self._in_window(now, "set_baud_after_window") and not self._settings_locked()):
            self._respond_rejected(f, now, {"baud": self.nvm["baud"]})
            return
        self._set_nvm(baud=code)
        if "set_baud_immediate" in self.faults:
            self.bitrate = BAUD_RATES.get(code, self.bitrate)
        self._respond(f, now, {"baud": self.nvm["baud"]})

    def _on_set_led(self, f: Frame, now: float) -> None:
        if not self._addressed(f):
            return
        option, color, blink = f.fields["option"], f.fields["color"], f.fields["blink"]
        no_operation = blink not in cat.LED_BLINK and self.config.led_blink_other == "no_operation"
        if self.config.has_led and option in (0, 1) and not self._settings_locked() and not no_operation:
            color &= 0x07  # "the lower three bits of Color are valid"
            blink = blink if blink in cat.LED_BLINK else 0  # "other: no operation is performed, no blinking"
            self.led_color, self.led_blink = color, blink
            if option == 1 or "led_unsaved_persisted" in self.faults:
                self._set_nvm(led_color=color, led_blink=blink)
        if "set_led_no_echo" in self.faults:
            self._respond(f, now, {"option": 0, "color": 0, "blink": 0})
            return
        self._respond(f, now, {"option": option, "color": self.led_color, "blink": self.led_blink})

    def _on_set_rotation(self, f: Frame, now: float) -> None:
        if not self._addressed(f):
            return
        rotation = f.fields["rotation"]
        if rotation != 0xFF and not self._settings_locked() and not self._motor_busy():
            if rotation in (0, 1):
                if "rotation_ignored" not in self.faults:
                    self._set_nvm(rotation=rotation)
            elif "rotation_accepts_illegal" in self.faults:
                self._set_nvm(rotation=1)
            else:
                self._respond_rejected(f, now, {"rotation": self.nvm["rotation"]})
                return
        elif rotation != 0xFF:
            self._respond_rejected(f, now, {"rotation": self.nvm["rotation"]})
            return
        self._respond(f, now, {"rotation": self.nvm["rotation"]})

    def _on_set_freq(self, f: Frame, now: float) -> None:
        if not self._addressed(f):
            return
        names = ("msg1_interval", "msg2_interval", "msg3_interval")
        lo, hi = cat.REPORT_INTERVAL_RANGE
        applied = f.fields["option"] != 1
        if f.fields["option"] == 1 and not self._settings_locked():
            values = {k: f.fields[k] for k in names}
            legal = {k: v for k, v in values.items() if lo <= v <= hi}
            if "set_freq_accepts_illegal" in self.faults:
                legal = {k: v for k, v in values.items() if v > 0}
            if len(legal) == 3 or ("set_freq_partial" in self.faults and legal):
                applied = True
                old = {k: self.nvm[k] for k in names}
                self._set_nvm(**legal)
                for which in _REPORT_NAMES:
                    key = f"{which}_interval"
                    if key in legal and legal[key] != old[key]:
                        self._next_report[which] = self._set_freq_next(which, now, old[key] * INTERVAL_UNIT_S)
        current = {k: self.nvm[k] for k in names}
        if "set_freq_read_wrong" in self.faults and f.fields["option"] == 0:
            current = dict(cat.DEFAULT_REPORT_INTERVALS)
        if not applied:
            self._respond_rejected(f, now, {"option": f.fields["option"], **current})
            return
        self._respond(f, now, {"option": f.fields["option"], **current})

    def _set_freq_next(self, which: str, now: float, old: float) -> float:
        """When ``which`` reports next after a Set Freq write changed its interval from ``old`` seconds (R9a:
        within the longer of the old and new interval plus a slack), as ``set_freq_timer`` says; with the fault
        'report_restart_late', one and a half of the longer interval after the write."""
        self._regrid.pop(which, None)
        self._report_floor = now
        scheduled = self._next_report.get(which, now)  # the report already due on the old interval
        new = self._interval(which)
        if "report_restart_late" in self.faults:
            return round(now + 1.5 * max(old, new), 9)
        timer = self.config.set_freq_timer
        if timer == "old_deadline":
            return max(scheduled, now)
        if timer == "restart":
            return round(now + new, 9)
        if timer == "at_once":
            return now
        return max(now, round(scheduled - old + new, 9))  # "last_report": the new interval from the last report

    def _on_throttle_select(self, f: Frame, now: float) -> None:
        if not self._addressed(f):
            return
        source = f.fields["source"]
        legal = source in (0, 1) or "throttle_select_accepts_illegal" in self.faults
        if not (legal and not self._settings_locked() and not self._motor_busy()):
            self._respond_rejected(f, now, {"source": self.nvm["throttle_source"]})
            return
        if "throttle_select_ignored" not in self.faults:
            self._set_nvm(throttle_source=source)
        self._respond(f, now, {"source": self.nvm["throttle_source"]})

    def _on_self_test(self, f: Frame, now: float) -> None:
        if not self._addressed(f) or "self_test_unanswered" in self.faults:
            return
        failed = self.self_test_fault != 0 and "self_test_always_passes" not in self.faults
        if "self_test_inverted" in self.faults:
            failed = not failed
        self._respond(f, now, {"status": int(failed)})

    def _on_expand_set(self, f: Frame, now: float) -> None:
        if not self._addressed(f) or "expand_set_part_absent" in self.faults:
            return
        code, part = f.fields["set_cmd"], f.fields["part"]
        if "expand_set_big_endian" in self.faults:
            code = int.from_bytes(f.data[:2], "big")
        if "expand_set_answered" in self.faults:  # the catalogue has no response layout (R14): echo the request
            self._echo_request(f, now)
        command = EXPAND_COMMANDS.get(code)
        if command is None or part not in command.parts or command.reserved:
            self.counters["rx_ignored"] += 1
            return
        if command.name == "read_temperature_records":
            self._send_records(now)
            return
        if command.name == "maintenance":
            self.test_mode = part == 0x11 if part in (0x10, 0x11) else self.test_mode
            return
        if self._settings_locked() or self._motor_busy():
            return  # 4.4.25 clarification 1: motor stopped; R12
        n = command.name
        if n == "direction":
            self._set_nvm(rotation=part - 1)
        elif n == "led":
            self.led_color = {0: 0, 1: 4, 2: 2, 3: 1}[part]
            self._set_nvm(led_color=self.led_color)
        elif n == "control_mode":
            if part in (2, 5):
                self._set_nvm(throttle_source=1)
            elif part in (3, 6):
                self._set_nvm(throttle_source=0)
        elif n == "active_freewheel":
            self._set_nvm(active_freewheel=part)
        elif n == "prop_lock":
            self._set_nvm(prop_lock=part)
        elif n == "startup_acceleration":
            self._set_nvm(startup_acceleration=part)
        elif n == "lost_signal_reduction":
            self._set_nvm(lost_signal_reduction=part)
        elif n == "baud":
            self._set_nvm(baud=part)

    def _send_records(self, now: float) -> None:
        if "get_rec_absent" in self.faults:
            return
        due = now + self.config.service_delay
        for index, sensor in enumerate(_RECORD_SENSORS, start=1):
            rec = self.nvm["records"][sensor]
            tag = 0 if "get_rec_untagged" in self.faults else index
            self._emit(due, "msg_exp12", {"t_max": rec["t_max"], "times": rec["times"] & 0xFFFF,
                                          "time": rec["time"] & 0xFFFFFFFF}, transfer_id=tag)

    def _echo_request(self, f: Frame, now: float) -> None:
        """A service answer repeating the request's payload (for requests the catalogue gives no answer)."""
        can_id = service_id(int(f.spec.priority), f.type_id, False, f.source, self.node_id)  # type: ignore[union-attr, arg-type]
        self._push(now + self.config.service_delay, WireFrame(can_id, f.data))

    def _on_get_rec(self, f: Frame, now: float) -> None:
        if self._addressed(f):
            if self.config.rec_answer == "echo" and "get_rec_absent" not in self.faults:
                self._echo_request(f, now)
            self._send_records(now)

    def _on_clear_rec(self, f: Frame, now: float) -> None:
        if self._addressed(f) and not {"clear_rec_ignored", "get_rec_absent"} & self.faults:
            if self.config.rec_answer == "echo":
                self._echo_request(f, now)
            self._set_nvm(records={s: {"t_max": 0, "times": 0, "time": 0} for s in _RECORD_SENSORS})

    def _on_esc_information(self, f: Frame, now: float) -> None:
        if not self._addressed(f):
            return
        c = self.config
        year, month, day = c.firmware_date
        if "esc_information_bcd_date" in self.faults:  # October -> 0x10 = 16
            year, month, day = (int(str(v), 16) for v in (year, month, day))
        self._respond(f, now, {"max_cells": c.max_cells, "max_current": c.max_current_10a,
                               "hardware_version": c.hardware_version, "protocol_version": c.protocol_version,
                               "firmware_year": year, "firmware_month": month, "firmware_day": day})

    def _on_maintenance(self, f: Frame, now: float) -> None:
        if not self._addressed(f):
            return
        option, n = f.fields["option"], self.nvm
        if option == 0:
            fields = {"total_run_time": self._whole(n["total_run_time"]), "mos_t_max": n["records"]["mos"]["t_max"],
                      "cap_t_max": n["records"]["cap"]["t_max"], "info_7": 0}
        elif option == 1:
            fields = {"run_time": self._whole(self.run_time), "runs": n["starts"], "info_7": 1}
        elif option == 2:
            ups, stops = n["power_ups"], n["stops"]
            if "maintenance_counts_wrong" in self.faults:
                ups, stops = stops, ups
            fields = {"power_ups": ups, "stops": stops, "fault_code": self.self_test_fault, "option": 2}
        else:
            self.counters["rx_ignored"] += 1
            return
        self._respond(f, now, fields, layout=f"response_option_{option}")
        if "maintenance_info_7_missing" in self.faults:  # drop Info_7 from the answer just queued
            for i, (due, seq, wire) in enumerate(self._outbox):
                if seq == self._seq:
                    self._outbox[i] = (due, seq, wire._replace(data=wire.data[:6] + wire.data[7:]))

    def _dronecan_node_info(self, msg: Any, now: float) -> bool:
        """Fault 'dronecan_node_info': answer DroneCAN GetNodeInfo (service 1), announcing a
        NodeStatus (message 341) first: ids outside the CKESC vendor ranges (4.3.1)."""
        can_id, data = msg.arbitration_id, bytes(msg.data)
        if not (can_id & 0x8080 == 0x8080 and (can_id >> 16) & 0xFF == 1 and (can_id >> 8) & 0x7F == self.node_id):
            return False
        due = now + self.config.service_delay
        status = bytes(7) + bytes((tail_byte(self._tids.next("dronecan341")),))
        self._push(due, WireFrame(message_id(Priority.LOW, 341, self.node_id), status, due))
        answer = bytes(7) + bytes((tail_byte(data[-1] & 0x1F if data else 0),))
        self._push(due, WireFrame(service_id(Priority.LOW, 1, False, can_id & 0x7F, self.node_id), answer, due))
        return True

    def _on_major_config(self, f: Frame, now: float) -> None:
        if not self._addressed(f) or (f.fields.get("option") and self.config.major_config_option == "ignore"):
            return
        n = self.nvm
        direction, source = n["rotation"], n["throttle_source"]
        if "major_config_bits_swapped" in self.faults:
            direction, source = source, direction
        # one-bit fields: a value stored by throttle_select_accepts_illegal (2, 255) must not crash the model
        self._respond(f, now, {"direction": direction & 1, "throttle_source": source & 1,
                               "throttle_channel": n["throttle_channel"] & 0x3F, "led_blink": self.led_blink & 0x1F,
                               "led_color": self.led_color & 0x07, "msg1_interval": n["msg1_interval"],
                               "msg2_interval": n["msg2_interval"], "msg3_interval": n["msg3_interval"]})


#: unlisted_priority (F5-unlisted): the priority of 240/241/242 answers; "request" keeps the request's
_UNLISTED_PRIORITY = {"medium": Priority.MEDIUM, "low": Priority.LOW, "lowest": Priority.LOWEST}

_TAIL_FAULTS = frozenset({"tail_toggle_set", "tail_not_single_frame"})

#: Faults that change which throttle frames address an ESC (see EscModel.throttle_keys).
_THROTTLE_READ_FAULTS = frozenset({"throttle_channel_ignored", "twelve_bit_nibbles_swapped", "twelve_bit_group_ignored",
                                   "fourteen_bit_byte_order"})

#: What an ESC acts on; everything else on the bus is counted and ignored.
_HANDLERS = {
    (Kind.MESSAGE, "can_test"): EscModel._on_can_test,
    (Kind.MESSAGE, "msg_control"): EscModel._on_msg_control,
    (Kind.MESSAGE, "get_esc_id"): EscModel._on_get_esc_id,
    (Kind.MESSAGE, "raw_command_14b"): EscModel._on_throttle,
    (Kind.MESSAGE, "raw_command_12b"): EscModel._on_throttle,
    (Kind.MESSAGE, "raw_command_10b"): EscModel._on_throttle,
    (Kind.REQUEST, "set_id"): EscModel._on_set_id,
    (Kind.REQUEST, "set_baud"): EscModel._on_set_baud,
    (Kind.REQUEST, "set_led"): EscModel._on_set_led,
    (Kind.REQUEST, "set_rotation"): EscModel._on_set_rotation,
    (Kind.REQUEST, "set_freq"): EscModel._on_set_freq,
    (Kind.REQUEST, "throttle_select"): EscModel._on_throttle_select,
    (Kind.REQUEST, "self_test"): EscModel._on_self_test,
    (Kind.REQUEST, "expand_set_part"): EscModel._on_expand_set,
    (Kind.REQUEST, "get_rec"): EscModel._on_get_rec,
    (Kind.REQUEST, "clear_rec"): EscModel._on_clear_rec,
    (Kind.REQUEST, "esc_information"): EscModel._on_esc_information,
    (Kind.REQUEST, "maintenance_information"): EscModel._on_maintenance,
    (Kind.REQUEST, "get_major_configuration"): EscModel._on_major_config,
}

THROTTLE_FRAMES = frozenset({"raw_command_14b", "raw_command_12b", "raw_command_10b"})
HANDLED = frozenset(_HANDLERS)
