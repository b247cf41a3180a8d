"""The real-time hub's bus faults, sans-IO (ckesc/emulator/hub_can.py; R20, issue #36): an emulated ESC's frames
through its controller while the bus is shorted or garbled by a node at another bit rate, driven here in steps of
simulated time as the real-time emulator's loop drives it in real time. Exact: every figure is bit times at 500
kbit/s."""

from __future__ import annotations

import pytest

from ckesc.emulator.config import EscConfig
from ckesc.emulator.hub_can import FOREIGN_FRAME_S, FOREIGN_PERIOD_S, HOST_RESTART_S, INF, Disturbance, HubCan
from ckesc.emulator.model import EscModel
from ckesc.emulator.sim_can import ESC_TX_MAILBOXES
from ckesc.protocol.canbus import recovery_seconds
from ckesc.protocol.catalogue import DEFAULT_BITRATE
from ckesc.protocol.frame import frame_bits

STEP_S = 0.0002  # the loop's wake-ups
RECOVERY_S = recovery_seconds(DEFAULT_BITRATE)
CODE_1M = 0  # Set Baud code of 1 Mbit/s (4.4.19-T)


def _esc(*faults: str) -> EscModel:
    esc = EscModel(EscConfig(node_id=1, boot_time=0.05, faults=frozenset(faults)))
    esc.power_on(0.0)
    return esc


def _hub() -> HubCan:
    """The hub with the host's adapter listening at its rate all along."""
    hub = HubCan(DEFAULT_BITRATE)
    hub.host_listens("host", -INF)
    return hub


def _drive(hub: HubCan, esc: EscModel, t0: float, t1: float) -> list:
    """The frames on the bus from ``t0`` to ``t1``, as the emulator's loop puts them there (its _emit_due and
    _can_poll): the ESC's due frames through the hub, the hub's own work at each wake while it is not quiet."""
    out, t = [], t0
    while t < t1:
        frames = esc.poll(t)
        if frames:
            frames = hub.send(esc, frames, t)
        out += frames
        if not hub.quiet:
            sent, rebooted = hub.poll(t)
            out += [w for _, w in sent]
            for e, at in rebooted:
                e.power_off(at)
                e.power_on(at)
        t = round(t + STEP_S, 9)
    return out


def test_a_short_sends_the_reporting_esc_bus_off_and_it_recovers_once_the_bus_is_free():
    hub, esc = _hub(), _esc()
    before = _drive(hub, esc, 0.0, 0.3)
    assert before and hub.quiet  # no fault: every frame at once, no controller kept
    fault = hub.start("short", 0.3, 0.5)
    during = _drive(hub, esc, 0.3, 0.8)
    assert during == [] and hub.counters["esc_bus_off"] == 1
    assert hub.state(esc)["state"] == "BUS-OFF"
    assert hub.listens_from(esc) == pytest.approx(fault.end + RECOVERY_S)
    after = _drive(hub, esc, 0.8, 1.0)
    # back 128 x 11 bits after the bus was freed, the frames it held first, back to back, lowest id first
    assert after[0].timestamp == pytest.approx(0.8 + RECOVERY_S, abs=1e-9)
    assert all(b.timestamp >= a.timestamp for a, b in zip(after, after[1:]))
    back_to_back = next(i for i, (a, b) in enumerate(zip(after, after[1:]), 1)
                        if b.timestamp > a.timestamp + frame_bits(len(a.data)) / DEFAULT_BITRATE + 1e-9)
    # its mailboxes held the reports of the 0.5 s it could not send (31 of them: 25 MSG1, 4 MSG2, 2 MSG3), the MSG1s
    # first; a new MSG1 wins the arbitration over the last of them
    assert back_to_back == 29 and hub.counters["esc_dropped"] == 0
    assert hub.quiet and hub.counters["esc_recovered"] == 1  # settled: delivered at once again
    assert esc.nvm["power_ups"] == 1


def test_what_does_not_fit_its_mailboxes_is_dropped():
    hub, esc = _hub(), _esc()
    _drive(hub, esc, 0.0, 0.3)
    hub.start("short", 0.3, 1.0)
    _drive(hub, esc, 0.3, 1.3)
    assert hub.state(esc)["queued"] == ESC_TX_MAILBOXES and hub.counters["esc_dropped"] > 0


