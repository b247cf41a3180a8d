"""Property tests: every catalogue frame type and layout round-trips, and no input makes the decoder
raise anything but :class:`ckesc.protocol.DecodeError`.

Values are generated from the catalogue's own ``Field`` objects (each field's wire width), so a new
frame or field is covered without touching this file. Budgets are small: the suite must stay fast.
"""

from __future__ import annotations

import can
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from ckesc.protocol import (
    CATALOGUE,
    DecodeError,
    Decoder,
    Frame,
    Kind,
    Layout,
    TransferIdCounter,
    WireFrame,
    encode,
    message_id,
    parse_can_id,
    parse_tail,
    service_id,
    tail_byte,
)
from ckesc.protocol.ids import RESERVED_NODE_IDS

FAST = settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
FUZZ = settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.too_slow])

NODE = st.integers(0, 127).filter(lambda n: n not in RESERVED_NODE_IDS)
PRIORITY = st.integers(0, 31)
TID = st.integers(0, 31)


def layout_values(layout: Layout) -> st.SearchStrategy[dict]:
    """Any value that fits each field's wire width (legal or not: the codec carries illegal values too)."""
    if layout.codec == "throttle14":
        return st.fixed_dictionaries({"channels": st.lists(st.integers(0, 0x3FFF), min_size=4, max_size=4)})
    if layout.codec == "throttle12":
        return st.fixed_dictionaries(
            {"channels": st.lists(st.integers(0, 0xFFF), min_size=4, max_size=4), "group": st.integers(0, 0xFF)}
        )
    if layout.codec == "throttle10":
        return st.fixed_dictionaries(
            {"channels": st.lists(st.integers(0, 0x3FF), min_size=6, max_size=6), "tail_bits": st.integers(0, 0xF)}
        )
    if layout.codec == "raw":
        return st.fixed_dictionaries({"payload": st.lists(st.integers(0, 0xFF), max_size=7)})
    assert layout.codec == "fields", layout.codec
    return st.fixed_dictionaries({f.name: st.integers(0, f.mask) for f in layout.fields})


def _all_layouts():
    for s in CATALOGUE:
        for lay in s.layouts:
            yield pytest.param(s, Kind.MESSAGE, lay, "lsb", id=f"{s.name}-message-{lay.name}")
            if lay.codec == "throttle12":
                yield pytest.param(s, Kind.MESSAGE, lay, "swapped", id=f"{s.name}-message-{lay.name}-swapped")
        if s.request is not None:
            yield pytest.param(s, Kind.REQUEST, s.request, "lsb", id=f"{s.name}-request")
        for lay in s.responses:
            yield pytest.param(s, Kind.RESPONSE, lay, "lsb", id=f"{s.name}-response-{lay.name}")


ALL_LAYOUTS = list(_all_layouts())


def test_every_frame_type_is_parametrized():
    names = {p.values[0].name for p in ALL_LAYOUTS}
    assert names == {s.name for s in CATALOGUE}


@pytest.mark.parametrize("spec,kind,layout,nibble_order", ALL_LAYOUTS)
@FAST
@given(data=st.data())
def test_round_trip(spec, kind, layout, nibble_order, data):
    values = data.draw(layout_values(layout), label="fields")
    priority = data.draw(PRIORITY, label="priority")
    tid = data.draw(TID, label="transfer_id")
    source = data.draw(NODE, label="source")
    destination = None if kind is Kind.MESSAGE else data.draw(st.integers(0, 127), label="destination")

    wire = encode(
        spec,
        values,
        kind=kind,
        source=source,
        destination=destination,
        transfer_id=tid,
        priority=priority,
        layout=None if kind is Kind.REQUEST else layout.name,
        nibble_order=nibble_order,
    )
    assert len(wire.data) == (layout.size if layout.size is not None else len(values["payload"])) + spec.has_tail
    msg = can.Message(arbitration_id=wire.arbitration_id, data=wire.data, is_extended_id=True)
    frame = Decoder(nibble_order=nibble_order).decode(msg, request=layout.when)

    expected = dict(values)
    if spec.tail_tag is not None:
        expected["record"] = tid
    assert frame.spec is spec
    assert frame.layout is layout
    assert frame.fields == expected
    assert frame.kind is kind
    assert frame.priority == priority
    assert frame.source == source
    assert frame.destination == destination
    assert frame.transfer_id == (tid if spec.has_tail else None)
    assert frame.anonymous == (kind is Kind.MESSAGE and source == 0)
    assert frame.can_id == wire.arbitration_id


