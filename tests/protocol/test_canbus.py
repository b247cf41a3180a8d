"""The CAN controller model (ckesc/protocol/canbus.py): ISO 11898-1's error counters and states, the ACK exception,
bus-off and its recovery, the transmit queue, and SocketCAN's error frames as linux/can/error.h lays them out."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from ckesc.protocol import canbus
from ckesc.protocol.canbus import Attempt, CanController, ErrorState, QueueFull

BITRATE = 500_000


def _filled(frames: int = 1, **kwargs) -> CanController:
    ctl = CanController(BITRATE, **kwargs)
    for n in range(frames):
        ctl.submit(f"frame{n}", 0x100 + n)
    return ctl


# ------------------------------------------------------------------------------------------ the constants
@pytest.mark.parametrize("header", ["/usr/include/linux/can/error.h", "/usr/include/linux/can.h"])
def test_constants_are_the_kernel_headers(header):
    """Every CAN_ERR_* / CAN_*_THRESHOLD constant the model writes is the value the kernel's header defines."""
    path = Path(header)
    if not path.exists():
        pytest.skip(f"{header} is not installed (apt-get install linux-libc-dev)")
    defined = {m[1]: int(m[2], 0) for m in re.finditer(r"#define\s+(CAN_\w+)\s+(0x[0-9A-Fa-f]+|\d+)U?\b", path.read_text())}
    ours = {name: getattr(canbus, name) for name in dir(canbus) if name in defined}
    assert len(ours) >= (15 if header.endswith("error.h") else 2), sorted(ours)
    assert {n: v for n, v in ours.items() if defined[n] != v} == {}


# ------------------------------------------------------------------------------------------ counters
def test_a_successful_transmission_takes_one_off_and_leaves_the_queue():
    ctl = _filled(2)
    ctl.attempt(Attempt.ERROR, 0.0)
    assert ctl.tec == 8
    assert ctl.attempt(Attempt.ACKED, 0.1) == "frame0"
    assert (ctl.tec, ctl.head(), len(ctl)) == (7, "frame1", 1)


def test_a_transmit_error_adds_eight_and_keeps_the_frame_at_the_head():
    ctl = _filled(2)
    assert ctl.attempt(Attempt.ERROR, 0.0) is None
    assert ctl.attempt(Attempt.SHORT, 0.0) is None
    assert (ctl.tec, ctl.head()) == (16, "frame0")


def test_receive_errors_add_one_or_eight_and_good_receptions_take_one_off():
    ctl = CanController(BITRATE)
    ctl.received(0.0, ok=False)
    ctl.received(0.0, ok=False, primary=True)
    assert ctl.rec == 9
    ctl.received(0.0)
    assert ctl.rec == 8


def test_a_good_reception_brings_a_passive_receiver_back_below_128():
    ctl = CanController(BITRATE)
    for _ in range(16):
        ctl.received(0.0, ok=False, primary=True)
    assert (ctl.rec, ctl.state) == (128, ErrorState.PASSIVE)
    ctl.received(0.0)
    assert (ctl.rec, ctl.state) == (canbus.REC_AFTER_PASSIVE, ErrorState.WARNING)


# ------------------------------------------------------------------------------------------ states
def test_states_follow_the_thresholds():
    ctl = _filled()
    seen = []
    for _ in range(32):
        ctl.attempt(Attempt.ERROR, 0.0)
        seen.append((ctl.tec, ctl.state))
    assert seen[11] == (96, ErrorState.WARNING) and seen[10] == (88, ErrorState.ACTIVE)
    assert seen[15] == (128, ErrorState.PASSIVE) and seen[14] == (120, ErrorState.WARNING)
    assert seen[30] == (248, ErrorState.PASSIVE)
    assert seen[31] == (256, ErrorState.BUS_OFF)
    assert ctl.bus_off and not ctl.can_send()
    with pytest.raises(RuntimeError, match="BUS-OFF"):
        ctl.attempt(Attempt.ERROR, 0.0)


def test_a_bus_off_node_receives_nothing():
    ctl = _filled()
    for _ in range(32):
        ctl.attempt(Attempt.SHORT, 0.0)
    ctl.received(0.0, ok=False)
    assert ctl.rec == 0


