"""The explorer's judge on hand-built frames (sans-IO)."""

from __future__ import annotations

import can

from ckesc.explore.judge import _answer_of
from ckesc.protocol.frame import Decoder, encode


def _frames(*wires_at):
    decoder = Decoder()
    return [decoder.decode(can.Message(arbitration_id=w.arbitration_id, data=w.data, is_extended_id=True, timestamp=t))
            for w, t in wires_at]


def test_an_answer_an_earlier_request_got_is_not_this_one_s():
    """Two Set IDs 10 ms apart, to node 1 then (it moved) to node 2, each transfer id 5 (F3 counts per destination).
    With the look-back for a late echo, the first answer would pass for the second's (found against the clean-room
    ESC: 'set_id {node_id=1} answered node_id=2'); the answer the first request took is not the second's."""
    first, second = ({"node_id": 2, "throttle_channel": 20}, {"node_id": 1, "throttle_channel": 20})
    req1, ans1, req2, ans2 = _frames(
        (encode("set_id", first, source=0, destination=1, transfer_id=5), 0.000),
        (encode("set_id", first, kind="response", source=2, destination=0, transfer_id=5), 0.004),
        (encode("set_id", second, source=0, destination=2, transfer_id=5), 0.010),
        (encode("set_id", second, kind="response", source=1, destination=0, transfer_id=5), 0.014))
    dut = [ans1, ans2]
    look_back = req2.timestamp - 0.009
    assert _answer_of(dut, req2, 0.1, since=look_back) is ans1  # the mistake the taken set prevents
    taken = {id(_answer_of(dut, req1, 0.1))}
    assert _answer_of(dut, req2, 0.1, since=look_back, taken=taken) is ans2
