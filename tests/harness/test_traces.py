"""Per-test traces: the lanes' listener hook, and the plugin's BLF/ASC file per test, read back
with python-can's own LogReader."""

from __future__ import annotations

import can

from ckesc.harness.lanes import SimLane
from ckesc.protocol import Decoder, encode


class _Collect(can.Listener):
    def __init__(self) -> None:
        self.msgs: list[can.Message] = []

    def on_message_received(self, msg: can.Message) -> None:
        self.msgs.append(msg)


def test_lane_listeners_hear_both_directions_and_frames_that_do_not_decode():
    lane = SimLane(nodes=(1,), esc_config={"boot_time": 0.0})
    try:
        heard = _Collect()
        lane.listeners.append(heard)
        wire = encode("get_esc_id", {"option": 0}, source=0, transfer_id=0, layout="query")
        lane.bus.send(can.Message(arbitration_id=wire.arbitration_id, data=wire.data, is_extended_id=True))
        junk = can.Message(arbitration_id=0x123, data=b"\x01\x02", is_extended_id=False)  # no CKESC frame at all
        lane.bus.send(junk)
        got = []
        while (msg := lane.recv(0.1 - lane.now())) is not None:
            got.append(msg)
    finally:
        lane.close()
    assert heard.msgs == got, "the listeners see exactly what the lane hands out, in order"
    own = [m for m in got if not m.is_rx]
    # both queued at once: the lower id wins arbitration and goes first
    assert [m.arbitration_id for m in own] == [0x123, wire.arbitration_id], "the host's sends, as their echoes"
    decoded = [Decoder().decode(m) for m in got if m.is_extended_id]
    assert [(f.source, f.layout.name) for f in decoded if f.name == "get_esc_id"] == [(0, "query"), (1, "reply")]
    assert any(f.name == "msg1" and f.source == 1 for f in decoded), "the ESC's reports"
    assert all(m.timestamp > 0 for m in got) and [m.timestamp for m in got] == sorted(m.timestamp for m in got)


def test_a_lane_without_listeners_is_unchanged():
    lane = SimLane(nodes=(1,))
    try:
        assert lane.listeners == []
        assert lane.heard(None) is None
        other = SimLane(nodes=(1,))
        try:
            lane.listeners.append(_Collect())
            assert other.listeners == [], "each lane has its own listeners"
        finally:
            other.close()
    finally:
        lane.close()
