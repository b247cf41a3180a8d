"""Malformed input: every case gets its specific DecodeError subclass, naming the frame (when the id
identifies one) and the reason. Also foreign traffic seen on real buses (reference notes 4.4/4.5), unknown
ids inside the vendor ranges, node-0 (anonymous) frames, and the EncodeError side.
"""

from __future__ import annotations

import itertools

import can
import pytest

from ckesc.protocol import (
    CATALOGUE,
    DecodeError,
    Decoder,
    EncodeError,
    Kind,
    LengthError,
    NotExtendedDataFrameError,
    ReservedNodeError,
    TailError,
    UnknownTypeError,
    decode,
    encode,
    message_id,
    parse_can_id,
    service_id,
    spec,
)

MSG1_ID = message_id(31, 20050, 5)  # 0x1F4E5205
MSG1_DATA = bytes.fromhex("34 12 E8 03 01 81 C0")


def _msg(can_id: int, data: bytes, **kw) -> can.Message:
    return can.Message(arbitration_id=can_id, data=data, is_extended_id=kw.pop("is_extended_id", True), **kw)


def _raises(exc_type: type[DecodeError], msg, *, frame: str | None, words: tuple[str, ...] = ()) -> DecodeError:
    with pytest.raises(DecodeError) as info:
        Decoder().decode(msg)
    err = info.value
    assert type(err) is exc_type, f"expected {exc_type.__name__}, got {type(err).__name__}: {err}"
    assert err.frame == frame
    if frame is not None:
        assert str(err).startswith(f"{frame}: "), str(err)
    assert err.reason == exc_type.reason
    for word in words:
        assert word.lower() in str(err).lower(), (word, str(err))
    return err


def test_reasons_are_distinct_words():
    classes = [NotExtendedDataFrameError, LengthError, TailError, ReservedNodeError, UnknownTypeError]
    reasons = [c.reason for c in classes]
    assert len(set(reasons)) == len(reasons)
    assert all(issubclass(c, DecodeError) for c in classes)
    assert not issubclass(EncodeError, DecodeError)


# --------------------------------------------------------------------------------------------------
# Not an extended data frame


@pytest.mark.parametrize("can_id", [0x000, 0x123, 0x7FF])
def test_standard_11bit_id(can_id):
    _raises(NotExtendedDataFrameError, _msg(can_id, MSG1_DATA, is_extended_id=False), frame=None, words=("standard", "11-bit"))


def test_standard_id_whose_value_would_be_a_catalogue_frame():
    # the numeric id is MSG1's, but the IDE bit says standard: refused, not decoded as MSG1
    msg = _msg(MSG1_ID, MSG1_DATA, is_extended_id=False, check=False)
    _raises(NotExtendedDataFrameError, msg, frame=None, words=("standard",))


def test_remote_frame():
    msg = can.Message(arbitration_id=MSG1_ID, is_extended_id=True, is_remote_frame=True, dlc=7)
    _raises(NotExtendedDataFrameError, msg, frame=None, words=("remote",))


def test_error_frame():
    msg = can.Message(arbitration_id=0x20000004, is_error_frame=True, data=bytes(8))
    _raises(NotExtendedDataFrameError, msg, frame=None, words=("error frame",))


@pytest.mark.parametrize("can_id", [0x20000000, 0x20000000 | MSG1_ID, 0xFFFFFFFF, 1 << 40, -1])
def test_id_wider_than_29_bits(can_id):
    _raises(NotExtendedDataFrameError, _msg(can_id, MSG1_DATA, check=False), frame=None, words=("29-bit",))


# --------------------------------------------------------------------------------------------------
# Wrong length


def _cases_wrong_length():
    """For every catalogue frame kind: each data length 0..8 the layout(s) do not allow, with a valid tail."""
    for s in CATALOGUE:
        groups = []
        if s.layouts:
            groups.append((Kind.MESSAGE, s.layouts))
        if s.request is not None:
            groups.append((Kind.REQUEST, (s.request,)))
        if s.response is not None:
            groups.append((Kind.RESPONSE, (s.response,)))
        for kind, layouts in groups:
            if any(lay.size is None for lay in layouts):
                continue  # 223/224: any payload 0..7 (R15 OBSERVE)
            ok = {lay.size + s.has_tail for lay in layouts}
            for n in range(0, 9):
                if n not in ok:
                    yield pytest.param(s.name, kind, n, sorted(ok), id=f"{s.name}-{kind.label}-{n}B")


def _can_id(name: str, kind: Kind, source: int = 5, destination: int = 0) -> int:
    s = spec(name)
    if kind is Kind.MESSAGE:
        return message_id(s.priority or 16, s.type_id, source)
    return service_id(s.priority or 16, s.type_id, kind is Kind.REQUEST, destination, source)


