"""The R17 classes of frame: a command the ESC would take, sent malformed or foreign (sans-IO).

R17 (READING): the ESC acts only on a single-frame transfer of one of its frame types, of its table's payload length,
and for a service on a request addressed to its node id. Each class here is one way a frame misses that: a start, a
middle or an end frame of a multi-frame transfer, a whole multi-frame transfer (DroneCAN's, its transfer CRC valid:
:func:`~ckesc.protocol.transfer.multi_frame`), an empty frame, one a byte short or long of its table, a request to
another node, a response frame. R17-toggle (OBSERVE): a single frame whose toggle bit is 1 (:data:`TOGGLE`), which
DroneCAN's own receiver takes.

Built from the fields of a valid command (:func:`ckesc.protocol.frame.encode`), so that an ESC that takes one acts on
a command: the robustness suite (``conformance/test_robustness_r17_malformed.py``, every class at once,
:func:`malformed`) and ``ckesc explore`` (one class a step, :func:`build`) send the same frames.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Iterable

from . import catalogue as cat
from .frame import WireFrame, encode
from .ids import ESC_NODE_IDS, Kind, parse_can_id, service_id
from .judgements import asked_node
from .transfer import TRANSFER_ID_MODULO, multi_frame, tail_byte, tail_transfer_id

#: classic CAN's most data bytes (a frame one byte longer than its table is sent where it fits)
MAX_DATA = 8
#: the bits of a node id (F1: seven, 1..127)
NODE_ID_BITS = max(ESC_NODE_IDS).bit_length()

# the classes, by name (an exploration program names its step's class)
START = "start"
MIDDLE = "middle"
END = "end"
WHOLE = "whole"
EMPTY = "empty"
SHORT = "short"
LONG = "long"
OTHER_NODE = "other_node"
RESPONSE = "response"
TOGGLE = "toggle"
#: the classes R17 says are ignored, in the order the robustness suite sends them
FORMS = (START, MIDDLE, END, WHOLE, EMPTY, SHORT, LONG, OTHER_NODE, RESPONSE)
#: what each class is, in a finding's or a verdict's words
DESCRIPTIONS = {
    START: "multi-frame start frame (start=1 end=0)",
    MIDDLE: "multi-frame middle frame (start=0 end=0 toggle=1)",
    END: "multi-frame end frame (start=0 end=1 toggle=1)",
    WHOLE: "whole multi-frame transfer with DroneCAN's CRC",
    EMPTY: "empty",
    SHORT: "one byte short",
    LONG: "one byte long",
    OTHER_NODE: "request to another node",
    RESPONSE: "response frame",
    TOGGLE: "single frame, toggle 1",
}


@dataclass
class Bad:
    """One malformed frame (or a whole multi-frame transfer: several frames) and what it is."""

    what: str
    frames: list[WireFrame]
    transfer_id: int | None
    form: str = ""

    def __str__(self) -> str:
        return f"{self.what} ({' '.join(str(w) for w in self.frames)})"


def host_layout(spec: cat.FrameSpec) -> cat.Layout | None:
    """The layout of what the host sends of ``spec`` (None: the ESC takes no such frame from the host)."""
    if spec.service:
        return spec.request
    return next((lay for lay in spec.layouts if lay.sender != "esc"), None)


def other_nodes(node_id: int, bench_nodes: Iterable[int] = ()) -> list[int]:
    """Node ids no ESC of the bench (``bench_nodes``) has, each one bit away from ``node_id``: an ESC that decodes
    fewer than the seven bits of a destination takes a request to one of them."""
    near = (node_id ^ (1 << bit) for bit in range(NODE_ID_BITS))
    taken = set(bench_nodes)
    return [n for n in dict.fromkeys(near) if n in ESC_NODE_IDS and n not in taken and n != node_id]


def applies(spec: cat.FrameSpec, form: str) -> bool:
    """Whether class ``form`` exists for frame type ``spec``: the tail classes need a tail byte (10-bit RawCommand
    has none, R5), a wrong length a fixed one (Get Rec's payload is free; Self Test's is empty: "empty" is its one
    byte short), one byte long room in CAN's 8, a request to another node and a response a service."""
    layout = host_layout(spec)
    if layout is None:
        return False
    if form in (START, MIDDLE, END, WHOLE, TOGGLE):
        return spec.has_tail
    if form == SHORT:
        return bool(layout.size)
    if form == LONG:
        return layout.size is not None and layout.size + spec.has_tail < MAX_DATA
    if form == OTHER_NODE:  # (Set ID ignores the destination, R11: a pseudo-broadcast, taken from any)
        return spec.service and asked_node(spec.name, 0) is not None
    if form == RESPONSE:
        return spec.service
    return form == EMPTY


