"""The host on a lane (:class:`Link`): sending, reading on the lane's clock, the frames heard, requests and
their answers, discovery, and the throttle safety every send goes through."""

from __future__ import annotations

import math
from collections import deque
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any, Callable, Iterator, Mapping, Sequence

import can

from ..protocol import catalogue as cat
from ..protocol import functions
from ..protocol.errors import TailError
from ..protocol.frame import Frame, WireFrame, classify, frame_bits
from ..protocol.host import Garbled, HostProtocol, Pending, Response
from ..protocol.ids import DEFAULT_ESC_NODE_ID, Kind
from ..protocol.judgements import timing_tolerance
from ..protocol.transfer import TAIL_BYTES, TRANSFER_ID_MODULO, tail_transfer_id
from .epochs import WINDOW_REQUESTS
from .errors import RestoreFailed
from .lanes import BOOTING, SWITCHED_OFF, BusFault, Lane, OwnFrame, stop_task
from .outcomes import Inconclusive, NotClaimed, Record
from .profile import DutProfile

#: How long the host waits for the echo of its own frame once it has left (the echo follows in microseconds
#: to milliseconds; it is read late only when the host itself was held up)
ECHO_WAIT_S = 0.05
#: Frames that did not decode kept per test (the latest): about 0.5 kB each
MAX_GARBLED = 20_000
#: type id -> name of the requests the 120 s window governs (R11): a power-up epoch records each one sent
_WINDOW_IDS = {cat.spec(name).type_id: name for name in WINDOW_REQUESTS}


@dataclass
class Sent:
    """A frame the host sent, in the bus's clock: :attr:`time` is when it was on the bus (its echo's stamp; without an
    echo the host's send time, mapped into the bus's clock: every lane stamps on the host's time base) and
    :attr:`error` that time's stated error, so that a consumer compares it with bus stamps and nothing else.
    ``host_time`` is the host's own clock at the send, for the host's own deadlines only."""

    wire: WireFrame
    host_time: float
    bus_time: float | None = None  # from the echo of our own frame (SocketCAN loopback / socketcand / sim)
    #: (clock, error in s) of a bus time, and of the host's time (an adapter without echo, an echo not read yet)
    bus_clock: tuple[str, float] = ("bus timestamp", 0.0)
    host_clock: tuple[str, float] = ("host clock", 0.0)
    #: why the host was alone on the bus when it sent this (None: it was not): nobody acknowledged the frame then, so a
    #: real adapter held it until the ESC's controller came up (R20); without an echo when it went out is not known
    alone: str | None = None

    @property
    def time(self) -> float:
        return self.bus_time if self.bus_time is not None else self.host_time

    @property
    def held(self) -> str | None:
        """Why :attr:`time` is not when this frame went on the bus (None: it is): it was sent while the host was alone
        (:attr:`alone`) and no echo says when it left (R20: a held frame is never judged as if sent on time)."""
        if self.alone is None or self.bus_time is not None:
            return None
        return (f"sent while {self.alone} (the host alone on the bus: nobody acknowledged it, a "
                "real adapter holds it until the ESC's controller is up) and no echo says when it went out")

    @property
    def clock(self) -> str:
        """The clock :attr:`time` is on: the bus's (the frame's echo) or the host's (at send)."""
        return (self.bus_clock if self.bus_time is not None else self.host_clock)[0]

    @property
    def error(self) -> float:
        """The error (s) of :attr:`time`: a measurement from it states this error."""
        return (self.bus_clock if self.bus_time is not None else self.host_clock)[1]


@dataclass
class Exchange:
    """A request and what answered it. ``until``: when the host stopped waiting for the answer, in the bus's clock
    (:meth:`Link.bus_now`; None: it did not wait): every frame it read meanwhile is stamped no later."""

    sent: Sent
    pending: Pending
    response: Frame | None = None
    mismatch: list[str] = field(default_factory=list)
    until: float | None = None

    @property
    def delay(self) -> float | None:
        if self.response is None or self.response.timestamp is None:
            return None
        return self.response.timestamp - self.sent.time

    @property
    def fields(self) -> dict[str, Any]:
        if self.response is None:
            raise AssertionError(f"no answer to {self.pending.name} (destination {self.pending.destination}, "
                                 f"transfer id {self.pending.transfer_id})")
        return self.response.fields


