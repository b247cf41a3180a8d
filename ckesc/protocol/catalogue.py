"""The frame catalogue: every CKESC 2.1 frame, written once.

Ids, kinds, table priorities, who sends what, request and response layouts, field names, widths,
units and scales, legal ranges and codes, defaults and the spec section. The codecs, the emulator,
the suites' illegal-value cases and the reports all read this module; nothing else may restate a
protocol fact.

Rule ids (F.., R..) refer to ``spec/INTERPRETATIONS.md``; sections to the vendor document.
All multi-byte fields are little-endian (F2).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import IntFlag
from types import MappingProxyType
from typing import Any, Mapping

from .ids import MESSAGE_VENDOR_RANGE, SERVICE_VENDOR_RANGE, Priority

# --------------------------------------------------------------------------------------------------
# Building blocks


@dataclass(frozen=True)
class Field:
    """One named value in a payload.

    The value is ``(little-endian word at [offset, offset+size)) >> shift``, masked to ``bits``.
    ``legal`` (an inclusive range) and ``codes`` (the legal discrete values, with their meaning)
    say what the document allows; ``rejected_by`` names the rule that makes an illegal value
    "ignored, never partly applied" (R10) - without it, what a device does with an illegal value is
    OBSERVE. ``scale``/``unit`` turn the raw integer into a physical value (raw * scale unit).
    """

    name: str
    offset: int
    size: int = 1
    shift: int = 0
    bits: int | None = None
    legal: tuple[int, int] | None = None
    codes: Mapping[int, str] | None = None
    default: int | None = None
    unit: str | None = None
    scale: float | None = None
    flags: type[IntFlag] | None = None
    rejected_by: str | None = None
    doc: str = ""

    def __post_init__(self) -> None:
        if self.size not in (1, 2, 4):
            raise ValueError(f"field {self.name}: size must be 1, 2 or 4 bytes")
        width = self.size * 8
        bits = width - self.shift if self.bits is None else self.bits
        if self.shift + bits > width:
            raise ValueError(f"field {self.name}: bits outside its word")
        object.__setattr__(self, "bits", bits)
        if self.codes is not None:
            object.__setattr__(self, "codes", MappingProxyType(dict(self.codes)))

    @property
    def mask(self) -> int:
        return (1 << self.bits) - 1  # type: ignore[operator]

    @property
    def max_raw(self) -> int:
        return self.mask

    def is_legal(self, value: int) -> bool:
        if self.codes is not None and value not in self.codes:
            return False
        if self.legal is not None and not self.legal[0] <= value <= self.legal[1]:
            return False
        return 0 <= value <= self.mask

    def physical(self, raw: int) -> float | int:
        return raw * self.scale if self.scale is not None else raw


@dataclass(frozen=True, eq=False)
class Layout:
    """The payload of one frame kind (the tail byte excluded).

    ``codec`` is ``fields`` (byte/bit fields above), ``throttle14``/``throttle12``/``throttle10``
    (the RawCommand packings, R3-R5) or ``raw`` (payload of unknown structure: 223/224, OBSERVE).
    ``when`` selects a response layout by the request's fields (241: by option).
    """

    name: str
    size: int | None  # payload bytes without the tail; None: any length 0..7 (codec 'raw')
    fields: tuple[Field, ...] = ()
    codec: str = "fields"
    sender: str = "host"  # 'host', 'esc' or 'any'
    when: Mapping[str, int] | None = None
    doc: str = ""

    def field(self, name: str) -> Field:
        for f in self.fields:
            if f.name == name:
                return f
        raise KeyError(name)

    @property
    def field_names(self) -> tuple[str, ...]:
        if self.codec == "throttle12":
            return ("channels", "group")
        if self.codec in ("throttle14", "throttle10"):
            return ("channels",) + (("tail_bits",) if self.codec == "throttle10" else ())
        if self.codec == "raw":
            return ("payload",)
        return tuple(f.name for f in self.fields)


@dataclass(frozen=True, eq=False)
class FrameSpec:
    """One frame type of the document's table (section 4.3.2)."""

    name: str
    title: str
    type_id: int
    service: bool
    section: str
    priority: Priority | None  # None: the table lists none (240/241/242, F5: OBSERVE)
    description: str
    layouts: tuple[Layout, ...] = ()  # messages: one per direction/length
    request: Layout | None = None
    responses: tuple[Layout, ...] = ()  # services: the first is the generic one; () = never answered
    has_tail: bool = True  # False for RawCommand_10b (R5)
    tail_tag: Mapping[int, str] | None = None  # MSG_EXP12: the transfer id names the record (R15)

    @property
    def response(self) -> Layout | None:
        return self.responses[0] if self.responses else None

    @property
    def kind_label(self) -> str:
        return "service" if self.service else "message"

    def response_for(self, request_fields: Mapping[str, object] | None) -> Layout | None:
        """The response layout that answers a request with these fields."""
        if not self.responses:
            return None
        if request_fields:
            for layout in self.responses:
                if layout.when and all(request_fields.get(k) == v for k, v in layout.when.items()):
                    return layout
        return self.responses[0]

    def message_layout(self, size: int) -> Layout | None:
        for layout in self.layouts:
            if layout.size == size:
                return layout
        return None

    @property
    def all_layouts(self) -> tuple[Layout, ...]:
        out = list(self.layouts)
        if self.request is not None:
            out.append(self.request)
        out.extend(self.responses)
        return tuple(out)


