"""Switchable faults: each makes an emulated ESC break one rule in one way.

The suite's self-test switches each fault on and checks that the tests citing the rules the fault
names fail, and only those. Rule ids are requirement ids of ``ckesc/protocol/requirements.toml``:
``F..``/``R..`` from ``spec/INTERPRETATIONS.md``, ``4.4.5-T`` for a section's parameter table,
``4.4.2-4`` for a numbered clarification of the document.

Two kinds: a ``single`` fault breaks one feature on its own, and the suite, which tests features one at a time,
must catch it. An ``interaction`` fault lives where two features meet, as real firmware has them (a save that
rewrites a whole flash block and clobbers its neighbour, a second suspend that latches): its rules are those of
the behaviour the faultless model follows, and the self-test reports whether the suite catches it, and by which
tests, or leaves it to ``ckesc explore`` (model-based exploration). A ``soak`` fault is a long-run defect (R19): it
shows only after its onset (``onset_s``: tens of minutes of power or of an uninterrupted RawCommand stream, longer
than the whole ten-minute suite and far longer than any of its streams), so the suite must NOT catch it (the
self-test proves it misses it) and ``ckesc soak`` must. ``NAME=SECONDS`` in a list of fault names (``--emulator-faults
reset_after_streaming=300``), or ``EscConfig.onsets``, moves a soak fault's onset (a short soak, a test).
"""

from __future__ import annotations

from dataclasses import dataclass
from types import MappingProxyType

SINGLE = "single"
INTERACTION = "interaction"
SOAK = "soak"


@dataclass(frozen=True)
class Fault:
    name: str
    rules: tuple[str, ...]
    description: str
    kind: str = SINGLE  # SINGLE, INTERACTION or SOAK (see the module docstring)
    onset_s: float | None = None  # SOAK: when the defect first shows by default (what it counts: its description)


#: The MCU clock of a warm ``clock_drift_warm`` ESC against true time: 320 / 300, as AM32 issue 268 measured (300 Hz
#: frames counted as 320 Hz).
WARM_CLOCK_RATE = 320 / 300
#: ``comm_flag_glitch``: after its first glitch (its onset), one glitch every this many seconds of power.
GLITCH_EVERY_S = 3600.0
#: ``run_time_wraps``: this run's time is kept in 50 ms ticks (the control loop's) in a uint16 (its onset: 65536 ticks).
RUN_TIME_TICK_S = 0.05