class Link:
    """The host on a lane, talking to ESCs: sends (with the throttle safety every send goes through), reads on
    the lane's clock, keeps every frame heard (``trace``, ``garbled``) and pairs requests with answers. The
    plugin uses it directly where it needs no more (zero throttle on an exit path); :class:`.dut.Dut` is the
    test author's, built on it."""

    def __init__(self, lane: Lane, profile: DutProfile, *, node_id: int | None = None, host_node: int = 0,
                 allow_motor_spin: bool = False) -> None:
        self.lane = lane
        self.profile = profile
        self.host_node = host_node
        self.proto = HostProtocol(host_node, nibble_order=profile.nibble_order)
        self.allow_motor_spin = allow_motor_spin
        self.trace: list[Frame] = []  # everything heard, decoded, in order
        # the latest MAX_GARBLED frames heard that did not decode (a DUT flooding the bus with garbage must
        # not grow memory without bound); how many older ones were let go
        self.garbled: deque[Garbled] = deque(maxlen=MAX_GARBLED)
        self.garbled_dropped = 0
        self._sent: list[Sent] = []
        self._heard_to = -math.inf  # the latest stamp of a frame read (bus_now)
        self._tasks: list[Any] = []
        self.record = Record()
        self.lane_seconds = 0.0  # lane time the test took (set by the dut fixture)
        self.throttled = False  # a non-zero throttle was sent: the dut fixture waits for the motor to stop
        self.sent_types: set[int] = set()  # type ids of every frame sent (restore: was the reporting mode touched?)
        self.node_id = node_id if node_id is not None else self.discover()
        # every ESC that answered discovery (multi_dut); just the DUT when its id was given
        self.nodes: list[int] = getattr(self, "discovered", [self.node_id])

    # ------------------------------------------------------------------ clock
    def now(self) -> float:
        return self.lane.now()

    def bus_now(self, now: float | None = None) -> float:
        """Now in the bus's clock, for the end of a window of frames heard: the lane's time, or the latest stamp read
        where that is later (a frame stamped at its end, or by a bench whose stamps run ahead of the host's clock within
        its stated error, is read before the host's clock reaches its stamp). A window ending here holds every frame
        read until now, whichever clock ran ahead. ``now``: the lane's time just read (each reading of a real-time
        lane's clock counts: :meth:`.lanes.BusLane.now`)."""
        return max(self.now() if now is None else now, self._heard_to)

    @property
    def clock(self) -> str:
        return self.lane.clock

    @property
    def interval_tolerance_ms(self) -> float:
        """How far one report interval may stray from its target. In the simulated lane: bus access
        only, two of the longest frames at the lane's bit rate (a report due while a frame is on the
        bus waits for it, and for one that wins arbitration); in real time: one report-scheduling tick
        (1 ms) plus the lane's error (``protocol.judgements.timing_tolerance``, as the bus rules judge). The
        profile's ``jitter_s`` (the DUT's own allowance) on top of either; the lane's error
        (``timing_error``) decides INCONCLUSIVE around it."""
        jitter = self.profile.jitter_s * 1000
        if self.clock == "simulated":
            return 2 * frame_bits(8) / self.lane.bitrate * 1000 + jitter
        return timing_tolerance(self.clock, self.lane.timing_error) * 1000 + jitter

    def wait(self, seconds: float) -> None:
        """Let lane time pass, reading the bus (nothing is lost)."""
        self.read_until(self.now() + seconds)

    def read_until(self, t: float, stop: Callable[[Frame], bool] | None = None) -> Frame | None:
        """Read frames until lane time ``t``; with ``stop``, return the first frame it accepts."""
        while True:
            left = t - self.now()
            if left <= 0:
                return None
            msg = self.lane.recv(left)
            if msg is None:
                continue
            frame = self._take(msg)
            if frame is not None and stop is not None and stop(frame):
                return frame

    def await_echo(self, sent: Sent, bound: float = ECHO_WAIT_S) -> None:
        """Read until the echo of ``sent`` is in (its bus time known), at most ``bound`` lane seconds: frames
        are kept as ever. Nothing to wait for on a lane without echo."""
        until = self.now() + bound
        while self.lane.echo and sent.bus_time is None and (left := until - self.now()) > 0:
            msg = self.lane.recv(left)
            if msg is not None:
                self._take(msg)

    def _take(self, msg: can.Message) -> Frame | None:
        if msg.timestamp and msg.timestamp > self._heard_to:
            self._heard_to = msg.timestamp
        if msg.is_extended_id and (msg.arbitration_id & 0x7F) == self.host_node and not msg.is_error_frame:
            self._match_echo(msg)
        elif self.lane.alone is not None and getattr(msg, "is_rx", True) and not getattr(msg, "is_error_frame", False):
            self.lane.alone = None  # another node is up: it acknowledges the host's frames
        for event in self.proto.receive(msg):
            if isinstance(event, Garbled):
                self._keep_garbled(event)  # the framing checks (4.1) report it
                if not isinstance(event.error, TailError):
                    return None
                # a frame whose tail says start/end/toggle wrongly (F2) still carries its payload:
                # read it as the single frame it must be, so one framing fault does not blind
                # every other test (the violation stays in ``garbled``)
                fixed = can.Message(arbitration_id=msg.arbitration_id, is_extended_id=True, timestamp=msg.timestamp,
                                    data=bytes(msg.data[:-1]) + TAIL_BYTES[tail_transfer_id(msg.data[-1])])
                return self._take_decoded(fixed)
            frame = event.frame
            self.trace.append(frame)
            if isinstance(event, Response):
                event.pending.response = frame
                event.pending.mismatch = event.mismatch
            return frame
        return None

    def _keep_garbled(self, event: Garbled) -> None:
        event.error.__traceback__ = None  # the message says why; the traceback would keep the decoder's frames alive
        if len(self.garbled) == MAX_GARBLED:
            if not self.garbled_dropped:
                self.record.observe("frames that did not decode", f"more than {MAX_GARBLED} in this test: only the "
                                    "latest are kept for the checks that look at them")
            self.garbled_dropped += 1
        self.garbled.append(event)

    def _take_decoded(self, msg: can.Message) -> Frame | None:
        for event in self.proto.receive(msg):
            if isinstance(event, Garbled):
                return None
            self.trace.append(event.frame)
            if isinstance(event, Response):
                event.pending.response = event.frame
                event.pending.mismatch = event.mismatch
            return event.frame
        return None

    def _match_echo(self, msg: can.Message) -> None:
        if isinstance(msg, OwnFrame):  # no echo: the lane's copy, stamped by the host clock at send
            return
        data = bytes(msg.data)
        for s in self._sent:
            if s.bus_time is None and s.wire.arbitration_id == msg.arbitration_id and s.wire.data == data:
                s.bus_time = msg.timestamp
                return

    # ------------------------------------------------------------------ sending
    def send_wire(self, wire: WireFrame) -> Sent:
        msg = can.Message(arbitration_id=wire.arbitration_id, data=wire.data, is_extended_id=wire.is_extended_id)
        sent = Sent(wire, self.now(), bus_clock=(self.lane.clock, self.lane.timing_error), host_clock=self.lane.host_clock,
                    alone=self.lane.alone)
        kind, type_id = classify(wire.arbitration_id)[:2]
        self.sent_types.add(type_id)
        if kind is Kind.REQUEST and type_id in _WINDOW_IDS and self.lane.epoch is not None:
            self.lane.epoch.config.append((_WINDOW_IDS[type_id], sent.host_time))
        self._sent.append(sent)
        if len(self._sent) > 256:
            del self._sent[:128]
        self.lane.bus.send(msg)
        return sent

    def _check_claimed(self, name: str, fields: Mapping[str, Any] | None) -> None:
        """A request for a function the profile declares absent ends the test as SKIPPED, not claimed (R9b)."""
        if self.profile.absent and (fn := functions.of_request(name, fields, self.profile.absent)) is not None:
            raise NotClaimed(fn.name, self.profile.name)

    def broadcast(self, name: str, fields: Mapping[str, Any] | None = None, **kw: Any) -> Sent:
        self._check_claimed(name, fields)
        if name in _THROTTLE_FRAMES:
            self._check_throttle(name, fields or {})
        return self.send_wire(self.proto.message(name, fields, **kw))

    def request(self, name: str, fields: Mapping[str, Any] | None = None, *, destination: int | None = None,
                timeout: float | None = None, **kw: Any) -> Exchange:
        """Send a request and read until its answer or ``timeout`` (lane seconds; default 0.1 s plus the
        lane's stated timing error: an answer that late is not "no answer" on a lane that cannot tell). The
        timeout runs from when the request reached the bus where its echo shows that the host was held up between
        reading the clock and sending (later than the stated send error and two frames on the bus), else from the send.
        A request sent while the ESC was switched off or booting (:attr:`.lanes.Lane.alone`) goes out when its
        controller is up to acknowledge it: that is waited for (at most the profile's boot time) and the timeout runs
        again from then (R20)."""
        self._check_claimed(name, fields)
        if timeout is None:
            timeout = 0.1 + self.lane.timing_error
        dest = self.node_id if destination is None else destination
        wire, pending = self.proto.request(name, fields, destination=dest, now=self.now(), timeout=timeout, **kw)
        sent = self.send_wire(wire)
        ex = Exchange(sent, pending)
        spec = cat.spec(name)
        if spec.responses and kw.get("expect_response", True):
            deadline = sent.host_time + timeout
            # how much later than the host's send a request may reach the bus without the host having been held up:
            # the stated send error and two frames ahead of it on the bus (within it the window runs from the send)
            held_up = self.lane.host_send_error + 2 * frame_bits(8) / self.lane.bitrate
            alone = sent.alone in (SWITCHED_OFF, BOOTING)  # sent while the ESC was not up: held until it is (R20)
            while True:
                self.read_until(deadline, stop=lambda f: pending.response is not None)
                if alone and pending.response is None:
                    alone = False  # the ESC's controller comes up within its boot time: the request goes out then
                    self.read_until(self.now() + self.profile.boot_s,
                                    stop=lambda f: self.lane.alone is None or pending.response is not None)
                    if pending.response is None and self.lane.alone is None:
                        deadline = pending.deadline = max(deadline, self.now() + timeout)
                        continue
                if pending.response is None and sent.bus_time is None and self.now() > deadline + held_up:
                    self.await_echo(sent)  # the host was held up past the deadline before it read the echo
                left_at = sent.bus_time if sent.bus_time is not None else sent.host_time
                if pending.response is not None or left_at - sent.host_time <= held_up or left_at + timeout <= deadline:
                    break
                deadline = pending.deadline = left_at + timeout  # the echo came late: the window is the bus's
            now = self.now()
            self.proto.expire(now)
            ex.until = self.bus_now(now)
        ex.response = pending.response
        ex.mismatch = pending.mismatch
        return ex

    def _why_no_answer(self, name: str, node: int, since: float) -> str:
        """What the node sent instead of an answer, when that explains it: a frame of the service with the
        request bit set (an answer flagged as a request, F1/F4), or one whose payload did not decode."""
        spec = cat.spec(name)
        as_request = [f for f in self.frames(name, since=since, source=node, kind=Kind.REQUEST)]
        if as_request:
            return (f" (it sent {len(as_request)} {spec.title} frame(s) with the request bit set, e.g. "
                    f"{as_request[0].can_id:08X}: an answer flagged as a request breaks F1/F4, see section 4.1)")
        bad = self.undecoded(name, since=since, source=node)
        if bad and classify(bad[0].msg.arbitration_id)[0] is Kind.REQUEST:
            return (f" (it sent a {spec.title} frame with the request bit set, {bad[0].msg.arbitration_id:08X}: an answer "
                    "flagged as a request breaks F1/F4, see section 4.1)")
        if bad:
            return f" (its {spec.title} frame did not decode: {bad[0].error})"
        return ""

    def ask(self, name: str, fields: Mapping[str, Any] | None = None, **kw: Any) -> dict[str, Any]:
        """A request whose answer the test needs (not what it checks): no answer is an error."""
        ex = self.request(name, fields, **kw)
        if ex.response is None:
            node = kw.get("destination", self.node_id)
            raise DutError(f"{name}: no answer from node {node}" + self._why_no_answer(name, node, ex.sent.time))
        return ex.response.fields

    # ------------------------------------------------------------------ looking at what came
    def frames(self, name: str | None = None, *, since: float | None = None, until: float | None = None,
               source: int | None = None, kind: Kind | None = None) -> list[Frame]:
        out = []
        for f in self.trace:
            if name is not None and f.name != name:
                continue
            if source is not None and f.source != source:
                continue
            if kind is not None and f.kind is not kind:
                continue
            ts = f.timestamp or 0.0
            if since is not None and ts < since:
                continue
            if until is not None and ts > until:
                continue
            out.append(f)
        return out

    def undecoded(self, name: str | None = None, *, since: float | None = None, source: int | None = None,
                  kind: Kind | None = None) -> list[Garbled]:
        """The frames heard that did not decode (``garbled``), selected by what their CAN id says, as
        :meth:`frames` selects the decoded ones."""
        spec = cat.spec(name) if name is not None else None
        out = []
        for g in self.garbled:
            gkind, _, src, _, gspec = classify(g.msg.arbitration_id)
            if ((spec is None or gspec is spec) and (source is None or src == source) and (kind is None or gkind is kind)
                    and (since is None or (g.msg.timestamp or 0.0) >= since)):
                out.append(g)
        return out

    def stamps(self, name: str, *, since: float, source: int) -> list[float]:
        """Timestamps of every ``name`` frame from ``source`` since ``since``, decoded or not: the CAN id
        says what a frame is, so the timing of a stream (R9) is judged even when its payload is wrong,
        which is another section's verdict."""
        out = {f.timestamp or 0.0 for f in self.frames(name, since=since, source=source)}
        out.update(g.msg.timestamp or 0.0 for g in self.undecoded(name, since=since, source=source))
        return sorted(out)

    def reports(self, name: str, seconds: float, *, source: int | None = None) -> list[Frame]:
        """Read for ``seconds`` and return the ``name`` frames the DUT sent meanwhile."""
        start = self.now()
        self.wait(seconds)
        return self.frames(name, since=start, source=self.node_id if source is None else source)

    def wait_for(self, name: str, timeout: float, *, source: int | None = None,
                 where: Callable[[Frame], bool] | None = None) -> Frame | None:
        src = self.node_id if source is None else source

        def ok(f: Frame) -> bool:
            return f.name == name and (src is None or f.source == src) and (where is None or where(f))

        return self.read_until(self.now() + timeout, stop=ok)

    # ------------------------------------------------------------------ discovery and state
    def discover(self) -> int:
        """Find the DUT's node id with GET_ESC_ID (R1), asking again until the profile's boot time
        (plus a second) has passed: an ESC that is still booting hears nothing. ``discovered``: every ESC
        that answered. ESCs on one supply do not boot at one instant (the real-time emulator staggers
        them as a bench does): an ESC heard reporting after a query that it did not answer was still
        booting when the query came, so the query is sent again (until every ESC heard reporting has
        answered, or the boot time has passed)."""
        give_up = self.now() + self.profile.boot_s + 1.0
        found: dict[int, None] = {}  # every ESC that answered, in the order of the answers
        sent = None
        while True:
            # a query still in the host's queue (its echo not back: nobody acknowledged it) is not asked again: on CAN
            # the next would wait behind it, and a queue of them fills (ENOBUFS); it goes as soon as an ESC listens
            if sent is None or sent.bus_time is not None or not self.lane.echo:
                try:
                    sent = self.broadcast("get_esc_id", {"option": 0}, layout="query")
                except BusFault as exc:
                    raise DutUnreachable(f"no ESC took the host's GET_ESC_ID at {self.lane.bitrate} bit/s: {exc}") from exc
            self.wait(cat.ANSWER_DELAY_MAX_S * 2)  # every ESC answers within 64 ms (R2); read them all
            replies = [f.source for f in self.frames("get_esc_id", since=sent.time)
                       if f.layout is not None and f.layout.name == "reply"]
            # a reply whose payload does not decode still names its sender in its CAN id: what the
            # payload should be is section 4.4.3's verdict (R1), not a reason to stop every test
            replies += [g.msg.arbitration_id & 0x7F for g in self.undecoded("get_esc_id", since=sent.time, kind=Kind.MESSAGE)
                        if g.msg.arbitration_id & 0x7F != self.host_node]
            found.update(dict.fromkeys(replies))
            # reporting from an id that answers GET_ESC_ID (not the host's, 0x7D or the reserved ones), not answered
            booting = {src for src, _, _ in self.report_starts(sent.time, None)
                       if src != self.host_node and 0 < src < DEFAULT_ESC_NODE_ID} - set(found)
            if found and (not booting or self.now() >= give_up):
                self.discovered = sorted(found)
                return next(iter(found))
            if self.now() >= give_up:
                raise DutUnreachable(f"no ESC answered GET_ESC_ID for {self.profile.boot_s + 1.0:.1f} s: is it powered, at "
                               f"{self.lane.bitrate} bit/s, and not at node id 0x7D (which answers nothing)? "
                               "Give --node-id to skip discovery.")

    # ------------------------------------------------------------------ reports heard
    #: MSG1..MSG3: a reporting DUT has sent each once within the longest legal interval
    READY_REPORTS = cat.REPORT_FRAMES
    #: ... or it reports in another mode (MSG_EXP mode, CAN Test): the first such frame will do
    OTHER_MODE_REPORTS = frozenset({s.name for s in cat.CATALOGUE if s.name.startswith("msg_exp")} | {"can_test"})

    def report_starts(self, since: float, source: int | None) -> list[tuple[int, str, float]]:
        """(source, report name, start time) of the reports since ``since`` from ``source`` (None: from any
        node), decoded or not (what its payload is is another test's verdict: that it came is what counts here)."""
        names = set(self.READY_REPORTS) | self.OTHER_MODE_REPORTS
        out = [(f.source, f.name, f.timestamp or since) for f in self.frames(since=since, source=source, kind=Kind.MESSAGE)
               if f.name in names]
        for g in self.undecoded(since=since, source=source, kind=Kind.MESSAGE):
            spec = classify(g.msg.arbitration_id)[4]
            if spec is not None and spec.name in names:
                out.append((g.msg.arbitration_id & 0x7F, spec.name, g.msg.timestamp or since))
        return out

    # ------------------------------------------------------------------ throttle (safety)
    def _check_throttle(self, name: str, fields: Mapping[str, Any]) -> None:
        if any(fields.get("channels", ())):
            if not self.allow_motor_spin:
                raise Inconclusive("this test spins the motor: run with --allow-motor-spin (and the propeller off)")
            self.throttled = True

    def throttle_stream(self, name: str, fields: Mapping[str, Any], period: float = 0.0025) -> Any:
        """Send a throttle frame every ``period`` s with its transfer id counting (F3) until
        :meth:`stop_throttle` (called on every exit path by the plugin)."""
        self._check_throttle(name, fields)
        task = self._start_periodic(*self._counting(name, fields), period)
        self._tasks.append(task)
        return task

    @contextmanager
    def periodic(self, name: str, fields: Mapping[str, Any] | None = None, period: float = 0.05, *,
                 destination: int | None = None, layout: str | None = None,
                 frames: Sequence[WireFrame] | None = None) -> Iterator[Any]:
        """Send frame ``name`` every ``period`` s while the ``with`` block runs, its transfer id counting (F3):
        a broadcast, or with ``destination`` a request to that node (its answers are heard as any frame, paired with
        no request: the block's end reads for an answer's time, so that a late one cannot pair with the next request
        of its service). ``frames``: another node's frames (one CAN id), sent in turn as they are (their transfer ids
        their own), ``name`` then only says what they are. Throttle frames are :meth:`throttle_stream`'s, which
        :meth:`stop_throttle` stops; this stream runs on until the block ends, whatever leaves it."""
        if name in _THROTTLE_FRAMES:
            raise ValueError(f"{name} is a throttle frame: stream it with throttle_stream (its safety checks)")
        if frames is not None:
            task = self._start_periodic([can.Message(arbitration_id=w.arbitration_id, data=w.data, is_extended_id=True)
                                         for w in frames], None, period)
        else:
            self._check_claimed(name, fields)
            task = self._start_periodic(*self._counting(name, fields, destination=destination, layout=layout), period)
        try:
            yield task
        finally:
            stop_task(task)
            if destination is not None and frames is None:
                self.wait(0.1 + self.lane.timing_error)  # the last request's answer, within request()'s timeout

    def _counting(self, name: str, fields: Mapping[str, Any] | None, *, destination: int | None = None,
                  layout: str | None = None) -> tuple[can.Message, Callable[[can.Message], None]]:
        """Frame ``name`` (a request to ``destination`` where one is given) and the callback that gives each send of
        it the next transfer id of its type (and destination) before it goes (F3)."""
        if destination is None:
            wire, key = self.proto.message(name, fields, layout=layout), (Kind.MESSAGE, name)
        else:
            wire = self.proto.request(name, fields, destination=destination, now=self.now(), timeout=0.0,
                                      expect_response=False)[0]
            key = (Kind.REQUEST, name)
        msg = can.Message(arbitration_id=wire.arbitration_id, data=wire.data, is_extended_id=True)
        tids, tail = self.proto.tids, cat.spec(name).has_tail

        def bump(m: can.Message) -> None:
            if tail:
                m.data[-1] = 0xC0 | tids.next(key, destination)

        return msg, bump

    def _start_periodic(self, msgs: can.Message | list[can.Message], bump: Callable[[can.Message], None] | None,
                        period: float) -> Any:
        return self.lane.bus.send_periodic(msgs, period, modifier_callback=bump)

    def stop_throttle(self) -> None:
        for task in self._tasks:
            stop_task(task)
        self._tasks.clear()

    def zero_throttle(self) -> None:
        """Stop every stream on the lane (this host's and any other's) and command zero on every channel in
        all three formats."""
        self.stop_throttle()
        self.lane.stop_streams()
        self.send_wire(self.proto.message("raw_command_14b", {"channels": [0] * 4}))
        for group in cat.THROTTLE_GROUPS:
            self.send_wire(self.proto.message("raw_command_12b", {"channels": [0] * 4, "group": group}))
        self.send_wire(self.proto.message("raw_command_10b", {"channels": [0] * 6}))

