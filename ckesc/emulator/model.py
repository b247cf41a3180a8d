"""The CKESC 2.1 ESC behaviour model: frames and a time in, frames and the next deadline out.

No sockets, threads, sleeps or clocks: the simulated-time bus and the real-time process drive the
same :class:`EscModel`. One model is one ESC; several share a bus in an :class:`~.emulated_bench.EmulatedBench`.

    esc = EscModel(EscConfig(slot=0), nvm=None)     # nvm: what was in flash, or None for factory state
    esc.power_on(now=0.0)
    esc.receive(wire_frame, now)                    # a frame heard on the bus (already at the ESC's bitrate)
    out = esc.poll(now)                             # frames due at or before now, timestamped with their due time
    esc.next_deadline()                             # when to poll next (None: nothing scheduled)

Persistent settings and counters live in ``esc.nvm`` (a plain dict); ``esc.nvm_dirty`` tells the
adapter to write them to its flash store. What is lost at power-off (R13), the RAM every part of the model shares,
is ``esc.state`` (:class:`~.esc_state.EscState`, a fresh one at each power-up).
"""

from __future__ import annotations

import copy
import heapq
import random
from typing import Any, Callable

from ..protocol import catalogue as cat
from ..protocol.catalogue import BAUD_RATES
from ..protocol.errors import DecodeError, LengthError, TailError, UnknownTypeError
from ..protocol.frame import Decoder, Frame, WireFrame, classify
from ..protocol.ids import Kind
from ..protocol.transfer import TransferIdCounter, parse_tail, tail_byte
from . import esc_state
from .config import REPORT_TIMERS, EscConfig, factory_nvm
from .esc_answers import Answers
from .esc_motor import Motor
from .esc_output import Output
from .esc_settings import Settings
from .esc_state import EscState
from .esc_telemetry import EXP_MODE, REPORT_NAMES, REPORTING, SUSPENDED, Telemetry
from .faults import onset

__all__ = ["EXP_MODE", "HANDLED", "REPORTING", "REPORT_TIMERS", "SUSPENDED", "THROTTLE_FRAMES", "EscConfig", "EscModel", "EscState",
           "factory_nvm"]

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