def test_bus_off_comes_after_32_tries():
    """16 error-active tries of 18 bits (start of frame, error flag and delimiter, intermission), then 16
    error-passive ones with 8 bits of suspend transmission: TEC 256 after 704 bit times."""
    hub, esc = _hub(), _esc()
    _drive(hub, esc, 0.0, 0.3)
    hub.start("short", 0.3, 0.5)
    _drive(hub, esc, 0.3, 0.35)
    ctl = hub._ctl[esc]
    first_due = 0.3  # the ESC reports every 10 ms: it has a frame due within the first step of the short
    assert ctl.tec == 256 and ctl.bus_off_at - first_due <= 704 / DEFAULT_BITRATE + 0.01


def test_without_automatic_recovery_the_esc_is_silent_until_a_power_cycle():
    hub, esc = _hub(), _esc("no_busoff_recovery")
    _drive(hub, esc, 0.0, 0.3)
    hub.start("short", 0.3, 0.2)
    assert _drive(hub, esc, 0.3, 1.0) == []
    assert hub.listens_from(esc) is None and not hub.settled()
    esc.power_off(1.0)
    hub.forget(esc)
    esc.power_on(1.0)
    assert _drive(hub, esc, 1.0, 1.2) and hub.quiet


def test_a_recovery_that_resets_reboots_the_esc_at_its_recovery():
    hub, esc = _hub(), _esc("busoff_recovery_resets")
    _drive(hub, esc, 0.0, 0.3)
    hub.start("short", 0.3, 0.2)
    _drive(hub, esc, 0.3, 0.6)
    assert esc.nvm["power_ups"] == 2 and esc.state.powered_at == pytest.approx(0.5 + RECOVERY_S)
    assert hub.quiet


def test_a_node_at_another_bit_rate_keeps_the_esc_bus_off_until_it_stops():
    """Its frames leave gaps of 0.5 ms, shorter than the 2.816 ms of recessive bits recovery needs."""
    hub, esc = _hub(), _esc()
    _drive(hub, esc, 0.0, 0.3)
    hub.start("other_bitrate", 0.3, 0.5)
    during = _drive(hub, esc, 0.3, 0.8)
    assert hub.counters["esc_bus_off"] == 1
    # before bus-off some tries fall in the gaps between its frames and are sent (each try's errors cost 8, each
    # frame sent gives 1 back)
    assert during and all(w.timestamp < hub._ctl[esc].bus_off_at for w in during)
    after = _drive(hub, esc, 0.8, 1.0)
    assert after[0].timestamp == pytest.approx(0.8 + RECOVERY_S, abs=1e-9)


def test_a_relay_fault_lasts_until_it_is_ended():
    hub, esc = _hub(), _esc()
    _drive(hub, esc, 0.0, 0.3)
    hub.start("short", 0.3)
    with pytest.raises(ValueError, match="is on until ended"):
        hub.start("short", 0.4, 0.1)
    assert _drive(hub, esc, 0.3, 0.7) == [] and hub.listens_from(esc) is None and hub.next_deadline() is None
    hub.stop(0.7)
    after = _drive(hub, esc, 0.7, 0.8)
    assert after[0].timestamp == pytest.approx(0.7 + RECOVERY_S, abs=1e-9)


def test_where_the_bus_is_free():
    short = Disturbance.of("short", 1.0, 0.5)
    assert short.dominant_until(1.2) == 1.5 and short.dominant_until(1.5) is None and short.next_dominant(0.5) == 1.0
    assert short.quiet_from(1.1, RECOVERY_S) == 1.5
    babble = Disturbance.of("other_bitrate", 1.0, 0.5)
    assert babble.dominant_until(1.0002) == pytest.approx(1.0 + FOREIGN_FRAME_S)
    assert babble.dominant_until(1.0007) is None
    assert babble.next_dominant(1.0007) == pytest.approx(1.0 + FOREIGN_PERIOD_S)
    assert babble.quiet_from(1.0002, RECOVERY_S) == 1.5  # its gaps are too short for a recovery
    relay = Disturbance.of("short", 1.0, None)
    assert relay.end == INF and relay.dominant_until(100.0) == INF
    with pytest.raises(ValueError, match="one of short, other_bitrate"):
        Disturbance.of("babble", 0.0, 1.0)


