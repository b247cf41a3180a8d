"""The document's own worked examples and the vectors INTERPRETATIONS.md pins (R3, R4)."""

from ckesc.protocol import decode, encode, message_id, pack_throttle12, pack_throttle14


def test_document_14bit_example():
    # 4.4.15 clarification 3a/b: four channels of 1000 -> E8 0F A0 3E 80 FA 03
    assert pack_throttle14([1000] * 4) == bytes.fromhex("E80FA03E80FA03")


def test_r4_12bit_vector():
    assert pack_throttle12([0x123, 0x456, 0x789, 0xABC], 1) == bytes.fromhex("2361458 9C7AB01".replace(" ", ""))
    assert pack_throttle12([0x123, 0x456, 0x789, 0xABC], 1, nibble_order="swapped")[:6] == bytes.fromhex("231645897CAB")


def test_msg1_can_id_fields():
    # MSG1 from node 5 at LOWEST: priority | type id | service=0 | source
    assert message_id(priority=31, type_id=20050, source=5) == 0b11111_0100111001010010_0_0000101  # 0x1F4E5205


def test_round_trip_through_decode():
    wire = encode("msg1", {"speed": 0x1234, "pwm": 1000, "status": 0x8101}, source=5)
    assert str(wire) == "1F4E5205#3412E8030181C0"
    frame = decode(wire)
    assert (frame.name, frame.source, frame.transfer_id) == ("msg1", 5, 0)
    assert frame.fields == {"speed": 0x1234, "pwm": 1000, "status": 0x8101}
