"""The frame table: every CKESC 2.1 frame (section 4.3.2), written once: its id, kind, table priority, who sends
what, its request and response layouts with their fields (names, widths, units and scales, legal ranges and
codes, defaults) and its spec section; then the families the code ranges over (the throttle frames, the reports)
and :func:`spec`, the one way to look a frame up by name, type id or title."""

from __future__ import annotations

from types import MappingProxyType
from typing import Any, Mapping

from ..ids import MESSAGE_VENDOR_RANGE, SERVICE_VENDOR_RANGE, Priority
from .codes import (
    CAN_TEST_OFF,
    CAN_TEST_ON,
    CAN_TEST_REPORT,
    FAULT_CODES_1,
    MSG_CONTROL_ANSWER,
    MSG_CONTROL_RESUME,
    MSG_CONTROL_RESUME_EXP,
    MSG_CONTROL_SUSPEND,
    MSG_EXP12_RECORDS,
    THROTTLE_CHANNELS,
    THROTTLE_GROUPS,
    THROTTLE_MAX,
    Status,
)
from .schema import Field, FrameSpec, Layout, nibble, u8, u16, u32
from .settings import (
    BAUD_RATES,
    DEFAULT_LED_COLOR,
    EXPAND_COMMANDS,
    INTERVAL_FIELDS,
    LED_BLINK,
    PERSISTED_SETTINGS,
    REPORT_FRAMES,
    LedColor,
)
from .timing import INTERVAL_UNIT_S, REPORT_INTERVAL_RANGE

# --------------------------------------------------------------------------------------------------
# Field shorthands of the table below (the facts are in the arguments)


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
# Families: the frames the suites, the emulator, the explorer and the bus rules range over (the settings' are
# :mod:`.settings`'). A consumer that enumerates one imports it from the catalogue, so an entry added here is
# covered everywhere.

#: The throttle frames, RawCommand 14b/12b/10b (4.4.15-4.4.17, R3-R5), in the document's order.
THROTTLE_FRAMES: tuple[str, ...] = tuple(s.name for s in CATALOGUE if any(lay.codec.startswith("throttle") for lay in s.layouts))
#: The throttle channels each throttle frame carries, by its name: RawCommand_14b channels 1..4 (4.4.15-4),
#: RawCommand_12b four, those of the group it names (4.4.16-3), RawCommand_10b 1..6 (4.4.17-4).
FORMAT_CHANNELS: Mapping[str, int] = MappingProxyType({"raw_command_14b": 4, "raw_command_12b": 4, "raw_command_10b": 6})


def addressed_channels(name: str, group: int | None = None) -> range:
    """The throttle channels a throttle frame ``name`` commands: RawCommand_12b's those of its ``group``, 4g-3..4g
    (4.4.16-3; a group outside 1..5 none), the others' all they carry."""
    n = FORMAT_CHANNELS[name]
    if name != "raw_command_12b":
        return range(1, n + 1)
    return range(n * (group - 1) + 1, n * group + 1) if group in THROTTLE_GROUPS else range(0)


#: Set/Get Freq's read (option 0; the intervals sent are ignored, 4.4.22).
FREQ_READ: Mapping[str, int] = MappingProxyType({"option": 0, **{k: 0 for k in INTERVAL_FIELDS}})
#: MSG_EXP mode's periodic reports (4.4.7-4.4.13); MSG_EXP12 comes once per Get Rec instead (R15).
EXP_REPORT_FRAMES: tuple[str, ...] = tuple(s.name for s in CATALOGUE if s.name.startswith("msg_exp") and s.tail_tag is None)
#: Every frame the ESC sends as a report (a ``report`` layout): MSG1..MSG3, MSG_EXP1..MSG_EXP12.
ESC_REPORT_FRAMES: tuple[str, ...] = tuple(s.name for s in CATALOGUE if any(lay.name == "report" for lay in s.layouts))
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
    assert set(FORMAT_CHANNELS) == set(THROTTLE_FRAMES), FORMAT_CHANNELS


_self_check()