@pytest.mark.parametrize("phase", range(20))
def test_a_node_at_another_bit_rate_sends_a_reporting_esc_bus_off_at_every_phase(phase):
    """Its frames on a clock of its own: an ESC's whole-millisecond report grid meets them at every phase (at exactly
    1 ms, 7 of these 20 starting phases left the ESC's reports in the gaps, never bus-off)."""
    hub, esc = _hub(), _esc()
    start = 0.3 + phase * 0.00005
    _drive(hub, esc, 0.0, start)
    hub.start("other_bitrate", start, 0.5)
    _drive(hub, esc, start, start + 0.5)
    assert hub.counters["esc_bus_off"] == 1


# ---------------------------------------------------------------------- acknowledgement: nobody listens


def _back_to_back(frames: list, bitrate: int = DEFAULT_BITRATE) -> int:
    """How many of ``frames`` from the first go each at the end of the one before (a queue sent at once)."""
    n = 1
    for a, b in zip(frames, frames[1:]):
        if b.timestamp != pytest.approx(a.timestamp + frame_bits(len(a.data)) / bitrate, abs=1e-9):
            break
        n += 1
    return n


def test_an_esc_alone_holds_its_frames_until_the_host_listens_then_sends_them_back_to_back():
    """Nobody acknowledges: 16 error-active tries of its first report (TEC 8 each), then error-passive, where the ACK
    exception keeps it (parked, no deadline); the host's handle opens at 0.5 s and the queue goes from the next
    retransmission on, back to back, lowest id first; then every frame at once again."""
    hub, esc = HubCan(DEFAULT_BITRATE), _esc()
    assert _drive(hub, esc, 0.0, 0.5) == []
    state = hub.state(esc)
    assert state["state"] == "ERROR-PASSIVE" and state["tec"] == 128 and state["no_ack"] and state["queued"] > 20
    assert hub.counters["esc_no_ack"] == 16 and hub.next_deadline() is None and not hub.quiet
    held = state["queued"]
    hub.host_listens("host", 0.5)
    after = _drive(hub, esc, 0.5, 0.8)
    assert 0.5 <= after[0].timestamp < 0.5 + 137 / DEFAULT_BITRATE  # its next retransmission: an error-passive try
    assert _back_to_back(after) >= held
    ids = [w.arbitration_id for w in after[:held]]
    assert ids == sorted(ids)  # its mailboxes, lowest id first
    assert not hub.quiet and hub.state(esc)["tec"] == 128 - len(after)  # each frame sent takes 1 off
    _drive(hub, esc, 0.8, 3.0)
    assert hub.quiet  # TEC back to 0 after 128 frames sent: at once again
    assert esc.nvm["power_ups"] == 1  # no reset: a controller's way, not the firmware's


def test_a_host_that_closes_its_handle_meets_what_the_esc_held_when_it_reopens():
    hub, esc = _hub(), _esc()
    before = _drive(hub, esc, 0.0, 0.3)
    assert before and hub.quiet
    hub.host_gone("host")  # Set Baud's reopen: the host's bus closed
    assert _drive(hub, esc, 0.3, 0.6) == []
    held = hub.state(esc)["queued"]
    hub.host_listens("host", 0.6)
    after = _drive(hub, esc, 0.6, 0.7)
    assert after[0].timestamp < 0.6 + 137 / DEFAULT_BITRATE and _back_to_back(after) >= held > 10


def test_an_esc_at_another_bit_rate_holds_until_the_host_moves_to_it():
    """After Set Baud and a power cycle the ESC runs at 1 Mbit/s, the host at 500 kbit/s: nobody takes its frames
    until the host moves; then they go back to back at the ESC's rate."""
    hub, esc = _hub(), EscModel(EscConfig(node_id=1, boot_time=0.05, baud_code=CODE_1M))
    esc.power_on(0.0)
    assert _drive(hub, esc, 0.0, 0.3) == [] and hub.state(esc)["no_ack"]
    held = hub.state(esc)["queued"]
    hub.set_bitrate(1_000_000, 0.3)
    after = _drive(hub, esc, 0.3, 0.4)
    assert after[0].timestamp >= 0.3 and _back_to_back(after, 1_000_000) >= held > 10


