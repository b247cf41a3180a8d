"""R17 as the bus reader applies it to the host's own frames: which of them an ESC acts on (sans-IO).

R17 (READING): the ESC acts only on a single-frame transfer of one of its frame types, of its table's payload length.
A host frame that misses that (a multi-frame start, middle or end frame, a frame a byte short or long) is ignored:
it suspends, resumes or switches nothing, writes no interval, moves no node id. So the reader does not take it as
a restart of reporting (R9a) nor as a reason not to judge a reset across it (R19, R17's "never resets"). A single
frame whose toggle bit is 1 may be taken or ignored (R17-toggle, OBSERVE): the reader takes it, so that nothing is
judged across it that a DUT taking it would break.

The frame is told malformed as the protocol's own decoder tells it (:func:`~ckesc.protocol.frame.read_form`, the
checks :class:`~ckesc.protocol.frame.Decoder` makes before it reads a field: its
:class:`~ckesc.protocol.errors.TailError` and :class:`~ckesc.protocol.errors.LengthError`), as the emulator's ESC and
the explorer's oracle tell it: one reading of R17's classes. No field is read: the reader decodes no frame (the
host's link decodes each frame once).
"""

from __future__ import annotations

from ..protocol.errors import LengthError, TailError
from ..protocol.frame import classify, read_form
from ..protocol.ids import RESERVED_NODE_IDS
from ..protocol.transfer import parse_tail


def taken(can_id: int, data: bytes) -> bool:
    """Whether an ESC may act on the host's frame ``can_id`` / ``data`` (a 29-bit data frame): False only where
    R17 says it is ignored (module docstring)."""
    if len(data) > 8:
        return False  # (more than classic CAN carries: the decoder's LengthError)
    kind, _, source, _, spec = classify(can_id)
    if spec is None or source in RESERVED_NODE_IDS:
        return True  # (not R17's: what the reader made of such a frame before stays)
    try:
        read_form(kind, spec, bytes(data))
    except TailError:
        tail = parse_tail(data[-1]) if data else None
        return tail is not None and tail.start and tail.end  # a single frame with toggle 1: R17-toggle, may be taken
    except LengthError:
        return False
    return True
