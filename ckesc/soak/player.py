"""A flight controller, sans-IO (R19): given the time, the frames due and the next deadline.

What it plays, as an autopilot does in flight: a RawCommand stream (its format, rate and channels; zero throttle
unless the caller allows the motor to spin and gives a throttle profile), GET_ESC_ID once a second from the host's
node, and, every few seconds, reads of Maintenance Information (241: option 1, the run time; option 2, the power-up
count) and now and then of Get Major Configuration (242, the settings). A stream frame that could not go out in
time (a real-time host that was not scheduled) is sent once, late, and the ones it missed are skipped, never sent
in a burst: :attr:`Player.skipped` counts them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import partial
from typing import Any, NamedTuple

from ..protocol import catalogue as cat
from ..protocol.frame import WireFrame, encode, new_wire
from ..protocol.ids import Kind
from ..protocol.transfer import TAIL_BYTES, TransferIdCounter

#: RawCommand formats by their command-line name: (frame name, channels per frame: the catalogue's)
FORMATS: dict[str, tuple[str, int]] = {f: (n, cat.FORMAT_CHANNELS[n]) for f, n in (("14b", "raw_command_14b"),
                                                                                  ("12b", "raw_command_12b"),
                                                                                  ("10b", "raw_command_10b"))}
#: the stream rates a flight controller uses (issue #31), in Hz
RATE_RANGE = (50.0, 500.0)
#: how often each read is made (s): GET_ESC_ID as R19 says, 241 and 242 as often as a log needs them
ESC_ID_PERIOD_S = 1.0
MAINTENANCE_PERIOD_S = 10.0
SETTINGS_PERIOD_S = 60.0
#: the 241 options read: 1 (this run: run time), 2 (counters: power-up count)
MAINTENANCE_OPTIONS = (1, 2)


class Planned(NamedTuple):
    """One frame the player wants on the bus: ``what`` (``stream``, ``get_esc_id``, ``maintenance``, ``settings``),
    the frame, the time it was due, and for a request its fields (a 241 answer's layout depends on them)."""

    what: str
    wire: WireFrame
    due: float
    fields: dict[str, Any] | None = None


#: ``_new_planned((what, wire, due, fields))``: a :class:`Planned` of all four fields, made without the Python-level
#: constructor namedtuple adds (``new_wire``'s way: a stream's 400 a second, hours long)
_new_planned = partial(tuple.__new__, Planned)


@dataclass(frozen=True)
class FlightPlan:
    """What the player plays. ``throttle``: the throttle profile, ``(from_s, value)`` steps (piecewise constant,
    the last held), only with ``allow_motor_spin``; ``channels``: the throttle channels the stream commands."""

    host_node: int
    node_id: int
    format: str = "14b"
    rate_hz: float = 400.0
    channels: tuple[int, ...] = (1, 2, 3, 4)
    throttle: tuple[tuple[float, int], ...] = ()
    allow_motor_spin: bool = False
    nibble_order: str = "lsb"

    def check(self) -> None:
        """A plan the player cannot play is a ``ValueError`` naming why."""
        if self.format not in FORMATS:
            raise ValueError(f"format {self.format!r}: one of {', '.join(FORMATS)}")
        lo, hi = RATE_RANGE
        if not lo <= self.rate_hz <= hi:
            raise ValueError(f"rate {self.rate_hz:g} Hz: a flight controller's stream runs at {lo:g}-{hi:g} Hz")
        legal = cat.THROTTLE_CHANNELS
        if not self.channels or any(c not in legal for c in self.channels):
            raise ValueError(f"channels {list(self.channels)}: each in {legal.start}..{legal.stop - 1}")
        per = FORMATS[self.format][1]
        if self.format != "12b" and max(self.channels) > per:
            raise ValueError(f"RawCommand_{self.format} carries channels 1..{per}, not {max(self.channels)}")
        if self.format == "12b" and max(self.channels) > per * len(cat.THROTTLE_GROUPS):
            raise ValueError(f"RawCommand_12b's groups carry channels 1..{per * len(cat.THROTTLE_GROUPS)}")
        if any(v for _, v in self.throttle) and not self.allow_motor_spin:
            raise ValueError("a throttle profile other than zero needs allow_motor_spin (and the propeller off)")
        if any(not 0 <= v <= cat.THROTTLE_MAX for _, v in self.throttle):
            raise ValueError(f"a throttle profile's values are 0..{cat.THROTTLE_MAX}")

    def throttle_at(self, t: float) -> int:
        """The throttle the profile asks for ``t`` seconds into the run (0 without a profile or motor spin)."""
        if not self.allow_motor_spin:
            return 0
        value = 0
        for start, v in self.throttle:
            if t >= start:
                value = v
        return value


class _Every:
    """A periodic duty: due at ``start + k * period``; one that fell behind skips to its next future slot."""

    __slots__ = ("start", "period", "k", "due")

    def __init__(self, start: float, period: float) -> None:
        self.start, self.period, self.k = start, period, 0
        self.due = start  #: ``start + k * period``, kept (read on every stream tick)

    def take(self, now: float) -> tuple[float, int]:
        """The slot due (at or before ``now``) and how many later slots, also past, are skipped."""
        due = self.due
        behind = math.floor((now - self.start) / self.period) - self.k
        if behind < 0:
            behind = 0
        self.k += behind + 1
        self.due = self.start + self.k * self.period
        return due, behind


class Player:
    """The flight controller of a :class:`FlightPlan`, from lane time ``start``: :meth:`due` the frames due by a
    time, :meth:`next_deadline` when the next one is."""

    def __init__(self, plan: FlightPlan, start: float) -> None:
        plan.check()
        self.plan = plan
        self.start = start
        self.tids = TransferIdCounter()
        self.stream = _Every(start, 1.0 / plan.rate_hz)
        self.esc_id = _Every(start, ESC_ID_PERIOD_S)
        # the reads start a little after the stream, spread over their period so that they do not come together
        self.maintenance = _Every(start + MAINTENANCE_PERIOD_S / 4, MAINTENANCE_PERIOD_S / len(MAINTENANCE_OPTIONS))
        self.settings = _Every(start + MAINTENANCE_PERIOD_S / 2, SETTINGS_PERIOD_S)
        self.sent_stream = 0
        self.skipped = 0  # stream frames skipped (the host was late by more than a period)
        self._reads = 0
        self._value: int | None = None  # the throttle of the stream's frames encoded in _wires
        self._wires: list[WireFrame] = []
        name = FORMATS[plan.format][0]
        self._key = (Kind.MESSAGE, name) if cat.spec(name).has_tail else None  # the stream's transfer id counter
        self._duties = ((self.esc_id, self._esc_id), (self.maintenance, self._maintenance), (self.settings, self._settings))
        self._reads_due = min(duty.due for duty, _ in self._duties)

    def next_deadline(self) -> float:
        return min(self.stream.due, self._reads_due)

    def due(self, now: float) -> list[Planned]:
        """Every frame due at or before ``now``, in order of their due times (a stream frame first at a tie)."""
        out: list[Planned] = []
        stream = self.stream
        while stream.due <= now:
            due, behind = stream.take(now)
            self.skipped += behind
            self._stream(due, out)
        if self._reads_due <= now:  # (the reads come once a second at most: the stream's path stays short)
            for duty, make in self._duties:
                while duty.due <= now:
                    out.extend(make(duty.take(now)[0]))
            self._reads_due = min(duty.due for duty, _ in self._duties)
            out.sort(key=lambda p: p.due)
        return out

    # ------------------------------------------------------------------ the frames
    def _message(self, name: str, fields: dict[str, Any], **kw: Any) -> WireFrame:
        tid = self.tids.next((Kind.MESSAGE, name))
        return encode(name, fields, source=self.plan.host_node, transfer_id=tid, nibble_order=self.plan.nibble_order, **kw)

    def _command(self, name: str, fields: dict[str, Any]) -> WireFrame:
        """A stream frame's command, encoded (its transfer id set as it goes out, :meth:`_renewed`)."""
        return encode(name, fields, source=self.plan.host_node, transfer_id=0, nibble_order=self.plan.nibble_order)

    def _request(self, name: str, fields: dict[str, Any]) -> WireFrame:
        node = self.plan.node_id
        tid = self.tids.next((Kind.REQUEST, name), node)
        return encode(name, fields, kind=Kind.REQUEST, source=self.plan.host_node, destination=node, transfer_id=tid)

    def _stream(self, due: float, out: list[Planned]) -> None:
        """The stream's frames of the tick ``due`` onto ``out`` (a tick's whole work: 400 a second, hours long)."""
        plan = self.plan
        value = plan.throttle_at(due - self.start) if plan.throttle else 0
        self.sent_stream += 1
        if value != self._value or not self._wires:  # else the same command again: only the transfer ids move on
            self._value, self._wires = value, [self._renewed(p.wire) for p in self._stream_of(value, due)]
        key = self._key
        if key is None:  # RawCommand_10b has no tail, hence no transfer id (R5)
            for w in self._wires:
                out.append(_new_planned(("stream", w[0], due, None)))
            return
        nxt = self.tids.next
        for w in self._wires:
            out.append(_new_planned(("stream", w[nxt(key)], due, None)))

    def _renewed(self, wire: WireFrame) -> tuple[WireFrame, ...]:
        """The command ``wire`` (encoded once) with each transfer id in its tail byte, by transfer id (0..31: the
        stream's counter's modulo); RawCommand_10b has no tail: the wire itself."""
        if self._key is None:
            return (wire,)
        return tuple(new_wire((wire.arbitration_id, wire.data[:-1] + tail, wire.timestamp, wire.is_extended_id))
                     for tail in TAIL_BYTES)

    def _stream_of(self, value: int, due: float) -> list[Planned]:
        plan = self.plan
        name, per = FORMATS[plan.format]
        if plan.format == "12b":
            groups = sorted({(c - 1) // per + 1 for c in plan.channels})
            return [Planned("stream", self._command(name, {"group": g, "channels": [
                value if (g - 1) * per + i + 1 in plan.channels else 0 for i in range(per)]}), due) for g in groups]
        channels = [value if i + 1 in plan.channels else 0 for i in range(per)]
        return [Planned("stream", self._command(name, {"channels": channels}), due)]

    def _esc_id(self, due: float) -> list[Planned]:
        return [Planned("get_esc_id", self._message("get_esc_id", {"option": 0}, layout="query"), due)]

    def _maintenance(self, due: float) -> list[Planned]:
        option = MAINTENANCE_OPTIONS[self._reads % len(MAINTENANCE_OPTIONS)]
        self._reads += 1
        fields = {"option": option}
        return [Planned("maintenance", self._request("maintenance_information", fields), due, fields)]

    def _settings(self, due: float) -> list[Planned]:
        fields = {"option": 0}
        return [Planned("settings", self._request("get_major_configuration", fields), due, fields)]

    @property
    def frames_per_tick(self) -> int:
        """How many frames each stream tick sends (RawCommand_12b: one per group of the channels)."""
        name, per = FORMATS[self.plan.format]
        return len({(c - 1) // per for c in self.plan.channels}) if self.plan.format == "12b" else 1

    def zero(self) -> list[WireFrame]:
        """Zero throttle on every channel the stream commands, in its format: the last frames of a run."""
        name, per = FORMATS[self.plan.format]
        if self.plan.format == "12b":
            return [self._message(name, {"group": g, "channels": [0] * per})
                    for g in sorted({(c - 1) // per + 1 for c in self.plan.channels})]
        return [self._message(name, {"channels": [0] * per})]
