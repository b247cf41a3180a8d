"""The shape every frame of the catalogue is written in: a :class:`Field` (one named value of a payload), a
:class:`Layout` (one payload: its fields, or a throttle packing), a :class:`FrameSpec` (one frame type of the
document's table) and the field shorthands (:func:`u8`, :func:`u16`, :func:`u32`, :func:`nibble`). No protocol fact
is written here: the facts are the arguments :mod:`.frames` gives them.

All multi-byte fields are little-endian (F2).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntFlag
from types import MappingProxyType
from typing import Mapping

from ..ids import Priority


@dataclass(frozen=True)
class Field:
    """One named value in a payload.

    The value is ``(little-endian word at [offset, offset+size)) >> shift``, masked to ``bits``.
    ``legal`` (an inclusive range) and ``codes`` (the legal discrete values, with their meaning)
    say what the document allows; ``rejected_by`` names the rule that makes an illegal value
    "ignored, never partly applied" (R10) - without it, what a device does with an illegal value is
    OBSERVE. ``scale``/``unit`` turn the raw integer into a physical value (raw * scale unit).
    """

    name: str
    offset: int
    size: int = 1
    shift: int = 0
    bits: int | None = None
    legal: tuple[int, int] | None = None
    codes: Mapping[int, str] | None = None
    default: int | None = None
    unit: str | None = None
    scale: float | None = None
    flags: type[IntFlag] | None = None
    rejected_by: str | None = None
    doc: str = ""

    def __post_init__(self) -> None:
        if self.size not in (1, 2, 4):
            raise ValueError(f"field {self.name}: size must be 1, 2 or 4 bytes")
        width = self.size * 8
        bits = width - self.shift if self.bits is None else self.bits
        if self.shift + bits > width:
            raise ValueError(f"field {self.name}: bits outside its word")
        object.__setattr__(self, "bits", bits)
        if self.codes is not None:
            object.__setattr__(self, "codes", MappingProxyType(dict(self.codes)))

    @property
    def mask(self) -> int:
        return (1 << self.bits) - 1  # type: ignore[operator]

    @property
    def max_raw(self) -> int:
        return self.mask

    def is_legal(self, value: int) -> bool:
        if self.codes is not None and value not in self.codes:
            return False
        if self.legal is not None and not self.legal[0] <= value <= self.legal[1]:
            return False
        return 0 <= value <= self.mask

    def physical(self, raw: int) -> float | int:
        return raw * self.scale if self.scale is not None else raw


@dataclass(frozen=True, eq=False)
class Layout:
    """The payload of one frame kind (the tail byte excluded).

    ``codec`` is ``fields`` (byte/bit fields above), ``throttle14``/``throttle12``/``throttle10``
    (the RawCommand packings, R3-R5) or ``raw`` (payload of unknown structure: 223/224, OBSERVE).
    ``when`` selects a response layout by the request's fields (241: by option).
    """

    name: str
    size: int | None  # payload bytes without the tail; None: any length 0..7 (codec 'raw')
    fields: tuple[Field, ...] = ()
    codec: str = "fields"
    sender: str = "host"  # 'host', 'esc' or 'any'
    when: Mapping[str, int] | None = None
    doc: str = ""

    def field(self, name: str) -> Field:
        for f in self.fields:
            if f.name == name:
                return f
        raise KeyError(name)

    @property
    def field_names(self) -> tuple[str, ...]:
        if self.codec == "throttle12":
            return ("channels", "group")
        if self.codec in ("throttle14", "throttle10"):
            return ("channels",) + (("tail_bits",) if self.codec == "throttle10" else ())
        if self.codec == "raw":
            return ("payload",)
        return tuple(f.name for f in self.fields)


@dataclass(frozen=True, eq=False)
class FrameSpec:
    """One frame type of the document's table (section 4.3.2)."""

    name: str
    title: str
    type_id: int
    service: bool
    section: str
    priority: Priority | None  # None: the table lists none (240/241/242, F5: OBSERVE)
    description: str
    layouts: tuple[Layout, ...] = ()  # messages: one per direction/length
    request: Layout | None = None
    responses: tuple[Layout, ...] = ()  # services: the first is the generic one; () = never answered
    has_tail: bool = True  # False for RawCommand_10b (R5)
    tail_tag: Mapping[int, str] | None = None  # MSG_EXP12: the transfer id names the record (R15)

    @property
    def response(self) -> Layout | None:
        return self.responses[0] if self.responses else None

    @property
    def kind_label(self) -> str:
        return "service" if self.service else "message"

    def response_for(self, request_fields: Mapping[str, object] | None) -> Layout | None:
        """The response layout that answers a request with these fields."""
        if not self.responses:
            return None
        if request_fields:
            for layout in self.responses:
                if layout.when and all(request_fields.get(k) == v for k, v in layout.when.items()):
                    return layout
        return self.responses[0]

    def message_layout(self, size: int) -> Layout | None:
        for layout in self.layouts:
            if layout.size == size:
                return layout
        return None

    @property
    def all_layouts(self) -> tuple[Layout, ...]:
        out = list(self.layouts)
        if self.request is not None:
            out.append(self.request)
        out.extend(self.responses)
        return tuple(out)

def u8(name: str, offset: int, **kw) -> Field:
    return Field(name, offset, 1, **kw)


def u16(name: str, offset: int, **kw) -> Field:
    return Field(name, offset, 2, **kw)


def u32(name: str, offset: int, **kw) -> Field:
    return Field(name, offset, 4, **kw)


def nibble(name: str, offset: int, high: bool, **kw) -> Field:
    return Field(name, offset, 1, shift=4 if high else 0, bits=4, **kw)
