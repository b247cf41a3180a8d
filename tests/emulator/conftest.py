"""Fixtures for the emulator's own tests, all in simulated time.

``lane(nodes=[1, 2], ...)`` opens a ``ckesc-sim`` bus on a channel no other test uses and returns a
:class:`Host` on it; every bus is shut down and its world discarded when the test ends. A
:class:`Host` sends catalogue frames as ``can.Message`` and collects what it hears until a time on
the lane's clock. Frames are timestamped at their last bit, so a frame with n data bytes that
starts at t arrives at ``t + tx_time(n)``.
"""

from __future__ import annotations

import itertools
from typing import Any, Iterable

import can
import pytest

from ckesc.bench.sim_lane import placed
from ckesc.emulator import sim_bus
from ckesc.emulator.model import EscConfig
from ckesc.protocol import BY_NAME, DecodeError, Decoder, Frame, Kind, TransferIdCounter, WireFrame, encode

BITRATE = 500_000
TOL = 1e-9  # float rounding only: the lane is deterministic


def tx_time(n_bytes: int, bitrate: int = BITRATE) -> float:
    """Seconds an extended data frame with ``n_bytes`` data bytes occupies the bus (67 + 8n bit times)."""
    return sim_bus.frame_bits(n_bytes) / bitrate


def due_times(frames: Iterable[Frame], bitrate: int = BITRATE, host: int = 0) -> list[float]:
    """When each frame became due at its sender, for frames heard back to back: a frame that starts
    when the previous one ends waited for it, so it was due when the burst started. Valid when every
    frame of a burst was due at the burst's start (one ESC whose reports share a 2 ms grid) and the
    host's frames went out on an idle bus (what starts as one of them ends is a reaction to it, due
    then). ``frames`` must be everything heard in that span, the host's own included, in order."""
    out: list[float] = []
    burst = prev_end = None
    prev_host = False
    for f in frames:
        end = f.timestamp
        start = end - tx_time(len(f.data), bitrate)
        if prev_end is None or prev_host or abs(start - prev_end) > TOL:
            burst = start
        out.append(burst)  # type: ignore[arg-type]
        prev_end, prev_host = end, f.source == host
    return out


def close(a: float, b: float) -> bool:
    return abs(a - b) <= TOL


