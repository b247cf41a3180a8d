"""The sans-IO protocol core: CAN ids, tail bytes, the frame catalogue and payload codecs.

Nothing in this package imports ``can``, ``time``, threads or sockets: frames go in, typed frames
come out, and frames to send are returned as :class:`WireFrame` for an IO adapter to put on a bus.
"""

from .catalogue import (
    BAUD_RATES,
    BY_NAME,
    CATALOGUE,
    EXPAND_COMMANDS,
    MESSAGES,
    SERVICES,
    Field,
    FrameSpec,
    Layout,
    LedColor,
    Status,
    spec,
)
from .codecs import (
    pack_throttle10,
    pack_throttle12,
    pack_throttle14,
    unpack_throttle10,
    unpack_throttle12,
    unpack_throttle14,
)
from .errors import (
    DecodeError,
    EncodeError,
    LengthError,
    NotExtendedDataFrameError,
    ProtocolError,
    ReservedNodeError,
    TailError,
    UnknownTypeError,
)
from .frame import Decoder, Frame, WireFrame, classify, decode, encode
from .ids import CanId, Kind, Priority, message_id, parse_can_id, priority_name, service_id
from .legality import IllegalCase, illegal_cases, illegal_fields
from .transfer import Tail, TransferIdCounter, parse_tail, tail_byte

__all__ = [name for name in dir() if not name.startswith("_")]