_FAULTS = (
    # framing (4.1)
    Fault("tail_toggle_set", ("F2",), "single-frame tail bytes carry toggle=1"),
    Fault("tail_not_single_frame", ("F2",), "tail bytes say start=1 end=0"),
    Fault("transfer_id_stuck", ("F3",), "message transfer ids never increment"),
    Fault("response_transfer_id_wrong", ("F4",), "service responses carry the request's transfer id + 1"),
    Fault("response_to_broadcast", ("F4",), "service responses go to node 127 instead of the requester"),
    Fault("response_as_request", ("F1", "F4"), "service responses have the request bit set"),
    Fault("wrong_priority", ("F5",), "reports (MSG1..3) are sent at MEDIUM instead of LOWEST"),
    Fault("response_wrong_priority", ("F5",), "service responses are sent at LOWEST (MEDIUM where the table says LOWEST)"),
    Fault("reports_at_default_id", ("F7",), "an ESC at node id 0x7D reports actively"),
    Fault("debug_frames_reserved_source", ("F7", "4.1.2-N2"), "in MSG_EXP mode MSG_EXP2 debug frames also go out, from the reserved node id 0x7F"),
    Fault("dronecan_node_info", ("4.3.1-1", "4.3.1-2"), "DroneCAN GetNodeInfo (service 1) is answered, after a NodeStatus (message 341): ids outside the vendor ranges"),
    # answers to broadcasts (4.4.2, 4.4.3)
    Fault("answer_late", ("R2",), "MSG Control and GET_ESC_ID are answered 80 ms after the request"),
    Fault("answer_not_staggered", ("R2",), "MSG Control and GET_ESC_ID answers come 10 ms after the request, whatever the node id"),
    Fault("answer_at_once", ("R2",), "MSG Control and GET_ESC_ID answers come 1 ms after the request, whatever the node id "
          "(inside node 1's slot error on a 2 ms bench: caught at a node id whose slot is wider)"),
    Fault("get_esc_id_with_option", ("R1",), "GET_ESC_ID replies carry [option, node_id, channel]"),
    Fault("get_esc_id_wrong_node", ("R1",), "GET_ESC_ID replies name node id + 1"),
    Fault("msg_control_answer_echo", ("R2",), "MSG Control is answered with the command echoed, not 0"),
    Fault("msg_control_no_answer", ("R2", "4.4.2-4"), "MSG Control is not answered"),
    Fault("resume_exp_ignored", ("4.4.2-T",), "MSG Control 0xEEEEEEEE is answered but starts no MSG_EXP reporting"),
    Fault("suspend_ignored", ("4.4.2-1", "4.4.2-T", "4.4.2-3", "R12", "4.4.20-6"), "MSG Control 0x55555555 does not stop active reporting"),
    Fault("resume_ignored", ("4.4.2-1", "4.4.2-T"), "MSG Control 0xAAAAAAAA does not restart active reporting"),
    # reports (4.4.4 - 4.4.14)
    Fault("report_interval_wrong", ("R9", "R9a"), "MSG1 comes every N x 3 ms instead of N x 2 ms"),
    Fault("report_jitter", ("R9", "R9a"), "report intervals jitter by up to +-30 %"),
    Fault("report_restart_late", ("R9a",), "after a resume, leaving MSG_EXP mode or CAN Test, or a Set Freq write, the first "
          "report of each type comes 1.5 intervals later (after a write, 1.5 x the longer of its old and new interval)"),
    Fault("msg2_interval_ignores_setting", ("R9",), "MSG2 keeps its default interval after Set Freq"),
    Fault("status_direction_bit14", ("R7",), "MSG1 reports the direction on bit 14 instead of bit 15"),
    Fault("status_running_wrong", ("R7",), "MSG1 bit 8 (run/stop) stays 0 while the motor runs"),
    Fault("msg2_scale_tenths", ("4.4.5-T",), "MSG2 voltage and current are in 0.1 units instead of 0.01"),
    Fault("msg3_short", ("4.4.6-T",), "MSG3 is sent with 3 payload bytes (Hobbywing's length)"),
    Fault("reports_padded", ("4.4.4-1", "4.4.5-1"), "MSG1 and MSG2 are zero-padded to 8 data bytes (7 payload bytes)"),
    Fault("exp1_scale_tenths", ("4.4.7-T",), "MSG_EXP1 voltage and current are in 0.1 units instead of 0.01"),
    Fault("exp7_direction_zero_based", ("4.4.9-T",), "MSG_EXP7 reports the direction as 0 forward / 1 reverse instead of 1 / 2"),
    Fault("exp8_power_ups_from_zero", ("4.4.10-T",), "MSG_EXP8 counts power-ups from zero (one less than 241 option 2)"),
    Fault("exp_run_times_ms", ("4.4.11-T", "4.4.12-T"), "MSG_EXP9 and MSG_EXP10 running times are in milliseconds instead of seconds"),
    Fault("exp11_msg3_order", ("4.4.13-T",), "MSG_EXP11 carries MSG3's order (MOS, CAP, motor, MCU) instead of MOS, MCU, CAP, motor"),
    Fault("speed_ignores_throttle", ("4.4.4-T",), "MSG1 PWM stays 0 whatever the throttle"),
    # comm loss (R8)
    Fault("comm_loss_late", ("R8",), "the comm-loss flag is set 400 ms after the last command"),
    Fault("comm_loss_early", ("R8",), "the comm-loss flag is set 100 ms after the last command"),
    Fault("comm_loss_never", ("R8",), "the comm-loss flag is never set"),
    Fault("comm_loss_sticky", ("R8",), "the comm-loss flag is not cleared by the next command"),
    Fault("comm_watchdog_kept_alive", ("R20-watchdog", "R8"),
          "the comm watchdog is refreshed by any frame addressed to the ESC (a read, a setting request) and by a "
          "GET_ESC_ID query, not by RawCommand alone (a keep-alive beside the commands, as in the public cases): while "
          "queries and reads go on the comm-loss flag never rises, and one clears it as a command would"),
    # the bus as CAN hardware makes it (R20)
    Fault("no_busoff_recovery", ("R20-recovery",), "the CAN controller does not recover from bus-off by itself (no "
          "automatic recovery, none by the firmware): after a bus short the ESC is silent until a power cycle"),
    Fault("busoff_recovery_resets", ("R20-recovery",), "the ESC recovers from bus-off by rebooting (its firmware resets "
          "on a bus-off): the power-up count moves and the transfer ids start again"),
    Fault("takes_other_bitrate", ("R20-bitrate",), "the ESC's CAN controller takes frames sent at another bit rate "
          "than its own: moved to another rate by Set Baud, it still obeys the commands, settings writes and queries of "
          "a host at its old rate (its answers go out at its own rate)"),
    # throttle (4.4.15 - 4.4.17)
    Fault("throttle_channel_ignored", ("4.4.18-6",), "the ESC always follows channel 1, not its own throttle channel"),
    Fault("twelve_bit_nibbles_swapped", ("R4",), "RawCommand_12b is read with the nibbles of p1/p4 swapped"),
    Fault("twelve_bit_group_ignored", ("R4",), "RawCommand_12b is applied whatever its group id"),
    Fault("ten_bit_not_doubled", ("R5",), "RawCommand_10b values are used as 0..1000 instead of doubled"),
    Fault("fourteen_bit_byte_order", ("R3",), "RawCommand_14b is read as little-endian 14-bit fields"),
    Fault("throttle_answered", ("4.4.15-1", "4.4.16-1", "4.4.17-1", "R9"),  # the extra MSG1s break its interval
          "every RawCommand addressed to the ESC is answered at once with an extra MSG1"),
    Fault("ten_bit_tail_checked", ("4.4.17-3", "R5"),
          "RawCommand_10b is dropped unless the high nibble of payload[7] is 0b1100 (read as a tail byte)"),
    # settings and rejects (R10 - R13)
    Fault("set_freq_accepts_illegal", ("R10",), "Set Freq applies values outside 10..250 (1..9, 251..255; 0 stays refused)"),
    Fault("set_freq_partial", ("R10",), "Set Freq applies the legal values of a partly illegal request"),
    Fault("set_id_accepts_illegal", ("R10",), "Set ID applies node ids 0, 0x7E and 0x7F"),
    Fault("set_baud_accepts_illegal", ("R10",), "Set Baud stores codes above 6"),
    Fault("rotation_accepts_illegal", ("R10",), "Set Rotation treats any value other than 0/0xFF as reverse"),
    Fault("throttle_select_accepts_illegal", ("R10",), "Throttle Select stores values above 1"),
    Fault("set_id_after_window", ("R11",), "Set ID is applied after the 120 s window"),
    Fault("set_baud_after_window", ("R11",), "Set Baud is applied after the 120 s window"),
    Fault("set_baud_immediate", ("R11",), "Set Baud changes the bit rate at once instead of at the next power-up"),
    Fault("set_id_needs_destination", ("R11",), "Set ID is obeyed only when addressed to the ESC's own node id"),
    Fault("config_window_short", ("R11",), "Set ID and Set Baud take effect only within 60 s of power-up, not 120 s"),
    Fault("set_id_channel_ignored", ("4.4.18-1", "4.4.18-6"), "Set ID changes the node id but keeps the throttle channel"),
    Fault("rotation_ignored", ("4.4.21-1", "4.4.21-T"), "Set Rotation 0 / 1 is answered but never changes the direction"),
    Fault("throttle_select_ignored", ("4.4.23-1",), "Throttle Select is answered but never changes the source"),
    Fault("settings_while_suspended", ("R12",), "Set Led, Set Rotation and Set Freq take effect while reporting is suspended"),
    Fault("set_id_while_suspended", ("R12", "4.4.2-3"), "Set ID (inside the 120 s window) takes effect while reporting "
          "is suspended; the other settings are held back"),
    Fault("set_baud_while_suspended", ("R12", "4.4.2-3"), "Set Baud (inside the 120 s window) is stored while "
          "reporting is suspended: the next power-up brings its bit rate; the other settings are held back"),
    Fault("rotation_while_running", ("R12",), "Set Rotation and Throttle Select take effect while the motor runs"),
    Fault("intervals_not_persisted", ("R13",), "report intervals are lost at power-off"),
    Fault("node_id_not_persisted", ("R13",), "node id and throttle channel are lost at power-off"),
    Fault("rotation_not_persisted", ("R13",), "the rotation is lost at power-off"),
    Fault("led_save_not_persisted", ("R13",), "Set Led with option 1 is lost at power-off"),
    Fault("led_unsaved_persisted", ("R13",), "Set Led with option 0 survives power-off"),
    Fault("throttle_source_not_persisted", ("R13",), "the throttle source is lost at power-off"),
    Fault("baud_not_persisted", ("R13",), "the Set Baud code is lost at power-off"),
    Fault("expand_not_persisted", ("R13",), "Expand Set Part settings are lost at power-off"),
    Fault("suspend_persisted", ("R13",), "MSG Control suspension survives power-off"),
    Fault("power_up_counter_stuck", ("4.4.27-T", "4.4.10-T"), "the power-up counter does not count power-ups"),
    # other services
    Fault("expand_set_answered", ("R14",), "Expand Set Part is answered"),
    Fault("expand_set_big_endian", ("R14",), "Expand Set Part's Set_cmd is read big-endian"),
    Fault("get_rec_untagged", ("R15",), "MSG_EXP12 records carry tail 0xC0 instead of 0xC1..0xC5"),
    # an ESC model without an optional function (R9b): FAILs, unless its profile declares the function absent
    Fault("get_rec_absent", ("R15",), "no temperature records: Get Rec (223), Clear Rec (224) and Expand Set Part's "
          "record read are ignored (an ESC model without Get Rec)"),
    Fault("expand_set_part_absent", ("R14",), "Expand Set Part (222) is ignored (an ESC model without it)"),
    # Clear Rec's effect is no rule (R15 is Get Rec's; 224's payload and answer are OBSERVE): recorded, never failed
    Fault("clear_rec_ignored", ("R15-payload",), "Clear Rec leaves the temperature records"),
    Fault("can_test_count_skips", ("R16",), "CAN Test counts up by 2 per frame"),
    Fault("can_test_reports_continue", ("R16",), "other reports continue in CAN Test mode"),
    Fault("can_test_off_ignored", ("R16", "4.4.1-3"), "CAN Test 0x55 does not end test mode"),
    Fault("can_test_off_resumes_reporting", ("R16", "4.4.1-3"),
          "leaving CAN Test starts normal reporting whatever the state before (suspended, MSG_EXP mode)"),
    Fault("can_test_persisted", ("R16", "R13"), "CAN Test mode survives power-off"),
    Fault("self_test_always_passes", ("4.4.24-1", "4.2.1-1"), "Self Test answers 0 even when the power-up self-test failed"),
    Fault("self_test_unanswered", ("4.1.1-2", "4.2.1-1", "4.4.24-1"), "Self Test requests are not answered"),
    Fault("self_test_inverted", ("4.2.1-1", "4.4.24-1"), "Self Test answers 1 (failed) for a passed power-up self-test and 0 for a failed one"),
    Fault("self_test_undefined_code", ("A-1",), "the power-up self-test fails with fault code 0x30, which the attachment does not define"),
    Fault("pwm_no_fallback", ("4.2-1",), "PWM+CAN: when the PWM signal is lost the CAN throttle does not take over (the motor stops)"),
    Fault("esc_information_bcd_date", ("4.4.26-T",), "240 answers the firmware date in BCD (October -> 0x10 = 16)"),
    Fault("maintenance_info_7_missing", ("4.4.27-T",), "241 answers have 6 payload bytes: Info_7 is missing"),
    Fault("set_led_no_echo", ("4.4.20-T",), "Set Led is answered with zeros"),
    Fault("set_freq_read_wrong", ("4.4.22-2",), "Set/Get Freq read answers the defaults, not the settings"),
    Fault("major_config_bits_swapped", ("4.4.28-1",), "242 puts the direction in bit 6 and the source in bit 7"),
    Fault("maintenance_counts_wrong", ("4.4.27-T",), "241 option 2 swaps the power-up and stop counters"),
    # malformed and foreign frames (R17): each frame here would be a valid command if its tail, length or address were
    # those of the table
    Fault("takes_multi_frame_start", ("R17",), "the start frame of a multi-frame transfer (tail start=1 end=0) is "
          "taken as a single frame"),
    Fault("short_raw_command_padded", ("R17", "R8"), "a RawCommand one byte short is zero-padded to its length and "
          "taken (its last channel read as zero; a comm refresh)"),
    Fault("wrong_length_taken", ("R17",), "a frame longer than its table is taken, the bytes beyond its payload "
          "ignored"),
    Fault("reset_on_multi_frame_start", ("R17",), "the start frame of a multi-frame transfer resets the ESC (a "
          "watchdog reset: the power-up count grows, the reports restart after the boot)"),
    Fault("destination_low_bits", ("R17",), "a request's destination node id is decoded from its low six bits: a "
          "request to the node id 64 away is taken and answered"),
    # a loaded bus (R18)
    Fault("drops_reports_under_load", ("R18",), "a report due when foreign frames took more than a third of the bus "
          "in the 10 ms before it is skipped (no hardware filter: the receive interrupt drops each foreign frame in "
          "software and starves the loop that sends the reports)"),
    # where features meet (kind INTERACTION): each feature works alone
    Fault("led_save_reverts_rotation", ("R13", "4.4.21-4"),
          "Set Led with option 1 rewrites the flash word it shares with the rotation, taking the rotation from the copy "
          "read at power-up: a direction set since power-up is lost at the next power cycle", INTERACTION),
    Fault("freq_save_resets_led", ("R13", "4.4.20-5"),
          "a Set Freq write rewrites the settings block with the LED at its factory default: a saved LED colour and "
          "blink are lost at the next power cycle", INTERACTION),
    Fault("rotation_save_resets_intervals", ("R13", "4.4.22-6"),
          "Set Rotation 0 / 1 rewrites the settings block with the default report intervals (10, 50, 250): intervals "
          "set before are lost at the next power cycle", INTERACTION),
    Fault("source_save_reverts_led", ("R13", "4.4.20-5"),
          "Throttle Select rewrites the settings block with the LED from the copy read at power-up: an LED saved since "
          "power-up is lost at the next power cycle", INTERACTION),
    Fault("set_id_resets_source", ("R13", "4.4.23-4"),
          "Set ID (inside the 120 s window) rewrites the node record with the throttle source back at CAN", INTERACTION),
    Fault("second_suspend_latches", ("4.4.2-1", "4.4.2-T"),
          "MSG Control suspends nest: a suspend while suspended needs a resume of its own, so the first resume after "
          "two suspends is answered but reporting stays off", INTERACTION),
    Fault("resume_reloads_default_intervals", ("R9",),
          "a resume after a suspension restarts the report timers at the default intervals (10, 50, 250) until the "
          "next Set Freq write or power-up; Set/Get Freq still reads the settings", INTERACTION),
    Fault("set_freq_moves_other_stream", ("R9",),
          "a Set Freq write that changes MSG1's interval and not MSG2's reloads MSG2's timer with MSG1's interval "
          "(until MSG2's own is written or the next power-up)", INTERACTION),
    Fault("comm_loss_sticky_after_resume", ("R8",),
          "once reporting has been suspended and resumed, the comm-loss flag is no longer cleared by the next "
          "command (until the next power-up)", INTERACTION),
    Fault("baud_change_counts_power_up_twice", ("4.4.27-T", "4.4.10-T"),
          "the power-up that brings a new Set Baud bit rate into force counts two power-ups", INTERACTION),
    Fault("answer_slot_from_boot_node", ("R2", "4.4.2-4", "4.4.3-4"),
          "MSG Control and GET_ESC_ID answers wait for the slot of the node id the ESC booted with: after a Set ID "
          "(until the next power-up) they come in the old node's slot, not the current one's", INTERACTION),
    Fault("throttle_select_drops_10b", ("4.4.17-1", "R5", "R8"),
          "after a Throttle Select (until the next power-up) RawCommand_10b is ignored: the parser table is rebuilt "
          "with the 14-bit and 12-bit formats only", INTERACTION),
    # long-run defects (kind SOAK, R19): each shows only after its onset, so the ten-minute suite misses it and a
    # soak finds it (the defects release qualification fears most: issue #31)
    Fault("reset_after_streaming", ("R19",),
          "after 20 min of an uninterrupted RawCommand stream to it (no gap as long as the comm-loss time, 200 ms), the "
          "ESC resets as its watchdog would: a power-up (the power-up count grows, reports and transfer ids restart "
          "after the boot, RAM state is lost, the settings in flash kept); the next 20 min of stream reset it again",
          SOAK, onset_s=1200.0),
    Fault("clock_drift_warm", ("R19", "R9"),
          "after 15 min powered (the board warm), the ESC's clock runs 6.7 % fast (320 / 300, as AM32 issue 268 "
          "measured): every report interval shrinks by that much (MSG1 every 18.75 ms instead of 20) and the running "
          "times (241, MSG_EXP9 and MSG_EXP10) count that much fast; cold again at the next power-up",
          SOAK, onset_s=900.0),
    Fault("run_time_wraps", ("R19", "4.4.27-T", "4.4.12-T"),
          "this run's time (241 option 1, MSG_EXP10) is kept in 50 ms ticks of the control loop in a uint16, not in "
          "its uint32 of seconds: after 65536 ticks (54 min 36.8 s of motor running) it wraps to 0 and counts again",
          SOAK, onset_s=65536 * RUN_TIME_TICK_S),
    Fault("comm_flag_glitch", ("R19", "R8"),
          "while the RawCommand stream runs without a break, one MSG1 carries the comm-loss flag (bit 13) once an hour "
          "of power: first 30 min after power-up, then every 60 min (a race of the comm-loss check with its timer); "
          "the next MSG1 is clear again",
          SOAK, onset_s=1800.0),
)

