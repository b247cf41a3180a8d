"""Tail byte (F2) and transfer-id counters (F3).

Every transfer in this protocol is a single frame: start=1, end=1, toggle=0, so a well-formed tail
byte is ``0xC0 | transfer_id``.
"""

from __future__ import annotations

from typing import Callable, NamedTuple

from .errors import EncodeError

SINGLE_FRAME = 0xC0
TRANSFER_ID_MODULO = 32


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


def parse_tail(byte: int) -> Tail:
    return Tail(bool(byte & 0x80), bool(byte & 0x40), bool(byte & 0x20), byte & 0x1F)


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
        self._next[slot] = (tid + 1) % TRANSFER_ID_MODULO
        return tid

    def peek(self, key: object, destination: int | None = None) -> int:
        slot = (key, destination)
        if slot not in self._next and self._first:
            self._next[slot] = self._first() % TRANSFER_ID_MODULO
        return self._next.get(slot, 0)