# ------------------------------------------------------------------------------------------ the ACK exception
def test_a_lone_transmitter_stops_at_128_and_retransmits_for_ever():
    """ISO 11898-1's exception: an error-passive transmitter's ACK errors do not raise its TEC."""
    ctl = _filled(3)
    for _ in range(1000):
        ctl.attempt(Attempt.NO_ACK, 0.0)
    assert (ctl.tec, ctl.state, ctl.head(), len(ctl)) == (128, ErrorState.PASSIVE, "frame0", 3)
    assert ctl.steady_without_ack()
    assert ctl.counts["no_ack"] == 1000
    ctl.attempt(Attempt.ACKED, 1.0)  # a second node comes up
    assert (ctl.tec, ctl.state) == (127, ErrorState.WARNING)


def test_the_exception_is_for_ack_errors_only():
    ctl = _filled()
    for _ in range(16):
        ctl.attempt(Attempt.NO_ACK, 0.0)
    ctl.attempt(Attempt.ERROR, 0.0)
    assert ctl.tec == 136


# ------------------------------------------------------------------------------------------ recovery
def _bus_off(**kwargs) -> CanController:
    ctl = _filled(2, **kwargs)
    for _ in range(32):
        ctl.attempt(Attempt.SHORT, 1.0)
    assert ctl.bus_off
    return ctl


def test_bus_off_ends_by_itself_after_128_times_11_recessive_bits():
    ctl = _bus_off()
    due = ctl.recovery_due()
    assert due == pytest.approx(1.0 + 1408 / BITRATE)  # 2.816 ms at 500 kbit/s
    assert not ctl.poll(due - 1e-9) and ctl.bus_off
    assert ctl.poll(due)
    assert (ctl.state, ctl.tec, ctl.rec, ctl.head()) == (ErrorState.ACTIVE, 0, 0, "frame0")
    assert ctl.counts["recovered"] == 1


def test_bus_off_recovery_counts_its_recessive_bits_only_once_a_short_has_ended():
    ctl = CanController(BITRATE)
    ctl.submit("frame", 0x100)
    while not ctl.bus_off:
        ctl.attempt(Attempt.SHORT, 0.001)
    short_ends = 0.5  # the bus held dominant until then: not one recessive bit to count
    assert ctl.recovery_due(short_ends) == pytest.approx(short_ends + 128 * 11 / BITRATE)
    assert not ctl.poll(short_ends + 0.001, short_ends) and ctl.poll(short_ends + 0.003, short_ends)


def test_without_automatic_recovery_only_a_restart_ends_bus_off():
    ctl = _bus_off(auto_recovery=False)
    assert ctl.recovery_due() is None
    assert not ctl.poll(1e9) and ctl.bus_off
    ctl.restart(5.0)
    assert (ctl.state, ctl.tec, ctl.rec) == (ErrorState.ACTIVE, 0, 0)


# ------------------------------------------------------------------------------------------ the queue
def test_the_queue_holds_txqueuelen_frames_then_refuses():
    ctl = _filled(canbus.DEFAULT_TXQUEUELEN)
    assert ctl.full
    with pytest.raises(QueueFull, match="10 frames"):
        ctl.submit("one more", 0)
    ctl.attempt(Attempt.ACKED, 0.0)
    ctl.submit("one more", 0)


def test_fifo_keeps_the_send_order_and_priority_sends_the_lowest_id_first():
    fifo, prio = CanController(BITRATE), CanController(BITRATE, order="priority", txqueuelen=None)
    for ctl in (fifo, prio):
        for name, can_id in (("late", 0x300), ("urgent", 0x010), ("middle", 0x100), ("urgent2", 0x010)):
            ctl.submit(name, can_id)
    assert list(fifo) == ["late", "urgent", "middle", "urgent2"]
    assert list(prio) == ["urgent", "urgent2", "middle", "late"]
    assert [prio.attempt(Attempt.ACKED, 0.0) for _ in range(4)] == ["urgent", "urgent2", "middle", "late"]
    with pytest.raises(ValueError, match="fifo"):
        CanController(BITRATE, order="lifo")


def test_a_frame_on_the_bus_is_not_overtaken_by_one_of_a_higher_priority_queued_meanwhile():
    ctl = CanController(500_000, order="priority")
    ctl.submit("low", 0x300)
    assert ctl.begin() == "low"
    ctl.submit("high", 0x100)  # arrives while "low" is on the bus: it waits for the next arbitration
    assert ctl.head() == "low" and ctl.attempt(Attempt.ACKED, 0.001) == "low"
    assert ctl.head() == "high" and list(ctl) == ["high"]
    ctl.submit("low2", 0x300)
    ctl.begin()
    ctl.submit("higher", 0x050)
    assert ctl.attempt(Attempt.NO_ACK, 0.002) is None
    assert ctl.head() == "higher"  # a failed try arbitrates again: the higher priority goes first


