"""The simulated bus's frames (:mod:`.sim_bus`): a frame on its way onto the bus (:class:`FrameOnItsWay`), and a
data frame as a host's bus hears it (:class:`Heard`, :class:`Echo`), each a tuple made without a Python-level
constructor: every frame of a simulated run is one of each."""

from __future__ import annotations

from functools import partial
from typing import Any, NamedTuple

from ..protocol.frame import WireFrame


class FrameOnItsWay(NamedTuple):
    """A frame on its way to the bus (its node's queue, then arbitration); made with :data:`new_pending`."""

    ready: float
    seq: int
    wire: WireFrame
    origin: Any
    bitrate: int
    flags: dict[str, bool] | None  # a host's remote or error frame: not a data frame, whatever its bytes


#: ``new_pending((ready, seq, wire, origin, bitrate, flags))``: without namedtuple's Python-level constructor (a
#: frame's way onto the bus: every frame of a simulated run)
new_pending = partial(tuple.__new__, FrameOnItsWay)


class Heard(WireFrame):
    """A data frame as a host's bus hears it, before any ``can.Message`` is made of it: a :class:`WireFrame` stamped at
    its last bit, with the ``can.Message`` attributes the readers of :meth:`~.sim_bus.SimEscBus.frames_until` ask for.
    :meth:`~.sim_bus.SimEscBus.recv` makes the ``can.Message`` (python-can's boundary); a soak's reader takes the frame
    as it is (hours of frames, none of which leaves the simulated world)."""

    __slots__ = ()
    is_rx = True  #: another node's frame (:class:`Echo`: the bus's own, heard back)
    is_remote_frame = False
    is_error_frame = False


class Echo(Heard):
    """A host bus's own data frame as it hears it back (``receive_own_messages``): ``is_rx`` False."""

    __slots__ = ()
    is_rx = False


#: ``new_heard((arbitration_id, data, timestamp, is_extended_id))``, ``new_echo(...)``: made as
#: :func:`~ckesc.protocol.frame.new_wire` makes a wire (no Python-level constructor: every frame of a simulated run)
new_heard = partial(tuple.__new__, Heard)
new_echo = partial(tuple.__new__, Echo)