FAULTS = MappingProxyType({f.name: f for f in _FAULTS})


def interaction(name: str) -> bool:
    """Whether fault ``name`` is an INTERACTION fault (the suite need not catch it)."""
    return FAULTS[name].kind == INTERACTION


def soak(name: str) -> bool:
    """Whether fault ``name`` is a SOAK fault (a long-run defect the suite must miss and ``ckesc soak`` find)."""
    return FAULTS[name].kind == SOAK


def onset(name: str, onsets=None) -> float:
    """SOAK fault ``name``'s onset in seconds: ``onsets[name]`` when given (EscConfig.onsets), else its default."""
    if onsets and name in onsets:
        return float(onsets[name])
    value = FAULTS[name].onset_s
    if value is None:
        raise ValueError(f"fault {name} has no onset (not a soak fault)")
    return value


def split(entry: str) -> tuple[str, float | None]:
    """A fault list's entry: ``NAME``, or ``NAME=SECONDS`` (a soak fault's onset moved); raises ValueError when
    SECONDS is no number."""
    name, eq, seconds = str(entry).partition("=")
    if not eq:
        return name.strip(), None
    try:
        return name.strip(), float(seconds)
    except ValueError:
        raise ValueError(f"fault {entry!r}: NAME=SECONDS takes a number of seconds, not {seconds!r}") from None