# --------------------------------------------------------------------------------------------------
# Arbitrary input: only DecodeError may come out, and whatever decodes re-encodes to the same bytes


def _targeted_id() -> st.SearchStrategy[int]:
    """Ids of catalogue types and of their neighbours, with any header: they reach the deep checks."""
    type_ids = sorted({s.type_id for s in CATALOGUE} | {19999, 20001, 20999, 21000, 199, 200, 217, 255, 0, 1030, 341})
    msg = st.builds(
        lambda p, t, s: p << 24 | (t & 0xFFFF) << 8 | s, PRIORITY, st.sampled_from(type_ids), st.integers(0, 127)
    )
    srv = st.builds(
        lambda p, t, r, d, s: p << 24 | (t & 0xFF) << 16 | r << 15 | d << 8 | 0x80 | s,
        PRIORITY,
        st.sampled_from([t for t in type_ids if t < 256]),
        st.integers(0, 1),
        st.integers(0, 127),
        st.integers(0, 127),
    )
    return st.one_of(msg, srv)


ANY_ID = st.one_of(
    st.integers(0, 0x1FFFFFFF),
    st.integers(0x20000000, 2**64),
    st.integers(-(2**32), -1),
    _targeted_id(),
)
SHORT_DATA = st.binary(max_size=8)
SINGLE_FRAME_DATA = st.builds(lambda body, tid: body + bytes([0xC0 | tid]), st.binary(max_size=7), TID)
LONG_DATA = st.binary(min_size=9, max_size=64)


def _decode_or_decode_error(decoder: Decoder, msg) -> Frame | None:
    try:
        return decoder.decode(msg)
    except DecodeError as exc:
        assert str(exc)  # every error says something
        assert isinstance(exc.reason, str) and exc.reason
        return None


def _assert_reencodes(frame: Frame, msg, nibble_order: str = "lsb") -> None:
    """Every bit of a decoded known frame is in its fields: encoding them gives the same frame back."""
    if not frame.known:
        assert frame.fields == {"payload": list(bytes(msg.data))}
        return
    wire = encode(
        frame.spec,
        frame.fields,
        kind=frame.kind,
        source=frame.source,
        destination=frame.destination,
        transfer_id=frame.transfer_id or 0,
        priority=frame.priority,
        layout=None if frame.kind is Kind.REQUEST else frame.layout.name,
        nibble_order=nibble_order,
    )
    assert wire.arbitration_id == msg.arbitration_id
    assert wire.data == bytes(msg.data)


@FUZZ
@given(
    can_id=ANY_ID,
    data=st.one_of(SHORT_DATA, SINGLE_FRAME_DATA),
    extended=st.booleans(),
    remote=st.booleans(),
    error=st.booleans(),
    nibble_order=st.sampled_from(["lsb", "swapped"]),
)
def test_random_can_messages_only_raise_decode_error(can_id, data, extended, remote, error, nibble_order):
    msg = can.Message(
        arbitration_id=can_id, data=data, is_extended_id=extended, is_remote_frame=remote, is_error_frame=error, check=False
    )
    frame = _decode_or_decode_error(Decoder(nibble_order=nibble_order), msg)
    if frame is not None:
        assert extended and not remote and not error and 0 <= can_id <= 0x1FFFFFFF
        _assert_reencodes(frame, msg, nibble_order)


@FUZZ
@given(can_id=st.one_of(_targeted_id(), st.integers(0, 0x1FFFFFFF)), data=st.one_of(SINGLE_FRAME_DATA, SHORT_DATA))
def test_extended_data_frames_decode_losslessly_or_raise_decode_error(can_id, data):
    """The hot path: extended data frames of catalogue types, mostly with a valid tail byte."""
    msg = can.Message(arbitration_id=can_id, data=data, is_extended_id=True)
    frame = _decode_or_decode_error(Decoder(), msg)
    if frame is not None:
        _assert_reencodes(frame, msg)


LAYOUT_TRIPLES = [p.values for p in ALL_LAYOUTS]


