"""Typed frames: decoding what comes off the bus, encoding what goes on it.

No IO here. :func:`decode` takes anything shaped like a ``can.Message`` (``arbitration_id``,
``data``, ``is_extended_id``, and optionally ``is_remote_frame``, ``is_error_frame``,
``timestamp``) or a :class:`WireFrame`; :func:`encode` returns a :class:`WireFrame` that an IO
adapter turns into a ``can.Message``.
"""

from __future__ import annotations

from enum import IntFlag
from functools import cache, partial
from typing import Any, Mapping, NamedTuple

from . import catalogue as cat
from .catalogue import FrameSpec, Layout
from .codecs import codec_for
from .errors import (
    DecodeError,
    EncodeError,
    LengthError,
    NotExtendedDataFrameError,
    ReservedNodeError,
    TailError,
    UnknownTypeError,
)
from .ids import (
    CAN_EXT_MASK,
    MESSAGE_VENDOR_RANGE,
    RESERVED_NODE_IDS,
    SERVICE_VENDOR_RANGE,
    Kind,
    Priority,
    message_id,
    priority_name,
    service_id,
)
from .transfer import SINGLE_FRAME, tail_byte, tail_transfer_id

#: Priority used for frames whose table entry lists none (240/241/242, F5: OBSERVE).
FALLBACK_PRIORITY = Priority.MEDIUM


class WireFrame(NamedTuple):
    """A frame as it goes on the wire: a 29-bit id and up to 8 data bytes."""

    arbitration_id: int
    data: bytes
    timestamp: float = 0.0
    is_extended_id: bool = True

    def __str__(self) -> str:  # candump style
        return f"{self.arbitration_id:08X}#{self.data.hex().upper()}"


#: ``new_wire((arbitration_id, data, timestamp, is_extended_id))``: a :class:`WireFrame` of all four fields, made
#: without the Python-level constructor namedtuple adds: the hot paths of a simulated run (every frame on the bus)
new_wire = partial(tuple.__new__, WireFrame)


class Frame:
    """A decoded frame. ``fields`` holds raw wire integers (lists for throttle channels);
    :meth:`physical` gives scaled values and names of codes."""

    __slots__ = (
        "spec",
        "layout",
        "kind",
        "type_id",
        "priority",
        "source",
        "destination",
        "transfer_id",
        "fields",
        "data",
        "timestamp",
        "anonymous",
    )

    def __init__(self, spec, layout, kind, type_id, priority, source, destination, transfer_id, fields, data, timestamp, anonymous=False):
        self.spec: FrameSpec | None = spec
        self.layout: Layout | None = layout
        self.kind: Kind = kind
        self.type_id: int = type_id
        self.priority: int = priority
        self.source: int = source
        self.destination: int | None = destination
        self.transfer_id: int | None = transfer_id  # None for RawCommand_10b, which has no tail (R5)
        self.fields: dict[str, Any] = fields
        self.data: bytes = data
        self.timestamp: float | None = timestamp
        self.anonymous: bool = anonymous

    @property
    def name(self) -> str:
        return self.spec.name if self.spec is not None else "unknown"

    @property
    def known(self) -> bool:
        return self.spec is not None

    @property
    def can_id(self) -> int:
        if self.kind is Kind.MESSAGE:
            return message_id(self.priority, self.type_id, self.source)
        return service_id(self.priority, self.type_id, self.kind is Kind.REQUEST, self.destination or 0, self.source)

    def physical(self) -> dict[str, Any]:
        """Fields with units applied and codes/flags named, for people."""
        if self.layout is None:
            return dict(self.fields)
        out: dict[str, Any] = {}
        by_name = {f.name: f for f in self.layout.fields}
        for name, raw in self.fields.items():
            f = by_name.get(name)
            if f is None:
                out[name] = raw
            elif f.flags is not None:
                out[name] = [label for bit, label in _flag_labels(f.flags) if raw & bit]
            elif f.codes is not None and raw in f.codes:
                out[name] = f.codes[raw]
            elif f.scale is not None:
                out[name] = round(raw * f.scale, 6)
            else:
                out[name] = raw
        if self.spec is not None and self.spec.tail_tag is not None and self.transfer_id is not None:
            out["record"] = self.spec.tail_tag.get(self.transfer_id, self.transfer_id)
        return out

    def to_json(self) -> dict[str, Any]:
        return {
            "id": self.type_id,
            "name": self.name,
            "kind": self.kind.label,
            "source": self.source,
            "destination": self.destination,
            "priority": self.priority,
            "priority_name": priority_name(self.priority),
            "transfer_id": self.transfer_id,
            "fields": self.fields,
            "decoded": self.physical(),
            "timestamp": self.timestamp,
        }

    def __repr__(self) -> str:
        dst = f"->{self.destination}" if self.destination is not None else ""
        return f"<Frame {self.name} {self.kind.label} {self.source}{dst} tid={self.transfer_id} {self.fields}>"


