"""The real-time hub's bus faults, sans-IO (ckesc/emulator/hub_can.py; R20, issue #36): an emulated ESC's frames
through its controller while the bus is shorted or garbled by a node at another bit rate, driven here in steps of
simulated time as the real-time emulator's loop drives it in real time. Exact: every figure is bit times at 500
kbit/s."""

from __future__ import annotations

import pytest

from ckesc.emulator.config import EscConfig
from ckesc.emulator.hub_can import FOREIGN_FRAME_S, FOREIGN_PERIOD_S, INF, Disturbance, HubCan
from ckesc.emulator.model import EscModel
from ckesc.emulator.sim_can import ESC_TX_MAILBOXES
from ckesc.protocol.canbus import recovery_seconds
from ckesc.protocol.catalogue import DEFAULT_BITRATE
from ckesc.protocol.frame import frame_bits

STEP_S = 0.0002  # the loop's wake-ups
RECOVERY_S = recovery_seconds(DEFAULT_BITRATE)


def _esc(*faults: str) -> EscModel:
    esc = EscModel(EscConfig(node_id=1, boot_time=0.05, faults=frozenset(faults)))
    esc.power_on(0.0)
    return esc


def _drive(hub: HubCan, esc: EscModel, t0: float, t1: float) -> list:
    """The frames on the bus from ``t0`` to ``t1``, as the emulator's loop puts them there (its _emit_due and
    _can_poll): the ESC's due frames through the hub while it is not quiet, the hub's own work at each wake."""
    out, t = [], t0
    while t < t1:
        frames = esc.poll(t)
        if frames and not hub.quiet:
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
    hub, esc = HubCan(DEFAULT_BITRATE), _esc()
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
    hub, esc = HubCan(DEFAULT_BITRATE), _esc()
    _drive(hub, esc, 0.0, 0.3)
    hub.start("short", 0.3, 1.0)
    _drive(hub, esc, 0.3, 1.3)
    assert hub.state(esc)["queued"] == ESC_TX_MAILBOXES and hub.counters["esc_dropped"] > 0


def test_bus_off_comes_after_32_tries():
    """16 error-active tries of 18 bits (start of frame, error flag and delimiter, intermission), then 16
    error-passive ones with 8 bits of suspend transmission: TEC 256 after 704 bit times."""
    hub, esc = HubCan(DEFAULT_BITRATE), _esc()
    _drive(hub, esc, 0.0, 0.3)
    hub.start("short", 0.3, 0.5)
    _drive(hub, esc, 0.3, 0.35)
    ctl = hub._ctl[esc]
    first_due = 0.3  # the ESC reports every 10 ms: it has a frame due within the first step of the short
    assert ctl.tec == 256 and ctl.bus_off_at - first_due <= 704 / DEFAULT_BITRATE + 0.01


def test_without_automatic_recovery_the_esc_is_silent_until_a_power_cycle():
    hub, esc = HubCan(DEFAULT_BITRATE), _esc("no_busoff_recovery")
    _drive(hub, esc, 0.0, 0.3)
    hub.start("short", 0.3, 0.2)
    assert _drive(hub, esc, 0.3, 1.0) == []
    assert hub.listens_from(esc) is None and not hub.settled()
    esc.power_off(1.0)
    hub.forget(esc)
    esc.power_on(1.0)
    assert _drive(hub, esc, 1.0, 1.2) and hub.quiet


def test_a_recovery_that_resets_reboots_the_esc_at_its_recovery():
    hub, esc = HubCan(DEFAULT_BITRATE), _esc("busoff_recovery_resets")
    _drive(hub, esc, 0.0, 0.3)
    hub.start("short", 0.3, 0.2)
    _drive(hub, esc, 0.3, 0.6)
    assert esc.nvm["power_ups"] == 2 and esc.state.powered_at == pytest.approx(0.5 + RECOVERY_S)
    assert hub.quiet


def test_a_node_at_another_bit_rate_keeps_the_esc_bus_off_until_it_stops():
    """Its frames leave gaps of 0.5 ms, shorter than the 2.816 ms of recessive bits recovery needs."""
    hub, esc = HubCan(DEFAULT_BITRATE), _esc()
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
    hub, esc = HubCan(DEFAULT_BITRATE), _esc()
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
    hub, esc = HubCan(DEFAULT_BITRATE), _esc()
    start = 0.3 + phase * 0.00005
    _drive(hub, esc, 0.0, start)
    hub.start("other_bitrate", start, 0.5)
    _drive(hub, esc, start, start + 0.5)
    assert hub.counters["esc_bus_off"] == 1
