"""Golden vectors (fixtures/vectors/*.json): hand-derived bytes for every catalogue entry and layout.

The bytes in the fixtures were worked out from the document's tables, not produced by our encoder, so
these tests fail if the encoder or the decoder drifts from the document.
"""

from __future__ import annotations

import json
from pathlib import Path

import can
import pytest

from ckesc.protocol import CATALOGUE, Decoder, Kind, decode, encode, parse_can_id, spec

VECTOR_DIR = Path(__file__).resolve().parents[2] / "fixtures" / "vectors"


def _load() -> list[dict]:
    out: list[dict] = []
    for path in sorted(VECTOR_DIR.glob("*.json")):
        out.extend(json.loads(path.read_text())["vectors"])
    return out


VECTORS = _load()
BY_NAME = {v["name"]: v for v in VECTORS}


def _msg(v: dict) -> can.Message:
    return can.Message(arbitration_id=int(v["can_id"], 16), data=bytes.fromhex(v["data"]), is_extended_id=True)


def _encode(v: dict, *, with_priority: bool = True):
    return encode(
        v["frame"],
        v["fields"],
        kind=v["kind"],
        source=v["source"],
        destination=v["destination"],
        transfer_id=v["transfer_id"] or 0,
        priority=v["priority"] if with_priority else None,
        layout=v["layout"] if v["kind"] != "request" else None,
        nibble_order=v.get("nibble_order", "lsb"),
    )


vector = pytest.mark.parametrize("v", VECTORS, ids=[v["name"] for v in VECTORS])


def test_vector_file_is_well_formed():
    assert len(VECTORS) == len(BY_NAME), "vector names must be unique"
    keys = {"name", "frame", "kind", "source", "destination", "transfer_id", "priority", "can_id", "data", "fields", "check"}
    for v in VECTORS:
        assert keys <= set(v), (v["name"], keys - set(v))
        assert v["kind"] in ("message", "request", "response"), v["name"]
        assert len(v["check"]) > 10, f"{v['name']}: say how the bytes were derived"
        assert len(bytes.fromhex(v["data"])) <= 8, v["name"]


@vector
def test_vector_id_and_tail_follow_f1_f2(v):
    """Re-derive the CAN id and tail byte from the vector's own header fields with the formulas of F1/F2
    (independent of ckesc.protocol.ids), so a typo in the fixture cannot hide."""
    s = spec(v["frame"])
    if v["kind"] == "message":
        expected = v["priority"] << 24 | s.type_id << 8 | v["source"]
    else:
        req = v["kind"] == "request"
        expected = v["priority"] << 24 | s.type_id << 16 | req << 15 | v["destination"] << 8 | 0x80 | v["source"]
    assert int(v["can_id"], 16) == expected
    data = bytes.fromhex(v["data"])
    if s.has_tail:
        assert data[-1] == 0xC0 | v["transfer_id"]
    else:
        assert v["transfer_id"] is None and len(data) == 8
    if v.get("default_priority"):
        assert v["priority"] == s.priority, "a table-priority vector must use the table's priority (F5)"


@vector
def test_encode_matches_vector(v):
    wire = _encode(v)
    assert wire.arbitration_id == int(v["can_id"], 16)
    assert wire.data.hex(" ").upper() == v["data"].upper()
    assert wire.is_extended_id


TABLE_PRIORITY = [v for v in VECTORS if v.get("default_priority")]


@pytest.mark.parametrize("v", TABLE_PRIORITY, ids=[v["name"] for v in TABLE_PRIORITY])
def test_encode_uses_table_priority(v):
    """Without an explicit priority, encode() uses the table's (F5); 240-242 list none and are not here."""
    assert _encode(v, with_priority=False).arbitration_id == int(v["can_id"], 16)


