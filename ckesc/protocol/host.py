"""The host's side of the protocol, sans-IO: transfer ids, outstanding requests, matching answers.

    host = HostProtocol(node_id=0)
    wire, pending = host.request("set_freq", {"option": 0, ...}, destination=5, now=t, timeout=0.1)
    ...put wire on the bus...
    for event in host.receive(msg, now):          # every frame heard
        ...Response(pending, frame) / Overheard(frame) / Garbled(msg, error)...
    for event in host.expire(now): ...             # TimedOut(pending) once a deadline passes

A response matches a request when it carries the same service id and transfer id, comes from the
node the request went to and is addressed to this host (F4, :func:`.judgements.f4_mismatches`). A
response that matches in all but one of those is still reported as :class:`Response` with
``mismatch`` naming what differs, so a suite can fail it with a clear message instead of timing out.
Which request a response answers is :func:`.judgements.f4_answers`'s to say (the rule written once).

The host need not be alone on the bus (a flight controller, F6): a request another node sent is remembered
(:attr:`HostProtocol.others`, the latest :data:`OTHERS_KEPT`), and a response that answers it (its service id and
transfer id, from the node it asked, addressed to that node: F4) is that node's, :class:`Overheard`, never paired
with one of this host's requests as a misaddressed answer.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field
from typing import Any, Mapping

from .errors import DecodeError
from .frame import Decoder, Frame, WireFrame, encode
from .ids import Kind
from .judgements import asked_node, f4_answers, f4_mismatches
from .transfer import TransferIdCounter

#: How many of other nodes' requests the host remembers (their answers come within ~64 ms)
OTHERS_KEPT = 64


@dataclass
class Pending:
    name: str
    service: int
    destination: int
    transfer_id: int
    fields: dict[str, Any]
    sent_at: float
    deadline: float
    wire: WireFrame
    response: Frame | None = None
    mismatch: list[str] = field(default_factory=list)


@dataclass
class Response:
    pending: Pending
    frame: Frame
    mismatch: list[str] = field(default_factory=list)


@dataclass
class Overheard:
    frame: Frame


@dataclass
class Garbled:
    msg: Any
    error: DecodeError


@dataclass
class TimedOut:
    pending: Pending


class HostProtocol:
    def __init__(self, node_id: int = 0, *, nibble_order: str = "lsb") -> None:
        self.node_id = node_id
        self.nibble_order = nibble_order
        self.decoder = Decoder(nibble_order=nibble_order)
        self.tids = TransferIdCounter()
        self.pending: list[Pending] = []
        #: (service id, transfer id, requester, asked node) of the latest requests other nodes sent
        self.others: deque[tuple[int, int, int, int | None]] = deque(maxlen=OTHERS_KEPT)

    # -------------------------------------------------------------- outgoing
    def message(self, name: str, fields: Mapping[str, Any] | None = None, *, layout: str | None = None,
                priority: int | None = None, transfer_id: int | None = None) -> WireFrame:
        """A broadcast from the host, with the next transfer id for its type (F3)."""
        tid = self.tids.next((Kind.MESSAGE, name)) if transfer_id is None else transfer_id
        return encode(name, fields, source=self.node_id, transfer_id=tid, layout=layout, priority=priority,
                      nibble_order=self.nibble_order)

    def request(self, name: str, fields: Mapping[str, Any] | None, *, destination: int, now: float, timeout: float,
                priority: int | None = None, transfer_id: int | None = None, expect_response: bool = True
                ) -> tuple[WireFrame, Pending]:
        """A service request; its answer is awaited until ``now + timeout`` (unless the service is
        never answered or ``expect_response`` is False)."""
        tid = self.tids.next((Kind.REQUEST, name), destination) if transfer_id is None else transfer_id
        wire = encode(name, fields, kind=Kind.REQUEST, source=self.node_id, destination=destination, transfer_id=tid,
                      priority=priority)
        from .catalogue import spec as _spec

        s = _spec(name)
        pending = Pending(name, s.type_id, destination, tid, dict(fields or {}), now, now + timeout, wire)
        if expect_response and s.responses:
            self.pending.append(pending)
        return wire, pending

    # -------------------------------------------------------------- incoming
    def receive(self, msg: Any) -> list[Response | Overheard | Garbled]:
        try:
            frame = self.decoder.decode(msg)
        except DecodeError as exc:
            return [Garbled(msg, exc)]
        if frame.kind is Kind.REQUEST and frame.source != self.node_id:
            self.others.append((frame.type_id, frame.transfer_id, frame.source, frame.destination))
        elif (frame.kind is Kind.RESPONSE and frame.destination != self.node_id
              and (frame.type_id, frame.transfer_id, frame.destination, frame.source) in self.others):
            return [Overheard(frame)]  # another node's answer to its own request
        if frame.kind is Kind.RESPONSE or (frame.kind is Kind.REQUEST and frame.source != self.node_id):
            match = self._match(frame)
            if match is not None:
                return [match]
        return [Overheard(frame)]

    def _match(self, frame: Frame) -> Response | None:
        asked = [(p.service, p.transfer_id, self.node_id, asked_node(p.name, p.destination)) for p in self.pending]
        i = f4_answers(frame, asked)
        if i is None:
            return None
        p = self.pending.pop(i)
        service, transfer_id, requester, node = asked[i]
        mismatch = f4_mismatches(frame, service=service, transfer_id=transfer_id, requester=requester, asked=node)
        if frame.kind is Kind.RESPONSE and len(p.fields) and frame.layout is not None and frame.layout.name == "response":
            # a response whose layout depends on the request (241): decode it again with the request
            spec = frame.spec
            if spec is not None and len(spec.responses) > 1:
                frame = self.decoder.decode(frame_to_msg(frame), request=p.fields)
        p.response = frame
        return Response(p, frame, mismatch)

    def expire(self, now: float) -> list[TimedOut]:
        gone = [p for p in self.pending if p.deadline <= now]
        for p in gone:
            self.pending.remove(p)
        return [TimedOut(p) for p in gone]

    def next_deadline(self) -> float | None:
        return min((p.deadline for p in self.pending), default=None)


def frame_to_msg(frame: Frame) -> WireFrame:
    return WireFrame(frame.can_id, frame.data, frame.timestamp or 0.0)
