"""What is fixed in an emulated ESC (:class:`EscConfig`: identity, capabilities, physical constants, the
freedoms the document leaves, the faults switched on) and its factory flash (:func:`factory_nvm`)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from ..protocol import catalogue as cat
from ..protocol.ids import DEFAULT_ESC_NODE_ID
from . import faults as _faults
from . import variants as _variants

#: How the report timer may behave when reporting comes back (EscConfig.report_timer; R9a allows each)
REPORT_TIMERS = _variants.FREEDOMS["report_timer"].choices
#: A freedom's default (:mod:`.variants`, the one list of the freedoms the document leaves): each freedom's field
#: below takes its default from there
_freedom = _variants.default

RECORD_SENSORS = ("mcu", "mos", "cap", "motor")  # MSG_EXP12 tail tags 0xC1..0xC4 (R15)


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
    boot_time: float = _freedom("boot_time")  # power-on to first answer; the ESC hears nothing before
    report_delay: float = _freedom("report_delay")  # boot to first report: an ESC may answer services before it reports
    #: what the report timer does when reporting comes back (resume, leaving CAN Test or MSG_EXP mode) - R9a
    #: leaves it open: "restart" (the first report at once, the next ones one interval apart), "grid" (one report
    #: at once, "immediately", then the old grid goes on, as if the timer had never stopped), "next_tick" (nothing
    #: at once: the first report at the old grid's next point) or "one_interval" (the timer restarted at the
    #: event: the first report one full interval later)
    report_timer: str = _freedom("report_timer")
    #: when a report whose interval a Set Freq write changed comes next - R9a leaves it open: "last_report" (the
    #: new interval counted from the last report), "old_deadline" (the report already scheduled on the old
    #: interval first, the new interval from it), "restart" (one new interval after the write) or "at_once"
    #: (a report at the write, the new interval from it)
    set_freq_timer: str = _freedom("set_freq_timer")
    #: the ESC's own report timing jitter, as its profile would declare it (jitter_s, R9): each report goes out
    #: within +- half of it of its grid point (so one interval strays by at most this much), the grid itself exact
    report_jitter_s: float = _freedom("report_jitter_s")
    #: when the comm-loss flag is raised (R8 leaves it open inside its window): "timer" (an exact 200 ms timer
    #: from the last command), "msg1" (checked when an MSG1 is due: the first one 200 ms or more after the last
    #: command carries it; an exact timer while nothing is reported) or "tick" (a periodic check on the report
    #: timer's 2 ms tick, which MSG1's grid is on)
    comm_loss_check: str = _freedom("comm_loss_check")
    #: where in its 2 ms slot (R2) an answer to MSG Control / GET_ESC_ID goes: "start", "inside" (a random
    #: place, the frame ending inside the slot) or "late" (as late as leaves room for one longest frame on the
    #: bus ahead of it)
    answer_place: str = _freedom("answer_place")
    #: a single frame whose tail's toggle bit is 1 (R17-toggle leaves it open): "ignore" it, or "take" it as
    #: DroneCAN's own receiver does
    toggle_single_frame: str = _freedom("toggle_single_frame")
    #: foreign load above half the bus (R18-above-half leaves what the ESC does free): "keep" reporting, or "drop"
    #: a report due when foreign frames took more than the bus's share variants.ABOVE_HALF_SHARE of the
    #: window before it
    above_half_load: str = _freedom("above_half_load")
    service_delay: float = _freedom("service_delay")  # request to response for services
    # the other freedoms the document leaves (ckesc/emulator/variants.py says what each value does)
    report_phase: str = _freedom("report_phase")  # the first MSG1..3 after power-up together, or staggered
    transfer_id_start: str = _freedom("transfer_id_start")  # message transfer-id counters' first value (F3)
    unlisted_priority: str = _freedom("unlisted_priority")  # 240/241/242 answers' priority (F5-unlisted)
    foreign_host: str = _freedom("foreign_host")  # frames from a host node other than 0 (F6)
    rejected_answer: str = _freedom("rejected_answer")  # the answer to an illegal or refused request (R10)
    over_max_throttle: str = _freedom("over_max_throttle")  # throttle above its maximum (R6)
    exp_frames: str = _freedom("exp_frames")  # which MSG_EXP frames, how often (R9-exp)
    value_rounding: str = _freedom("value_rounding")  # temperatures, run times, voltage, current to their units
    can_test_count: str = _freedom("can_test_count")  # CAN Test's count's start (R16)
    led_blink_other: str = _freedom("led_blink_other")  # Set LED blink codes other than 0/1/2/5 (4.4.20)
    major_config_option: str = _freedom("major_config_option")  # 242 with option != 0 (4.4.28-2)
    rec_answer: str = _freedom("rec_answer")  # Get Rec / Clear Rec answered (R15-payload)
    max_rpm: int = 9000
    motor_tau: float = 0.15  # rpm first-order lag
    supply_voltage: float = 50.4  # 12S full
    seed: int = 0
    faults: frozenset[str] = field(default_factory=frozenset)
    #: soak faults' onsets in seconds, by fault name, where not their default (faults.FAULTS[name].onset_s); a
    #: ``NAME=SECONDS`` entry of ``faults`` adds one
    onsets: dict[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        given = self.faults
        self.faults = _faults.check(given)
        self.onsets = {**_faults.onsets_in(given), **_faults.check_onsets(self.onsets)}
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
        "records": {s: {"t_max": 0, "times": 0, "time": 0} for s in RECORD_SENSORS},
        "can_test": False,  # only kept when the 'can_test_persisted' fault is on
        "suspended": False,  # only kept when the 'suspend_persisted' fault is on
    }