# --------------------------------------------------------------------------------------------------
# Shared value tables


class Status(IntFlag):
    """MSG1 status word (4.4.4, rule R7). Bit 15 is the direction (DroneCAN's GUI reads bit 14: the
    document wins)."""

    SELFTEST_A_OUTPUT_HIGH = 1 << 0
    SELFTEST_B_OUTPUT_HIGH = 1 << 1  # the document says "phase C" twice; bit 1 is phase B by pattern
    SELFTEST_C_OUTPUT_HIGH = 1 << 2
    SELFTEST_COM_INPUT_HIGH = 1 << 3
    SELFTEST_A_OUTPUT_LOW = 1 << 4
    SELFTEST_B_OUTPUT_LOW = 1 << 5
    SELFTEST_C_OUTPUT_LOW = 1 << 6
    SELFTEST_COM_INPUT_LOW = 1 << 7
    RUNNING = 1 << 8
    OVER_TEMPERATURE = 1 << 9
    OVER_CURRENT = 1 << 10
    OVER_VOLTAGE = 1 << 11
    PHASE_SEQUENCE = 1 << 12
    COMM_FAULT = 1 << 13  # R8: no command for more than 200 ms under CAN throttle
    THROTTLE_PWM = 1 << 14  # 0: CAN throttle, 1: PWM throttle
    DIRECTION_CCW = 1 << 15  # 0: CW / forward, 1: CCW / reverse


SELFTEST_ERROR_MASK = 0x00FF


class LedColor(IntFlag):
    """Set Led colour bits (4.4.20): bit 2 red, bit 1 green, bit 0 blue."""

    OFF = 0
    BLUE = 1
    GREEN = 2
    RED = 4


#: Set Baud codes (4.4.19). Codes 4 and 5 differ from Hobbywing's DSDL (there 100k/50k).
BAUD_RATES: Mapping[int, int] = MappingProxyType(
    {0: 1_000_000, 1: 500_000, 2: 250_000, 3: 200_000, 4: 125_000, 5: 100_000, 6: 50_000}
)
DEFAULT_BAUD_CODE = 1
DEFAULT_BITRATE = BAUD_RATES[DEFAULT_BAUD_CODE]

LED_BLINK = MappingProxyType({0x00: "steady", 0x01: "1 Hz", 0x02: "2 Hz", 0x05: "5 Hz"})
DEFAULT_LED_COLOR = LedColor.GREEN  # 4.4.20 clarification 3

#: Report interval unit of Set/Get Freq and 242 (4.4.22): value x 2 ms.
INTERVAL_UNIT_S = 0.002
REPORT_INTERVAL_RANGE = (10, 250)
DEFAULT_REPORT_INTERVALS = MappingProxyType({"msg1_interval": 10, "msg2_interval": 50, "msg3_interval": 250})

#: MSG Control commands (4.4.2).
MSG_CONTROL_ANSWER = 0x00000000
MSG_CONTROL_SUSPEND = 0x55555555
MSG_CONTROL_RESUME = 0xAAAAAAAA
MSG_CONTROL_RESUME_EXP = 0xEEEEEEEE

#: CAN Test options (4.4.1).
CAN_TEST_REPORT = 0x00
CAN_TEST_ON = 0xAA
CAN_TEST_OFF = 0x55

#: Timing facts.
ANSWER_SLOT_S = 0.002  # R2: answer after (node_id % 32) x 2 ms
ANSWER_DELAY_MAX_S = 0.064  # 4.4.2 clarification 4, 4.4.3 clarification 4
ANSWER_SLOTS = round(ANSWER_DELAY_MAX_S / ANSWER_SLOT_S)  # R2: the slots (node_id % 32) tile the 64 ms


def answer_slot_s(node_id: int) -> float:
    """R2: when node ``node_id``'s answer slot (MSG Control, GET_ESC_ID) starts after the request."""
    return (node_id % ANSWER_SLOTS) * ANSWER_SLOT_S


COMM_LOSS_TIMEOUT_S = 0.200  # 4.4.4 clarification 3 (R8)
CONFIG_WINDOW_S = 120.0  # 4.3.2 table, R11: Set ID / Set Baud valid 120 s after power-up
RESTART_SLACK_MIN_S = 0.003  # R9a: the first report after a restart within one interval + max(3 ms, interval / 4)


def restart_limit_s(interval: float) -> float:
    """R9a (READING): the first report of a type after a restart (power-up, a resume, leaving MSG_EXP mode, CAN
    Test off) comes within its interval plus a slack of max(3 ms, a quarter of it); after a Set Freq write,
    ``interval`` is the longer of its old and new interval."""
    return interval + max(RESTART_SLACK_MIN_S, interval / 4)