def echo_probe(host_node: int = 0, *, nibble_order: str = "lsb") -> can.Message:
    """The frame a lane sends to find out whether the host's own frames come back
    (:meth:`BusLane.find_echo`): the GET_ESC_ID query the suite sends first anyway, harmless to every
    ESC (R1), with the transfer id before the first one the :class:`Dut` uses, so that the DUT sees the
    host's transfer ids count on."""
    wire = HostProtocol(host_node, nibble_order=nibble_order).message("get_esc_id", {"option": 0}, layout="query",
                                                                      transfer_id=TRANSFER_ID_MODULO - 1)
    return can.Message(arbitration_id=wire.arbitration_id, data=wire.data, is_extended_id=wire.is_extended_id)


class DutError(RuntimeError):
    """The DUT did not answer what a test needed (a request's answer, a frame after power-up, GET_ESC_ID): no verdict
    on the DUT in a test of a stronger requirement (ERROR), what the DUT did in an OBSERVE test (OBSERVED). The
    harness's own failures are :class:`~ckesc.bench.errors.HarnessError`'s, a bench it could not put back
    :class:`~ckesc.bench.errors.RestoreFailed`'s (:func:`restoring`)."""


@contextmanager
def restoring(what: str) -> Iterator[None]:
    """A block that puts the bench back (``what``: "the DUT's throttle channel 3"): a DUT that does not answer
    meanwhile leaves the bench not restored, the harness's failure (:class:`~ckesc.bench.errors.RestoreFailed`),
    not an observation of the test's."""
    try:
        yield
    except DutError as exc:
        raise RestoreFailed(f"could not put back {what}: {exc}") from exc


class DutUnreachable(DutError):
    """No ESC answers at all (discovery heard nothing): the bench, not one test, is the problem; the
    plugin aborts the run on it."""


_THROTTLE_FRAMES = frozenset(cat.THROTTLE_FRAMES)