class EscModel(Output, Motor, Telemetry, Settings, Answers):
    """One emulated ESC. See the module docstring for the driving contract; each concern's methods live in
    the module of its base class (config, esc_output, esc_motor, esc_telemetry, esc_settings, esc_answers), and what
    they share in RAM is :attr:`state`."""

    #: this power-up's RAM, which every part reads and writes (``esc_state.py``: each field, and which part uses it);
    #: a fresh one at each power-up. What outlives power-off: :attr:`nvm` (flash), :attr:`config`, :attr:`faults`
    state: EscState

    def __init__(self, config: EscConfig | None = None, nvm: dict[str, Any] | None = None) -> None:
        self.config = config or EscConfig()
        self.faults: set[str] = set(self.config.faults)
        self.nvm: dict[str, Any] = copy.deepcopy(nvm) if nvm is not None else factory_nvm(self.config)
        for key, value in factory_nvm(self.config).items():  # flash from an older emulator: fill gaps
            self.nvm.setdefault(key, value)
        self.nvm_dirty = nvm is None
        #: the public hook for a request the model rejects (an illegal value, or refused: R10-R12), called with the
        #: request before its answer (whose form is the ESC's freedom, ``config.rejected_answer``); None: no one asks
        self.on_rejected: Callable[[Frame], None] | None = None
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
        self._boot_baud: int | None = None  # the Set Baud code in force at the last power-up
        self._reset_volatile(0.0)

    def __setattr__(self, name: str, value: Any) -> None:
        # the RAM is self.state's (esc_state.py): a part (a fault added later, say) that sets it on the model itself
        # would set a copy no other part reads
        if name in esc_state.FIELDS or name in esc_state.OLD_NAMES:
            raise AttributeError(f"EscModel.{name}: the ESC's RAM is in self.state "
                                 f"(self.state.{esc_state.OLD_NAMES.get(name, name)}; ckesc/emulator/esc_state.py)")
        object.__setattr__(self, name, value)

    def __getattr__(self, name: str) -> Any:  # (only for a name not found: no cost to the rest)
        if name in esc_state.FIELDS or name in esc_state.OLD_NAMES:
            raise AttributeError(f"EscModel.{name}: the ESC's RAM is in self.state "
                                 f"(self.state.{esc_state.OLD_NAMES.get(name, name)}; ckesc/emulator/esc_state.py)")
        raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")

    # ------------------------------------------------------------------------------------------
    # power

    def _reset_volatile(self, now: float) -> None:
        """A power-up's RAM, fresh (:class:`EscState`; its fields say what each is)."""
        rng, config = self._rng, self.config
        self.state = EscState(
            powered_at=now, ready_at=now + config.boot_time,
            bitrate=BAUD_RATES.get(self.nvm["baud"], cat.DEFAULT_BITRATE),
            can_test_count=rng.randrange(1 << 31) if config.can_test_count == "from_random" else 0,
            led_color=self.nvm["led_color"], led_blink=self.nvm["led_blink"],
            # self_test_undefined_code: a failed self-test whose code the attachment does not define
            self_test_fault=0x30 if "self_test_undefined_code" in self.faults else config.self_test_fault,
            tids=TransferIdCounter((lambda: rng.randrange(32)) if config.transfer_id_start == "random" else None),
            last_update=now, last_thermal=now, report_floor=now,
            boot={k: self.nvm[k] for k in _PERSIST_FAULTS}, boot_node=self.nvm["node_id"])
        self.onsets_moved()
        if config.report_jitter_s:  # drawn after the CAN Test count, as always: one seed, one ESC
            self.state.offset = {k: self._jitter() for k in REPORT_NAMES}

    def onsets_moved(self) -> None:
        """The soak faults' times from this power-up (again, when ``config.onsets`` changed): when the clock runs fast
        (clock_drift_warm) and the next comm flag glitch (comm_flag_glitch)."""
        self.state.warm_at = self.state.powered_at + onset("clock_drift_warm", self.config.onsets)
        self.state.glitch_at = self.state.powered_at + onset("comm_flag_glitch", self.config.onsets)

    def power_on(self, now: float) -> None:
        if self.powered:
            return
        self.powered = True
        self._power_epoch += 1
        self._reset_volatile(now)
        if "can_test_persisted" in self.faults and self.nvm.get("can_test"):
            self.state.can_test = True
        if "suspend_persisted" in self.faults and self.nvm.get("suspended"):
            self.state.reporting = SUSPENDED
        if "power_up_counter_stuck" not in self.faults:
            twice = "baud_change_counts_power_up_twice" in self.faults and self._boot_baud not in (None, self.nvm["baud"])
            self.nvm["power_ups"] = (self.nvm["power_ups"] + 1 + twice) & 0xFFFF
        self._boot_baud = self.nvm["baud"]
        self.nvm_dirty = True
        start = self.state.ready_at + self.config.report_delay
        stagger = (0.0, 0.007, 0.013) if self.config.report_phase == "staggered" else (0.0, 0.0, 0.0)
        self.state.next_report = {k: start + d for k, d in zip(REPORT_NAMES, stagger)}
        self.state.report_floor = start
        self.state.next_can_test = start

    def power_off(self, now: float) -> None:
        if not self.powered:
            return
        self._update(now)
        for key, fault in _PERSIST_FAULTS.items():  # the faults that make a setting forget
            if fault in self.faults:
                self.nvm[key] = factory_nvm(self.config)[key]
        self.nvm.update(self.state.flash_only)  # a clobbering save (interaction faults): flash differs from RAM
        self.nvm["can_test"] = self.state.can_test
        self.nvm["suspended"] = self.state.reporting == SUSPENDED
        self.nvm_dirty = True
        self.powered = False
        self.state.outbox.clear()

    # ------------------------------------------------------------------------------------------
    # the driving contract

    @property
    def node_id(self) -> int:
        return self.nvm["node_id"]

    def next_deadline(self) -> float | None:
        if not self.powered:
            return None
        # the earliest of these, in this order (the first of equal ones, as min() of them): called after every poll
        # and every frame an ESC acts on, so no list is built
        state = self.state
        t = state.outbox[0][0] if state.outbox else None
        if self._reports_active():
            for due in (self._next_report_times() if state.offset else state.next_report.values()):
                if t is None or due < t:
                    t = due
        if state.can_test and (t is None or state.next_can_test < t):
            t = state.next_can_test
        cl = self._comm_loss_deadline()
        if cl is not None and (t is None or cl < t):
            t = cl
        if state.rpm > 0.5 or state.throttle:
            moves = state.last_update + 0.05  # motor and temperatures move
            if t is None or moves < t:
                t = moves
        return t

    def handle(self, frame: Any | None, now: float) -> tuple[list[WireFrame], float | None]:
        """h11-style single entry point: feed one frame (or None for a timer), get what is due."""
        if frame is not None:
            self.receive(frame, now)
        return self.poll(now), self.next_deadline()

    def listens_at(self, bitrate: int) -> bool:
        """Whether its CAN controller takes (and acknowledges) a frame sent at ``bitrate``: at its own rate only
        (R20), at any with the fault ``takes_other_bitrate``."""
        return self.state.bitrate == bitrate or "takes_other_bitrate" in self.faults

    def receive(self, msg: Any, now: float, *, decoded: Frame | DecodeError | None = None) -> bool:
        """A frame heard on the bus at ``now`` (the adapter has checked the bitrate matches).
        ``decoded``: the frame already decoded (or its DecodeError), when a bench decodes once for all.
        Returns whether the ESC acted on it (its next deadline may have moved)."""
        if not self.powered or now < self.state.ready_at:
            return False
        self.counters["rx"] += 1
        if decoded is None:
            try:
                decoded = self._decoder.decode(msg)
            except DecodeError as exc:
                decoded = exc
        if isinstance(decoded, DecodeError):
            # another protocol's type id (DroneCAN NodeStatus, ...) is foreign; anything else malformed (R17)
            self.counters["rx_foreign" if isinstance(decoded, UnknownTypeError) else "rx_malformed"] += 1
            if self._counts_foreign and isinstance(decoded, UnknownTypeError):
                self._heard_foreign(msg, now)
            if self._malformed_faults or self.config.toggle_single_frame != "ignore":
                taken = self._take_malformed(msg, decoded, now)
                if taken is True:
                    return True
                if taken is not None:
                    decoded = taken
            if isinstance(decoded, DecodeError):
                return "dronecan_node_info" in self.faults and self._dronecan_node_info(msg, now)
        frame = decoded
        if frame.spec is None:
            self.counters["rx_foreign"] += 1
            if self._counts_foreign:
                self._heard_foreign(msg, now)
            return False
        kept = "comm_watchdog_kept_alive" in self.faults and self._keep_alive(frame, now)
        handler = _HANDLERS.get((frame.kind, frame.spec.name))  # (spec.name: Frame.name's, without its call)
        if handler is None or (frame.source and self.config.foreign_host == "ignore"):
            self.counters["rx_ignored"] += 1
            return kept
        if handler is not EscModel._on_throttle:
            self._update(now)  # throttle frames update only when addressed to this ESC's channel
        return handler(self, frame, now) is not False or kept

    @property
    def _counts_foreign(self) -> bool:
        """Whether it keeps the foreign frames it hears (the bus share they took): the fault drops_reports_under_load
        and the variant above_half_load=drop act on it."""
        return "drops_reports_under_load" in self.faults or self.config.above_half_load == "drop"

    @property
    def _malformed_faults(self) -> bool:
        return bool(self.faults & MALFORMED_FAULTS)

    def _take_malformed(self, msg: Any, error: DecodeError, now: float) -> Frame | bool | None:
        """What a faulty ESC (or the toggle variant, R17-toggle) makes of a frame R17 says to ignore: the frame it
        takes instead, True when it reset (the frame consumed), None when it still ignores it."""
        data = bytes(msg.data)
        spec = classify(msg.arbitration_id)[4]
        if spec is None:
            return None
        if isinstance(error, TailError) and data:
            tail = parse_tail(data[-1])
            if tail.start and not tail.end and "reset_on_multi_frame_start" in self.faults:
                self.power_off(now)  # a watchdog reset: the frame's handling hangs, the ESC restarts
                self.power_on(now)
                return True
            single = tail.start and (tail.end or "takes_multi_frame_start" in self.faults)
            if not single or (tail.toggle and tail.end and self.config.toggle_single_frame != "take"):
                return None
            data = data[:-1] + bytes((tail_byte(tail.transfer_id),))
        elif isinstance(error, LengthError):
            size = _table_size(spec, classify(msg.arbitration_id)[0])
            if size is None:
                return None
            if len(data) == size - 1 and spec.name in THROTTLE_FRAMES and "short_raw_command_padded" in self.faults:
                data = data[:-1] + bytes(1) + data[-1:] if spec.has_tail else data + bytes(1)
            elif len(data) > size and "wrong_length_taken" in self.faults:
                data = data[:size - 1] + data[-1:] if spec.has_tail else data[:size]
            else:
                return None
        else:
            return None
        try:
            return self._decoder.decode(type(msg)(arbitration_id=msg.arbitration_id, data=data, is_extended_id=True)
                                        if not isinstance(msg, WireFrame) else msg._replace(data=data))
        except DecodeError:
            return None

    def poll(self, now: float) -> list[WireFrame]:
        """Everything due at or before ``now``, in due order, each stamped with its due time."""
        if not self.powered:
            return []
        self._update(now)
        if now >= self.state.ready_at:
            self._schedule_reports(now)
        out = []
        while self.state.outbox and self.state.outbox[0][0] <= now:
            out.append(heapq.heappop(self.state.outbox)[2])  # stamped with its due time when queued
        self.counters["tx"] += len(out)
        return out


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

THROTTLE_FRAMES = frozenset(cat.THROTTLE_FRAMES)

#: The faults that take a frame R17 says to ignore (faults.py's "robustness (R17)" group, but for the one of
#: the destination's, which Settings._addressed plays).
MALFORMED_FAULTS = frozenset({"takes_multi_frame_start", "short_raw_command_padded", "wrong_length_taken",
                              "reset_on_multi_frame_start"})


def _table_size(spec, kind: Kind) -> int | None:
    """A frame's data length by its table (the tail byte included) for what the host sends: None when the table
    allows any length (Get Rec, Clear Rec)."""
    layout = spec.request if kind is Kind.REQUEST else next((lay for lay in spec.layouts if lay.sender != "esc"), None)
    if layout is None or layout.size is None:
        return None
    return layout.size + spec.has_tail
HANDLED = frozenset(_HANDLERS)
