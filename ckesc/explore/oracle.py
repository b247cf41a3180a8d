"""The ESC model as oracle, in lockstep with the DUT (sans-IO: frames and times in, predictions out).

A fresh, faultless :class:`~ckesc.emulator.model.EscModel` is given the DUT's state at the start of a program
(its node id, the settings 242 and 214 read back, the counters of 241) and then exactly what the DUT was
given: every host frame, at the bus time the DUT saw it (its echo's timestamp), and every power switch at the
lane time it happened. What it sends is its prediction; :mod:`ckesc.explore.judge` compares it with what the
DUT sent, only where the document (or a stated READING) is specific.

The model plays the emulator's default choice of every freedom (``variants.py``); where its choice shows in
what it sends, the judge does not look (an answer to a rejected request, the first reports after a restart,
which MSG_EXP frames come). A rejected request (R10-R12: whether and how it is answered is free) is noted in
:attr:`Oracle.free` and gets no predicted answer.

A foreign load (R18) is told to it by share (:meth:`Oracle.load`): its ESC does on a loaded bus what it does on a quiet
one, and the judge widens R9 by the queueing the load can cause.

A bus short (R20) is told to it by its start, its end and when the ESC's reports are back on their grid
(:meth:`Oracle.mark`: ``bus short``, ``bus free``, ``bus settled``; :attr:`Oracle.shorts`): its ESC goes on as if the
bus carried its frames, and the judge judges nothing of the reports in between but R20's recovery. The frames the
host sent while it was alone on the bus (a power cycle's, R20) reach it when they went out (their echo), those the
DUT took only (:attr:`Oracle.held`: their answers are OBSERVE).

A frame the runner sent malformed or foreign (R17) is given to the model too, which ignores it (that is R17's
oracle: whatever the DUT does on it is a finding), and kept in :attr:`Oracle.malformed` for the judge; a single frame
with toggle 1 (R17-toggle, OBSERVE) is given to it as the DUT took it: as a single frame where the DUT answered it,
else as the malformed frame it is.
"""

from __future__ import annotations

import bisect
from dataclasses import dataclass, field
from typing import Any, Mapping

from ..emulator.model import EXP_MODE, SUSPENDED, EscConfig, EscModel, factory_nvm
from ..protocol import catalogue as cat
from ..protocol.errors import DecodeError
from ..protocol.frame import Decoder, Frame
from ..protocol.ids import Kind, parse_can_id

#: DUT settings (Dut.settings() keys, 242 / 214) -> the model's flash keys: the same names
SETTING_KEYS = ("rotation", "throttle_source", "throttle_channel", "led_color", "led_blink", *cat.INTERVAL_FIELDS)
#: the marks of a bus short (R20), in order: its start, its end, the reports back on their grid
SHORT_MARKS = ("bus short", "bus free", "bus settled")


@dataclass
class State:
    """What the model's ESC is doing after an event: its mode and report intervals (seconds)."""

    t: float
    label: str
    mode: str  # normal | suspended | exp | can_test | off
    intervals: dict[str, float]
    step: int | None = None
    cause: str = ""  # the event that put the model's ESC into this mode (the label of the state it changed at)
    source: int = 0  # the throttle source (242): comm loss (R8) is judged under CAN throttle (0) only
    bitrate: int = cat.DEFAULT_BITRATE  # the bus's bit rate in force (Set Baud's, from the last power-up)
    load: float = 0.0  # the foreign load on the bus, a share of its capacity (R18)


@dataclass(frozen=True)
class Malformed:
    """A frame sent malformed or foreign (R17), as the DUT heard it: ``what`` it was (its class and command)."""

    t: float
    name: str  # the command's frame type
    form: str  # its class (:mod:`ckesc.protocol.malformed`)
    what: str
    kind: Kind
    type_id: int
    transfer_id: int | None
    step: int | None
    destination: int | None = None  # a request's (F4: its answer would come from that node)