@pytest.mark.parametrize("name,kind,length,expected", list(_cases_wrong_length()))
def test_wrong_length(name, kind, length, expected):
    data = bytes(range(1, length)) + bytes([0xC3]) if length else b""
    err = _raises(LengthError, _msg(_can_id(name, kind), data), frame=name)
    if length:
        assert f"{length} data bytes" in str(err)
        assert "expected " + " or ".join(str(n) for n in expected) in str(err)
    else:
        assert "no data" in str(err) or "0 data bytes" in str(err)


def test_too_short_and_too_long_are_both_covered():
    lengths = {(p.values[0], p.values[1]): [] for p in _cases_wrong_length()}
    for p in _cases_wrong_length():
        lengths[(p.values[0], p.values[1])].append(p.values[2])
    assert lengths[("msg1", Kind.MESSAGE)] == [0, 1, 2, 3, 4, 5, 6, 8]
    assert lengths[("raw_command_10b", Kind.MESSAGE)] == list(range(8))
    assert lengths[("get_esc_id", Kind.MESSAGE)] == [0, 1, 4, 5, 6, 7, 8]


@pytest.mark.parametrize("option", [0, 1, 2])
def test_wrong_length_of_a_241_option_response(option):
    dec = Decoder()
    dec.decode(_msg(_can_id("maintenance_information", Kind.REQUEST, source=0, destination=5), bytes([option, 0xC0 | option])))
    with pytest.raises(LengthError) as info:
        dec.decode(_msg(_can_id("maintenance_information", Kind.RESPONSE), bytes(6) + bytes([0xC0 | option])))
    assert info.value.frame == "maintenance_information"


@pytest.mark.parametrize("length", [9, 12, 64])
def test_more_than_8_bytes(length):
    with pytest.raises(LengthError) as info:
        decode(_msg(MSG1_ID, bytes(length - 1) + b"\xc0", is_fd=True))
    assert "at most 8" in str(info.value)
    assert info.value.frame == "msg1"


# --------------------------------------------------------------------------------------------------
# Tail byte: not a single-frame transfer (F2)

NOT_SINGLE = [(s, e, t) for s, e, t in itertools.product((0, 1), repeat=3) if (s, e, t) != (1, 1, 0)]


@pytest.mark.parametrize("start,end,toggle", NOT_SINGLE, ids=[f"s{s}e{e}t{t}" for s, e, t in NOT_SINGLE])
@pytest.mark.parametrize(
    "name,kind,payload",
    [
        ("msg1", Kind.MESSAGE, bytes(6)),
        ("raw_command_14b", Kind.MESSAGE, bytes.fromhex("E80FA03E80FA03")),
        ("msg_exp12", Kind.MESSAGE, bytes(7)),
        ("set_id", Kind.REQUEST, b"\x05\x01"),
        ("self_test", Kind.RESPONSE, b"\x00"),
        ("self_test", Kind.REQUEST, b""),
    ],
)
def test_tail_not_single_frame(name, kind, payload, start, end, toggle):
    tail = start << 7 | end << 6 | toggle << 5 | 7
    _raises(TailError, _msg(_can_id(name, kind), payload + bytes([tail])), frame=name, words=(f"start={start} end={end} toggle={toggle}",))


# --------------------------------------------------------------------------------------------------
# Reserved source node ids (F7)


@pytest.mark.parametrize("source", [0x7E, 0x7F])
@pytest.mark.parametrize(
    "name,kind,data",
    [
        ("msg1", Kind.MESSAGE, MSG1_DATA),
        ("get_esc_id", Kind.MESSAGE, b"\x7e\x01\xc0"),
        ("set_id", Kind.RESPONSE, b"\x05\x01\xc0"),
        ("self_test", Kind.REQUEST, b"\xc0"),
    ],
)
def test_reserved_source_node(name, kind, data, source):
    _raises(ReservedNodeError, _msg(_can_id(name, kind, source=source), data), frame=name, words=(str(source), "reserved"))


def test_reserved_source_node_on_an_unknown_vendor_type():
    _raises(ReservedNodeError, _msg(message_id(31, 20500, 0x7F), b"\xc0"), frame=None, words=("127",))


def test_reserved_destination_is_not_a_decode_error():
    # F7 reserves the ids as node ids; a frame addressed to one is still well-formed (who answers is OBSERVE)
    frame = decode(_msg(service_id(16, 210, True, 0x7F, 0), b"\x05\x01\xc0"))
    assert (frame.name, frame.destination) == ("set_id", 0x7F)


