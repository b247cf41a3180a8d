"""The frame catalogue: every CKESC 2.1 frame, written once.

Ids, kinds, table priorities, who sends what, request and response layouts, field names, widths,
units and scales, legal ranges and codes, defaults and the spec section. The codecs, the emulator,
the suites' illegal-value cases and the reports all read this module; nothing else may restate a
protocol fact.

Written in five modules by kind, each importable on its own; this package re-exports every name, so a
consumer imports ``from ckesc.protocol import catalogue as cat`` and reads ``cat.X`` whichever module holds it:
:mod:`.schema` (the shape: Field, Layout, FrameSpec), :mod:`.timing` (the time limits), :mod:`.codes` (the code
tables the fields carry), :mod:`.settings` (what an ESC keeps, its defaults, R13's persisted settings) and
:mod:`.frames` (the frame table, its families and :func:`spec`).

Rule ids (F.., R..) refer to ``spec/INTERPRETATIONS.md``; sections to the vendor document.
All multi-byte fields are little-endian (F2).
"""

from .codes import (
    CAN_TEST_OFF,
    CAN_TEST_ON,
    CAN_TEST_REPORT,
    FAULT_CODE_STATUS_BITS,
    FAULT_CODES_1,
    MSG_CONTROL_ANSWER,
    MSG_CONTROL_RESUME,
    MSG_CONTROL_RESUME_EXP,
    MSG_CONTROL_SUSPEND,
    MSG_EXP12_RECORDS,
    SELFTEST_ERROR_MASK,
    STATUS_STATE_BITS,
    THROTTLE_10B_MAX,
    THROTTLE_CHANNELS,
    THROTTLE_GROUPS,
    THROTTLE_MAX,
    Status,
)
from .frames import (
    BY_NAME,
    CATALOGUE,
    ESC_REPORT_FRAMES,
    EXP_REPORT_FRAMES,
    FORMAT_CHANNELS,
    FREQ_READ,
    MESSAGES,
    PSEUDO_BROADCAST,
    SERVICES,
    THROTTLE_FRAMES,
    addressed_channels,
    firmware_date,
    spec,
)
from .schema import (
    Field,
    FrameSpec,
    Layout,
    nibble,
    u8,
    u16,
    u32,
)
from .settings import (
    BAUD_RATES,
    DEFAULT_BAUD_CODE,
    DEFAULT_BITRATE,
    DEFAULT_LED_COLOR,
    DEFAULT_REPORT_INTERVALS,
    EXPAND_COMMANDS,
    INTERVAL_FIELDS,
    LED_BLINK,
    PERSISTED,
    PERSISTED_SETTINGS,
    REPORT_FRAMES,
    REPORT_INTERVAL_FIELDS,
    SETTING_WRITERS,
    ExpandCommand,
    LedColor,
    PersistedSetting,
)
from .timing import (
    ANSWER_DELAY_MAX_S,
    ANSWER_SLOT_S,
    ANSWER_SLOTS,
    COMM_LOSS_TIMEOUT_S,
    CONFIG_WINDOW_S,
    INTERVAL_UNIT_S,
    REPORT_INTERVAL_RANGE,
    RESTART_SLACK_MIN_S,
    answer_slot_s,
    restart_limit_s,
)

__all__ = [name for name in dir() if not name.startswith("_")]
