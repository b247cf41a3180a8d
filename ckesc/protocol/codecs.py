"""Payload codecs: bytes <-> field dicts, driven by the catalogue's layouts.

Each layout is compiled once into a :class:`LayoutCodec` (a ``struct`` for its words and a plan for
bit fields), so decoding a report costs one ``unpack_from`` and a ``dict``. The three throttle
packings are plain functions (R3, R4, R5), also usable on their own.
"""

from __future__ import annotations

import struct
from functools import cache
from typing import Mapping, Sequence

from .catalogue import Layout
from .errors import EncodeError

_WORD = {1: "B", 2: "H", 4: "I"}

# ---------------------------------------------------------------------------------------------------
# Throttle packings


def pack_throttle14(channels: Sequence[int]) -> bytes:
    """R3: four 14-bit channels, MSB-first bit stream, each value as its low 8 bits then its upper 6
    bits (DroneCAN int14). ``[1000]*4`` -> ``E8 0F A0 3E 80 FA 03`` (the document's example)."""
    if len(channels) != 4:
        raise EncodeError(f"raw_command_14b carries exactly 4 channels, got {len(channels)}")
    stream = 0
    for v in channels:
        _check_width("channel", v, 14)
        stream = (stream << 14) | ((v & 0xFF) << 6) | (v >> 8)
    return stream.to_bytes(7, "big")


def unpack_throttle14(payload: bytes) -> list[int]:
    stream = int.from_bytes(payload[:7], "big")
    out = []
    for i in range(3, -1, -1):
        chunk = (stream >> (14 * i)) & 0x3FFF
        out.append(((chunk >> 6) & 0xFF) | ((chunk & 0x3F) << 8))
    return out


#: R4: RawCommand_12b's payload byte that names its group (the four channels' 48 bits before it)
THROTTLE12_GROUP_BYTE = 6


def pack_throttle12(channels: Sequence[int], group: int, *, nibble_order: str = "lsb") -> bytes:
    """R4: four 12-bit channels A..D of group g, LSB-first:
    p0=A[7:0] p1=B[3:0]<<4|A[11:8] p2=B[11:4] p3=C[7:0] p4=D[3:0]<<4|C[11:8] p5=D[11:4] p6=g.
    ``nibble_order='swapped'`` puts A[11:8] in the high nibble of p1 (and C[11:8] of p4) instead:
    the one alternative a DUT profile may select."""
    if len(channels) != 4:
        raise EncodeError(f"raw_command_12b carries exactly 4 channels, got {len(channels)}")
    for v in channels:
        _check_width("channel", v, 12)
    _check_width("group", group, 8)
    a, b, c, d = channels
    out = bytearray((a | b << 12 | c << 24 | d << 36).to_bytes(THROTTLE12_GROUP_BYTE, "little"))
    if nibble_order == "swapped":
        out[1] = _swap_nibbles(out[1])
        out[4] = _swap_nibbles(out[4])
    elif nibble_order != "lsb":
        raise EncodeError(f"nibble_order must be 'lsb' or 'swapped', got {nibble_order!r}")
    out.append(group)
    return bytes(out)


def unpack_throttle12(payload: bytes, *, nibble_order: str = "lsb") -> tuple[list[int], int]:
    body = bytearray(payload[:THROTTLE12_GROUP_BYTE])
    if nibble_order == "swapped":
        body[1] = _swap_nibbles(body[1])
        body[4] = _swap_nibbles(body[4])
    v = int.from_bytes(body, "little")
    return [v & 0xFFF, (v >> 12) & 0xFFF, (v >> 24) & 0xFFF, (v >> 36) & 0xFFF], payload[THROTTLE12_GROUP_BYTE]


TAIL_BITS_10B = 0b1100  # R5: the host writes start=1, end=1, toggle=0 in the high nibble of payload[7]


def pack_throttle10(channels: Sequence[int], *, tail_bits: int = TAIL_BITS_10B) -> bytes:
    """R5: six 10-bit channels packed LSB-first over all 8 bytes; the high nibble of the last byte
    (bits 60..63) carries ``tail_bits``, which the ESC ignores."""
    if len(channels) != 6:
        raise EncodeError(f"raw_command_10b carries exactly 6 channels, got {len(channels)}")
    v = 0
    for i, ch in enumerate(channels):
        _check_width("channel", ch, 10)
        v |= ch << (10 * i)
    _check_width("tail_bits", tail_bits, 4)
    return (v | tail_bits << 60).to_bytes(8, "little")


def unpack_throttle10(payload: bytes) -> tuple[list[int], int]:
    v = int.from_bytes(payload[:8], "little")
    return [(v >> (10 * i)) & 0x3FF for i in range(6)], v >> 60