@cache
def _flag_labels(flags: type[IntFlag]) -> tuple[tuple[int, str], ...]:
    """(bit, lower-case name) of every non-zero member, in iteration order: Frame.physical names flags
    with plain int tests instead of IntFlag arithmetic (which dominated ``ckesc decode``'s profile)."""
    return tuple((int(m), m.name.lower()) for m in flags if m)


def frame_bits(dlc: int) -> int:
    """Bit times on the wire of an extended (29-bit) data frame with ``dlc`` data bytes, with the 3-bit
    interframe space (stuff bits not counted)."""
    return 67 + 8 * dlc


def classify(can_id: int) -> tuple[Kind, int, int, int | None, FrameSpec | None]:
    """Fast id classification: (kind, type id, source, destination, catalogue entry or None)."""
    if can_id & 0x80:
        kind = Kind.REQUEST if can_id & 0x8000 else Kind.RESPONSE
        type_id = (can_id >> 16) & 0xFF
        return kind, type_id, can_id & 0x7F, (can_id >> 8) & 0x7F, cat.SERVICES.get(type_id)
    type_id = (can_id >> 8) & 0xFFFF
    return Kind.MESSAGE, type_id, can_id & 0x7F, None, cat.MESSAGES.get(type_id)


def read_form(kind: Kind, spec: FrameSpec, data: bytes) -> tuple[Layout | None, int | None, bytes]:
    """A frame's form, as the decoder reads it before any field (F2, the table's length: R17's classes): its layout (a
    message's by its length, a request's; None for a response, whose layout is its request's), its transfer id and its
    payload. Raises :class:`TailError` (not a single-frame transfer) or :class:`LengthError` (not the table's length).
    One reading for the decoder and for what the bus reader takes the host's frames to be (``evidence/taken.py``),
    which reads no field."""
    name = spec.name
    if spec.has_tail:
        if not data:
            raise LengthError("no data: every frame ends with a tail byte (F2)", frame=name)
        tail = data[-1]
        if tail & 0xE0 != SINGLE_FRAME:
            raise TailError(
                f"tail byte 0x{tail:02X} has start={tail >> 7 & 1} end={tail >> 6 & 1} toggle={tail >> 5 & 1}; "
                "a single-frame transfer has start=1 end=1 toggle=0 (F2)",
                frame=name,
            )
        tid: int | None = tail_transfer_id(tail)
        payload = data[:-1]
    else:
        tid = None
        payload = data
    n = len(payload)
    if kind is Kind.MESSAGE:
        layout = spec.message_layout(n)
        if layout is None:
            expected = " or ".join(str(lay.size + spec.has_tail) for lay in spec.layouts)  # type: ignore[operator]
            raise LengthError(f"{len(data)} data bytes, expected {expected}", frame=name)
        return layout, tid, payload
    if kind is Kind.REQUEST:
        layout = spec.request
        assert layout is not None
        if layout.size is not None and n != layout.size:
            raise LengthError(f"{kind.label}: {len(data)} data bytes, expected {layout.size + 1}", frame=name)
        return layout, tid, payload
    return None, tid, payload


