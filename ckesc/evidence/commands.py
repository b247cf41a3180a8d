"""R8's clock, sans-IO: per ESC node, the last throttle command that addresses its throttle channel, as the bus
reader (:mod:`.tracker`) knows the channel.

An ESC acts on a RawCommand only where the frame carries its throttle channel (the catalogue's
:func:`~ckesc.protocol.catalogue.addressed_channels`: RawCommand_14b channels 1..4, RawCommand_12b those of the group
it names, RawCommand_10b 1..6), so R8's "no RawCommand has arrived for more than 200 ms" counts from the last frame
that carries it (4.4.4-3 "does not receive any command"), as the emulator's ESC and the explorer's model read it:
after Set ID to channel 20, a 10-bit stream commands nothing of that ESC. A frame R17 says the ESC ignores
(:func:`~.taken.taken`) commands nothing either.

The channel is learned from what the bus says of it, no tolerance of its own:

* a GET_ESC_ID reply and a 242 answer (:meth:`CommandClock.read`): the channel in force. One other than the channel
  known took effect at the last Set ID heard (only Set ID moves it, 4.4.18);
* a Set ID answer (:meth:`CommandClock.set_id_answer`): the channel the ESC took at the request, except where the
  answer may echo a request the ESC refused (R10-R12 leave a refused request's answer free, "the request's values
  echoed while nothing is applied" among them): one with an illegal value, one while reporting is suspended, one
  more than 120 s after a power-up the host reported (R11). Where the power-up is not known (a capture, a lane that
  found the ESC on), an answer that says what the request asked may be such an echo: the channel is then not known
  until the next read (R8 is not judged meanwhile);
* what a consumer read where the reader was not fed the answer (:meth:`CommandClock.read`, the reader's ``clock``:
  the explorer's baseline).

Until a node's channel is known no command addresses it: its last command is None (R8 is not judged on it). A
Set ID that moves an ESC to another node id starts the new id's clock at the request (what the old id heard is
another node's). Memory: one time per command key (at most 3 formats and 256 groups) and per node.
"""

from __future__ import annotations

import math
from functools import cache
from typing import Callable

from ..protocol import catalogue as cat
from ..protocol.codecs import THROTTLE12_GROUP_BYTE
from ..protocol.transfer import SINGLE_FRAME
from .taken import taken

_12B = cat.spec("raw_command_12b").type_id
#: each throttle frame's common form, by type id: its length on the bus (its table's, with its tail byte) and the tail
#: bits of a single frame (start, end; none for RawCommand_10b, which has no tail byte)
_FORM = {cat.spec(n).type_id: (cat.spec(n).layouts[0].size + cat.spec(n).has_tail,
                               SINGLE_FRAME if cat.spec(n).has_tail else 0) for n in cat.THROTTLE_FRAMES}
_SET_ID = cat.spec("set_id")
_SET_ID_NODE, _SET_ID_CHANNEL = (_SET_ID.request.field(k) for k in ("node_id", "throttle_channel"))  # type: ignore[union-attr]
#: where each answer that says a node's channel carries it: GET_ESC_ID's reply, Set ID's answer, 242's answer
_REPLY_CHANNEL = cat.spec("get_esc_id").message_layout(2).field("throttle_channel")  # type: ignore[union-attr]
_ANSWER_CHANNEL = {_SET_ID.type_id: _SET_ID.response.field("throttle_channel"),  # type: ignore[union-attr]
                   cat.spec("get_major_configuration").type_id:
                       cat.spec("get_major_configuration").response.field("throttle_channel")}  # type: ignore[union-attr]


def command_key(type_id: int, group: int = 0) -> int:
    """A throttle frame's key: its type, and for RawCommand_12b the group it names."""
    return type_id << 8 | group


@cache
def keys_for(channel: int) -> frozenset[int]:
    """The keys (:func:`command_key`) of the throttle frames that carry ``channel``."""
    out = set()
    for name in cat.THROTTLE_FRAMES:
        type_id = cat.spec(name).type_id
        for group in (cat.THROTTLE_GROUPS if type_id == _12B else (0,)):
            if channel in cat.addressed_channels(name, group or None):
                out.add(command_key(type_id, group))
    return frozenset(out)


def _read(data, f) -> int:
    """Field ``f``'s value in ``data`` (its word, shifted and masked)."""
    return (int.from_bytes(data[f.offset:f.offset + f.size], "little") >> f.shift) & f.mask


class _Esc:
    __slots__ = ("channel", "keys", "before", "since")

    def __init__(self) -> None:
        self.channel: int | None = None
        self.keys: frozenset[int] = frozenset()
        self.before: float | None = None  # the last command that addressed it before its channel last changed
        self.since = -math.inf  # commands on its keys count from here (its channel's change)


