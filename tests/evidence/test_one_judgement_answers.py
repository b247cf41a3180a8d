"""One trace, every consumer that pairs a service response with its request, one pairing (issue #35, F4): the bus reader
(:class:`~ckesc.evidence.pairing.RequestPairing`, told to its consumers as
:meth:`~ckesc.evidence.events.ReaderEvents.response`), the host's link (:class:`~ckesc.protocol.host.HostProtocol`,
which ``Dut.request`` reads answers through), ``ckesc check-log`` and ``ckesc explore``'s judge, which takes the
reader's pairing (:mod:`ckesc.explore.answers`) and keeps only what its model alone knows (what should be answered).

* **By transfer id, not by order** (found against the clean-room ESC: "set_id {node_id=1, throttle_channel=1} not
  answered", SHALL): Set ID to the illegal node id 0 (R10: whether it is answered is OBSERVE), then a legal one 10 ms
  later. An ESC that does not answer the first (``rejected_answer`` none, a conforming variant) answers the second
  with its transfer id; pairing by order gave that answer to the first request and found the second unanswered.
* **An answer from a node that was not asked** (the emulator's fault ``destination_low_bits``: a request to the node
  64 ids away is taken and answered from the ESC's own id): F4's pairing (:func:`~ckesc.protocol.judgements.f4_answers`,
  one field off) makes it that request's answer, failed with the field named. The reader's reading was that it
  answers no request (it looked only among the requests to the node that answered); the explorer's (F4's) won: the
  reader now pairs it, the explorer cites R17 for it (an answer to a request to another node), every consumer F4.
"""

from __future__ import annotations

import pytest

from ckesc.evidence.events import EventLog
from ckesc.evidence.rules import BusRules
from ckesc.explore.judge import Params, judge
from ckesc.explore.oracle import Oracle
from ckesc.protocol import catalogue as cat
from ckesc.protocol import malformed as r17
from ckesc.protocol.host import HostProtocol, Response
from ckesc.protocol.ids import Kind

from .test_one_judgement import BOOT_S, NODE, check_log, decoded, play, request

END_S = 1.2
SET_IDS = ((0.50, {"node_id": 0, "throttle_channel": 1}), (0.51, {"node_id": NODE, "throttle_channel": 1}))
OTHER = NODE + 64  # the node the fault takes for its own
SELF_TEST_AT = 0.7


def _requests(other_node: bool) -> list:
    out = [request("set_id", fields, t, transfer_id=k) for k, (t, fields) in enumerate(SET_IDS)]
    if other_node:
        out.append(request("self_test", {}, SELF_TEST_AT, destination=OTHER, transfer_id=2))
    return out


def _trace(rejected: str, faults: tuple[str, ...] = ()) -> tuple[list, list]:
    host = _requests(bool(faults))
    return host, play([(m.timestamp, m) for m in host], END_S, rejected_answer=rejected, faults=faults)


def _reader(frames) -> tuple[dict[int, int], list]:
    """The reader's pairing: request transfer id -> the answer's, and its F4 verdicts."""
    rules = BusRules(tolerance=0.0, complete=True, power_known=True)
    log = rules.events = EventLog()
    found = [v for m in frames for v in rules.feed_message(m)]
    return {key[2]: _tid(can_id, ts, frames) for key, (can_id, ts, _) in log.answers.items()}, \
        sorted({v.subject for v in found if "F4" in v.rules})


def _tid(can_id: int, ts: float, frames) -> int:
    return next(m.data[-1] & 0x1F for m in frames if m.arbitration_id == can_id and m.timestamp == ts)


def _link(host, frames) -> dict[int, int]:
    """The host's link: each request pending (as ``Dut.request`` leaves it), every frame heard."""
    proto = HostProtocol(0)
    for m in host:
        f = decoded([m])[0]
        proto.request(f.name, f.fields, destination=f.destination, now=m.timestamp, timeout=1.0, transfer_id=f.transfer_id)
    out = {}
    for m in frames:
        if m.is_rx:
            for e in proto.receive(m):
                if isinstance(e, Response):
                    out[e.pending.transfer_id] = e.frame.transfer_id
    return out


def _explorer(host, frames) -> list[str]:
    oracle = Oracle({"node_id": NODE, "throttle_channel": NODE, **cat.DEFAULT_REPORT_INTERVALS}, powered_at=0.0, start=BOOT_S)
    for m in host:
        if m.arbitration_id & 0x7F == 0 and decoded([m])[0].destination == OTHER:
            oracle.malformed_frame(m, "self_test", r17.OTHER_NODE, "self_test as a request to another node")
        else:
            oracle.host_frame(m, 0)
    oracle.finish(END_S)
    rules = BusRules(tolerance=0.0, complete=True, power_known=True)
    heard = rules.events = EventLog()  # the one reader of the whole trace, as the runner's live one
    for m in frames:
        rules.feed_message(m)
    dut = decoded(m for m in frames if m.is_rx and m.timestamp >= BOOT_S)
    return sorted(f"{' '.join(f.requirements)} {f.subject}" for f in judge(oracle, dut, BOOT_S, END_S, Params(boot_s=BOOT_S),
                                                                           heard=heard) if f.kind == "answer")


@pytest.mark.parametrize("rejected", ["none", "current", "echo"])
def test_one_trace_an_answer_answers_the_request_whose_transfer_id_it_carries_to_every_consumer(rejected, tmp_path, capsys):
    host, frames = _trace(rejected)
    expected = {1: 1} if rejected == "none" else {0: 0, 1: 1}  # (by order, the first request took the second's answer)
    pairs, f4 = _reader(frames)
    assert {"reader": pairs, "link": _link(host, frames)} == {"reader": expected, "link": expected}
    assert f4 == [] and _explorer(host, frames) == []
    code, text, _ = check_log(frames, tmp_path, capsys)
    assert code == 0, text


def test_one_trace_an_answer_from_a_node_not_asked_is_that_request_s_answer_and_f4_to_every_consumer(tmp_path, capsys):
    host, frames = _trace("none", ("destination_low_bits",))
    answer = [m for m in frames if m.is_rx and decoded([m])[0].name == "self_test" and decoded([m])[0].kind is Kind.RESPONSE]
    assert [m.arbitration_id & 0x7F for m in answer] == [NODE]  # the fault answered from its own id
    pairs, f4 = _reader(frames)
    assert (pairs.get(2), f4) == (2, ["self_test response from a node that was not asked"])
    assert _link(host, frames).get(2) == 2  # (f4_answers: one field off, the source, is still its answer)
    assert _explorer(host, frames) == ["R17 self_test answered, other_node"]
    code, text, _ = check_log(frames, tmp_path, capsys)
    assert code == 1 and "F4" in text and "!= the node asked" in text, text