class Decoder:
    """Decodes frames with options that a DUT profile may set, and remembers outstanding
    requests so that responses whose layout depends on the request (241) decode fully."""

    def __init__(self, *, nibble_order: str = "lsb", track_requests: bool = True) -> None:
        self.nibble_order = nibble_order
        self.track_requests = track_requests
        self._pending: dict[tuple[int, int, int, int | None], dict] = {}

    def decode(self, msg: Any, *, request: Frame | Mapping[str, Any] | None = None) -> Frame:
        """Decode one frame or raise :class:`DecodeError` (and nothing else) naming the reason."""
        try:
            return self._decode(msg, request)
        except DecodeError:
            raise
        except Exception as exc:  # pragma: no cover - a bug here must still not escape as another type
            raise DecodeError(f"internal decoder error on {msg!r}: {exc!r}") from exc

    def _decode(self, msg: Any, request: Frame | Mapping[str, Any] | None) -> Frame:
        if getattr(msg, "is_error_frame", False):
            raise NotExtendedDataFrameError("error frame")
        if getattr(msg, "is_remote_frame", False):
            raise NotExtendedDataFrameError("remote frame (RTR): only data frames are used")
        can_id = msg.arbitration_id
        if not getattr(msg, "is_extended_id", True):
            raise NotExtendedDataFrameError(f"standard 11-bit id 0x{can_id:03X}: the protocol uses 29-bit ids")
        if not isinstance(can_id, int) or not 0 <= can_id <= CAN_EXT_MASK:
            raise NotExtendedDataFrameError(f"id {can_id!r} is not a 29-bit value")
        raw = msg.data
        if not isinstance(raw, (bytes, bytearray, memoryview, list, tuple)):
            raise DecodeError(f"data must be bytes, got {type(raw).__name__}")
        data = bytes(raw)
        timestamp = getattr(msg, "timestamp", None)

        kind, type_id, source, destination, spec = classify(can_id)
        priority = (can_id >> 24) & 0x1F
        anonymous = kind is Kind.MESSAGE and source == 0
        name = spec.name if spec is not None else None
        if len(data) > 8:
            raise LengthError(f"{len(data)} data bytes: classic CAN carries at most 8", frame=name)
        if source in RESERVED_NODE_IDS:
            raise ReservedNodeError(f"source node id {source} is reserved (F7)", frame=name)

        if spec is None:
            vendor = MESSAGE_VENDOR_RANGE if kind is Kind.MESSAGE else SERVICE_VENDOR_RANGE
            label = "message type" if kind is Kind.MESSAGE else "service"
            if type_id not in vendor:
                raise UnknownTypeError(f"{label} id {type_id} is outside the CKESC vendor range [{vendor.start}, {vendor.stop})")
            tid = tail_transfer_id(data[-1]) if data else None
            return Frame(None, None, kind, type_id, priority, source, destination, tid, {"payload": list(data)}, data, timestamp, anonymous)

        layout, tid, payload = read_form(kind, spec, data)
        if layout is None:  # a response: its layout is its request's
            if request is None:
                request = self._pending.pop((type_id, destination, source, tid), None)
            req_fields = request.fields if isinstance(request, Frame) else request
            layout = spec.response_for(req_fields)
            if layout is None:
                raise DecodeError(f"{spec.title} is never answered (R14), yet a response came", frame=name)
            if layout.size is not None and len(payload) != layout.size:
                raise LengthError(f"{kind.label}: {len(data)} data bytes, expected {layout.size + 1}", frame=name)

        fields = codec_for(layout, self.nibble_order).decode(payload)
        if spec.tail_tag is not None:
            fields["record"] = tid
        frame = Frame(spec, layout, kind, type_id, priority, source, destination, tid, fields, data, timestamp, anonymous)
        if kind is Kind.REQUEST and len(spec.responses) > 1 and self.track_requests:
            self._remember(frame)
        return frame

    def _remember(self, frame: Frame) -> None:
        if len(self._pending) > 4096:  # a log full of unanswered requests must not grow memory without bound
            self._pending.clear()
        # keyed as the response will be: (service, response destination = requester, responder, tid)
        self._pending[(frame.type_id, frame.source, frame.destination, frame.transfer_id)] = frame.fields


