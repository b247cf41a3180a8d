"""The device under test as the suites see it: a host on a lane, talking to one ESC.

Everything a test needs goes through :class:`Dut`: send a broadcast or a request, wait on the
lane's clock, look at what came (every frame is kept in ``dut.trace`` with its bus timestamp),
power-cycle with proof, change throttle safely, snapshot and restore settings.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field
from typing import Any, Callable, Iterable, Mapping

import can

from ..protocol import catalogue as cat
from ..protocol import functions
from ..protocol.errors import TailError
from ..protocol.frame import Frame, WireFrame, classify, frame_bits
from ..protocol.host import Garbled, HostProtocol, Pending, Response
from ..protocol.ids import DEFAULT_ESC_NODE_ID, Kind
from ..protocol.transfer import TRANSFER_ID_MODULO
from .epochs import INSIDE, WINDOW_MARGIN_S, WINDOW_REQUESTS, PowerEpoch, unusable
from .lanes import Lane, OwnFrame
from .profile import DutProfile
from .verdict import Inconclusive, NotClaimed, Record

#: Frames that did not decode kept per test (the latest): about 0.5 kB each
MAX_GARBLED = 20_000
#: type id -> name of the requests the 120 s window governs (R11): a power-up epoch records each one sent
_WINDOW_IDS = {cat.spec(name).type_id: name for name in WINDOW_REQUESTS}
#: type ids of the frames that change how the DUT reports (MSG Control, CAN Test): restore resumes after them
_MODE_IDS = frozenset(cat.spec(name).type_id for name in ("msg_control", "can_test"))


@dataclass
class Sent:
    wire: WireFrame
    host_time: float
    bus_time: float | None = None  # from the echo of our own frame (SocketCAN loopback / socketcand / sim)
    #: (clock, error in s) of a bus time, and of the host's time (an adapter without echo, an echo not read yet)
    bus_clock: tuple[str, float] = ("bus timestamp", 0.0)
    host_clock: tuple[str, float] = ("host clock", 0.0)

    @property
    def time(self) -> float:
        return self.bus_time if self.bus_time is not None else self.host_time

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
    """A request and what answered it."""

    sent: Sent
    pending: Pending
    response: Frame | None = None
    mismatch: list[str] = field(default_factory=list)

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


class Dut:
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

    @property
    def clock(self) -> str:
        return self.lane.clock

    @property
    def interval_tolerance_ms(self) -> float:
        """How far one report interval may stray from its target. In the simulated lane: bus access
        only, two of the longest frames at the lane's bit rate (a report due while a frame is on the
        bus waits for it, and for one that wins arbitration); in real time: one report-scheduling tick
        (1 ms) plus the lane's error. The profile's ``jitter_s`` (the DUT's own allowance) on top of
        either; the lane's error (``timing_error``) decides INCONCLUSIVE around it."""
        jitter = self.profile.jitter_s * 1000
        if self.clock == "simulated":
            return 2 * frame_bits(8) / self.lane.bitrate * 1000 + jitter
        return 1.0 + self.lane.timing_error * 1000 + jitter

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

    def _take(self, msg: can.Message) -> Frame | None:
        if msg.is_extended_id and (msg.arbitration_id & 0x7F) == self.host_node and not msg.is_error_frame:
            self._match_echo(msg)
        for event in self.proto.receive(msg):
            if isinstance(event, Garbled):
                self._keep_garbled(event)  # the framing checks (4.1) report it
                if not isinstance(event.error, TailError):
                    return None
                # a frame whose tail says start/end/toggle wrongly (F2) still carries its payload:
                # read it as the single frame it must be, so one framing fault does not blind
                # every other test (the violation stays in ``garbled``)
                fixed = can.Message(arbitration_id=msg.arbitration_id, is_extended_id=True, timestamp=msg.timestamp,
                                    data=bytes(msg.data[:-1]) + bytes([0xC0 | (msg.data[-1] & 0x1F)]))
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
        sent = Sent(wire, self.now(), bus_clock=(self.lane.clock, self.lane.timing_error), host_clock=self.lane.host_clock)
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
        lane's stated timing error: an answer that late is not "no answer" on a lane that cannot tell)."""
        self._check_claimed(name, fields)
        if timeout is None:
            timeout = 0.1 + self.lane.timing_error
        dest = self.node_id if destination is None else destination
        wire, pending = self.proto.request(name, fields, destination=dest, now=self.now(), timeout=timeout, **kw)
        sent = self.send_wire(wire)
        ex = Exchange(sent, pending)
        spec = cat.spec(name)
        if spec.responses and kw.get("expect_response", True):
            self.read_until(sent.host_time + timeout, stop=lambda f: pending.response is not None)
            self.proto.expire(self.now())
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
            raise DutError(f"{name}: no answer from node {node}" + self._why_no_answer(name, node, ex.sent.host_time))
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
        while True:
            sent = self.broadcast("get_esc_id", {"option": 0}, layout="query")
            self.wait(cat.ANSWER_DELAY_MAX_S * 2)  # every ESC answers within 64 ms (R2); read them all
            replies = [f.source for f in self.frames("get_esc_id", since=sent.host_time)
                       if f.layout is not None and f.layout.name == "reply"]
            # a reply whose payload does not decode still names its sender in its CAN id: what the
            # payload should be is section 4.4.3's verdict (R1), not a reason to stop every test
            replies += [g.msg.arbitration_id & 0x7F for g in self.undecoded("get_esc_id", since=sent.host_time, kind=Kind.MESSAGE)
                        if g.msg.arbitration_id & 0x7F != self.host_node]
            found.update(dict.fromkeys(replies))
            # reporting from an id that answers GET_ESC_ID (not the host's, 0x7D or the reserved ones), not answered
            booting = {src for src, _, _ in self._reports(sent.host_time, None)
                       if src != self.host_node and 0 < src < DEFAULT_ESC_NODE_ID} - set(found)
            if found and (not booting or self.now() >= give_up):
                self.discovered = sorted(found)
                return next(iter(found))
            if self.now() >= give_up:
                raise DutUnreachable(f"no ESC answered GET_ESC_ID for {self.profile.boot_s + 1.0:.1f} s: is it powered, at "
                               f"{self.lane.bitrate} bit/s, and not at node id 0x7D (which answers nothing)? "
                               "Give --node-id to skip discovery.")

    def settings(self) -> dict[str, int]:
        """The settings tests may change (242 and Set/Get Freq read)."""
        cfg = self.ask("get_major_configuration", {"option": 0})
        freq = self.ask("set_freq", {"option": 0, "msg1_interval": 0, "msg2_interval": 0, "msg3_interval": 0})
        return {
            "rotation": cfg["direction"],
            "throttle_source": cfg["throttle_source"],
            "throttle_channel": cfg["throttle_channel"],
            "led_color": cfg["led_color"],
            "led_blink": cfg["led_blink"],
            "msg1_interval": freq["msg1_interval"],
            "msg2_interval": freq["msg2_interval"],
            "msg3_interval": freq["msg3_interval"],
        }

    def restore(self, snapshot: Mapping[str, int]) -> list[str]:
        """Put back what a test changed; returns what could not be restored (after verifying). Normal reporting
        is resumed (MSG Control) unless nothing the test sent can have left it and the DUT's MSG1 still comes."""
        interval = snapshot["msg1_interval"] * cat.INTERVAL_UNIT_S
        still = self.frames("msg1", since=self.now() - 2 * interval - self.lane.timing_error, source=self.node_id)
        if not still or self.sent_types & _MODE_IDS:
            self.broadcast("msg_control", {"option": 0, "command": cat.MSG_CONTROL_RESUME})
            self.wait(cat.ANSWER_DELAY_MAX_S)
        now = self.settings()
        if any(now[k] != snapshot[k] for k in ("msg1_interval", "msg2_interval", "msg3_interval")):
            self.ask("set_freq", {"option": 1, **{k: snapshot[k] for k in ("msg1_interval", "msg2_interval", "msg3_interval")}})
        if now["rotation"] != snapshot["rotation"]:
            self.ask("set_rotation", {"rotation": snapshot["rotation"]})
        if now["throttle_source"] != snapshot["throttle_source"]:
            self.ask("throttle_select", {"source": snapshot["throttle_source"]})
        if self.profile.has("led") and (now["led_color"], now["led_blink"]) != (snapshot["led_color"], snapshot["led_blink"]):
            self.ask("set_led", {"option": 1, "color": snapshot["led_color"], "blink": snapshot["led_blink"]})
        after = self.settings()
        return [f"{k}: {after[k]} (was {snapshot[k]})" for k in snapshot if after[k] != snapshot[k]]

    def power_up_count(self) -> int | None:
        ex = self.request("maintenance_information", {"option": 2})
        if ex.response is None or "power_ups" not in ex.response.fields:
            return None
        return ex.response.fields["power_ups"]

    def power_cycle(self, off_time: float = 1.0, boot_wait: float = 1.0) -> None:
        """Power off, wait, on, and prove the cycle by the power-up counter (241 option 2);
        raises Inconclusive when it cannot be proven, DutError when the DUT sent nothing at all after
        power-up (no report, no answer: it did not come back)."""
        if not self.lane.power.available:
            raise Inconclusive("this test needs a power cycle and no power control was given (--power)")
        self.stop_throttle()
        before = self.power_up_count()
        on = self.switch_power(off_time, boot_wait)
        after = self.power_up_count()
        self.record.observe("power-up counter", f"{before} -> {after}")
        if after is None and not self.heard_from(on):
            raise DutError(f"node {self.node_id} sent nothing after power-up: no report within "
                           f"{self.ready_bound_s(boot_wait):.2f} s, no answer to the power-up counter (241 option 2): "
                           f"did it come back, at {self.lane.bitrate} bit/s?")
        if before is None or after is None or after != (before + 1) & 0xFFFF:
            raise Inconclusive(f"power cycle not proven: power-up counter {before} -> {after} (241 option 2)")
        self.proved_power_up(on, before, after)

    def proved_power_up(self, on: float, before: int, after: int) -> None:
        """The power-up counter proved the power-up at lane time ``on`` (``before`` -> ``after``): its epoch is
        proven (what a window test may share). For tests that prove a cycle their own way (another rate)."""
        epoch = self.lane.epoch
        if epoch is not None and epoch.on_earliest <= on and after == (before + 1) & 0xFFFF:
            epoch.proven, epoch.counter = True, (before, after)
            epoch.node_id, epoch.bitrate = self.node_id, self.lane.bitrate  # where it answered the counter
            if not self.heard_from(on):  # no report came: the answer to the counter is the first sign of life
                epoch.ready = self.now()

    def window_left(self) -> float:
        """Lane seconds left, at the least, of the 120 s Set ID / Set Baud window (R11) of the DUT's current
        power-up as the harness made it (0 when it made none, or the window has closed)."""
        epoch = self.lane.epoch
        if epoch is None:
            return 0.0
        return max(0.0, epoch.on_earliest + cat.CONFIG_WINDOW_S - self.now())

    def _window_unusable(self, kind: str, *, lead: float = 0.0, margin: float = WINDOW_MARGIN_S) -> str | None:
        """Why the current power-up's window cannot serve an act of ``kind`` now (:func:`epochs.unusable`)."""
        return unusable(self.lane.epoch, kind, now=self.now(), node_id=self.node_id, bitrate=self.lane.bitrate,
                        lead=lead, margin=margin)

    def open_window(self, left_s: float = 60.0) -> PowerEpoch:
        """A 120 s Set ID / Set Baud window (R11) for a test to act in: of a power-up the counter proved, in which
        no Set ID / Set Baud has been sent, at the DUT's node id and bit rate, with at least ``left_s`` of it
        left. The current power-up's when it is such (a power cycle spared), else a proven power cycle's."""
        if self._window_unusable(INSIDE, lead=left_s) is None:
            assert self.lane.epoch is not None
            self.record.observe("window", f"of the current power-up: {self.lane.epoch.describe()}")
        else:
            self.power_cycle(self.profile.off_s, self.profile.boot_s)
        assert self.lane.epoch is not None
        return self.lane.epoch

    def at_window_moment(self, kind: str, margin: float = WINDOW_MARGIN_S) -> PowerEpoch:
        """Wait for the moment of the 120 s Set ID / Set Baud window (R11) a window test acts at: ``margin``
        inside its earliest end (``kind`` "inside") or ``margin`` after its latest end ("after"). The window
        of the DUT's current power-up is used when the power-up counter proved it and nothing since can
        have changed where it stands or what the DUT does in it (:func:`epochs.unusable`); the run-order
        scheduler has other tests run meanwhile. Otherwise a fresh window is opened with a proven power
        cycle, and the whole window waited out. Returns the power-up epoch the moment belongs to."""
        why = self._window_unusable(kind, margin=margin)
        if why is None:
            epoch = self.lane.epoch
            assert epoch is not None
            self.record.observe("window", f"shared: {epoch.describe()}")
        else:
            self.power_cycle(self.profile.off_s, self.profile.boot_s)
            epoch = self.lane.epoch
            assert epoch is not None
            epoch.opened_by = epoch.opened_by or "this test"
            self.record.observe("window", f"opened by this test ({why}): {epoch.describe()}")
        self.read_until(epoch.moment(kind, margin))
        return epoch

    def switch_power(self, off_time: float | None = None, boot_wait: float | None = None) -> float:
        """Power off, wait, on, and wait for the boot (default: the profile's off and boot times): until the
        DUT reports again (:meth:`await_reports`), at most :meth:`ready_bound_s`, so that nothing is asked
        of a DUT still booting. Without proof: :meth:`power_cycle` proves it; this alone only puts things
        back, where the state is verified afterwards. Returns the lane time of power-on. On a bench of several
        ESCs (``nodes``) it waits for each of them that was reporting before the power went off: they do not
        boot at one instant, and one still booting would miss what is asked next (a GET_ESC_ID broadcast)."""
        self.stop_throttle()
        others = set(self.nodes) - {self.node_id} if len(self.nodes) > 1 else set()
        if others:
            longest = cat.REPORT_INTERVAL_RANGE[1] * cat.INTERVAL_UNIT_S
            others &= {src for src, _, _ in self._reports(self.now() - longest, None)}
        self.lane.epoch = None  # no window stands until the DUT is up again
        self.lane.power.off()
        self._power_switched()
        self.lane.wait_power(self.profile.off_s if off_time is None else off_time)
        earliest = self.now()  # the DUT cannot have been switched on before this
        self.lane.power.on()
        on = self.now()
        self._power_switched()
        heard = self.await_reports(on, on + self.ready_bound_s(boot_wait), others)
        first = min((t for t in heard.values()), default=None)
        self.lane.epoch = PowerEpoch(earliest, first if first is not None else self.now(), self.node_id, self.lane.bitrate)
        self.record.observe("after power-up", f"first report {(first - on) * 1000:.1f} ms after power-on" if first is not None
                            else f"no report within {self.ready_bound_s(boot_wait):.2f} s of power-on")
        return on

    # ------------------------------------------------------------------ readiness
    #: MSG1..MSG3: a reporting DUT has sent each once within the longest legal interval
    READY_REPORTS = ("msg1", "msg2", "msg3")
    #: ... or it reports in another mode (MSG_EXP mode, CAN Test): the first such frame will do
    OTHER_MODE_REPORTS = frozenset({s.name for s in cat.CATALOGUE if s.name.startswith("msg_exp")} | {"can_test"})

    def ready_bound_s(self, boot: float | None = None) -> float:
        """How long after power-on (or discovery) a DUT may take to report: its boot time (the profile's
        boot_s, "power-on to first report", unless given), then one longest legal report interval (the
        first MSG3 may come that late), and the lane's stated error."""
        longest = cat.REPORT_INTERVAL_RANGE[1] * cat.INTERVAL_UNIT_S
        return (self.profile.boot_s if boot is None else boot) + longest + self.lane.timing_error

    def _reports(self, since: float, source: int | None) -> list[tuple[int, str, float]]:
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

    def _reports_since(self, since: float, source: int | None = None) -> dict[str, float]:
        """{report name: first start time} of the DUT's reports (or ``source``'s) since ``since``."""
        out: dict[str, float] = {}
        for _, name, t in self._reports(since, self.node_id if source is None else source):
            out.setdefault(name, t)
        return out

    def _ready(self, heard: dict[str, float]) -> bool:
        """Whether ``heard`` (:meth:`_reports_since`) shows a node reporting: each of MSG1..MSG3, or another mode's report."""
        return set(self.READY_REPORTS) <= heard.keys() or bool(heard.keys() & self.OTHER_MODE_REPORTS)

    def await_reports(self, since: float, until: float, others: Iterable[int] = ()) -> dict[str, float]:
        """Read until the DUT has sent each of MSG1..MSG3 since ``since`` (or one frame of another reporting
        mode), and so has each node of ``others``, or until lane time ``until``: {report name: first time} of
        what the DUT sent ({} when nothing came)."""
        while True:
            heard = self._reports_since(since)
            if (self._ready(heard) and all(self._ready(self._reports_since(since, n)) for n in others)) or self.now() >= until:
                return heard
            self.read_until(min(until, self.now() + 0.01))

    def heard_from(self, since: float) -> bool:
        """Whether the DUT sent any frame since ``since`` (decoded or not)."""
        return (any(f.source == self.node_id for f in self.frames(since=since))
                or any(g.msg.arbitration_id & 0x7F == self.node_id for g in self.undecoded(since=since)))

    def _power_switched(self) -> None:
        """Tell the lane's listeners that care (the live bus rules: R9a) that the power was switched."""
        now = self.now()
        for listener in self.lane.listeners:
            note = getattr(listener, "power_switched", None)
            if note is not None:
                note(now)

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
        wire = self.proto.message(name, fields)
        msg = can.Message(arbitration_id=wire.arbitration_id, data=wire.data, is_extended_id=True)
        spec = cat.spec(name)
        key = (Kind.MESSAGE, name)

        def bump(m: can.Message) -> None:
            if spec.has_tail:
                m.data[-1] = 0xC0 | self.proto.tids.next(key)

        task = self.lane.bus.send_periodic(msg, period, modifier_callback=bump)
        self._tasks.append(task)
        return task

    def stop_throttle(self) -> None:
        for task in self._tasks:
            try:
                task.stop()
            except Exception:  # noqa: BLE001 - on an exit path every stop is attempted
                pass
        self._tasks.clear()

    def zero_throttle(self) -> None:
        """Stop every stream and command zero on every channel in all three formats."""
        self.stop_throttle()
        self.send_wire(self.proto.message("raw_command_14b", {"channels": [0] * 4}))
        for group in cat.THROTTLE_GROUPS:
            self.send_wire(self.proto.message("raw_command_12b", {"channels": [0] * 4, "group": group}))
        self.send_wire(self.proto.message("raw_command_10b", {"channels": [0] * 6}))

    # ------------------------------------------------------------------ operations the suites share
    #: How long a motor may take to start or to spin down: a test allowance, not a protocol fact
    MOTOR_STOP_S = 5.0
    #: Time given to the throttle output to follow a new command (a real ESC may ramp): not a protocol fact
    OUTPUT_SETTLE_S = 0.2

    def reports_heard(self, seconds: float) -> int:
        """How many report frames the DUT sends in the next ``seconds``, decoded or not (their format is
        4.4.4 - 4.4.14's business; here only whether it reports counts)."""
        report_ids = {s.type_id for s in cat.CATALOGUE if any(lay.name == "report" for lay in s.layouts)}
        start = self.now()
        self.wait(seconds)
        heard = [f for f in self.frames(source=self.node_id, kind=Kind.MESSAGE, since=start) if f.type_id in report_ids]
        heard += [g for g in self.undecoded(source=self.node_id, kind=Kind.MESSAGE, since=start)
                  if classify(g.msg.arbitration_id)[1] in report_ids]
        return len(heard)

    def suspend_reporting(self) -> None:
        """MSG Control 0x55555555, verified: INCONCLUSIVE (reporting resumed first) unless the reports
        stop, for whether they do is 4.4.2's verdict, not the verdict of a test that needs them stopped."""
        interval = self.settings()["msg1_interval"] * cat.INTERVAL_UNIT_S
        self.broadcast("msg_control", {"option": 0, "command": cat.MSG_CONTROL_SUSPEND})
        self.wait(cat.ANSWER_DELAY_MAX_S)
        if self.reports_heard(2 * interval):
            self.resume_reporting()
            raise Inconclusive("MSG Control 0x55555555 did not stop the reports (see 4.4.2): suspension cannot be tested")

    def resume_reporting(self) -> None:
        """MSG Control 0xAAAAAAAA, verified: if the reports do not come back (4.4.2's verdict) the DUT is
        power-cycled back to reporting where the lane can (suspension is not kept, R13) and the test is
        INCONCLUSIVE."""
        self.broadcast("msg_control", {"option": 0, "command": cat.MSG_CONTROL_RESUME})
        self.wait(cat.ANSWER_DELAY_MAX_S)
        if self.reports_heard(2 * self.settings()["msg1_interval"] * cat.INTERVAL_UNIT_S):
            return
        if self.lane.power.available:
            self.power_cycle(self.profile.off_s, self.profile.boot_s)
        raise Inconclusive("MSG Control 0xAAAAAAAA did not bring the reports back (see 4.4.2): this test cannot be judged")

    def wait_motor_stopped(self) -> Frame | None:
        """Zero throttle, then read until MSG1 shows the motor stopped (speed and pwm 0): that MSG1, or
        None when none did within MOTOR_STOP_S (the motor may have stopped unseen)."""
        self.zero_throttle()
        return self.wait_for("msg1", self.MOTOR_STOP_S, where=lambda f: f.fields["speed"] == 0 and f.fields["pwm"] == 0)

    def stop_motor(self) -> None:
        """:meth:`wait_motor_stopped`, INCONCLUSIVE when no MSG1 shows the motor stopped."""
        if self.wait_motor_stopped() is None:
            raise Inconclusive(f"the motor still runs {self.MOTOR_STOP_S} s after zero throttle (MSG1 speed, pwm)")

    def start_motor(self, name: str, fields: Mapping[str, Any]) -> None:
        """Stream throttle frame ``name`` with ``fields`` until MSG1 shows the motor running (the run bit or
        a speed: either will do, R7 is 4.4.4's business); when none does within MOTOR_STOP_S, the motor is
        let spin down and the test is INCONCLUSIVE. The caller stops it (:meth:`stop_motor`)."""
        self.throttle_stream(name, fields)
        if self.wait_for("msg1", self.MOTOR_STOP_S,
                         where=lambda f: bool(f.fields["status"] & cat.Status.RUNNING) or f.fields["speed"] > 0) is None:
            self.wait_motor_stopped()
            raise Inconclusive("the motor did not start (no MSG1 showed it running): the test cannot be judged")

    def msg1_interval(self, node: int | None = None) -> float:
        """The MSG1 report interval (s) of ``node`` (default: the DUT), read with Set/Get Freq."""
        freq = self.ask("set_freq", {"option": 0, "msg1_interval": 0, "msg2_interval": 0, "msg3_interval": 0},
                        destination=self.node_id if node is None else node)
        return freq["msg1_interval"] * cat.INTERVAL_UNIT_S

    def read_output(self, *, nodes: list[int] | None = None, intervals: Mapping[int, float] | None = None
                    ) -> dict[int, list[int]]:
        """The throttle output (MSG1 ``pwm``, 4.4.4) of each of ``nodes`` (default: the DUT) under whatever
        commands them now: OUTPUT_SETTLE_S and one MSG1 interval for it to settle, then {node: [pwm, ...]}
        of the next three intervals' MSG1. INCONCLUSIVE when a node's MSG1 did not decode. ``intervals``:
        the nodes' MSG1 intervals where already read (else asked)."""
        nodes = [self.node_id] if nodes is None else nodes
        known = intervals or {}
        interval = max(known[n] if n in known else self.msg1_interval(n) for n in nodes)
        self.wait(self.OUTPUT_SETTLE_S + interval)
        start = self.now()
        self.wait(3 * interval + cat.INTERVAL_UNIT_S)
        out = {n: [f.fields["pwm"] for f in self.frames("msg1", since=start, source=n)] for n in nodes}
        for n, pwms in out.items():
            if not pwms:
                raise Inconclusive(f"no MSG1 decoded from node {n}: its throttle output cannot be read (see 4.4.4)")
        return out

    def throttle_output(self, name: str, frames: list[Mapping[str, Any]], *, nodes: list[int] | None = None,
                        intervals: Mapping[int, float] | None = None) -> dict[int, list[int]]:
        """:meth:`read_output` while each field dict of ``frames`` is streamed as throttle frame ``name``
        (in that order, every period); the streams are stopped afterwards."""
        nodes = [self.node_id] if nodes is None else nodes
        known = intervals or {}
        known = {n: known[n] if n in known else self.msg1_interval(n) for n in nodes}  # read before the throttle runs
        for fields in frames:
            self.throttle_stream(name, fields)
        try:
            return self.read_output(nodes=nodes, intervals=known)
        finally:
            self.stop_throttle()


def echo_probe(host_node: int = 0, *, nibble_order: str = "lsb") -> can.Message:
    """The frame a lane sends to find out whether the host's own frames come back
    (:meth:`BusLane.find_echo`): the GET_ESC_ID query the suite sends first anyway, harmless to every
    ESC (R1), with the transfer id before the first one the :class:`Dut` uses, so that the DUT sees the
    host's transfer ids count on."""
    wire = HostProtocol(host_node, nibble_order=nibble_order).message("get_esc_id", {"option": 0}, layout="query",
                                                                      transfer_id=TRANSFER_ID_MODULO - 1)
    return can.Message(arbitration_id=wire.arbitration_id, data=wire.data, is_extended_id=wire.is_extended_id)


class DutError(RuntimeError):
    """The harness could not do what a test needed (not a verdict on the DUT)."""


class DutUnreachable(DutError):
    """No ESC answers at all (discovery heard nothing): the bench, not one test, is the problem; the
    plugin aborts the run on it."""


_THROTTLE_FRAMES = frozenset({"raw_command_14b", "raw_command_12b", "raw_command_10b"})
