"""One CAN controller as ISO 11898-1's fault confinement makes it, sans-IO: no clock, no bus, no ``can``.

A :class:`CanController` keeps a node's transmit queue and its error counters. Its owner (the simulated lane's bus,
:mod:`ckesc.emulator.sim_bus`) tells it what happened to each try of its head frame (:meth:`CanController.attempt`:
acknowledged, no acknowledgement, an error, a bus short) and to each frame it received; the controller moves its
counters and its state by the standard's rules and says what SocketCAN would report (:class:`ErrorFrame`, laid out as
``linux/can/error.h`` says). Times are arguments; durations are bit times (:func:`attempt_bits`).

The rules (ISO 11898-1, fault confinement), each applied in one place:

* a transmit error adds 8 to the transmit error counter (TEC), a successful transmission takes 1 off;
* a receive error adds 1 to the receive error counter (REC), 8 where the receiver saw the error first (the primary
  error), a good reception takes 1 off (from above 127 it drops to 119: the standard allows 119 to 127);
* error-active while both counters are at most 127, error-passive above, bus-off once TEC passes 255 (SocketCAN also
  reports error-warning at 96, which changes nothing of the protocol);
* the ACK exception: an error-passive transmitter that gets no acknowledgement does not raise its TEC, so a node
  alone on the bus stops at TEC 128 and retransmits its head frame for ever, never bus-off;
* bus-off ends after 128 occurrences of 11 recessive bits (:data:`RECOVERY_BITS`) where the controller recovers by
  itself, else only at a restart (:meth:`CanController.restart`, SocketCAN's ``ip link set canX type can restart``);
  either way both counters start again at 0.
"""

from __future__ import annotations

import heapq
import itertools
import math
from collections import deque
from enum import Enum
from typing import Any, Iterator, NamedTuple

# --------------------------------------------------------------------- linux/can.h and linux/can/error.h
CAN_ERR_FLAG = 0x20000000  #: can.h: an error message frame
CAN_ERR_MASK = 0x1FFFFFFF  #: can.h: the id bits of a frame without its EFF, RTR and ERR flags
CAN_ERR_DLC = 8  #: error.h: the data length of an error frame

# error class, in the id
CAN_ERR_TX_TIMEOUT = 0x001
CAN_ERR_LOSTARB = 0x002
CAN_ERR_CRTL = 0x004  #: controller problems: data[1]
CAN_ERR_PROT = 0x008  #: protocol violations: data[2] (type), data[3] (location)
CAN_ERR_TRX = 0x010
CAN_ERR_ACK = 0x020  #: received no ACK on transmission
CAN_ERR_BUSOFF = 0x040
CAN_ERR_BUSERROR = 0x080
CAN_ERR_RESTARTED = 0x100  #: controller restarted
CAN_ERR_CNT = 0x200  #: TX error counter in data[6], RX error counter in data[7]

# data[1]: the controller's error status
CAN_ERR_CRTL_RX_WARNING = 0x04
CAN_ERR_CRTL_TX_WARNING = 0x08
CAN_ERR_CRTL_RX_PASSIVE = 0x10
CAN_ERR_CRTL_TX_PASSIVE = 0x20
CAN_ERR_CRTL_ACTIVE = 0x40  #: recovered to error active state

# data[2]: the protocol error's type; data[3]: its location
CAN_ERR_PROT_BIT0 = 0x08  #: unable to send a dominant bit
CAN_ERR_PROT_TX = 0x80  #: the error occurred on transmission
CAN_ERR_PROT_LOC_ACK = 0x19  #: the ACK slot
CAN_ERR_PROT_LOC_SOF = 0x03  #: start of frame

# error.h's thresholds (ISO 11898-1's)
CAN_ERROR_WARNING_THRESHOLD = 96
CAN_ERROR_PASSIVE_THRESHOLD = 128
CAN_BUS_OFF_THRESHOLD = 256

