"""The DUT's supply as the tests use it (:class:`Supply`): power cycles proven by the power-up counter, the
120 s Set ID / Set Baud window of a power-up, and waiting for a DUT to report after power-on."""

from __future__ import annotations

from typing import Iterable

from ..protocol import catalogue as cat
from .epochs import INSIDE, WINDOW_MARGIN_S, PowerEpoch, unusable
from .lanes import BOOTING, SWITCHED_OFF, UNHEARD
from .link import DutError, Link
from .outcomes import Inconclusive


class Supply:
    """Power operations on a :class:`.link.Link` (the link's lane has the power control)."""

    def __init__(self, link: Link) -> None:
        self.link = link

    def power_up_count(self) -> int | None:
        ex = self.link.request("maintenance_information", {"option": 2})
        if ex.response is None or "power_ups" not in ex.response.fields:
            return None
        return ex.response.fields["power_ups"]

    def power_cycle(self, off_time: float = 1.0, boot_wait: float = 1.0) -> None:
        """Power off, wait, on, and prove the cycle by the power-up counter (241 option 2);
        raises Inconclusive when it cannot be proven, DutError when the DUT sent nothing at all after
        power-up (no report, no answer: it did not come back)."""
        if not self.link.lane.power.available:
            raise Inconclusive("this test needs a power cycle and no power control was given (--power)")
        self.link.stop_throttle()
        before = self.power_up_count()
        on = self.switch_power(off_time, boot_wait)
        after = self.power_up_count()
        self.link.record.observe("power-up counter", f"{before} -> {after}")
        if after is None and not self.heard_from(on):
            raise DutError(f"node {self.link.node_id} sent nothing after power-up: no report within "
                           f"{self.ready_bound_s(boot_wait):.2f} s, no answer to the power-up counter (241 option 2): "
                           f"did it come back, at {self.link.lane.bitrate} bit/s?")
        if before is None or after is None or after != (before + 1) & 0xFFFF:
            raise Inconclusive(f"power cycle not proven: power-up counter {before} -> {after} (241 option 2)")
        self.proved_power_up(on, before, after)

    def proved_power_up(self, on: float, before: int, after: int) -> None:
        """The power-up counter proved the power-up at lane time ``on`` (``before`` -> ``after``): its epoch is
        proven (what a window test may share). For tests that prove a cycle their own way (another rate)."""
        epoch = self.link.lane.epoch
        if epoch is not None and epoch.on_earliest <= on and after == (before + 1) & 0xFFFF:
            epoch.proven, epoch.counter = True, (before, after)
            epoch.node_id, epoch.bitrate = self.link.node_id, self.link.lane.bitrate  # where it answered the counter
            if not self.heard_from(on):  # no report came: the answer to the counter is the first sign of life
                epoch.ready = self.link.now()

    def window_left(self) -> float:
        """Lane seconds left, at the least, of the 120 s Set ID / Set Baud window (R11) of the DUT's current
        power-up as the harness made it (0 when it made none, or the window has closed)."""
        epoch = self.link.lane.epoch
        if epoch is None:
            return 0.0
        return max(0.0, epoch.on_earliest + cat.CONFIG_WINDOW_S - self.link.now())

    def _window_unusable(self, kind: str, *, lead: float = 0.0, margin: float = WINDOW_MARGIN_S) -> str | None:
        """Why the current power-up's window cannot serve an act of ``kind`` now (:func:`epochs.unusable`)."""
        return unusable(self.link.lane.epoch, kind, now=self.link.now(), node_id=self.link.node_id, bitrate=self.link.lane.bitrate,
                        lead=lead, margin=margin)

    def open_window(self, left_s: float = 60.0) -> PowerEpoch:
        """A 120 s Set ID / Set Baud window (R11) for a test to act in: of a power-up the counter proved, in which
        no Set ID / Set Baud has been sent, at the DUT's node id and bit rate, with at least ``left_s`` of it
        left. The current power-up's when it is such (a power cycle spared), else a proven power cycle's."""
        if self._window_unusable(INSIDE, lead=left_s) is None:
            assert self.link.lane.epoch is not None
            self.link.record.observe("window", f"of the current power-up: {self.link.lane.epoch.describe()}")
        else:
            self.power_cycle(self.link.profile.off_s, self.link.profile.boot_s)
        assert self.link.lane.epoch is not None
        return self.link.lane.epoch

    def at_window_moment(self, kind: str, margin: float = WINDOW_MARGIN_S) -> PowerEpoch:
        """Wait for the moment of the 120 s Set ID / Set Baud window (R11) a window test acts at: ``margin``
        inside its earliest end (``kind`` "inside") or ``margin`` after its latest end ("after"). The window
        of the DUT's current power-up is used when the power-up counter proved it and nothing since can
        have changed where it stands or what the DUT does in it (:func:`epochs.unusable`); the run-order
        scheduler has other tests run meanwhile. Otherwise a fresh window is opened with a proven power
        cycle, and the whole window waited out. Returns the power-up epoch the moment belongs to."""
        why = self._window_unusable(kind, margin=margin)
        if why is None:
            epoch = self.link.lane.epoch
            assert epoch is not None
            self.link.record.observe("window", f"shared: {epoch.describe()}")
        else:
            self.power_cycle(self.link.profile.off_s, self.link.profile.boot_s)
            epoch = self.link.lane.epoch
            assert epoch is not None
            epoch.opened_by = epoch.opened_by or "this test"
            self.link.record.observe("window", f"opened by this test ({why}): {epoch.describe()}")
        self.link.read_until(epoch.moment(kind, margin))
        return epoch

    def switch_power(self, off_time: float | None = None, boot_wait: float | None = None) -> float:
        """Power off, wait, on, and wait for the boot (default: the profile's off and boot times): until the
        DUT reports again (:meth:`await_reports`), at most :meth:`ready_bound_s`, so that nothing is asked
        of a DUT still booting. Without proof: :meth:`power_cycle` proves it; this alone only puts things
        back, where the state is verified afterwards. Returns the lane time of power-on. On a bench of several
        ESCs (``nodes``) it waits for each of them that was reporting before the power went off: they do not
        boot at one instant, and one still booting would miss what is asked next (a GET_ESC_ID broadcast)."""
        others = self.power_off()
        self.link.lane.wait_power(self.link.profile.off_s if off_time is None else off_time)
        return self.power_on(others, boot_wait)

    def power_off(self) -> set[int]:
        """The first half of :meth:`switch_power`: every stream stopped, the power off. From now on the host is
        alone on the bus (:attr:`.lanes.Lane.alone`: nobody acknowledges its frames, a real adapter holds them). Returns
        the other ESCs of the bench that were reporting (:meth:`power_on` waits for them too)."""
        self.link.stop_throttle()
        others = set(self.link.nodes) - {self.link.node_id} if len(self.link.nodes) > 1 else set()
        if others:
            longest = cat.REPORT_INTERVAL_RANGE[1] * cat.INTERVAL_UNIT_S
            others &= {src for src, _, _ in self.link.report_starts(self.link.now() - longest, None)}
        self.link.lane.epoch = None  # no window stands until the DUT is up again
        self.link.lane.alone = SWITCHED_OFF
        self.link.lane.power.off()
        self._power_switched()
        return others

    def power_on(self, others: Iterable[int] = (), boot_wait: float | None = None) -> float:
        """The second half of :meth:`switch_power`: the power on, then the boot awaited (the host is alone until the
        ESC reports: its controller is not up before); the lane time of power-on."""
        earliest = self.link.now()  # the DUT cannot have been switched on before this
        self.link.lane.power.on()
        on = self.link.now()
        self.link.lane.alone = BOOTING
        self._power_switched()
        heard = self.await_reports(on, on + self.ready_bound_s(boot_wait), others)
        first = min((t for t in heard.values()), default=None)
        self.link.lane.alone = None if first is not None else UNHEARD
        self.link.lane.epoch = PowerEpoch(earliest, first if first is not None else self.link.now(), self.link.node_id, self.link.lane.bitrate)
        self.link.record.observe("after power-up", f"first report {(first - on) * 1000:.1f} ms after power-on" if first is not None
                            else f"no report within {self.ready_bound_s(boot_wait):.2f} s of power-on")
        return on

    # ------------------------------------------------------------------ readiness
    def ready_bound_s(self, boot: float | None = None) -> float:
        """How long after power-on (or discovery) a DUT may take to report: its boot time (the profile's
        boot_s, "power-on to first report", unless given), then one longest legal report interval (the
        first MSG3 may come that late), and the lane's stated error."""
        longest = cat.REPORT_INTERVAL_RANGE[1] * cat.INTERVAL_UNIT_S
        return (self.link.profile.boot_s if boot is None else boot) + longest + self.link.lane.timing_error

    def _reports_since(self, since: float, source: int | None = None) -> dict[str, float]:
        """{report name: first start time} of the DUT's reports (or ``source``'s) since ``since``."""
        out: dict[str, float] = {}
        for _, name, t in self.link.report_starts(since, self.link.node_id if source is None else source):
            out.setdefault(name, t)
        return out

    def _ready(self, heard: dict[str, float]) -> bool:
        """Whether ``heard`` (:meth:`_reports_since`) shows a node reporting: each of MSG1..MSG3, or another mode's report."""
        return set(self.link.READY_REPORTS) <= heard.keys() or bool(heard.keys() & self.link.OTHER_MODE_REPORTS)

    def await_reports(self, since: float, until: float, others: Iterable[int] = ()) -> dict[str, float]:
        """Read until the DUT has sent each of MSG1..MSG3 since ``since`` (or one frame of another reporting
        mode), and so has each node of ``others``, or until lane time ``until``: {report name: first time} of
        what the DUT sent ({} when nothing came)."""
        while True:
            heard = self._reports_since(since)
            if (self._ready(heard) and all(self._ready(self._reports_since(since, n)) for n in others)) or self.link.now() >= until:
                return heard
            self.link.read_until(min(until, self.link.now() + 0.01))

    def heard_from(self, since: float) -> bool:
        """Whether the DUT sent any frame since ``since`` (decoded or not)."""
        return (any(f.source == self.link.node_id for f in self.link.frames(since=since))
                or any(g.msg.arbitration_id & 0x7F == self.link.node_id for g in self.link.undecoded(since=since)))

    def _power_switched(self) -> None:
        """Tell the lane's listeners that care (the live bus rules: R9a) that the power was switched."""
        now = self.link.now()
        for listener in self.link.lane.listeners:
            note = getattr(listener, "power_switched", None)
            if note is not None:
                note(now)