class CommandClock:
    """Which throttle command addressed which ESC node last (see the module docstring). ``sink``: told
    ``sink(ts, node)`` for each command that addresses a node whose channel is known, and when a node's channel is
    learned, the last frame since the change that carried it (heard before the answer that says so: told late); a
    consumer that keeps them (the explorer's :class:`~.events.EventLog`) sorts them. None (the default) tells none."""

    def __init__(self) -> None:
        self._on: dict[int, float] = {}  # per command key: the last command's time
        self._escs: dict[int, _Esc] = {}
        #: the last taken Set ID: time, node id, channel, refused (R10-R12), taken or not is unknown (the window's)
        self._set_id: tuple = (-math.inf, None, None, False, False)
        self._snapshot: dict[int, float | None] = {}  # each node's last command at that Set ID
        self.sink: Callable[[float, int], None] | None = None

    # ------------------------------------------------------------------ the bus
    def command(self, can_id: int, type_id: int, data, ts: float) -> None:
        """A host's throttle frame (the hot path: a stream's every frame)."""
        length, single = _FORM[type_id]
        if (len(data) != length or data[-1] & single != single) and not taken(can_id, data):
            return  # (the common frame is taken: its form is read only otherwise)
        key = type_id << 8
        if type_id == _12B:
            key |= data[THROTTLE12_GROUP_BYTE]
        self._on[key] = ts
        if self.sink is not None:
            for node, esc in self._escs.items():
                if key in esc.keys:
                    self.sink(ts, node)

    def set_id(self, ts: float, data, *, suspended: bool, up_for: float | None) -> None:
        """A taken Set ID request at ``ts`` (every ESC may take it, R11): the last command of each node before it kept.
        ``suspended``: reporting is suspended (R12 refuses it); ``up_for``: how long the ESC has been powered, where
        the host reported its power-up (None: not known)."""
        if len(data) <= max(_SET_ID_NODE.offset, _SET_ID_CHANNEL.offset):
            return
        node, channel = _read(data, _SET_ID_NODE), _read(data, _SET_ID_CHANNEL)
        refused = (not (_SET_ID_NODE.is_legal(node) and _SET_ID_CHANNEL.is_legal(channel)) or suspended
                   or (up_for is not None and up_for > cat.CONFIG_WINDOW_S))
        self._set_id = (ts, node, channel, refused, up_for is None)
        self._snapshot = {n: self.last(n) for n, esc in self._escs.items() if esc.channel is not None}

    def reply(self, node: int, data) -> None:
        """A GET_ESC_ID reply of ``node``: its channel in force."""
        if len(data) > _REPLY_CHANNEL.offset:
            self.read(node, _read(data, _REPLY_CHANNEL))

    def answer(self, service: int, node: int, data, request_t: float) -> None:
        """An answer of ``node`` paired with its request (sent at ``request_t``): 242's says its channel in force, Set
        ID's the channel it took at the request (unless it may echo a refused one: the module docstring)."""
        f = _ANSWER_CHANNEL.get(service)
        if f is None or len(data) <= f.offset:
            return
        channel = _read(data, f)
        if service != _SET_ID.type_id:
            self.read(node, channel)
            return
        t, asked_node, asked_channel, refused, unsure = self._set_id
        if t != request_t:
            return  # an answer to an earlier Set ID: a read says the channel
        if (refused or unsure) and (_read(data, _SET_ID_NODE), channel) == (asked_node, asked_channel):
            if not refused and node == asked_node:  # taken, or refused and echoed from the id it kept: a read says
                self._escs.pop(node, None)
            return  # (refused, or from another id than asked: maybe a refused request's echo, the channel unchanged)
        self._learn(node, channel, t)

    # ------------------------------------------------------------------ what the reader knows
    def read(self, node: int, channel: int) -> None:
        """``node``'s channel in force, read: one other than the channel known took effect at the last Set ID."""
        self._learn(node, channel, self._set_id[0])

    def _learn(self, node: int, channel: int, since: float) -> None:
        if channel not in cat.THROTTLE_CHANNELS:
            return  # (no ESC takes an illegal channel, R10: the answer says nothing of the one in force)
        esc = self._escs.get(node)
        if esc is None:
            esc = self._escs[node] = _Esc()
        if esc.channel == channel:
            return
        # what addressed it before the change: its last command at that Set ID (none where it had no channel known
        # then, or the Set ID is not the one the reader kept)
        esc.before = self._snapshot.get(node) if since == self._set_id[0] else None
        esc.channel, esc.keys, esc.since = channel, keys_for(channel), since
        if self.sink is not None:  # the last frame that carried it since the change, heard before the answer said so
            last = max((t for k in esc.keys if (t := self._on.get(k)) is not None and t >= since), default=None)
            if last is not None:
                self.sink(last, node)

    def channel(self, node: int) -> int | None:
        """``node``'s throttle channel as the reader knows it (None: not known)."""
        esc = self._escs.get(node)
        return None if esc is None else esc.channel

    def last(self, node: int) -> float | None:
        """When the last throttle command that addressed ``node``'s channel was on the bus (None: none since its
        channel is known, or its channel is not known)."""
        esc = self._escs.get(node)
        if esc is None:
            return None
        best = esc.before
        on = self._on
        for k in esc.keys:
            t = on.get(k)
            if t is not None and t >= esc.since and (best is None or t > best):
                best = t
        return best
