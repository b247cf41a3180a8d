"""The code tables the frames' fields carry: MSG1's status word (R7, R8), the MSG Control commands and CAN Test
options, the throttle scales (R3-R6), the self-test fault codes and MSG_EXP12's record tags (R15)."""

from __future__ import annotations

from enum import IntFlag
from types import MappingProxyType
from typing import Mapping


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

#: MSG Control commands (4.4.2).
MSG_CONTROL_ANSWER = 0x00000000
MSG_CONTROL_SUSPEND = 0x55555555
MSG_CONTROL_RESUME = 0xAAAAAAAA
MSG_CONTROL_RESUME_EXP = 0xEEEEEEEE

#: CAN Test options (4.4.1).
CAN_TEST_REPORT = 0x00
CAN_TEST_ON = 0xAA
CAN_TEST_OFF = 0x55

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

#: MSG_EXP12's temperature records by the transfer id of its tail byte, 0xC1..0xC5 (4.4.14, R15).
MSG_EXP12_RECORDS = MappingProxyType({1: "mcu", 2: "mos", 3: "cap", 4: "motor", 5: "reserved"})

#: MSG1 status bits that follow the ESC's state and settings (R7, R8): direction, throttle source, comm loss, running.
STATUS_STATE_BITS = Status.DIRECTION_CCW | Status.THROTTLE_PWM | Status.COMM_FAULT | Status.RUNNING