#: Throttle scales (4.4.15-4.4.17, 4.4.23 clarification 5).
THROTTLE_MAX = 2000
THROTTLE_10B_MAX = 1000
THROTTLE_CHANNELS = range(1, 21)  # 4.4.18 clarification 6: at most 20 channels
THROTTLE_GROUPS = range(1, 6)  # 4.4.16 clarification 3

#: Fault code 1 (the document's attachment); also reported in MSG_EXP9 and 241 option 2.
FAULT_CODES_1: Mapping[int, str] = MappingProxyType(
    {
        0x00: "power-up self-test normal",
        0x01: "low COM voltage during motor drive circuit test",
        0x02: "high COM voltage during motor drive circuit test",
        0x11: "high A-phase test voltage during motor drive circuit test",
        0x12: "high B-phase test voltage during motor drive circuit test",
        0x13: "high C-phase test voltage during motor drive circuit test",
        0x21: "low A-phase test voltage during motor drive circuit test",
        0x22: "low B-phase test voltage during motor drive circuit test",
        0x23: "low C-phase test voltage during motor drive circuit test",
    }
)

#: Fault code 1 -> the MSG1 self-test error bit (4.4.4 status bits 7..0) of the same test. The document lists
#: both tables but does not say how they map: this is the reading the emulator plays (phase and COM by name).
FAULT_CODE_STATUS_BITS: Mapping[int, int] = MappingProxyType(
    {
        0x00: 0,
        0x01: int(Status.SELFTEST_COM_INPUT_LOW),
        0x02: int(Status.SELFTEST_COM_INPUT_HIGH),
        0x11: int(Status.SELFTEST_A_OUTPUT_HIGH),
        0x12: int(Status.SELFTEST_B_OUTPUT_HIGH),
        0x13: int(Status.SELFTEST_C_OUTPUT_HIGH),
        0x21: int(Status.SELFTEST_A_OUTPUT_LOW),
        0x22: int(Status.SELFTEST_B_OUTPUT_LOW),
        0x23: int(Status.SELFTEST_C_OUTPUT_LOW),
    }
)


@dataclass(frozen=True)
class ExpandCommand:
    """One Set_cmd of Expand Set Part (4.4.25, R14) with its legal Part values."""

    code: int
    name: str
    parts: Mapping[int, str]
    reserved: bool = False  # every Part of it is marked "(reserved)" in the document
    persisted: bool = True  # R13: Expand Set Part settings persist


def _parts(lo: int, hi: int, label: str) -> Mapping[int, str]:
    return MappingProxyType({v: f"{label} {v}" for v in range(lo, hi + 1)})


#: R14: the document's five-digit codes 0xffff6..0xffffe are typos for 0xfff6..0xfffe.
EXPAND_COMMANDS: Mapping[int, ExpandCommand] = MappingProxyType(
    {
        c.code: c
        for c in (
            ExpandCommand(0xFFF0, "direction", {0x01: "forward", 0x02: "reverse"}),
            ExpandCommand(0xFFF1, "led", {0x00: "off", 0x01: "red", 0x02: "green", 0x03: "blue"}),
            ExpandCommand(
                0xFFF2,
                "control_mode",
                {
                    0x01: "PWM (reserved)",
                    0x02: "PWM+TCAN",
                    0x03: "TCAN",
                    0x04: "DSHOT25 (reserved)",
                    0x05: "PWM+UAVCAN",
                    0x06: "UAVCAN",
                },
            ),
            ExpandCommand(0xFFF4, "active_freewheel", {0x00: "off", 0x01: "on"}),
            ExpandCommand(0xFFF5, "entry_angle_1", _parts(1, 4, "angle"), reserved=True),
            ExpandCommand(0xFFF6, "entry_angle_2", _parts(1, 4, "angle"), reserved=True),
            ExpandCommand(0xFFF7, "load_type", _parts(1, 4, "load"), reserved=True),
            ExpandCommand(0xFFF8, "prop_lock", {0: "off", 1: "weak", 2: "medium", 3: "strong"}),
            ExpandCommand(0xFFF9, "startup_acceleration", _parts(0, 15, "level")),
            ExpandCommand(0xFFFA, "lost_signal_reduction", _parts(0, 15, "level")),
            ExpandCommand(0xFFFB, "read_temperature_records", {0x01: "read"}, persisted=False),
            ExpandCommand(0xFFFC, "baud", {k: f"{v} bit/s" for k, v in BAUD_RATES.items()}),
            ExpandCommand(
                0xFFFE,
                "maintenance",
                {0x00: "factory settings (not enabled)", 0x10: "test mode off", 0x11: "test mode on"},
                persisted=False,
            ),
        )
    }
)

MSG_EXP12_RECORDS = MappingProxyType({1: "mcu", 2: "mos", 3: "cap", 4: "motor", 5: "reserved"})

# --------------------------------------------------------------------------------------------------
# Field helpers (layout shorthands; the facts are in the arguments)