# --------------------------------------------------------------------- ISO 11898-1
TX_ERROR = 8  #: TEC added by a transmit error
RX_ERROR = 1  #: REC added by a receive error
RX_PRIMARY_ERROR = 8  #: REC added where the receiver detected the error first
REC_AFTER_PASSIVE = 119  #: REC after a good reception from above 127 (the standard allows 119..127)
RECOVERY_BITS = 128 * 11  #: bus-off recovery: 128 occurrences of 11 consecutive recessive bits
ERROR_FRAME_BITS = 6 + 8 + 3  #: an error flag, its delimiter and the intermission
SUSPEND_BITS = 8  #: an error-passive transmitter's suspend transmission before it tries again
DEFAULT_TXQUEUELEN = 10  #: a SocketCAN CAN device's transmit queue (txqueuelen)


def attempt_bits(dlc: int, outcome: Attempt, passive: bool = False) -> int:
    """Bit times one try of an extended data frame with ``dlc`` bytes holds the bus (stuff bits not counted, as
    :func:`ckesc.protocol.frame.frame_bits`): the whole frame and the interframe space when it is acknowledged;
    up to its ACK slot and then an error frame without an acknowledgement; its start of frame and an error frame
    on a shorted bus (the first dominant bit reads back recessive) or a frame destroyed by another node's error
    flag (counted from its start: where in the frame it happens is not modelled). An error-passive transmitter
    waits :data:`SUSPEND_BITS` more after an error."""
    if outcome is Attempt.ACKED:
        return 67 + 8 * dlc
    head = 56 + 8 * dlc if outcome is Attempt.NO_ACK else 1
    return head + ERROR_FRAME_BITS + (SUSPEND_BITS if passive else 0)


def recovery_seconds(bitrate: int) -> float:
    """How long bus-off recovery takes at ``bitrate`` (128 x 11 bit times: 2.816 ms at 500 kbit/s)."""
    return RECOVERY_BITS / bitrate


class ErrorState(Enum):
    """A controller's state, as SocketCAN names it (``ip -details link show``)."""

    ACTIVE = "ERROR-ACTIVE"
    WARNING = "ERROR-WARNING"
    PASSIVE = "ERROR-PASSIVE"
    BUS_OFF = "BUS-OFF"


_ORDER = {ErrorState.ACTIVE: 0, ErrorState.WARNING: 1, ErrorState.PASSIVE: 2, ErrorState.BUS_OFF: 3}


def counter_state(count: int) -> ErrorState:
    """The state one counter alone stands for (error.h's table)."""
    if count >= CAN_BUS_OFF_THRESHOLD:
        return ErrorState.BUS_OFF
    if count >= CAN_ERROR_PASSIVE_THRESHOLD:
        return ErrorState.PASSIVE
    if count >= CAN_ERROR_WARNING_THRESHOLD:
        return ErrorState.WARNING
    return ErrorState.ACTIVE


class Attempt(Enum):
    """What one try of the head frame met."""

    ACKED = "acked"  #: another node acknowledged it: sent
    NO_ACK = "no ack"  #: nobody at its bit rate listened: an ACK error
    ERROR = "error"  #: another node's error flag (a node at another bit rate, a babbling one) destroyed it
    SHORT = "bus short"  #: the bus is shorted: the first dominant bit reads back recessive (a bit error)


class ErrorFrame(NamedTuple):
    """An error frame as a SocketCAN socket reads it: ``can_id`` is the error class (without
    :data:`CAN_ERR_FLAG`; python-can's ``arbitration_id`` of an ``is_error_frame`` message, a standard id),
    ``data`` the :data:`CAN_ERR_DLC` bytes error.h describes."""

    can_id: int
    data: bytes
    timestamp: float

    @property
    def raw_id(self) -> int:
        """The id as the kernel writes it into ``struct can_frame``."""
        return CAN_ERR_FLAG | self.can_id


