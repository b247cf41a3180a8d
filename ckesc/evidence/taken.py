"""R17 as the bus reader applies it to the host's own frames: which of them an ESC acts on (sans-IO).

R17 (READING): the ESC acts only on a single-frame transfer of one of its frame types, of its table's payload length.
A host frame that misses that (a multi-frame start, middle or end frame, a frame a byte short or long) is ignored:
it suspends, resumes or switches nothing, writes no interval, moves no node id. So the reader does not take it as
a restart of reporting (R9a) nor as a reason not to judge a reset across it (R19, R17's "never resets"). A single
frame whose toggle bit is 1 may be taken or ignored (R17-toggle, OBSERVE): the reader takes it, so that nothing is
judged across it that a DUT taking it would break.

The frame is told malformed by the protocol's own decoder (:class:`~ckesc.protocol.frame.Decoder`: its
:class:`~ckesc.protocol.errors.TailError` and :class:`~ckesc.protocol.errors.LengthError`), as the emulator's ESC
and the explorer's oracle tell it: one reading of R17's classes.
"""

from __future__ import annotations

from ..protocol.errors import DecodeError, LengthError, TailError
from ..protocol.frame import Decoder, WireFrame
from ..protocol.transfer import parse_tail

_DECODER = Decoder(track_requests=False)


def taken(can_id: int, data: bytes) -> bool:
    """Whether an ESC may act on the host's frame ``can_id`` / ``data`` (a 29-bit data frame): False only where
    R17 says it is ignored (module docstring)."""
    try:
        _DECODER.decode(WireFrame(can_id, bytes(data)))
    except TailError:
        tail = parse_tail(data[-1]) if data else None
        return tail is not None and tail.start and tail.end  # a single frame with toggle 1: R17-toggle, may be taken
    except LengthError:
        return False
    except DecodeError:
        return True  # (not R17's: what the reader made of such a frame before stays)
    return True