def u8(name: str, offset: int, **kw) -> Field:
    return Field(name, offset, 1, **kw)


def u16(name: str, offset: int, **kw) -> Field:
    return Field(name, offset, 2, **kw)


def u32(name: str, offset: int, **kw) -> Field:
    return Field(name, offset, 4, **kw)


def nibble(name: str, offset: int, high: bool, **kw) -> Field:
    return Field(name, offset, 1, shift=4 if high else 0, bits=4, **kw)


def _interval(name: str, offset: int, default: int | None, rejected_by: str | None = None) -> Field:
    return u8(
        name,
        offset,
        legal=REPORT_INTERVAL_RANGE,
        default=default,
        unit="ms",
        scale=INTERVAL_UNIT_S * 1000,
        rejected_by=rejected_by,
    )


_THROTTLE_CHANNEL = dict(legal=(THROTTLE_CHANNELS.start, THROTTLE_CHANNELS.stop - 1))
_NODE_ID = dict(legal=(1, 0x7D))
_TEMP = dict(unit="degC")
_V = dict(unit="V", scale=0.01)
_A = dict(unit="A", scale=0.01)

_COUNT_OPTION = (
    u8("option", 0, codes={CAN_TEST_REPORT: "report", CAN_TEST_ON: "on", CAN_TEST_OFF: "off"}),
    u32("count", 1, default=0),
)
_MSG_CONTROL = (
    u8("option", 0, codes={0: "command"}, default=0),
    u32(
        "command",
        1,
        codes={
            MSG_CONTROL_ANSWER: "answer",
            MSG_CONTROL_SUSPEND: "suspend",
            MSG_CONTROL_RESUME: "resume",
            MSG_CONTROL_RESUME_EXP: "resume_exp",
        },
    ),
)
_SET_ID = (
    u8("node_id", 0, rejected_by="R10", **_NODE_ID),
    u8("throttle_channel", 1, **_THROTTLE_CHANNEL),
)
_SET_BAUD = (u8("baud", 0, codes={k: f"{v} bit/s" for k, v in BAUD_RATES.items()}, rejected_by="R10"),)
_SET_LED = (
    u8("option", 0, codes={0: "do not save", 1: "save"}),
    u8("color", 1, legal=(0, 7), flags=LedColor, default=int(DEFAULT_LED_COLOR)),
    u8("blink", 2, codes=LED_BLINK, default=0),
)
_ROTATION = {0x00: "forward", 0x01: "reverse"}
_SET_FREQ_REQUEST = (
    u8("option", 0, codes={0: "read", 1: "write"}),
    _interval("msg1_interval", 1, 10, "R10"),
    _interval("msg2_interval", 2, 50, "R10"),
    _interval("msg3_interval", 3, 250, "R10"),
)
_THROTTLE_SOURCE = {0x00: "CAN", 0x01: "PWM+CAN"}
_OPTION_ZERO = (u8("option", 0, codes={0: "query"}, default=0),)
_RAW = Layout("payload", None, codec="raw", sender="any", doc="structure not given by the document (R15: OBSERVE)")

_THROTTLE_DOC = "throttle channels; the legal range is the document's, larger values are OBSERVE (R6)"

# --------------------------------------------------------------------------------------------------
# The catalogue


def _msg(name, title, type_id, section, priority, description, *layouts, **kw) -> FrameSpec:
    return FrameSpec(name, title, type_id, False, section, priority, description, layouts=layouts, **kw)


def _srv(name, title, type_id, section, priority, description, request, *responses) -> FrameSpec:
    return FrameSpec(name, title, type_id, True, section, priority, description, request=request, responses=responses)


def _report(*fields: Field) -> Layout:
    return Layout("report", max(f.offset + f.size for f in fields), fields, sender="esc")


def _exp_debug(n: int) -> FrameSpec:
    return _msg(
        f"msg_exp{n}",
        f"MSG_EXP{n}",
        20052 + n,
        "4.4.8",
        Priority.LOWEST,
        "Debugging information (the table shows six one-byte columns; its 'Test_1-7 uint16' does not fit)",
        _report(*(u8(f"test_{i + 1}", i) for i in range(6))),
    )


