"""Tail byte (F2) and transfer-id counters (F3).

Every transfer in this protocol is a single frame: start=1, end=1, toggle=0, so a well-formed tail
byte is ``0xC0 | transfer_id``.
"""

from __future__ import annotations

from typing import Callable, NamedTuple

from .errors import EncodeError

SINGLE_FRAME = 0xC0
#: F2/F3: a transfer id is five bits of the tail byte, and counts modulo 32
TRANSFER_ID_MODULO = 32
TRANSFER_ID_MASK = TRANSFER_ID_MODULO - 1


class Tail(NamedTuple):
    start: bool
    end: bool
    toggle: bool
    transfer_id: int

    @property
    def single_frame(self) -> bool:
        return self.start and self.end and not self.toggle


def tail_byte(transfer_id: int, *, start: bool = True, end: bool = True, toggle: bool = False) -> int:
    if not isinstance(transfer_id, int) or not 0 <= transfer_id < TRANSFER_ID_MODULO:
        raise EncodeError(f"transfer id must be in 0..31, got {transfer_id!r}")
    return int(start) << 7 | int(end) << 6 | int(toggle) << 5 | transfer_id


#: a single-frame transfer's tail byte by transfer id, as one byte (``TAIL_BYTES[tid] == bytes((tail_byte(tid),))``):
#: the hot paths that stamp a frame's transfer id (a report, a stream's command) index it instead of building it
TAIL_BYTES: tuple[bytes, ...] = tuple(bytes((tail_byte(tid),)) for tid in range(TRANSFER_ID_MODULO))


def parse_tail(byte: int) -> Tail:
    return Tail(bool(byte & 0x80), bool(byte & 0x40), bool(byte & 0x20), byte & TRANSFER_ID_MASK)


def tail_transfer_id(byte: int) -> int:
    """The transfer id a tail byte carries (F2), whatever its start/end/toggle bits say."""
    return byte & TRANSFER_ID_MASK


def next_transfer_id(transfer_id: int, step: int = 1) -> int:
    """The transfer id ``step`` transfers after ``transfer_id`` on one counter (F3: +1 per transfer, modulo 32)."""
    return (transfer_id + step) % TRANSFER_ID_MODULO


class TransferIdCounter:
    """One counter per (frame type, destination) at a sender, +1 per transfer, modulo 32 (F3).

    ``key`` is whatever identifies the frame type for the caller, e.g. ``(Kind.REQUEST, 214)``.
    Messages use ``destination=None``.
    """

    def __init__(self, first: Callable[[], int] | None = None) -> None:
        self._next: dict[tuple[object, int | None], int] = {}
        self._first = first  # each counter's first value (None: 0); F3 says only +1 per transfer

    def next(self, key: object, destination: int | None = None) -> int:
        slot = (key, destination)
        tid = self._next.get(slot)
        if tid is None:
            tid = self._first() % TRANSFER_ID_MODULO if self._first else 0
        self._next[slot] = (tid + 1) % TRANSFER_ID_MODULO  # (next_transfer_id's, inline: every frame a sender sends)
        return tid

    def peek(self, key: object, destination: int | None = None) -> int:
        slot = (key, destination)
        if slot not in self._next and self._first:
            self._next[slot] = self._first() % TRANSFER_ID_MODULO
        return self._next.get(slot, 0)


# --------------------------------------------------------------------------------------------------
# Multi-frame transfers (DroneCAN's, which this protocol never sends: R17's robustness cases build them)

#: The CKESC document names no DSDL data type signature for its frames; a multi-frame transfer of one of its
#: types is seeded with this one (DroneCAN's receivers check the CRC with the signature of the type they know).
NO_SIGNATURE = 0


def crc16(data: bytes, crc: int = 0xFFFF) -> int:
    """CRC-16-CCITT (poly 0x1021, initial 0xFFFF, no reflection, no final xor): DroneCAN's transfer CRC."""
    for byte in data:
        crc ^= byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1021) & 0xFFFF if crc & 0x8000 else (crc << 1) & 0xFFFF
    return crc


def transfer_crc(payload: bytes, signature: int = NO_SIGNATURE) -> int:
    """DroneCAN's transfer CRC of a multi-frame transfer: CRC-16-CCITT over the data type signature (64 bits,
    little-endian), then the payload."""
    return crc16(bytes(payload), crc16(signature.to_bytes(8, "little")))


def multi_frame(payload: bytes, transfer_id: int, *, signature: int = NO_SIGNATURE, chunk: int = 7) -> list[bytes]:
    """The frames' data of a multi-frame transfer of ``payload`` as DroneCAN sends one: the transfer CRC
    (little-endian) ahead of the payload, ``chunk`` bytes (7 on classic CAN) and a tail byte a frame, start on the
    first, end on the last, the toggle alternating from 0. A payload that would fit one frame is split too (a
    smaller ``chunk``: at least two frames), so that what is built is always a multi-frame transfer."""
    if not 1 <= chunk <= 7:
        raise EncodeError(f"a frame carries 1..7 bytes of a multi-frame transfer, not {chunk}")
    crc = transfer_crc(payload, signature)
    body = bytes((crc & 0xFF, crc >> 8)) + bytes(payload)
    if len(body) <= chunk:
        chunk = max(1, (len(body) + 1) // 2)
    pieces = [body[i:i + chunk] for i in range(0, len(body), chunk)]
    return [piece + bytes((tail_byte(transfer_id, start=i == 0, end=i == len(pieces) - 1, toggle=bool(i % 2)),))
            for i, piece in enumerate(pieces)]
