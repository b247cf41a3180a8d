"""What an emulated ESC sends: frames built from the catalogue (with the framing faults), service answers
(their priority, transfer id and destination), the answer slots of MSG Control and GET_ESC_ID (R2)."""

from __future__ import annotations

import heapq

from ..protocol import catalogue as cat
from ..protocol.catalogue import ANSWER_SLOT_S, answer_slot_s
from ..protocol.codecs import codec_for
from ..protocol.frame import Frame, WireFrame, encode, frame_bits, new_wire
from ..protocol.ids import Kind, Priority, message_id, service_id
from ..protocol.transfer import TAIL_BYTES, next_transfer_id, tail_byte

#: unlisted_priority (F5-unlisted): the priority of 240/241/242 answers; "request" keeps the request's
_UNLISTED_PRIORITY = {"medium": Priority.MEDIUM, "low": Priority.LOW, "lowest": Priority.LOWEST}

_TAIL_FAULTS = frozenset({"tail_toggle_set", "tail_not_single_frame"})
#: reports' payloads by (layout, fields) and their CAN ids by (priority, type id, node): the same few, hours long
#: (an ESC at rest reports the same values); bounded, a value that keeps changing must not grow the memory
_PAYLOADS: dict[tuple, bytes] = {}
_IDS: dict[tuple[int, int, int], int] = {}
_CACHE_MAX = 4096


class Output:
    """Part of :class:`~ckesc.emulator.model.EscModel`: the frames it sends (its outbox)."""

    def _emit(self, due: float, name: str, fields: dict, *, kind: Kind = Kind.MESSAGE, destination: int | None = None,
              transfer_id: int | None = None, priority: int | None = None, layout: str | None = None,
              id_or: int = 0) -> None:
        spec = cat.BY_NAME[name]
        if transfer_id is None:
            transfer_id = self.state.tids.peek(name) if "transfer_id_stuck" in self.faults else self.state.tids.next(name)
        if priority is None:
            priority = spec.priority if spec.priority is not None else Priority.MEDIUM
        if kind is Kind.MESSAGE and layout is None and len(spec.layouts) == 1 and spec.has_tail:
            # reports, the bulk of what an ESC sends: the layout's compiled codec directly, its payload and id
            # remembered (encoding is a pure function of them; what fails to encode is never remembered)
            lay = spec.layouts[0]
            # keyed by the values' types too: True, 1.0 and 1 are equal, and only 1 encodes
            key: tuple | None = (lay, *fields.items(), *map(type, fields.values()))
            try:
                payload = _PAYLOADS.get(key)
            except TypeError:  # a value that cannot be a key (a list): encoded each time
                payload = key = None
            if payload is None:
                payload = codec_for(lay).encode(fields)
                if key is not None:
                    if len(_PAYLOADS) >= _CACHE_MAX:
                        _PAYLOADS.clear()
                    _PAYLOADS[key] = payload
            ids = (priority, spec.type_id, self.node_id)
            can_id = _IDS.get(ids)
            if can_id is None:
                can_id = message_id(*ids)
                if len(_IDS) >= _CACHE_MAX:
                    _IDS.clear()
                _IDS[ids] = can_id
            tail = TAIL_BYTES[transfer_id] if type(transfer_id) is int and 0 <= transfer_id < 32 \
                else bytes((tail_byte(transfer_id),))
            wire = new_wire((can_id, payload + tail, due, True))
        else:
            wire = encode(spec, fields, kind=kind, source=self.node_id, destination=destination,
                          transfer_id=transfer_id, priority=priority, layout=layout, timestamp=due)
        if not self.faults.isdisjoint(_TAIL_FAULTS):  # (no set built: every frame an ESC sends passes here)
            wire = self._mangle_tail(wire, spec)
        if id_or:
            wire = wire._replace(arbitration_id=wire.arbitration_id | id_or)
        self._push(due, wire)

    def _push(self, due: float, wire: WireFrame) -> None:
        self.state.seq += 1
        heapq.heappush(self.state.outbox, (due, self.state.seq, wire))

    def _mangle_tail(self, wire: WireFrame, spec) -> WireFrame:
        if not spec.has_tail:
            return wire
        data = bytearray(wire.data)
        if "tail_toggle_set" in self.faults:
            data[-1] |= 0x20
        if "tail_not_single_frame" in self.faults:
            data[-1] &= ~0x40 & 0xFF
        return wire._replace(data=bytes(data))

    def _respond(self, req: Frame, now: float, fields: dict, *, layout: str | None = None) -> None:
        spec = req.spec
        assert spec is not None
        priority = spec.priority if spec.priority is not None else _UNLISTED_PRIORITY.get(
            self.config.unlisted_priority, req.priority)  # F5: 240..242 list none
        if "response_wrong_priority" in self.faults:
            priority = Priority.LOWEST if priority != Priority.LOWEST else Priority.MEDIUM
        tid = req.transfer_id or 0
        if "response_transfer_id_wrong" in self.faults:
            tid = next_transfer_id(tid)
        destination = 127 if "response_to_broadcast" in self.faults else req.source
        request_bit = 0x8000 if "response_as_request" in self.faults else 0
        self._emit(now + self.config.service_delay, spec.name, fields, kind=Kind.RESPONSE, destination=destination,
                   transfer_id=tid, priority=priority, layout=layout, id_or=request_bit)

    def _respond_rejected(self, req: Frame, now: float, current: dict) -> None:
        """The answer to a request that changed nothing (an illegal value, or refused: R10-R12 leave open
        whether, and with what, it is answered): the current values, none, or the request's values echoed. The
        model's ``on_rejected`` hook, if set, hears of the request first."""
        if self.on_rejected is not None:
            self.on_rejected(req)
        how = self.config.rejected_answer
        if how == "current":
            self._respond(req, now, current)
        elif how == "echo":
            self._respond(req, now, {k: req.fields.get(k, v) for k, v in current.items()})

    def _answer_delay(self) -> float:
        if "answer_late" in self.faults:
            return 0.080
        if "answer_not_staggered" in self.faults:
            return 0.010
        if "answer_at_once" in self.faults:
            return 0.001
        node = self.state.boot_node if "answer_slot_from_boot_node" in self.faults else self.node_id
        start = answer_slot_s(node)  # R2
        if self.config.answer_place == "start":
            return start
        # the latest start that still ends inside the slot with one longest frame on the bus ahead of it (the
        # answer frames are shorter than 8 data bytes); at a slow bit rate that may be the slot's start
        room = max(ANSWER_SLOT_S - 2 * frame_bits(8) / self.state.bitrate, 0.0)
        if self.config.answer_place == "late":
            return start + room
        return start + self._rng.uniform(0.0, room)

    def _emit_raw(self, due: float, type_id: int, payload: bytes, priority: int) -> None:
        """A frame the catalogue's layouts cannot express (the faults that send wrong lengths)."""
        tid = self.state.tids.next(f"raw{type_id}")
        self._push(due, WireFrame(message_id(priority, type_id, self.node_id), payload + bytes([tail_byte(tid)]), due))


    def _echo_request(self, f: Frame, now: float) -> None:
        """A service answer repeating the request's payload (for requests the catalogue gives no answer)."""
        can_id = service_id(int(f.spec.priority), f.type_id, False, f.source, self.node_id)  # type: ignore[union-attr, arg-type]
        self._push(now + self.config.service_delay, WireFrame(can_id, f.data))