def test_another_esc_that_boots_acknowledges_and_the_other_bitrate_node_never_does():
    first, second = _esc(), EscModel(EscConfig(node_id=2, boot_time=0.4))
    hub = HubCan(DEFAULT_BITRATE, [first, second])
    second.power_on(0.0)
    hub.start("other_bitrate", 0.2, 0.01)  # a node at another bit rate: it garbles, it acknowledges nothing
    assert _drive(hub, first, 0.0, 0.4) == []
    held = hub.state(first)["queued"]
    after = _drive(hub, first, 0.4, 0.5)
    assert 0.4 <= after[0].timestamp and _back_to_back(after) >= held > 10  # the second ESC up at 0.4 s: it listens


def test_what_waits_for_a_listener_is_bounded_by_its_mailboxes():
    hub, esc = HubCan(DEFAULT_BITRATE), _esc()
    _drive(hub, esc, 0.0, 2.0)
    assert hub.state(esc)["queued"] == ESC_TX_MAILBOXES and hub.counters["esc_dropped"] > 0
    assert hub.settled()  # nothing to wait for but a listener: not a fault's work


# ---------------------------------------------------------------------- the host's adapter in a fault


def test_the_hosts_adapter_goes_bus_off_in_a_short_and_is_restarted_after_restart_ms():
    """A host frame held in a short: its adapter tries it, error-passive after 16 bit errors, bus-off after 32 (704
    bit times); SocketCAN's driver restarts it after restart-ms and it goes bus-off again while the short lasts; after
    the short its restart stays: each as the error frame SocketCAN reports (the class python-can reads)."""
    hub = _hub()
    hub.start("short", 0.0, 0.15)
    hub.host_waiting("conn", 0.01, 8)
    frames = []
    t = 0.0
    while t < 0.4:
        frames += [(round(f.timestamp, 6), f.can_id) for _, f in hub.host_poll(t)]
        t = round(t + STEP_S, 9)
    crtl, off = 0x204, 0x240  # CAN_ERR_CRTL | CAN_ERR_CNT (its data: warning, passive), CAN_ERR_BUSOFF | CAN_ERR_CNT
    restarted = 0x300  # CAN_ERR_RESTARTED | CAN_ERR_CNT
    assert [c for _, c in frames] == [crtl, crtl, off, restarted] * 2
    assert frames[2][0] == pytest.approx(0.01 + 704 / DEFAULT_BITRATE)
    assert frames[3][0] == pytest.approx(frames[2][0] + HOST_RESTART_S)  # still shorted: tried again, bus-off again
    assert frames[7][0] == pytest.approx(frames[6][0] + HOST_RESTART_S) and frames[7][0] > 0.15
    assert hub.host_restart_due() is None and not hub.host_bus_off()
    hub.host_sent("conn", 0.4)
    hub.poll(0.4)
    assert hub.quiet  # its frame sent, the short over: nothing left of either


def test_without_restart_ms_the_hosts_adapter_stays_bus_off():
    hub = HubCan(DEFAULT_BITRATE, host_restart_s=None)
    hub.start("short", 0.0, 0.01)
    hub.host_waiting("conn", 0.0, 8)
    assert [f.can_id for _, f in hub.host_poll(0.5)] == [0x204, 0x204, 0x240] and hub.host_bus_off()


def test_a_host_frame_heard_while_the_held_queue_goes_waits_for_the_frame_on_the_bus():
    """One wire: the host's frame does not overlap the ESC frame in flight; it goes at its end, and the ESC's next
    frame after the host's (so the stamps a host reads stay in bus order, a busy stretch without a hole)."""
    hub, esc = HubCan(DEFAULT_BITRATE), _esc()
    _drive(hub, esc, 0.0, 0.3)
    hub.host_listens("host", 0.3)
    slot = hub.next_deadline()  # its next retransmission: acknowledged now
    (_, w), = hub.poll(slot)[0]  # the first held frame, on the bus from then
    in_flight_end = w.timestamp + frame_bits(len(w.data)) / DEFAULT_BITRATE
    end = hub.place_host(slot, 2)
    assert end == pytest.approx(in_flight_end + frame_bits(2) / DEFAULT_BITRATE)
    nxt = hub.poll(0.31)[0]
    assert nxt[0][1].timestamp == pytest.approx(end)
    assert hub.place_host(5.0, 2) == 5.0  # the bus free: where it was heard