def _tail(start: bool, end: bool, toggle: bool) -> Callable[[bytes], bytes]:
    return lambda d: d[:-1] + bytes((tail_byte(tail_transfer_id(d[-1]), start=start, end=end, toggle=toggle),))


def build(name: str, fields: dict, form: str, *, source: int, node_id: int, others: list[int],
          transfer_id: Callable[[int | None], int], nibble_order: str | None = None) -> list[Bad]:
    """``name``'s command ``fields`` in class ``form`` (empty where it does not apply, :func:`applies`): one
    :class:`Bad`, but for :data:`OTHER_NODE`, one request to each of ``others`` (:func:`other_nodes`; none: none).
    ``source``: the sender's node id (the host's); ``node_id``: the ESC's; ``transfer_id(destination)``: the transfer
    id of the next frame (each its own, so that an answer names the frame it answers). A response frame comes from
    ``others[0]`` (from node 0, a bench whose echo is not told apart would take it for the DUT's)."""
    spec = cat.spec(name)
    if not applies(spec, form) or (form in (OTHER_NODE, RESPONSE) and not others):
        return []
    kind = Kind.REQUEST if spec.service else Kind.MESSAGE
    layout = "query" if name == "get_esc_id" else None
    enc = {} if nibble_order is None else {"nibble_order": nibble_order}

    def wire(tid: int, destination: int | None = None) -> WireFrame:
        node = (node_id if destination is None else destination) if spec.service else None
        return encode(spec, fields, kind=kind, source=source, destination=node, transfer_id=tid, layout=layout, **enc)

    def bad(what: str, data=lambda d: d, *, destination: int | None = None, response: bool = False,
            whole: bool = False) -> Bad:
        tid = transfer_id(node_id if spec.service and destination is None else destination)
        w = wire(tid, destination)
        can_id = w.arbitration_id
        if response:  # the same frame with the request bit clear, from another node: a response the ESC never asked
            i = parse_can_id(can_id)
            can_id = service_id(i.priority, i.type_id, False, node_id, others[0])
        # a whole transfer as DroneCAN splits it (7 bytes a frame), but that no frame of it has the table's 8 bytes:
        # an ESC that takes a start frame would read the CRC as a command (a throttle, with no --allow-motor-spin)
        chunk = MAX_DATA - 2 if len(w.data) == MAX_DATA else MAX_DATA - 1
        datas = multi_frame(w.data[:-1], tid, chunk=chunk) if whole else [data(w.data)]
        return Bad(what, [WireFrame(can_id, d) for d in datas], tid if spec.has_tail else None, form)

    what = DESCRIPTIONS[form]
    if form == START:
        return [bad(what, _tail(True, False, False))]
    if form == MIDDLE:
        return [bad(what, _tail(False, False, True))]
    if form == END:
        return [bad(what, _tail(False, True, True))]
    if form == TOGGLE:
        return [bad(what, _tail(True, True, True))]
    if form == WHOLE:
        return [bad(what, whole=True)]
    if form == EMPTY:
        return [bad(what, lambda d: b"")]
    if form == SHORT:
        return [bad(what, lambda d: d[:-2] + d[-1:] if spec.has_tail else d[:-1])]
    if form == LONG:
        return [bad(what, lambda d: d[:-1] + bytes(1) + d[-1:] if spec.has_tail else d + bytes(1))]
    if form == OTHER_NODE:
        return [bad(f"request to node {n}", destination=n) for n in others]
    return [bad(f"response frame from node {others[0]}", response=True)]


def malformed(name: str, fields: dict, *, source: int, node_id: int, others: list[int],
              nibble_order: str | None = None, toggle_only: bool = False) -> list[Bad]:
    """``name``'s command ``fields`` in every class R17 names (:data:`FORMS`, each that applies), each frame with its
    own transfer id (0, 1, ... in order); only the single frame with toggle 1 (R17-toggle) when ``toggle_only``."""
    tids = iter(range(TRANSFER_ID_MODULO))

    def tid(destination: int | None) -> int:
        return next(tids)

    out: list[Bad] = []
    for form in (TOGGLE,) if toggle_only else FORMS:
        out += build(name, fields, form, source=source, node_id=node_id, others=others, transfer_id=tid,
                     nibble_order=nibble_order)
    return out
