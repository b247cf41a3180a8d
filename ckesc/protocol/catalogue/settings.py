"""The settings an ESC keeps: the Set Baud codes, the LED's colours and blink codes, the report intervals with
their factory defaults (and the MSG1..MSG3 reports whose interval each holds), Expand Set Part's commands (R14),
and R13's persisted settings with the request that writes each and the frame it is read back with."""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import IntFlag
from types import MappingProxyType
from typing import Mapping


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

#: The report intervals of Set/Get Freq (4.4.22) as a new ESC has them (value x 2 ms).
DEFAULT_REPORT_INTERVALS = MappingProxyType({"msg1_interval": 10, "msg2_interval": 50, "msg3_interval": 250})
#: The reports of normal reporting, MSG1..MSG3 (4.4.4-4.4.6), each with the Set/Get Freq field that holds its
#: interval (4.4.22, R9).
REPORT_INTERVAL_FIELDS: Mapping[str, str] = MappingProxyType({k.removesuffix("_interval"): k for k in DEFAULT_REPORT_INTERVALS})
REPORT_FRAMES: tuple[str, ...] = tuple(REPORT_INTERVAL_FIELDS)
INTERVAL_FIELDS: tuple[str, ...] = tuple(REPORT_INTERVAL_FIELDS.values())


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