# --------------------------------------------------------------------------------------------------
# Type ids outside / inside the vendor ranges (4.3.1)


@pytest.mark.parametrize("type_id", [0, 1, 341, 1030, 19999, 21000, 30000, 65535])
def test_unknown_message_type_outside_vendor_range(type_id):
    _raises(UnknownTypeError, _msg(message_id(16, type_id, 5), b"\x00\xc0"), frame=None, words=(str(type_id), "[20000, 21000)"))


@pytest.mark.parametrize("service", [0, 1, 5, 199])
@pytest.mark.parametrize("is_request", [True, False])
def test_unknown_service_outside_vendor_range(service, is_request):
    _raises(UnknownTypeError, _msg(service_id(16, service, is_request, 5, 0), b"\xc0"), frame=None, words=(str(service), "[200, 256)"))


@pytest.mark.parametrize("type_id", [20001, 20009, 20011, 20049, 20065, 20099, 20103, 20150, 20999])
def test_unknown_message_type_inside_vendor_range(type_id):
    frame = decode(_msg(message_id(31, type_id, 9), b"\x01\x02\xc4"))
    assert (frame.name, frame.known, frame.spec, frame.layout) == ("unknown", False, None, None)
    assert (frame.kind, frame.type_id, frame.source, frame.destination) == (Kind.MESSAGE, type_id, 9, None)
    assert frame.fields == {"payload": [1, 2, 0xC4]}
    assert frame.transfer_id == 4


@pytest.mark.parametrize("service", [200, 209, 217, 225, 239, 243, 250, 255])
@pytest.mark.parametrize("kind", [Kind.REQUEST, Kind.RESPONSE])
def test_unknown_service_inside_vendor_range(service, kind):
    frame = decode(_msg(service_id(16, service, kind is Kind.REQUEST, 5, 0), b"\xc1"))
    assert (frame.name, frame.known, frame.kind, frame.type_id) == ("unknown", False, kind, service)
    assert (frame.source, frame.destination, frame.transfer_id) == (0, 5, 1)


def test_catalogue_ids_are_inside_the_vendor_ranges():
    for s in CATALOGUE:
        assert (200 <= s.type_id < 256) if s.service else (20000 <= s.type_id < 21000), s.name


# --------------------------------------------------------------------------------------------------
# Foreign traffic seen on real buses (reference notes 4.4, 4.5)


@pytest.mark.parametrize("data", [b"\x00\xc0", b"\xff\xc0"])
def test_ardupilot_safety_state_on_20000_is_a_length_error(data):
    # ardupilot.indication.SafetyState shares DTID 20000 with CAN Test: 1 byte + tail, CAN Test has 5 + tail
    _raises(LengthError, _msg(0x184E200A, data), frame="can_test", words=("2 data bytes", "expected 6"))


def test_ap_periph_battery_continuous_first_frame_on_20010_is_a_tail_error():
    # ardupilot.equipment.power.BatteryContinuous is multi-frame: first frame start=1 end=0
    data = bytes.fromhex("41 B6 00 00 00 00 00 80")
    can_id = message_id(24, 20010, 124)
    _raises(TailError, _msg(can_id, data), frame="msg_control", words=("start=1 end=0 toggle=0",))


@pytest.mark.parametrize(
    "data",
    [bytes.fromhex("E0 A7 E8 0F A0 3E 80 84"), bytes.fromhex("FA 03 E8 0F A0 30 64")],
    ids=["first", "last"],
)
def test_dronecan_multi_frame_raw_command_for_6_escs_is_a_tail_error(data):
    # the last frame is 7 bytes, the length of a valid RawCommand_14b: only the tail byte gives it away
    _raises(TailError, _msg(0x084E840A, data), frame="raw_command_14b")


def test_response_to_expand_set_part_is_a_decode_error():
    # R14: 222 is never answered
    for data in (b"\xf1\xff\x02\xc0", b"\xc0"):
        err = _raises(DecodeError, _msg(service_id(16, 222, False, 0, 5), data), frame="expand_set_part", words=("never answered",))
        assert err.reason == "malformed"


# --------------------------------------------------------------------------------------------------
# Node 0: the CKESC host, an anonymous frame to a DroneCAN stack (ids.py, notes 4.4)