def reported_state(error_class: int, data: bytes) -> ErrorState | None:
    """What one SocketCAN error frame says of the state of the controller that reads it (the host's own adapter):
    ``error_class`` its id without :data:`CAN_ERR_FLAG` (python-can's ``arbitration_id`` of an ``is_error_frame``
    message), ``data`` its bytes. None: it says nothing of the state (a bus error, a lost arbitration)."""
    if error_class & CAN_ERR_BUSOFF:
        return ErrorState.BUS_OFF
    if error_class & CAN_ERR_RESTARTED:
        return ErrorState.ACTIVE
    if error_class & CAN_ERR_CRTL and len(data) > 1:
        status = data[1]
        if status & (CAN_ERR_CRTL_TX_PASSIVE | CAN_ERR_CRTL_RX_PASSIVE):
            return ErrorState.PASSIVE
        if status & (CAN_ERR_CRTL_TX_WARNING | CAN_ERR_CRTL_RX_WARNING):
            return ErrorState.WARNING
        if status & CAN_ERR_CRTL_ACTIVE:
            return ErrorState.ACTIVE
    return None


class QueueFull(Exception):
    """The transmit queue is full (SocketCAN: ``send()`` fails with ENOBUFS)."""


def _crtl_bits(count: int, warning: int, passive: int) -> int:
    state = counter_state(count)
    return {ErrorState.ACTIVE: CAN_ERR_CRTL_ACTIVE, ErrorState.WARNING: warning}.get(state, passive)


