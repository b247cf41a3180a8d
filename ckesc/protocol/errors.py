"""One error tree for the protocol layer (h11 style).

Decoding never raises anything but :class:`DecodeError` (or a subclass) for bad input, and every
message names the frame (when it is known) and the reason.
"""

from __future__ import annotations


class ProtocolError(Exception):
    """Base class; never raised directly."""


class DecodeError(ProtocolError):
    """A frame from the bus does not parse.

    ``frame`` is the catalogue name of the frame when the CAN id identifies one (else ``None``),
    ``reason`` a short machine-stable word, and the message says the rest.
    """

    reason = "malformed"

    def __init__(self, message: str, *, frame: str | None = None) -> None:
        self.frame = frame
        prefix = f"{frame}: " if frame else ""
        super().__init__(prefix + message)


class NotExtendedDataFrameError(DecodeError):
    """Standard (11-bit) id, remote frame, error frame, or an id wider than 29 bits."""

    reason = "not-extended-data-frame"


class LengthError(DecodeError):
    """The payload length is not the one the frame type has."""

    reason = "wrong-length"


class TailError(DecodeError):
    """Start/end/toggle bits of the tail byte are not those of a single-frame transfer."""

    reason = "not-single-frame"


class ReservedNodeError(DecodeError):
    """The frame comes from a reserved node id (0x7E, 0x7F)."""

    reason = "reserved-node-id"


class UnknownTypeError(DecodeError):
    """The type id is neither in the catalogue nor in the CKESC vendor ranges."""

    reason = "unknown-type-id"


class EncodeError(ProtocolError):
    """We were asked to build a frame the wire format cannot carry (unknown field, value too wide, ...)."""