@pytest.mark.parametrize("name,data", [("get_esc_id", b"\x00\xc0"), ("raw_command_14b", bytes.fromhex("E80FA03E80FA03C0"))])
def test_message_from_node_0_is_flagged_anonymous_with_full_type_id(name, data):
    s = spec(name)
    can_id = message_id(s.priority, s.type_id, 0)
    frame = decode(_msg(can_id, data))
    assert frame.name == name and frame.type_id == s.type_id and frame.source == 0
    assert frame.anonymous
    cid = parse_can_id(can_id)
    assert cid.anonymous and cid.type_id == s.type_id
    # what a DroneCAN stack sees: the discriminator (bits 23..10) and type_id & 3 (bits 9..8)
    assert cid.discriminator == s.type_id >> 2 == (can_id >> 10) & 0x3FFF
    assert (can_id >> 8) & 3 == s.type_id & 3


def test_notes_anonymous_examples():
    assert parse_can_id(0x004E8400).discriminator == 5025  # RawCommand_14b from host 0 (notes 4.4)
    assert parse_can_id(0x104E2D00).type_id & 3 == 1  # GetEscID from host 0: DTID 1 = dynamic_node_id.Allocation


def test_messages_from_other_nodes_and_services_from_node_0_are_not_anonymous():
    assert not decode(_msg(message_id(16, 20013, 10), b"\x00\xc0")).anonymous
    frame = decode(_msg(service_id(16, 210, True, 0x7D, 0), b"\x05\x01\xc0"))
    assert frame.source == 0 and not frame.anonymous
    assert parse_can_id(service_id(16, 210, True, 0x7D, 0)).discriminator is None


# --------------------------------------------------------------------------------------------------
# EncodeError: frames the wire cannot carry


@pytest.mark.parametrize(
    "call,words",
    [
        (lambda: encode("msg1", {"speed": 1 << 16, "pwm": 0, "status": 0}, source=5), ("speed", "0..65535")),
        (lambda: encode("msg1", {"speed": -1, "pwm": 0, "status": 0}, source=5), ("speed",)),
        (lambda: encode("msg1", {"speed": True, "pwm": 0, "status": 0}, source=5), ("speed",)),
        (lambda: encode("msg1", {"rpm": 1}, source=5), ("unknown field", "rpm")),
        (lambda: encode("msg1", {"speed": 1, "pwm": 0}, source=5), ("status", "required")),
        (lambda: encode("msg_exp7", {"direction": 16}, source=5), ("direction", "0..15")),
        (lambda: encode("raw_command_14b", {"channels": [1, 2, 3]}, source=0), ("exactly 4",)),
        (lambda: encode("raw_command_14b", {"channels": [0, 0, 0, 16384]}, source=0), ("channel",)),
        (lambda: encode("raw_command_12b", {"channels": [4096, 0, 0, 0], "group": 1}, source=0), ("channel",)),
        (lambda: encode("raw_command_12b", {"channels": [0] * 4}, source=0), ("group", "required")),
        (lambda: encode("raw_command_10b", {"channels": [1024] + [0] * 5}, source=0), ("channel",)),
        (lambda: encode("raw_command_10b", {"channels": [0] * 6, "tail_bits": 16}, source=0), ("tail_bits",)),
        (lambda: encode("get_rec", {"payload": list(range(8))}, source=0, destination=5), ("at most 7",)),
        (lambda: encode("set_id", {"node_id": 5, "throttle_channel": 1}, source=0), ("destination",)),
        (lambda: encode("set_id", {"node_id": 5, "throttle_channel": 1}, kind="message", source=0), ("service",)),
        (lambda: encode("msg1", {"speed": 1, "pwm": 0, "status": 0}, kind="request", source=5, destination=1), ("message",)),
        (lambda: encode("expand_set_part", {"set_cmd": 0xFFF1, "part": 1}, kind="response", source=5, destination=0), ("no response",)),
        (lambda: encode("msg1", {"speed": 1, "pwm": 0, "status": 0}, source=128), ("source",)),
        (lambda: encode("msg1", {"speed": 1, "pwm": 0, "status": 0}, source=5, priority=32), ("priority",)),
        (lambda: encode("msg1", {"speed": 1, "pwm": 0, "status": 0}, source=5, transfer_id=32), ("transfer id",)),
        (lambda: encode("set_id", {"node_id": 5, "throttle_channel": 1}, source=0, destination=128), ("destination",)),
        (lambda: encode("get_esc_id", {}, source=0), ("layout",)),
        (lambda: encode("maintenance_information", {}, kind="response", source=5, destination=0, layout="nope"), ("nope",)),
    ],
)
def test_encode_errors(call, words):
    with pytest.raises(EncodeError) as info:
        call()
    for word in words:
        assert word.lower() in str(info.value).lower(), (word, str(info.value))


def test_unknown_frame_name_is_a_key_error():
    with pytest.raises(KeyError, match="no frame named"):
        encode("msg99", {}, source=5)