CATALOGUE: tuple[FrameSpec, ...] = (
    _msg(
        "can_test",
        "CAN Test",
        20000,
        "4.4.1",
        Priority.LOWEST,
        "Bus test mode: on (0xAA) the ESC stops other reporting and sends counting frames (R16)",
        Layout("command", 5, _COUNT_OPTION, sender="any"),
    ),
    _msg(
        "msg_control",
        "MSG Control",
        20010,
        "4.4.2",
        Priority.MEDIUM,
        "Suspend/resume active reporting; every ESC answers with command 0 (R2)",
        Layout("command", 5, _MSG_CONTROL, sender="any"),
    ),
    _msg(
        "get_esc_id",
        "FRAME_MSG_GET_ESC_ID",
        20013,
        "4.4.3",
        Priority.MEDIUM,
        "Query ESC id and throttle channel; every ESC replies [node_id, throttle_channel] (R1)",
        Layout("query", 1, _OPTION_ZERO),
        Layout("reply", 2, (u8("node_id", 0, **_NODE_ID), u8("throttle_channel", 1, **_THROTTLE_CHANNEL)), sender="esc"),
    ),
    _msg(
        "msg1",
        "MSG1",
        20050,
        "4.4.4",
        Priority.LOWEST,
        "Speed, throttle output and status",
        _report(
            u16("speed", 0, unit="rpm"),
            u16("pwm", 2, legal=(0, THROTTLE_MAX)),
            u16("status", 4, flags=Status),
        ),
    ),
    _msg(
        "msg2",
        "MSG2",
        20051,
        "4.4.5",
        Priority.LOWEST,
        "Voltage, current (unsigned, 0.01 units: not Hobbywing's signed 0.1) and MOS temperature",
        _report(u16("voltage", 0, **_V), u16("current", 2, **_A), u8("temperature", 4, **_TEMP)),
    ),
    _msg(
        "msg3",
        "MSG3",
        20052,
        "4.4.6",
        Priority.LOWEST,
        "MOS, capacitor, motor and MCU temperatures",
        _report(
            u8("mos_t", 0, **_TEMP),
            u8("cap_t", 1, **_TEMP),
            u8("motor_t", 2, **_TEMP),
            u8("mcu_t", 3, **_TEMP),
            u8("reserved_1", 4, default=0),
            u8("reserved_2", 5, default=0),
            u8("reserved_3", 6, default=0),
        ),
    ),
    _msg(
        "msg_exp1",
        "MSG_EXP1",
        20053,
        "4.4.7",
        Priority.LOWEST,
        "Speed, voltage and current",
        _report(u16("speed", 0, unit="rpm"), u16("voltage", 2, **_V), u16("current", 4, **_A)),
    ),
    *(_exp_debug(n) for n in range(2, 7)),
    _msg(
        "msg_exp7",
        "MSG_EXP7",
        20059,
        "4.4.9",
        Priority.LOWEST,
        "Setting parameters, one nibble each",
        _report(
            nibble("direction", 0, False, codes={1: "forward", 2: "reverse"}),
            nibble("led", 0, True, codes={0: "off", 1: "red", 2: "green", 3: "blue"}),
            nibble("comm_interface", 1, False, codes={2: "PWM_CAN", 3: "CAN"}),
            nibble("reserved_1", 1, True, default=0),
            nibble("active_freewheel", 2, False, codes={0: "off", 1: "on"}),
            nibble("entry_angle_1", 2, True, default=0, doc="reserved"),
            nibble("entry_angle_2", 3, False, default=0, doc="reserved"),
            nibble("load_type", 3, True, default=0, doc="reserved"),
            nibble("prop_lock", 4, False, codes={0: "off", 1: "weak", 2: "medium", 3: "strong"}),
            nibble("startup_acceleration", 4, True, legal=(1, 15)),
            nibble("lost_signal_protection", 5, False, legal=(1, 15)),
            nibble("reserved_2", 5, True, default=0),
        ),
    ),
    _msg(
        "msg_exp8",
        "MSG_EXP8",
        20060,
        "4.4.10",
        Priority.LOWEST,
        "Number of power-ups, starts and normal stops",
        _report(u16("power_ups", 0), u16("starts", 2), u16("stops", 4)),
    ),
    _msg(
        "msg_exp9",
        "MSG_EXP9",
        20061,
        "4.4.11",
        Priority.LOWEST,
        "Accumulated running time and self-test fault code 1",
        _report(u32("total_run_time", 0, unit="s"), u16("fault_code_1", 4, codes=FAULT_CODES_1)),
    ),
    _msg(
        "msg_exp10",
        "MSG_EXP10",
        20062,
        "4.4.12",
        Priority.LOWEST,
        "Time of this run and self-test fault code 2",
        _report(u32("run_time", 0, unit="s"), u16("fault_code_2", 4)),
    ),
    _msg(
        "msg_exp11",
        "MSG_EXP11",
        20063,
        "4.4.13",
        Priority.LOWEST,
        "MOS, MCU, capacitor and motor temperatures (note: not MSG3's order)",
        _report(
            u8("mos_t", 0, **_TEMP),
            u8("mcu_t", 1, **_TEMP),
            u8("cap_t", 2, **_TEMP),
            u8("motor_t", 3, **_TEMP),
            u8("reserved_1", 4, default=0),
            u8("reserved_2", 5, default=0),
        ),
    ),
    _msg(
        "msg_exp12",
        "MSG_EXP12",
        20064,
        "4.4.14",
        Priority.LOWEST,
        "Temperature record, once per Get Rec; the tail byte 0xC1..0xC5 names the record (R15)",
        _report(u8("t_max", 0, **_TEMP), u16("times", 1), u32("time", 3, unit="s")),
        tail_tag=MSG_EXP12_RECORDS,
    ),
    _msg(
        "raw_command_14b",
        "RawCommand_14b",
        20100,
        "4.4.15",
        Priority.HIGHEST,
        "Four 14-bit throttle channels 1..4 (R3, DroneCAN int14 packing)",
        Layout("command", 7, codec="throttle14", doc=_THROTTLE_DOC),
    ),
    _msg(
        "raw_command_12b",
        "RawCommand_12b",
        20101,
        "4.4.16",
        Priority.HIGHEST,
        "Four 12-bit throttle channels of group 1..5, LSB-first (R4)",
        Layout("command", 7, codec="throttle12", doc=_THROTTLE_DOC),
    ),
    _msg(
        "raw_command_10b",
        "RawCommand_10b",
        20102,
        "4.4.17",
        Priority.HIGHEST,
        "Six 10-bit throttle channels 1..6 over all 8 bytes, no tail byte (R5)",
        Layout("command", 8, codec="throttle10", doc=_THROTTLE_DOC),
        has_tail=False,
    ),
    _srv(
        "set_id",
        "Set Id",
        210,
        "4.4.18",
        Priority.MEDIUM,
        "Set node id and throttle channel; pseudo-broadcast, only within 120 s of power-up (R11)",
        Layout("request", 2, _SET_ID),
        Layout("response", 2, _SET_ID, sender="esc"),
    ),
    _srv(
        "set_baud",
        "Set Baud",
        211,
        "4.4.19",
        Priority.MEDIUM,
        "Set the bus rate, effective after the next power-up, only within 120 s of power-up (R11)",
        Layout("request", 1, _SET_BAUD),
        Layout("response", 1, _SET_BAUD, sender="esc"),
    ),
    _srv(
        "set_led",
        "Set Led",
        212,
        "4.4.20",
        Priority.LOW,
        "LED colour and blink; option 1 saves (R13); not while reporting is suspended (R12)",
        Layout("request", 3, _SET_LED),
        Layout("response", 3, _SET_LED, sender="esc"),
    ),
    _srv(
        "set_rotation",
        "Set Rotation",
        213,
        "4.4.21",
        Priority.LOW,
        "Motor direction; 0xFF queries; motor stopped and reporting on (R12)",
        Layout("request", 1, (u8("rotation", 0, codes={**_ROTATION, 0xFF: "query"}, rejected_by="R10"),)),
        Layout("response", 1, (u8("rotation", 0, codes=_ROTATION, default=0),), sender="esc"),
    ),
    _srv(
        "set_freq",
        "Set/Get Freq",
        214,
        "4.4.22",
        Priority.MEDIUM,
        "Read or write the MSG1/MSG2/MSG3 report intervals (value x 2 ms, 10..250) (R9, R10)",
        Layout("request", 4, _SET_FREQ_REQUEST),
        Layout("response", 4, _SET_FREQ_REQUEST, sender="esc"),
    ),
    _srv(
        "throttle_select",
        "Throttle Select",
        215,
        "4.4.23",
        Priority.MEDIUM,
        "Throttle source: CAN or PWM+CAN; at zero throttle (R12)",
        Layout("request", 1, (u8("source", 0, codes=_THROTTLE_SOURCE, rejected_by="R10"),)),
        Layout("response", 1, (u8("source", 0, codes=_THROTTLE_SOURCE, default=0),), sender="esc"),
    ),
    _srv(
        "self_test",
        "Self Test",
        216,
        "4.4.24",
        Priority.LOWEST,
        "Query the power-up self-test status",
        Layout("request", 0),
        Layout("response", 1, (u8("status", 0, codes={0: "passed", 1: "failed"}),), sender="esc"),
    ),
    _srv(
        "expand_set_part",
        "Expand Set Part",
        222,
        "4.4.25",
        Priority.MEDIUM,
        "Extended settings; never answered; motor stopped (R12, R14)",
        Layout(
            "request",
            3,
            (
                u16("set_cmd", 0, codes={c.code: c.name for c in EXPAND_COMMANDS.values()}),
                u8("part", 2),
            ),
        ),
    ),
    _srv(
        "get_rec",
        "Get Rec",
        223,
        "4.4.25",
        Priority.MEDIUM,
        "Read the temperature records: the ESC sends MSG_EXP12 frames (R15)",
        _RAW,
        _RAW,
    ),
    _srv(
        "clear_rec",
        "Clear Rec",
        224,
        "4.4.25",
        Priority.MEDIUM,
        "Clear the temperature records (R15)",
        _RAW,
        _RAW,
    ),
    _srv(
        "esc_information",
        "ESC Information",
        240,
        "4.4.26",
        None,
        "Hardware, protocol and firmware version information",
        Layout("request", 1, _OPTION_ZERO),
        Layout(
            "response",
            7,
            (
                u8("max_cells", 0, unit="S"),
                u8("max_current", 1, unit="A", scale=10),
                u8("hardware_version", 2),
                u8("protocol_version", 3),
                u8("firmware_year", 4),
                u8("firmware_month", 5, legal=(1, 12)),
                u8("firmware_day", 6, legal=(1, 31)),
            ),
            sender="esc",
        ),
    ),
    _srv(
        "maintenance_information",
        "Maintance Information",
        241,
        "4.4.27",
        None,
        "Run-time log; the response layout depends on the request's option",
        Layout("request", 1, (u8("option", 0, codes={0: "temperatures", 1: "this run", 2: "counters"}),)),
        Layout("response", 7, tuple(u8(f"info_{i + 1}", i) for i in range(7)), sender="esc"),
        Layout(
            "response_option_0",
            7,
            (u32("total_run_time", 0, unit="s"), u8("mos_t_max", 4, **_TEMP), u8("cap_t_max", 5, **_TEMP), u8("info_7", 6, default=0)),
            sender="esc",
            when={"option": 0},
        ),
        Layout(
            "response_option_1",
            7,
            (u32("run_time", 0, unit="s"), u16("runs", 4), u8("info_7", 6, default=0)),
            sender="esc",
            when={"option": 1},
        ),
        Layout(
            "response_option_2",
            7,
            (u16("power_ups", 0), u16("stops", 2), u16("fault_code", 4, codes=FAULT_CODES_1), u8("option", 6, default=2)),
            sender="esc",
            when={"option": 2},
        ),
    ),
    _srv(
        "get_major_configuration",
        "Get Major Configuration",
        242,
        "4.4.28",
        None,
        "Direction, throttle source and channel, LED and report intervals in one answer",
        Layout("request", 1, _OPTION_ZERO),
        Layout(
            "response",
            7,
            (
                Field("direction", 0, shift=7, bits=1, codes=_ROTATION),
                Field("throttle_source", 0, shift=6, bits=1, codes=_THROTTLE_SOURCE),
                Field("throttle_channel", 0, bits=6, **_THROTTLE_CHANNEL),
                Field("led_blink", 1, shift=3, bits=5, codes=LED_BLINK),
                Field("led_color", 1, bits=3, flags=LedColor),
                _interval("msg1_interval", 2, None),
                _interval("msg2_interval", 3, None),
                _interval("msg3_interval", 4, None),
                u16("reserved", 5, default=0),
            ),
            sender="esc",
        ),
    ),
)