@vector
def test_decode_matches_vector(v):
    frame = Decoder(nibble_order=v.get("nibble_order", "lsb")).decode(_msg(v), request=v.get("request"))
    assert frame.name == v["frame"]
    assert frame.known
    assert frame.kind is Kind[v["kind"].upper()]
    assert frame.type_id == spec(v["frame"]).type_id
    assert frame.priority == v["priority"]
    assert frame.source == v["source"]
    assert frame.destination == v["destination"]
    assert frame.transfer_id == v["transfer_id"]
    assert frame.fields == v["fields"]
    assert frame.layout is not None and frame.layout.name == v["layout"]
    assert frame.anonymous == v.get("anonymous", False)
    assert frame.data == bytes.fromhex(v["data"])
    assert frame.can_id == int(v["can_id"], 16)


@vector
def test_parse_can_id_matches_vector(v):
    cid = parse_can_id(int(v["can_id"], 16))
    assert cid.kind is Kind[v["kind"].upper()]
    assert (cid.priority, cid.type_id, cid.source, cid.destination) == (
        v["priority"],
        spec(v["frame"]).type_id,
        v["source"],
        v["destination"],
    )
    assert cid.anonymous == v.get("anonymous", False)


def test_every_catalogue_entry_and_layout_has_a_vector():
    covered = {(v["frame"], v["kind"], v["layout"]) for v in VECTORS}
    wanted = set()
    for s in CATALOGUE:
        for lay in s.layouts:
            wanted.add((s.name, "message", lay.name))
        if s.request is not None:
            wanted.add((s.name, "request", s.request.name))
        for lay in s.responses:
            wanted.add((s.name, "response", lay.name))
    missing = sorted(wanted - covered)
    assert not missing, f"catalogue layouts without a golden vector: {missing}"
    assert not covered - wanted, f"vectors naming layouts the catalogue lacks: {sorted(covered - wanted)}"


def test_document_and_r4_examples_are_in_the_vectors():
    payloads = {bytes.fromhex(v["data"])[:7] for v in VECTORS}
    assert bytes.fromhex("E8 0F A0 3E 80 FA 03") in payloads  # 4.4.15 worked example
    assert bytes.fromhex("23 61 45 89 C7 AB 01") in payloads  # R4 vector
    tails = {bytes.fromhex(v["data"])[-1] for v in VECTORS if v["frame"] == "msg_exp12"}
    assert tails <= set(range(0xC1, 0xC6)) and tails


def test_msg_exp12_tail_names_the_record():
    frame = decode(_msg(BY_NAME["msg_exp12_record_mcu"]))
    assert frame.physical()["record"] == "mcu"
    frame = decode(_msg(BY_NAME["msg_exp12_record_reserved"]))
    assert frame.physical()["record"] == "reserved"


@pytest.mark.parametrize("option", [0, 1, 2])
def test_241_response_layout_follows_the_remembered_request(option):
    """A Decoder that saw the request decodes the response by the request's option (F4 keys)."""
    dec = Decoder()
    req = dec.decode(_msg(BY_NAME[f"maintenance_information_request_option{option}"]))
    assert req.fields == {"option": option}
    resp_v = BY_NAME[f"maintenance_information_response_option{option}"]
    resp = dec.decode(_msg(resp_v))
    assert resp.layout is not None and resp.layout.name == f"response_option_{option}"
    assert resp.fields == resp_v["fields"]
    # the request is consumed: the same response again falls back to the generic layout
    again = dec.decode(_msg(resp_v))
    assert again.layout is not None and again.layout.name == "response"


def test_241_response_with_other_transfer_id_is_not_matched():
    dec = Decoder()
    dec.decode(_msg(BY_NAME["maintenance_information_request_option0"]))  # tid 0
    resp = dec.decode(_msg(BY_NAME["maintenance_information_response_option1"]))  # tid 1
    assert resp.layout is not None and resp.layout.name == "response"


def test_physical_values_of_msg2():
    frame = decode(_msg(BY_NAME["msg2"]))
    assert frame.physical() == {"voltage": 25.2, "current": 12.34, "temperature": 45}