def onsets_in(entries) -> dict[str, float]:
    """The onsets ``NAME=SECONDS`` entries of a fault list give (checked: soak faults only, seconds >= 0)."""
    return check_onsets({name: value for name, value in map(split, entries or ()) if value is not None})


def check_onsets(onsets) -> dict[str, float]:
    """EscConfig.onsets checked: soak fault names to a number of seconds >= 0; raises ValueError."""
    out: dict[str, float] = {}
    for name, value in dict(onsets or {}).items():
        if name not in FAULTS or FAULTS[name].kind != SOAK:
            raise ValueError(f"onset for {name!r}: only soak faults have one ({', '.join(n for n, f in FAULTS.items() if f.kind == SOAK)})")
        if not float(value) >= 0:
            raise ValueError(f"onset for {name!r}: {value!r} is not a number of seconds >= 0")
        out[name] = float(value)
    return out


def check(names) -> frozenset[str]:
    """Validate fault names (``NAME=SECONDS`` entries too: :func:`split`), the names without their onsets; raises
    ValueError listing the unknown ones and the known ones."""
    names = frozenset(split(n)[0] for n in names or ())
    unknown = names - FAULTS.keys()
    if unknown:
        raise ValueError(f"unknown fault(s) {', '.join(sorted(unknown))}; known: {', '.join(sorted(FAULTS))}")
    return names