MESSAGES: Mapping[int, FrameSpec] = MappingProxyType({s.type_id: s for s in CATALOGUE if not s.service})
SERVICES: Mapping[int, FrameSpec] = MappingProxyType({s.type_id: s for s in CATALOGUE if s.service})
BY_NAME: Mapping[str, FrameSpec] = MappingProxyType({s.name: s for s in CATALOGUE})


# --------------------------------------------------------------------------------------------------
# Families: the frames and settings the suites, the emulator, the explorer and the bus rules range over.
# A consumer that enumerates one imports it from here, so an entry added here is covered everywhere.

#: The throttle frames, RawCommand 14b/12b/10b (4.4.15-4.4.17, R3-R5), in the document's order.
THROTTLE_FRAMES: tuple[str, ...] = tuple(s.name for s in CATALOGUE if any(lay.codec.startswith("throttle") for lay in s.layouts))
#: The reports of normal reporting, MSG1..MSG3 (4.4.4-4.4.6), each with the Set/Get Freq field that holds its
#: interval (4.4.22, R9).
REPORT_INTERVAL_FIELDS: Mapping[str, str] = MappingProxyType({k.removesuffix("_interval"): k for k in DEFAULT_REPORT_INTERVALS})
REPORT_FRAMES: tuple[str, ...] = tuple(REPORT_INTERVAL_FIELDS)
INTERVAL_FIELDS: tuple[str, ...] = tuple(REPORT_INTERVAL_FIELDS.values())
#: Set/Get Freq's read (option 0; the intervals sent are ignored, 4.4.22).
FREQ_READ: Mapping[str, int] = MappingProxyType({"option": 0, **{k: 0 for k in INTERVAL_FIELDS}})
#: MSG_EXP mode's periodic reports (4.4.7-4.4.13); MSG_EXP12 comes once per Get Rec instead (R15).
EXP_REPORT_FRAMES: tuple[str, ...] = tuple(s.name for s in CATALOGUE if s.name.startswith("msg_exp") and s.tail_tag is None)
#: Every frame the ESC sends as a report (a ``report`` layout): MSG1..MSG3, MSG_EXP1..MSG_EXP12.
ESC_REPORT_FRAMES: tuple[str, ...] = tuple(s.name for s in CATALOGUE if any(lay.name == "report" for lay in s.layouts))