class Host:
    """A host node on a simulated bench (node 0 unless told otherwise)."""

    BOOT = EscConfig().boot_time
    SERVICE_DELAY = EscConfig().service_delay
    tx_time = staticmethod(tx_time)
    due_times = staticmethod(due_times)
    close = staticmethod(close)

    def __init__(self, bus: can.BusABC, channel: str, bitrate: int, source: int = 0) -> None:
        self.bus = bus
        self.channel = channel
        self.bitrate = bitrate
        self.source = source
        self.decoder = Decoder()  # remembers our requests, so 241 answers decode with their option's layout
        self.tids = TransferIdCounter()  # F3, like a real host

    # ------------------------------------------------------------------ the lane
    @property
    def now(self) -> float:
        return self.bus.now()

    @property
    def bench(self):
        return self.bus.bench

    def esc(self, node_id: int):
        return self.bus.bench.esc(node_id)

    def tx(self, n_bytes: int) -> float:
        return tx_time(n_bytes, self.bitrate)

    # ------------------------------------------------------------------ sending
    def wire(self, name: str, fields: dict | None = None, *, destination: int | None = None,
             transfer_id: int | None = None, source: int | None = None, **kw: Any) -> WireFrame:
        """Encode a catalogue frame from this host (transfer ids count per frame type and destination)."""
        if transfer_id is None:
            transfer_id = self.tids.next((name, kw.get("kind")), destination)
        src = self.source if source is None else source
        return encode(name, fields or {}, source=src, destination=destination, transfer_id=transfer_id, **kw)

    def send(self, name: str, fields: dict | None = None, **kw: Any) -> can.Message:
        return self.send_wire(self.wire(name, fields, **kw))

    def send_wire(self, wire: WireFrame) -> can.Message:
        return self.send_raw(wire.arbitration_id, wire.data)

    def send_raw(self, arbitration_id: int, data: bytes | list[int], **flags: Any) -> can.Message:
        flags.setdefault("is_extended_id", True)
        msg = can.Message(arbitration_id=arbitration_id, data=bytes(data), **flags)
        try:
            self.bus.send(msg)
        except can.CanOperationError as exc:  # a burst of more than SocketCAN's queue: wait for room, as the suite's lane
            placed(self.bus, exc, self.bus.send, msg)
        return msg

    def message(self, name: str, fields: dict | None = None, **kw: Any) -> can.Message:
        """A can.Message for ``bus.send_periodic``."""
        wire = self.wire(name, fields, **kw)
        return can.Message(arbitration_id=wire.arbitration_id, data=wire.data, is_extended_id=True)

    # ------------------------------------------------------------------ receiving
    def collect_raw(self, until: float, *, own: bool = False) -> list[can.Message]:
        """Every frame heard until ``until`` on the lane clock (own frames too if ``own``)."""
        out = []
        while True:
            remaining = until - self.bus.now()
            if remaining < 0:
                break
            msg = self.bus.recv(remaining)
            if msg is None:
                break
            if not msg.is_rx:
                try:
                    self.decoder.decode(msg)  # remember our requests
                except DecodeError:
                    pass
                if not own:
                    continue
            out.append(msg)
        return out

    def collect(self, until: float, *, own: bool = False) -> list[Frame]:
        """Decoded frames heard until ``until``; an undecodable frame from the ESCs fails the test."""
        out = []
        for msg in self.collect_raw(until, own=own):
            try:
                out.append(self.decoder.decode(msg))
            except DecodeError as exc:
                if msg.is_rx:
                    raise AssertionError(f"undecodable frame {msg}: {exc}") from exc
        return out

    def wait_until(self, t: float) -> None:
        """Let the lane run until ``t``, dropping what is heard meanwhile."""
        self.collect_raw(t)

    def wait(self, seconds: float) -> None:
        self.wait_until(self.now + seconds)

    def call(self, name: str, fields: dict | None = None, destination: int = 1, *, window: float = 0.02,
             **kw: Any) -> Frame:
        """Send a service request and return its one response (fails if there is not exactly one)."""
        wire = self.wire(name, fields, destination=destination, **kw)
        self.send_wire(wire)
        tid = wire.data[-1] & 0x1F
        spec = BY_NAME[name]
        frames = self.collect(self.now + window)
        answers = [f for f in frames if f.kind is Kind.RESPONSE and f.type_id == spec.type_id
                   and f.destination == (kw.get("source") or self.source) and f.transfer_id == tid]
        assert len(answers) == 1, f"{name} to {destination}: expected one response, got {answers}"
        return answers[0]

    @staticmethod
    def of(frames: Iterable[Frame], name: str, source: int | None = None) -> list[Frame]:
        return [f for f in frames if f.name == name and (source is None or f.source == source)]


class Lane:
    """Opens simulated benches on unique channels and tidies them up (see the module docstring)."""

    def __init__(self, test_id: str) -> None:
        self._test_id = test_id
        self._count = itertools.count()
        self._buses: list[can.BusABC] = []
        self._channels: set[str] = set()

    def new_channel(self) -> str:
        channel = f"{self._test_id}#{next(self._count)}"
        self._channels.add(channel)
        return channel

    def __call__(self, nodes: Iterable[int] = (1,), *, channel: str | None = None, bitrate: int = BITRATE,
                 source: int = 0, **kwargs: Any) -> Host:
        """A host on a new bench (or on ``channel``, joining the bench there)."""
        if channel is None:
            channel = self.new_channel()
        self._channels.add(channel)
        bus = can.Bus(interface="ckesc-sim", channel=channel, nodes=list(nodes), bitrate=bitrate,
                      receive_own_messages=True, ignore_config=True, **kwargs)
        self._buses.append(bus)
        return Host(bus, channel, bitrate, source)

    def join(self, host: Host, *, bitrate: int = BITRATE, source: int = 0) -> Host:
        """A second host on the same simulated bus (e.g. at another bit rate)."""
        return self(channel=host.channel, bitrate=bitrate, source=source)

    def close(self) -> None:
        for bus in self._buses:
            bus.shutdown()
        for channel in self._channels:
            sim_bus.discard(channel)


@pytest.fixture
def lane(request):
    lane = Lane(request.node.nodeid)
    yield lane
    lane.close()