def test_a_full_priority_queue_makes_room_for_a_higher_priority_by_its_lowest():
    ctl = CanController(BITRATE, order="priority", txqueuelen=3)
    for name, can_id in (("report1", 0x300), ("report2", 0x300), ("other", 0x200)):
        ctl.submit(name, can_id)
    assert ctl.evict_for(0x300) is None  # not below the lowest queued: the new frame is the one that does not fit
    assert ctl.evict_for(0x100) == "report2" and len(ctl) == 2  # the lowest priority, the latest of them
    ctl.submit("answer", 0x100)
    assert list(ctl) == ["answer", "other", "report1"]
    alone = CanController(BITRATE, order="priority", txqueuelen=1)
    alone.submit("low", 0x300)
    assert alone.begin() == "low" and alone.evict_for(0x100) is None  # never the frame on the bus
    assert CanController(BITRATE, txqueuelen=3).evict_for(0) is None  # a FIFO (SocketCAN's) refuses instead


def test_attempt_bits():
    assert canbus.attempt_bits(8, Attempt.ACKED) == 131  # frame_bits(8)
    assert canbus.attempt_bits(8, Attempt.NO_ACK) == 120 + 17
    assert canbus.attempt_bits(8, Attempt.NO_ACK, passive=True) == 120 + 17 + 8
    assert canbus.attempt_bits(0, Attempt.SHORT) == 18


# ------------------------------------------------------------------------------------------ error frames
def test_error_frames_of_the_state_changes():
    ctl = _filled()
    for _ in range(32):
        ctl.attempt(Attempt.ERROR, 2.0)
    frames = ctl.take_error_frames()
    assert [(f.can_id, f.data) for f in frames] == [
        (canbus.CAN_ERR_CRTL | canbus.CAN_ERR_CNT, bytes([0, canbus.CAN_ERR_CRTL_TX_WARNING, 0, 0, 0, 0, 96, 0])),
        (canbus.CAN_ERR_CRTL | canbus.CAN_ERR_CNT, bytes([0, canbus.CAN_ERR_CRTL_TX_PASSIVE, 0, 0, 0, 0, 128, 0])),
        (canbus.CAN_ERR_BUSOFF | canbus.CAN_ERR_CNT, bytes([0, 0, 0, 0, 0, 0, 255, 0])),
    ]
    assert all(len(f.data) == canbus.CAN_ERR_DLC and f.timestamp == 2.0 for f in frames)
    assert frames[0].raw_id == 0x20000204  # CAN_ERR_FLAG | CAN_ERR_CNT | CAN_ERR_CRTL
    assert ctl.take_error_frames() == []
    ctl.poll(10.0)
    [back] = ctl.take_error_frames()
    assert (back.can_id, back.data[1], back.data[6:]) == (canbus.CAN_ERR_CRTL | canbus.CAN_ERR_CNT,
                                                         canbus.CAN_ERR_CRTL_ACTIVE, b"\0\0")
    ctl.restart(11.0)
    [restarted] = ctl.take_error_frames()
    assert restarted.can_id == canbus.CAN_ERR_RESTARTED | canbus.CAN_ERR_CNT


def test_receive_side_changes_say_rx():
    ctl = CanController(BITRATE)
    for _ in range(16):
        ctl.received(0.0, ok=False, primary=True)
    assert [f.data[1] for f in ctl.take_error_frames()] == [canbus.CAN_ERR_CRTL_RX_WARNING, canbus.CAN_ERR_CRTL_RX_PASSIVE]


def test_bus_errors_are_reported_only_with_berr_reporting():
    quiet, loud = _filled(), _filled(berr_reporting=True)
    for ctl in (quiet, loud):
        ctl.attempt(Attempt.NO_ACK, 0.0)
        ctl.attempt(Attempt.SHORT, 0.0)
    assert quiet.take_error_frames() == []
    ack, short = loud.take_error_frames()
    prot = canbus.CAN_ERR_PROT | canbus.CAN_ERR_BUSERROR | canbus.CAN_ERR_CNT
    assert (ack.can_id, ack.data) == (prot | canbus.CAN_ERR_ACK,
                                      bytes([0, 0, canbus.CAN_ERR_PROT_TX, canbus.CAN_ERR_PROT_LOC_ACK, 0, 0, 8, 0]))
    assert (short.can_id, short.data) == (prot, bytes([0, 0, canbus.CAN_ERR_PROT_TX | canbus.CAN_ERR_PROT_BIT0,
                                                       canbus.CAN_ERR_PROT_LOC_SOF, 0, 0, 16, 0]))