#: MSG1 status bits that follow the ESC's state and settings (R7, R8): direction, throttle source, comm loss, running.
STATUS_STATE_BITS = Status.DIRECTION_CCW | Status.THROTTLE_PWM | Status.COMM_FAULT | Status.RUNNING


@dataclass(frozen=True)
class PersistedSetting:
    """One setting R13 keeps across power-off, with the request that writes it and where it is read back.

    ``fields`` maps the writer's request fields to the names the setting is read back as (the host's settings
    read: 242 and Set/Get Freq read; GET_ESC_ID for the node id); ``save`` are the writer's fixed fields of a
    write that saves (Set LED and Set Freq option 1). ``clause`` is the requirement of its own section that says
    a written value is kept. ``window``: written only within the 120 s after power-up (R11); ``at_power_up``: a
    write takes effect only after the next power-up (Set Baud). Every one of them is a parameter change R12 holds
    back while reporting is suspended (4.4.2-3). Expand Set Part's settings are :data:`EXPAND_COMMANDS`'s."""

    name: str
    writer: str
    fields: Mapping[str, str]
    reader: str | None  # the frame it is read back with; None: only the bit rate it answers at after a power-up
    clause: str
    label: str  # the write that saves it, as a message says it: "Set Led option 1"
    save: Mapping[str, int] = field(default_factory=dict)
    window: bool = False
    at_power_up: bool = False

    def __post_init__(self) -> None:
        object.__setattr__(self, "fields", MappingProxyType(dict(self.fields)))
        object.__setattr__(self, "save", MappingProxyType(dict(self.save)))

    @property
    def keys(self) -> tuple[str, ...]:
        """The names it is read back as."""
        return tuple(self.fields.values())