@dataclass
class Oracle:
    """Drive a faultless model along the DUT's program. ``baseline``: the DUT's node id, settings and counters
    as read at the program's start; ``powered_at``: the lane time of the DUT's current power-up (its 120 s window)."""

    baseline: Mapping[str, Any]
    powered_at: float
    start: float | None = None  # the program's start (what the model sends before it is not kept)
    host_node: int = 0
    model: EscModel = field(init=False)
    #: the requests the model rejected, as (name, transfer id): their answer is the DUT's freedom (R10-R12)
    free: set[tuple[str, int]] = field(init=False, default_factory=set)
    out: list[Frame] = field(default_factory=list)  # the model's frames, decoded, stamped with their due time
    states: list[State] = field(default_factory=list)
    host: list[tuple[Frame, int | None]] = field(default_factory=list)  # host frames fed, with the program step
    malformed: list[Malformed] = field(default_factory=list)  # the frames sent malformed or foreign (R17), in order
    load_share: float = 0.0  # the foreign load on the bus now (R18): the model's ESC does what it does on a quiet one
    #: the requests the host sent alone on the bus (R20), as (name, transfer id): their answers are OBSERVE
    held: set[tuple[str, int]] = field(default_factory=set)
    start_channel: int = field(init=False, default=0)  # its ESC's throttle channel at the start (the baseline's)

    def __post_init__(self) -> None:
        b = self.baseline
        # rejected_answer "none": a rejected request gets no predicted answer, only a note in ``free`` (on_rejected)
        config = EscConfig(node_id=b["node_id"], throttle_channel=b.get("throttle_channel"), boot_time=0.0,
                           report_delay=0.0, baud_code=b.get("baud", cat.DEFAULT_BAUD_CODE), rejected_answer="none")
        nvm = factory_nvm(config)
        nvm.update({k: b[k] for k in SETTING_KEYS if k in b})
        nvm.update({k: b[k] for k in ("power_ups", "stops") if b.get(k) is not None})
        if b.get("power_ups") is not None:
            nvm["power_ups"] = (b["power_ups"] - 1) & 0xFFFF  # power_on() below counts the power-up the DUT had
        self.model = EscModel(config, nvm)
        self.start_channel = nvm["throttle_channel"]
        self.model.on_rejected = lambda req: self.free.add((req.name, req.transfer_id or 0))
        self._decoder = Decoder()
        self.model.power_on(self.powered_at)
        start = self.powered_at if self.start is None else self.start
        self.advance(start)
        self.out.clear()
        self._note(start, "start")

    # ---------------------------------------------------------------- feeding
    @property
    def node_id(self) -> int:
        return self.model.node_id

    def advance(self, t: float) -> None:
        """Let the model run up to lane time ``t``, keeping what it sends."""
        m = self.model
        while (d := m.next_deadline()) is not None and d <= t:
            self._keep(m.poll(d))
            if m.next_deadline() == d:  # nothing more can happen at d (guards a model that re-arms at once)
                break
        self._keep(m.poll(t))

    def host_frame(self, msg: Any, step: int | None = None) -> None:
        """A host frame the DUT heard at ``msg.timestamp`` (its bus echo)."""
        t = msg.timestamp
        self.advance(t)
        try:
            frame = self._decoder.decode(msg)
        except DecodeError:
            frame = None
        self.model.receive(msg, t)
        self._keep(self.model.poll(t))
        if frame is not None:
            self.host.append((frame, step))
            if frame.name not in cat.THROTTLE_FRAMES:
                self._note(t, frame.name, step)

    def malformed_frame(self, msg: Any, name: str, form: str, what: str, step: int | None = None) -> None:
        """A frame sent malformed or foreign (R17) that the DUT heard at ``msg.timestamp``: the model ignores it (a
        model that acted on it is the oracle's defect, raised); a stretch of its own starts there for the judge."""
        t = msg.timestamp
        self.advance(t)
        before = (self.model.state.last_command, self.mode(), dict(self.model.nvm))
        self.model.receive(msg, t)
        self._keep(self.model.poll(t))
        if (self.model.state.last_command, self.mode(), dict(self.model.nvm)) != before:
            raise AssertionError(f"the oracle model took a frame R17 says to ignore: {what} ({msg})")
        i = parse_can_id(msg.arbitration_id)
        data = bytes(msg.data)
        tid = data[-1] & 0x1F if data and cat.spec(name).has_tail else None
        self.malformed.append(Malformed(t, name, form, what, i.kind, i.type_id, tid, step, i.destination))
        self._note(t, f"malformed {name}", step)

    def power(self, on: bool, t: float, step: int | None = None) -> None:
        self.advance(t)
        if on:
            self.model.power_on(t)
        else:
            self.model.power_off(t)
        self._note(t, "power on" if on else "power off", step)

    def load(self, t: float, share: float, step: int | None = None) -> None:
        """From lane time ``t`` on the bus carries a foreign load of ``share`` of its capacity (R18): a stretch of
        its own for the judge, which widens R9 by the queueing it can cause (and above half judges nothing)."""
        self.advance(t)
        self.load_share = share
        self._note(t, "load", step)

    def mark(self, t: float, label: str, step: int | None = None) -> None:
        """A moment the runner knows of (the DUT ready after a power-up): a stretch of its own for the judge."""
        self.advance(t)
        self._note(t, label, step)

    @property
    def shorts(self) -> list[tuple[float, float, float, int | None]]:
        """Each bus short (R20): (its start, its end, when the reports were back on their grid, its step)."""
        marks = [s for s in self.states if s.label in SHORT_MARKS]
        return [(a.t, b.t, c.t, a.step) for a, b, c in zip(marks[::3], marks[1::3], marks[2::3])]

    def finish(self, t: float) -> None:
        self.advance(t)

    # ---------------------------------------------------------------- what it predicts
    def state_at(self, t: float) -> State:
        """The state the model's ESC is in at lane time ``t``."""
        times = [s.t for s in self.states]
        return self.states[max(0, bisect.bisect_right(times, t) - 1)]

    def max_load(self, lo: float, hi: float) -> float:
        """The highest foreign load (R18's share) on the bus between lane times ``lo`` and ``hi``, or in the stretch
        before (a load's queue outlasts it a little)."""
        times = [s.t for s in self.states]
        first = max(0, bisect.bisect_right(times, lo) - 2)
        return max((s.load for s in self.states[first:bisect.bisect_right(times, hi)]), default=0.0)

    def _keep(self, wires) -> None:
        for w in wires:
            try:
                self.out.append(self._decoder.decode(w))
            except DecodeError:  # the faultless model sends nothing that does not decode
                raise AssertionError(f"the oracle model sent a frame that does not decode: {w}") from None

    def mode(self) -> str:
        m = self.model
        if not m.powered:
            return "off"
        if m.state.can_test:
            return "can_test"
        return {SUSPENDED: "suspended", EXP_MODE: "exp"}.get(m.state.reporting, "normal")

    def _note(self, t: float, label: str, step: int | None = None) -> None:
        nvm = self.model.nvm
        intervals = {k: nvm[f"{k}_interval"] * cat.INTERVAL_UNIT_S for k in cat.REPORT_FRAMES}
        mode = self.mode()
        prev = self.states[-1] if self.states else None
        cause = prev.cause if prev is not None and prev.mode == mode and label not in ("power on", "ready") else label
        self.states.append(State(t, label, mode, intervals, step, cause, nvm["throttle_source"], self.model.state.bitrate,
                                 self.load_share))