_DEFAULT = Decoder(track_requests=False)


def decode(msg: Any, *, request: Frame | Mapping[str, Any] | None = None) -> Frame:
    """Decode one frame with default options (R4 nibble order 'lsb'). Stateless: a 241 response
    decodes with its per-option layout only when ``request`` is given (or use a :class:`Decoder`)."""
    return _DEFAULT.decode(msg, request=request)


def encode(
    frame: str | FrameSpec,
    fields: Mapping[str, Any] | None = None,
    *,
    kind: Kind | str | None = None,
    source: int,
    destination: int | None = None,
    transfer_id: int = 0,
    priority: int | None = None,
    layout: str | None = None,
    nibble_order: str = "lsb",
    timestamp: float = 0.0,
) -> WireFrame:
    """Build one frame. Field values must fit their wire width (else :class:`EncodeError`), but
    may be outside the document's legal range: the suite sends illegal values on purpose (see
    :func:`ckesc.protocol.illegal_fields`).

    ``kind`` defaults to ``message`` for messages and ``request`` for services. For messages with
    several layouts (20013) the layout is chosen by ``layout`` or by the field names given.
    For MSG_EXP12 a ``record`` field sets the transfer id (R15).
    """
    spec = frame if isinstance(frame, FrameSpec) else cat.spec(frame)
    values = dict(fields or {})
    if isinstance(kind, str):
        kind = Kind[kind.upper()]
    if kind is None:
        kind = Kind.REQUEST if spec.service else Kind.MESSAGE
    if spec.service == (kind is Kind.MESSAGE):
        raise EncodeError(f"{spec.name} is a {spec.kind_label}, not a {kind.label}")
    if priority is None:
        priority = spec.priority if spec.priority is not None else FALLBACK_PRIORITY

    if spec.tail_tag is not None and "record" in values:
        transfer_id = values.pop("record")

    chosen: Layout | None
    if kind is Kind.MESSAGE:
        chosen = _pick_message_layout(spec, layout, values)
        can_id = message_id(priority, spec.type_id, source)
    else:
        if destination is None:
            raise EncodeError(f"{spec.name}: a service frame needs a destination node id")
        if kind is Kind.REQUEST:
            chosen = spec.request
        elif layout is not None:
            chosen = next((lay for lay in spec.responses if lay.name == layout), None)
            if chosen is None:
                raise EncodeError(f"{spec.name}: no response layout {layout!r}")
        else:
            chosen = pick_response_layout(spec, values)
        if chosen is None:
            raise EncodeError(f"{spec.title} has no response (R14)")
        can_id = service_id(priority, spec.type_id, kind is Kind.REQUEST, destination, source)

    payload = codec_for(chosen, nibble_order).encode(values)
    data = payload if not spec.has_tail else payload + bytes([tail_byte(transfer_id)])
    return WireFrame(can_id, data, timestamp)


def _pick_message_layout(spec: FrameSpec, name: str | None, values: Mapping[str, Any]) -> Layout:
    if name is not None:
        for lay in spec.layouts:
            if lay.name == name:
                return lay
        raise EncodeError(f"{spec.name}: no layout {name!r}; has {', '.join(lay.name for lay in spec.layouts)}")
    if len(spec.layouts) == 1:
        return spec.layouts[0]
    for lay in spec.layouts:
        if set(values) <= set(lay.field_names) and values:
            return lay
    raise EncodeError(f"{spec.name}: say which layout ({', '.join(lay.name for lay in spec.layouts)})")


def pick_response_layout(spec: FrameSpec, values: Mapping[str, Any]) -> Layout | None:
    """The response layout whose fields are the ones given (241: by option), else the generic one."""
    for lay in spec.responses[1:]:
        if values and set(values) <= set(lay.field_names) and (lay.when is None or all(values.get(k, v) == v for k, v in lay.when.items() if k in lay.field_names)):
            return lay
    return spec.response
