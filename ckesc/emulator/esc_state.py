"""What an emulated ESC holds in RAM (:class:`EscState`): everything its parts (``esc_output``, ``esc_motor``,
``esc_telemetry``, ``esc_settings``, ``esc_answers``) share and lose at power-off (R13), as one explicit object
beside the model (h11's ``ConnectionState`` beside its ``Connection``): a part reads and writes ``self.state.X``, so
what it depends on is a field named here. What outlives a power cycle is not here: the flash (``EscModel.nvm``),
the fixed :class:`~ckesc.emulator.config.EscConfig`, the faults switched on, and the model's own bookkeeping
(``powered``, the PWM input signal the bench drives, counters). :meth:`EscModel.power_on` makes a fresh one."""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field
from typing import Any

from ..protocol.frame import WireFrame
from ..protocol.transfer import TransferIdCounter

# Reporting states (MSG Control, 4.4.2)
REPORTING = "normal"
SUSPENDED = "suspended"
EXP_MODE = "exp"


def _temps() -> dict[str, float]:
    return {"mos": 25.0, "cap": 25.0, "mcu": 30.0, "motor": 25.0}


@dataclass(eq=False, slots=True)
class EscState:
    """One power-up's RAM, field by field (times are the driver's ``now``, in seconds). Slotted: a field not named
    here cannot be set by mistake."""

    # ---- power-up and the bus (model, esc_settings' 120 s window, esc_output's answer slot)
    powered_at: float = 0.0  #: when this power-up began: Set ID / Set Baud's 120 s window counts from it (R11)
    ready_at: float = 0.0  #: when it hears frames: powered_at + the boot time
    bitrate: int = 0  #: the bit rate its CAN controller runs at: the stored Set Baud code's, as at power-up (4.4.19)

    # ---- modes (esc_telemetry: MSG Control, CAN Test; esc_settings: R12's lock while suspended)
    reporting: str = REPORTING  #: REPORTING, SUSPENDED or EXP_MODE (MSG Control, 4.4.2)
    can_test: bool = False  #: CAN Test on (4.4.26): the count frames instead of the reports
    can_test_prev: str = REPORTING  #: the reporting state CAN Test on found (kept for its off, R16)
    can_test_count: int = 0  #: the next CAN Test frame's count (can_test_count variant: where it starts)
    next_can_test: float = 0.0  #: when the next CAN Test frame is due
    test_mode: bool = False  #: Expand Set Part's maintenance test mode (part 0x11 on, 0x10 off)

    # ---- the LED as shown (esc_settings writes it, esc_answers' 242 and esc_telemetry's EXP7 read it)
    led_color: int = 0  #: Set LED's colour in force (flash's at power-up; an unsaved Set LED changes only this)
    led_blink: int = 0  #: Set LED's blink code in force

    # ---- throttle and motor (esc_motor; esc_telemetry's MSG1 and status word read them)
    throttle: int = 0  #: the throttle in use, 0..2000: the CAN one or the PWM input's, whichever is the source
    can_throttle: int = 0  #: the last CAN throttle command for its channel (0 after comm loss)
    last_command: float | None = None  #: when the last throttle command came (R8's 200 ms count from it)
    comm_fault: bool = False  #: the comm-loss flag (R8; MSG1 status)
    rpm: float = 0.0  #: the motor's speed, following the throttle with a first-order lag
    running: bool = False  #: the motor turning (MSG1 status; starts and stops counted in flash)
    run_time: float = 0.0  #: motor running seconds in this power-up (241 option 1, EXP10)
    temps: dict[str, float] = field(default_factory=_temps)  #: degC per sensor: mos, cap, mcu, motor
    current: float = 0.0  #: amperes drawn, from the motor's load
    self_test_fault: int = 0  #: the power-up self-test's fault code 1 (0: passed; MSG1 status, 241, EXP9)
    pwm_seen: bool = False  #: a PWM throttle signal was in use (fault pwm_no_fallback)
    last_update: float = 0.0  #: when the motor model last moved
    last_thermal: float = 0.0  #: when the temperatures last moved (a coarser step)

    # ---- the outbox (esc_output; esc_answers edits an answer just queued)
    outbox: list[tuple[float, int, WireFrame]] = field(default_factory=list)  #: (due, seq, frame), a heap by due
    seq: int = 0  #: the last frame queued's sequence number (ties in the outbox go in queueing order)
    tids: TransferIdCounter = field(default_factory=TransferIdCounter)  #: each message's transfer id counter (F3)

    # ---- report timers (esc_telemetry; esc_settings' Set Freq and esc_motor's comm-loss check on MSG1's grid)
    next_report: dict[str, float] = field(default_factory=dict)  #: each report's next grid point (msg1/msg2/msg3)
    regrid: dict[str, float] = field(default_factory=dict)  #: report_timer "grid": the old grid's next point after a report sent at once
    #: report_jitter_s: each report's offset from its grid point (empty without jitter: the hot path stays as it was)
    offset: dict[str, float] = field(default_factory=dict)
    report_floor: float = 0.0  #: the earliest a jittered report may go out: not before the event that set its timer
    last_jittered: dict[str, float] = field(default_factory=dict)  #: each report's last jittered time: the next never goes before it
    reports_were_active: bool = True  #: reports flowed at the last poll (coming back: start afresh, no catch-up burst)

    # ---- the interaction faults' state (faults.INTERACTION; all empty / off in a faultless ESC)
    boot: dict[str, Any] = field(default_factory=dict)  #: the persisted settings as read at power-up
    flash_only: dict[str, Any] = field(default_factory=dict)  #: what a clobbering save wrote to flash, RAM unchanged: in force at power-up
    suspends: int = 0  #: second_suspend_latches: suspends beyond the first, each wanting a resume
    default_timers: bool = False  #: resume_reloads_default_intervals: the timers run on the default intervals
    timer_from: dict[str, str] = field(default_factory=dict)  #: set_freq_moves_other_stream: report -> the report whose interval it takes
    resumed: bool = False  #: comm_loss_sticky_after_resume: reporting was suspended and resumed
    selected: bool = False  #: throttle_select_drops_10b: a Throttle Select was taken
    boot_node: int = 0  #: answer_slot_from_boot_node: the node id it booted with
    #: drops_reports_under_load: (end, bus time) of the foreign frames of the last few ms
    foreign: deque[tuple[float, float]] = field(default_factory=deque)

    # ---- the soak faults' state (faults.SOAK: each shows only after its onset, counted from power-up or the stream)
    stream_since: float | None = None  #: reset_after_streaming: when the uninterrupted command stream began
    warm_at: float = math.inf  #: clock_drift_warm: from when the clock runs fast (EscModel.onsets_moved)
    glitch_at: float = math.inf  #: comm_flag_glitch: the next comm flag glitch (EscModel.onsets_moved)


#: every field of the RAM, and the model's attribute names from before it had :class:`EscState` (``_next_report``)
FIELDS = frozenset(EscState.__dataclass_fields__)
OLD_NAMES = {f"_{name}": name for name in FIELDS}