class CanController:
    """A node's CAN controller: its transmit queue and error counters (see the module docstring).

    ``txqueuelen``: frames the queue holds, the head included (None: no limit); ``order``: ``"fifo"`` (SocketCAN's
    queue) or ``"priority"`` (lowest id first, as a controller's mailboxes by id); ``auto_recovery``: whether bus-off
    ends by itself after :data:`RECOVERY_BITS` (STM32's ABOM, SocketCAN's ``restart-ms``) or only at
    :meth:`restart`; ``berr_reporting``: whether each bus error is reported as an error frame too (SocketCAN's
    ``berr-reporting on``), besides the changes of state."""

    def __init__(self, bitrate: int, *, txqueuelen: int | None = DEFAULT_TXQUEUELEN, order: str = "fifo",
                 auto_recovery: bool = True, berr_reporting: bool = False) -> None:
        if order not in ("fifo", "priority"):
            raise ValueError(f"transmit queue order {order!r}: 'fifo' or 'priority'")
        self.bitrate = bitrate
        self.txqueuelen = txqueuelen
        self.order = order
        self.auto_recovery = auto_recovery
        self.berr_reporting = berr_reporting
        self.tec = 0
        self.rec = 0
        self.state = ErrorState.ACTIVE
        self.bus_off_at: float | None = None  #: when it went bus-off (None: it is not)
        self.counts = {"sent": 0, "no_ack": 0, "errors": 0, "bus_off": 0, "recovered": 0}
        self.size = 0  #: frames queued, the head included (len(), kept as a number: read once per frame)
        self._fifo: deque[Any] = deque()
        self._heap: list[tuple[int, int, Any]] = []
        self._seq = itertools.count()
        #: the frame on the bus now (:meth:`begin`), until its try ends (None: none); read, never set, by its owner
        self.sending: Any | None = None
        self._reports: list[ErrorFrame] = []

    # ------------------------------------------------------------------ the transmit queue
    def __len__(self) -> int:
        return self.size

    def __iter__(self) -> Iterator[Any]:
        """The queued frames, the head first."""
        if self.order == "fifo":
            return iter(self._fifo)
        return (item for _, _, item in sorted(self._heap))

    @property
    def full(self) -> bool:
        n = self.txqueuelen
        return n is not None and self.size >= n

    def submit(self, frame: Any, can_id: int) -> None:
        """Queue ``frame`` (any object; ``can_id`` orders a priority queue). Raises :class:`QueueFull`."""
        n = self.txqueuelen  # (:attr:`full`, without its call: every frame of a simulated run is queued here)
        if n is not None and self.size >= n:
            raise QueueFull(f"the transmit queue is full ({self.txqueuelen} frames)")
        if self.order == "fifo":
            self._fifo.append(frame)
        else:
            heapq.heappush(self._heap, (can_id, next(self._seq), frame))
        self.size += 1

    def evict_for(self, can_id: int) -> Any | None:
        """Make room in a full priority queue for a frame of ``can_id``: the queue's lowest-priority frame (the
        highest id, the latest of them), unless it is on the bus or not below ``can_id``, leaves it and is returned
        (None: nothing left; the new frame is the one that does not fit). A firmware's priority transmit queue does
        so (libuavcan's), so that an answer is not lost behind reports that waited for an acknowledgement."""
        if self.order != "priority" or not self._heap:
            return None
        i = max(range(len(self._heap)), key=lambda k: self._heap[k][:2])
        can_worst, _, frame = self._heap[i]
        if can_worst <= can_id or frame is self.sending:
            return None
        self._heap[i] = self._heap[-1]
        self._heap.pop()
        heapq.heapify(self._heap)
        self.size -= 1
        return frame

    def head(self) -> Any | None:
        """The frame the controller tries next, or the one it is trying (None: nothing to send)."""
        if self.sending is not None:
            return self.sending
        if self._fifo:
            return self._fifo[0]
        return self._heap[0][2] if self._heap else None

    def begin(self) -> Any:
        """The head frame goes on the bus: it stays the head until its try ends (:meth:`attempt`), so that a frame of
        a higher priority queued meanwhile waits for the next arbitration, as a controller's mailbox in transmission
        is not overtaken."""
        sending = self.sending  # (:meth:`head`, without its call: once per frame)
        if sending is None:
            if self._fifo:
                sending = self.sending = self._fifo[0]
            elif self._heap:
                sending = self.sending = self._heap[0][2]
        return sending

    def clear(self) -> None:
        """Drop every queued frame (a power cycle, an interface taken down)."""
        self._fifo.clear()
        self._heap.clear()
        self.sending = None
        self.size = 0

    def _pop(self) -> Any:
        sending, self.sending = self.sending, None
        if self._fifo:
            return self._fifo.popleft()
        if sending is None or self._heap[0][2] is sending:
            return heapq.heappop(self._heap)[2]
        i = next(i for i, item in enumerate(self._heap) if item[2] is sending)  # a frame overtaken while on the bus
        self._heap[i] = self._heap[-1]
        self._heap.pop()
        heapq.heapify(self._heap)
        return sending

    # ------------------------------------------------------------------ what the bus did
    @property
    def passive(self) -> bool:
        return self.state is ErrorState.PASSIVE

    @property
    def bus_off(self) -> bool:
        return self.state is ErrorState.BUS_OFF

    def can_send(self) -> bool:
        return self.state is not ErrorState.BUS_OFF and bool(self)

    def steady_without_ack(self) -> bool:
        """Whether a further unacknowledged try changes nothing (the ACK exception holds): the owner may stop
        playing the tries one by one until another node can listen."""
        return self.state is ErrorState.PASSIVE and self.rec < CAN_ERROR_PASSIVE_THRESHOLD

    def attempt(self, outcome: Attempt, now: float) -> Any | None:
        """One try of the head frame ended at ``now`` with ``outcome``: the counters move; an acknowledged frame leaves
        the queue and is returned, any other stays at the head (None). A bus-off controller does not try."""
        if self.state is ErrorState.BUS_OFF or not self.size:
            raise RuntimeError(f"no try possible: the controller is {self.state.value} with {len(self)} frame(s)")
        if outcome is Attempt.ACKED:  # (the hot path of a simulated run: every frame on the bus)
            self.counts["sent"] += 1
            fifo = self._fifo
            if fifo:  # (:meth:`_pop`'s FIFO case, without its call)
                self.sending = None
                frame = fifo.popleft()
            else:
                frame = self._pop()
            self.size -= 1
            if self.tec:
                self.tec -= 1
                self._settle(now)
            return frame
        if outcome is Attempt.NO_ACK:
            self.counts["no_ack"] += 1
            if not self.passive:  # the ACK exception: an error-passive transmitter's TEC stays
                self.tec += TX_ERROR
            self._bus_error(now, CAN_ERR_ACK, 0, CAN_ERR_PROT_LOC_ACK)
        else:
            self.counts["errors"] += 1
            self.tec += TX_ERROR
            self._bus_error(now, 0, CAN_ERR_PROT_BIT0 if outcome is Attempt.SHORT else 0,
                            CAN_ERR_PROT_LOC_SOF if outcome is Attempt.SHORT else 0)
        self.sending = None  # the next try arbitrates again: a frame of a higher priority queued meanwhile goes first
        self._settle(now)
        return None

    def received(self, now: float, ok: bool = True, primary: bool = False) -> None:
        """A frame received (``ok``) or destroyed while this node received it (``primary``: this node saw the error
        first). A bus-off node receives nothing."""
        if self.state is ErrorState.BUS_OFF:
            return
        if ok:
            if self.rec > CAN_ERROR_PASSIVE_THRESHOLD - 1:
                self.rec = REC_AFTER_PASSIVE
            elif self.rec:
                self.rec -= 1
        else:
            self.rec = min(self.rec + (RX_PRIMARY_ERROR if primary else RX_ERROR), 255)
            self._bus_error(now, 0, 0, 0)
        self._settle(now)

    # ------------------------------------------------------------------ bus-off and its end
    def recovery_due(self, recessive_from: float = -math.inf) -> float | None:
        """When bus-off ends by itself (None: it is not bus-off, or it waits for :meth:`restart`): 128 x 11 recessive
        bits after it went bus-off, counted from ``recessive_from`` where the bus was held dominant until then (a
        short: no recessive bit to count)."""
        if self.bus_off_at is None or not self.auto_recovery:
            return None
        return max(self.bus_off_at, recessive_from) + recovery_seconds(self.bitrate)

    def poll(self, now: float, recessive_from: float = -math.inf) -> bool:
        """Recover from bus-off if its time has come (:meth:`recovery_due`); whether it did."""
        due = self.recovery_due(recessive_from)
        if due is None or now < due:
            return False
        self._reset(due, CAN_ERR_CRTL, bytes([0, CAN_ERR_CRTL_ACTIVE]))
        return True

    def restart(self, now: float) -> None:
        """The controller restarted by software (SocketCAN's ``restart``, a driver's restart after ``restart-ms``):
        error-active, both counters 0; its queue is kept."""
        self._reset(now, CAN_ERR_RESTARTED, b"")

    def _reset(self, now: float, can_id: int, data: bytes) -> None:
        was_off = self.state is ErrorState.BUS_OFF
        self.tec = self.rec = 0
        self.state = ErrorState.ACTIVE
        self.bus_off_at = None
        if was_off:
            self.counts["recovered"] += 1
        self._report(now, can_id, data)

    # ------------------------------------------------------------------ SocketCAN's error frames
    def take_error_frames(self) -> list[ErrorFrame]:
        """The error frames reported since the last call, oldest first."""
        out, self._reports = self._reports, []
        return out

    def _settle(self, now: float) -> None:
        """The state the counters stand for, and SocketCAN's error frame when it changed (``can_change_state``)."""
        tx, rx = counter_state(self.tec), counter_state(min(self.rec, CAN_BUS_OFF_THRESHOLD - 1))
        new = tx if _ORDER[tx] >= _ORDER[rx] else rx
        if new is self.state:
            return
        self.state = new
        if new is ErrorState.BUS_OFF:
            self.bus_off_at = now
            self.counts["bus_off"] += 1
            self._report(now, CAN_ERR_BUSOFF, b"")
            return
        status = 0
        if _ORDER[tx] >= _ORDER[rx]:
            status |= _crtl_bits(self.tec, CAN_ERR_CRTL_TX_WARNING, CAN_ERR_CRTL_TX_PASSIVE)
        if _ORDER[tx] <= _ORDER[rx]:
            status |= _crtl_bits(self.rec, CAN_ERR_CRTL_RX_WARNING, CAN_ERR_CRTL_RX_PASSIVE)
        self._report(now, CAN_ERR_CRTL, bytes([0, status]))

    def _bus_error(self, now: float, extra: int, kind: int, location: int) -> None:
        if self.berr_reporting:
            tx = CAN_ERR_PROT_TX if extra or kind else 0
            self._report(now, CAN_ERR_PROT | CAN_ERR_BUSERROR | extra, bytes([0, 0, kind | tx, location]))

    def _report(self, now: float, can_id: int, data: bytes) -> None:
        counters = bytes([min(self.tec, 255), min(self.rec, 255)])
        body = data.ljust(6, b"\0") + counters
        self._reports.append(ErrorFrame(can_id | CAN_ERR_CNT, body, now))