def _swap_nibbles(b: int) -> int:
    return ((b & 0x0F) << 4) | (b >> 4)


def _check_width(name: str, value: object, bits: int) -> None:
    if not isinstance(value, int) or isinstance(value, bool) or not 0 <= value < (1 << bits):
        raise EncodeError(f"{name} must be an integer in 0..{(1 << bits) - 1}, got {value!r}")


# ---------------------------------------------------------------------------------------------------
# Field layouts


class LayoutCodec:
    """A layout compiled for speed. ``decode(payload)`` assumes the length was checked."""

    __slots__ = ("layout", "_struct", "_plan", "_simple", "_names", "_nibble_order", "_known", "_n_words", "_fill")

    def __init__(self, layout: Layout, nibble_order: str = "lsb") -> None:
        self.layout = layout
        self._nibble_order = nibble_order
        words: list[tuple[int, int]] = sorted({(f.offset, f.size) for f in layout.fields})
        fmt, pos = "<", 0
        for offset, size in words:
            if offset < pos:
                raise ValueError(f"layout {layout.name}: overlapping words at {offset}")
            fmt += "x" * (offset - pos) + _WORD[size]
            pos = offset + size
        self._struct = struct.Struct(fmt)
        index = {w: i for i, w in enumerate(words)}
        self._plan = tuple(
            (f.name, index[(f.offset, f.size)], f.shift, f.mask, f.size * 8 == f.bits) for f in layout.fields
        )
        self._names = tuple(f.name for f in layout.fields)
        self._known = frozenset(layout.field_names)
        self._n_words = len(words)
        # (name, word index, shift, mask, default) in field order, for encode
        self._fill = tuple((f.name, index[(f.offset, f.size)], f.shift, f.mask, f.default) for f in layout.fields)
        self._simple = len(words) == len(layout.fields) and all(p[4] for p in self._plan)

    def decode(self, payload: bytes) -> dict:
        codec = self.layout.codec
        if codec == "fields":
            words = self._struct.unpack_from(payload)
            if self._simple:
                return dict(zip(self._names, words))
            return {name: (words[i] >> shift) & mask for name, i, shift, mask, _ in self._plan}
        if codec == "throttle14":
            return {"channels": unpack_throttle14(payload)}
        if codec == "throttle12":
            channels, group = unpack_throttle12(payload, nibble_order=self._nibble_order)
            return {"channels": channels, "group": group}
        if codec == "throttle10":
            channels, tail_bits = unpack_throttle10(payload)
            return {"channels": channels, "tail_bits": tail_bits}
        return {"payload": list(payload)}  # raw

    def encode(self, values: Mapping[str, object]) -> bytes:
        layout = self.layout
        unknown = values.keys() - self._known
        if unknown:
            raise EncodeError(
                f"{layout.name}: unknown field(s) {', '.join(sorted(unknown))}; this layout has "
                f"{', '.join(layout.field_names) or 'no fields'}"
            )
        codec = layout.codec
        if codec == "throttle14":
            return pack_throttle14(_need(values, "channels", layout))
        if codec == "throttle12":
            return pack_throttle12(_need(values, "channels", layout), _need(values, "group", layout), nibble_order=self._nibble_order)
        if codec == "throttle10":
            return pack_throttle10(_need(values, "channels", layout), tail_bits=values.get("tail_bits", TAIL_BITS_10B))  # type: ignore[arg-type]
        if codec == "raw":
            payload = values.get("payload", [])
            if not isinstance(payload, (list, tuple, bytes, bytearray)) or len(payload) > 7:
                raise EncodeError(f"{layout.name}: payload must be a list of at most 7 bytes")
            for b in payload:
                _check_width("payload byte", b, 8)
            return bytes(payload)
        words = [0] * self._n_words
        for name, i, shift, mask, default in self._fill:
            value = values.get(name, default)
            if value is None:
                raise EncodeError(f"{layout.name}: field {name} is required (no default)")
            if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= mask:
                raise EncodeError(f"{layout.name}: {name} must be an integer in 0..{mask}, got {value!r}")
            words[i] |= value << shift
        return self._struct.pack(*words) if layout.size is None else self._struct.pack(*words).ljust(layout.size, b"\0")


def _need(values: Mapping[str, object], name: str, layout: Layout):
    if name not in values:
        raise EncodeError(f"{layout.name}: field {name} is required")
    return values[name]


@cache
def codec_for(layout: Layout, nibble_order: str = "lsb") -> LayoutCodec:
    return LayoutCodec(layout, nibble_order)