#: R13's persisted settings (4.4.18-4.4.23): the ones a test can write at any time first, then the two of the window.
PERSISTED_SETTINGS: tuple[PersistedSetting, ...] = (
    PersistedSetting("rotation", "set_rotation", {"rotation": "rotation"}, "get_major_configuration", "4.4.21-4",
                     "Set Rotation"),
    PersistedSetting("throttle_source", "throttle_select", {"source": "throttle_source"}, "get_major_configuration",
                     "4.4.23-4", "Throttle Select"),
    PersistedSetting("led", "set_led", {"color": "led_color", "blink": "led_blink"}, "get_major_configuration",
                     "4.4.20-5", "Set Led option 1", save={"option": 1}),
    PersistedSetting("intervals", "set_freq", dict(zip(INTERVAL_FIELDS, INTERVAL_FIELDS)), "set_freq", "R13",
                     "Set Freq", save={"option": 1}),
    PersistedSetting("node_id", "set_id", {"node_id": "node_id", "throttle_channel": "throttle_channel"}, "get_esc_id",
                     "4.4.18-7", "Set Id", window=True),
    PersistedSetting("baud", "set_baud", {"baud": "baud"}, None, "4.4.19-3", "Set Baud", window=True,
                     at_power_up=True),
)
PERSISTED: Mapping[str, PersistedSetting] = MappingProxyType({s.name: s for s in PERSISTED_SETTINGS})
#: The requests that write a persisted setting: the parameter changes R12 holds back while reporting is suspended.
SETTING_WRITERS: frozenset[str] = frozenset(s.writer for s in PERSISTED_SETTINGS)
#: The requests an ESC takes whatever their destination node id: Set ID is a pseudo-broadcast (R11, 4.4.18-3).
PSEUDO_BROADCAST: frozenset[str] = frozenset({"set_id"})


def spec(name: str) -> FrameSpec:
    """The catalogue entry named ``name`` (``'set_freq'``); also accepts a type id or the document's title."""
    if name in BY_NAME:
        return BY_NAME[name]
    for s in CATALOGUE:
        if s.title.lower() == str(name).lower() or str(s.type_id) == str(name):
            return s
    raise KeyError(f"no frame named {name!r}; known: {', '.join(BY_NAME)}")


def firmware_date(fields: Mapping[str, Any] | None) -> str | None:
    """ESC Information 240's firmware date as ``YYYY-MM-DD`` (its year byte counts from 2000), None when the
    answer or a field is missing."""
    if not isinstance(fields, Mapping):
        return None
    y, m, d = fields.get("firmware_year"), fields.get("firmware_month"), fields.get("firmware_day")
    return None if None in (y, m, d) else f"20{int(y):02d}-{int(m):02d}-{int(d):02d}"


def _self_check() -> None:
    for s in CATALOGUE:
        assert (s.type_id in SERVICE_VENDOR_RANGE) if s.service else (s.type_id in MESSAGE_VENDOR_RANGE), s.name
        for layout in s.all_layouts:
            limit = 8 if not s.has_tail else 7
            assert layout.size is None or layout.size <= limit, (s.name, layout.name)
            for f in layout.fields:
                assert layout.size is not None and f.offset + f.size <= layout.size, (s.name, f.name)
        sizes = [lay.size for lay in s.layouts]
        assert len(sizes) == len(set(sizes)), f"{s.name}: message layouts must differ in length"
    assert len(BY_NAME) == len(CATALOGUE)
    for p in PERSISTED_SETTINGS:
        writer = spec(p.writer)
        assert writer.request is not None and set(p.fields) | set(p.save) <= set(writer.request.field_names), p.name
        assert p.reader is None or p.reader in BY_NAME, p.name
    assert len(THROTTLE_FRAMES) == 3 and len(REPORT_FRAMES) == 3, (THROTTLE_FRAMES, REPORT_FRAMES)


_self_check()
