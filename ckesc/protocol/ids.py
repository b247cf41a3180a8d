"""29-bit CAN identifiers of UAVCAN v0 as the document uses them (section 4.1.2, rule F1).

Message:   priority<<24 | type_id<<8  | 0<<7 | source
Service:   priority<<24 | service<<16 | request<<15 | destination<<8 | 1<<7 | source
Anonymous: priority<<24 | discriminator<<10 | (type_id & 3)<<8 | 0<<7 | 0

The CKESC host is node 0 (4.4.18 note 8) and sends messages from node 0 with the *full* type id
(F1). Structurally such a frame is an anonymous UAVCAN v0 frame, and DroneCAN stacks read it so;
:func:`parse_can_id` therefore flags it (``anonymous=True``, with the discriminator and the two
low type-id bits a DroneCAN stack would use) while reporting the full CKESC type id.
"""

from __future__ import annotations

from enum import IntEnum
from typing import NamedTuple

CAN_EXT_MASK = 0x1FFFFFFF

HOST_NODE_ID = 0  # 4.4.18 note 8
DEFAULT_ESC_NODE_ID = 0x7D  # 4.4.18 note 4, F7
RESERVED_NODE_IDS = frozenset({0x7E, 0x7F})  # F7 (0 is the host's)
ESC_NODE_IDS = range(1, 0x7E)  # 1..0x7D, F7

#: Vendor id ranges of section 4.3.1.
MESSAGE_VENDOR_RANGE = range(20000, 21000)
SERVICE_VENDOR_RANGE = range(200, 256)


class Priority(IntEnum):
    """Priority names of section 4.3.2 (libcanard's constants)."""

    HIGHEST = 0x00
    HIGH = 0x08
    MEDIUM = 0x10
    LOW = 0x18
    LOWEST = 0x1F


class Kind(IntEnum):
    MESSAGE = 0
    REQUEST = 1
    RESPONSE = 2

    @property
    def label(self) -> str:
        return self.name.lower()


class CanId(NamedTuple):
    kind: Kind
    priority: int
    type_id: int  # message type id (16 bits) or service id (8 bits)
    source: int
    destination: int | None  # None for messages
    anonymous: bool = False  # message from node 0: an anonymous frame to a DroneCAN stack
    discriminator: int | None = None


def _check(name: str, value: int, lo: int, hi: int) -> None:
    if not isinstance(value, int) or not lo <= value <= hi:
        from .errors import EncodeError

        raise EncodeError(f"{name} must be an integer in {lo}..{hi}, got {value!r}")


def message_id(priority: int, type_id: int, source: int) -> int:
    """CAN id of a message frame (F1)."""
    _check("priority", priority, 0, 31)
    _check("message type id", type_id, 0, 0xFFFF)
    _check("source node id", source, 0, 127)
    return priority << 24 | type_id << 8 | source


def service_id(priority: int, service: int, request: bool, destination: int, source: int) -> int:
    """CAN id of a service request or response frame (F1)."""
    _check("priority", priority, 0, 31)
    _check("service type id", service, 0, 0xFF)
    _check("destination node id", destination, 0, 127)
    _check("source node id", source, 0, 127)
    return priority << 24 | service << 16 | int(bool(request)) << 15 | destination << 8 | 0x80 | source


def parse_can_id(can_id: int) -> CanId:
    """Split a 29-bit id into its fields. The caller has checked it is an extended id."""
    priority = (can_id >> 24) & 0x1F
    source = can_id & 0x7F
    if can_id & 0x80:
        kind = Kind.REQUEST if can_id & 0x8000 else Kind.RESPONSE
        return CanId(kind, priority, (can_id >> 16) & 0xFF, source, (can_id >> 8) & 0x7F)
    if source == 0:
        return CanId(Kind.MESSAGE, priority, (can_id >> 8) & 0xFFFF, 0, None, True, (can_id >> 10) & 0x3FFF)
    return CanId(Kind.MESSAGE, priority, (can_id >> 8) & 0xFFFF, source, None)


def priority_name(priority: int) -> str:
    """'MEDIUM' for 16; the number itself for values with no name."""
    try:
        return Priority(priority).name
    except ValueError:
        return str(priority)