@FUZZ
@given(case=st.sampled_from(LAYOUT_TRIPLES), data=st.data())
def test_well_formed_random_bytes_always_decode_and_reencode(case, data):
    """Any bytes of the right length with a single-frame tail, under a catalogue id from a non-reserved
    node, decode (never raise) and re-encode to the very same frame: the codecs lose no bit."""
    spec, kind, layout, nibble_order = case
    size = layout.size if layout.size is not None else data.draw(st.integers(0, 7), label="size")
    body = data.draw(st.binary(min_size=size, max_size=size), label="payload")
    raw = body + bytes([0xC0 | data.draw(TID, label="tid")]) if spec.has_tail else body
    priority, source = data.draw(PRIORITY, label="priority"), data.draw(NODE, label="source")
    if kind is Kind.MESSAGE:
        can_id = message_id(priority, spec.type_id, source)
    else:
        destination = data.draw(st.integers(0, 127), label="destination")
        can_id = service_id(priority, spec.type_id, kind is Kind.REQUEST, destination, source)
    msg = can.Message(arbitration_id=can_id, data=raw, is_extended_id=True)
    frame = Decoder(nibble_order=nibble_order).decode(msg, request=layout.when)
    assert frame.layout is layout
    _assert_reencodes(frame, msg, nibble_order)


@settings(max_examples=100, deadline=None)
@given(can_id=st.one_of(ANY_ID, _targeted_id()), data=LONG_DATA, fd=st.booleans())
def test_more_than_eight_bytes_only_raise_decode_error(can_id, data, fd):
    msg = can.Message(arbitration_id=can_id, data=data, is_extended_id=True, is_fd=fd, check=False)
    with pytest.raises(DecodeError):
        Decoder().decode(msg)
    with pytest.raises(DecodeError):
        Decoder().decode(WireFrame(can_id, data))


@settings(max_examples=100, deadline=None)
@given(
    can_id=st.one_of(st.integers(), st.none(), st.text(max_size=3), st.floats(allow_nan=True)),
    data=st.one_of(
        st.binary(max_size=12),
        st.none(),
        st.lists(st.integers(-300, 300), max_size=9),
        st.text(max_size=4),
        st.integers(-1, 9),
    ),
)
def test_duck_typed_garbage_only_raises_decode_error(can_id, data):
    """decode() accepts anything shaped like a can.Message; malformed objects still give DecodeError."""

    class Shaped:
        arbitration_id = can_id
        is_extended_id = True

    Shaped.data = data  # type: ignore[attr-defined]
    try:
        Decoder().decode(Shaped())
    except DecodeError:
        pass


def test_objects_without_can_attributes_raise_decode_error():
    for garbage in (object(), None, 42, b"\x00\x01", "1F4E5205#3412E8030181C0"):
        with pytest.raises(DecodeError):
            Decoder().decode(garbage)


# --------------------------------------------------------------------------------------------------
# Id and tail codecs


@settings(max_examples=200, deadline=None)
@given(priority=PRIORITY, type_id=st.integers(0, 0xFFFF), source=st.integers(0, 127))
def test_message_id_round_trip(priority, type_id, source):
    can_id = message_id(priority, type_id, source)
    assert 0 <= can_id <= 0x1FFFFFFF and not can_id & 0x80
    cid = parse_can_id(can_id)
    assert (cid.kind, cid.priority, cid.type_id, cid.source, cid.destination) == (Kind.MESSAGE, priority, type_id, source, None)
    assert cid.anonymous == (source == 0)
    assert cid.discriminator == ((type_id >> 2) if source == 0 else None)


@settings(max_examples=200, deadline=None)
@given(priority=PRIORITY, service=st.integers(0, 0xFF), request=st.booleans(), dst=st.integers(0, 127), src=st.integers(0, 127))
def test_service_id_round_trip(priority, service, request, dst, src):
    can_id = service_id(priority, service, request, dst, src)
    assert 0 <= can_id <= 0x1FFFFFFF and can_id & 0x80
    cid = parse_can_id(can_id)
    kind = Kind.REQUEST if request else Kind.RESPONSE
    assert (cid.kind, cid.priority, cid.type_id, cid.source, cid.destination, cid.anonymous) == (
        kind,
        priority,
        service,
        src,
        dst,
        False,
    )


@given(tid=TID, start=st.booleans(), end=st.booleans(), toggle=st.booleans())
@settings(max_examples=50, deadline=None)
def test_tail_byte_round_trip(tid, start, end, toggle):
    b = tail_byte(tid, start=start, end=end, toggle=toggle)
    tail = parse_tail(b)
    assert tail == (start, end, toggle, tid)
    assert tail.single_frame == (start and end and not toggle)


@given(n=st.integers(0, 100))
@settings(max_examples=20, deadline=None)
def test_transfer_id_counter_wraps_modulo_32(n):
    counter = TransferIdCounter()
    got = [counter.next(("msg", 20050)) for _ in range(n)]
    assert got == [i % 32 for i in range(n)]
    assert counter.peek(("msg", 20050)) == n % 32
    assert counter.next(("msg", 20050), destination=5) == 0  # one counter per (type, destination), F3
