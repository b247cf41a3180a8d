"""The load generator (ckesc.protocol.load, R18): its share, burst bound, ids and priorities, and the load it
reaches on the simulated bus, where its frames contend by arbitration with the ESC's."""

import can
import pytest

from ckesc.emulator import sim_bus
from ckesc.protocol import catalogue as cat
from ckesc.protocol.errors import UnknownTypeError
from ckesc.protocol.frame import decode, frame_bits
from ckesc.protocol.ids import Priority, message_id, parse_can_id, service_id
from ckesc.protocol.judgements import R18_BURST_FRAMES, r18_gap, r18_judged, r18_mean, r18_queueing_s, r18_tells
from ckesc.protocol.load import PRIORITIES, LoadSource, takes
from ckesc.protocol.traffic import TrafficSource, bus_load

RATE = 500000


def _frames(src, seconds):
    return src.take_due(seconds)


@pytest.mark.parametrize("priority", PRIORITIES)
def test_the_share_is_reached_and_no_window_holds_more_than_the_share_and_the_burst(priority):
    src = LoadSource(0.3, RATE, priority=priority, seed=7, exclude_nodes=[1])
    assert isinstance(src, TrafficSource)
    frames = _frames(src, 2.0)
    assert bus_load(frames, 2.0, RATE) == pytest.approx(0.3, rel=0.01)
    assert [f.timestamp for f in frames] == sorted(f.timestamp for f in frames)
    # the arrival bound r18_queueing_s assumes: over any window t, at most share x t + R18_BURST_FRAMES longest frames
    burst = R18_BURST_FRAMES * frame_bits(8)
    bits = [frame_bits(len(f.data)) for f in frames]
    worst = 0.0
    for i, first in enumerate(frames[:1000]):
        total = 0
        for f, b in zip(frames[i:i + 200], bits[i:i + 200]):  # windows up to 200 frames long
            total += b
            worst = max(worst, total - 0.3 * RATE * (f.timestamp - first.timestamp))
    assert 0 < worst <= burst
    # some randomness in the spacing: the gaps between bursts are not all alike
    gaps = {round(b.timestamp - a.timestamp, 6) for a, b in zip(frames, frames[1:]) if b.timestamp > a.timestamp}
    assert len(gaps) > 100


def test_a_seed_gives_the_same_load_and_another_seed_another():
    a, b, c = (LoadSource(0.5, RATE, seed=s).take_due(0.5) for s in (1, 1, 2))
    assert a == b and a != c


def test_no_load_frame_is_one_the_esc_takes_and_none_comes_from_a_node_excluded():
    frames = LoadSource(0.5, RATE, priority="mixed", seed=3, exclude_nodes=range(1, 40)).take_due(2.0)
    assert not any(takes(f) for f in frames)
    ids = [parse_can_id(f.arbitration_id) for f in frames]
    assert all(i.source >= 40 and i.source not in (0x7E, 0x7F) for i in ids)
    for f in frames[:200]:  # no catalogue type, whatever the node: the decoder calls each foreign
        with pytest.raises(UnknownTypeError):
            decode(f)
    # each a single-frame transfer, each node's transfer id counting
    assert all(f.data[-1] & 0xC0 == 0xC0 for f in frames)


def test_high_load_beats_every_report_and_loses_to_the_answers_low_load_loses_to_everything_the_esc_sends():
    reports = [message_id(Priority.LOWEST, cat.spec(n).type_id, 1) for n in cat.ESC_REPORT_FRAMES]
    answer = message_id(Priority.MEDIUM, cat.spec("get_esc_id").type_id, 1)
    services = [service_id(Priority.LOWEST, t, False, 0x7F, 0x7F) for t in cat.SERVICES]
    high = LoadSource(0.5, RATE, priority="high", seed=4).take_due(1.0)
    low = LoadSource(0.5, RATE, priority="low", seed=4).take_due(1.0)
    assert all(answer < f.arbitration_id < min(reports) for f in high)
    assert all(f.arbitration_id > max(reports + services) for f in low)
    mixed = LoadSource(0.5, RATE, priority="mixed", seed=4).take_due(1.0)
    assert {f.arbitration_id < min(reports) for f in mixed} == {True, False}


def test_the_queueing_bound_grows_with_the_share_and_the_players_lateness():
    longest = frame_bits(8) / RATE
    assert r18_queueing_s(0.5, RATE) == pytest.approx(2 * (1 + R18_BURST_FRAMES) * longest)
    assert r18_queueing_s(0.1, RATE) < r18_queueing_s(0.3, RATE) < r18_queueing_s(0.5, RATE)
    assert r18_queueing_s(0.5, RATE, late=0.01) == pytest.approx(r18_queueing_s(0.5, RATE) + 0.01)


@pytest.mark.parametrize("share", [0.1, 0.5, 0.7])
def test_on_the_simulated_bus_the_load_reaches_its_share_and_delays_the_reports_no_more_than_the_bound(share):
    channel = f"load-test-{share}"
    bus = can.Bus(interface="ckesc-sim", channel=channel, nodes=[1], receive_own_messages=False)
    try:
        world = sim_bus.world(channel)
        bus.advance(0.5)
        world.add_source(LoadSource(share, RATE, priority="high", seed=5, exclude_nodes=[1]))
        starts = []
        t0 = bus.now()
        while bus.now() < t0 + 1.0:
            m = bus.recv(0.1)
            if m is not None and m.arbitration_id == message_id(Priority.LOWEST, cat.spec("msg3").type_id, 1):
                starts.append(m.timestamp - frame_bits(len(m.data)) / RATE)
        st = world.source_stats["load"]
        assert st["busy_s"] / 1.0 == pytest.approx(share, rel=0.02)
        # MSG3 (the lowest of the three reports due together at 500 ms) is late by no more than the bound + the two
        # reports ahead of it (MSG1, MSG2) stretched by the load
        due = [round(s / 0.5) * 0.5 for s in starts]
        worst = max(s - d for s, d in zip(starts, due))
        if share <= 0.5:
            assert worst <= r18_queueing_s(share, RATE) + 2 * frame_bits(8) / RATE / (1 - share)
    finally:
        bus.shutdown()
        sim_bus.discard(channel)


def test_r18_passes_a_report_the_load_delayed_and_fails_one_missing_or_off_its_interval():
    w = r18_queueing_s(0.5, RATE)
    grid = [i * 0.02 for i in range(12)]
    delayed = [t + (w if i in (0, 5) else 0.0) for i, t in enumerate(grid)]
    assert r18_mean(delayed, 0.02, share=0.5, bitrate=RATE).ok
    assert all(r18_gap(b - a, 0.02, share=0.5, bitrate=RATE).ok for a, b in zip(delayed, delayed[1:]))
    missing = grid[:5] + grid[6:]
    assert not r18_mean(missing, 0.02, share=0.5, bitrate=RATE).ok
    assert not r18_gap(0.04, 0.02, share=0.5, bitrate=RATE).ok
    slow = [i * 0.022 for i in range(12)]  # every 22 ms instead of 20: no load excuses it
    assert not r18_mean(slow, 0.02, share=0.5, bitrate=RATE).ok
    assert r18_judged(0.5) and not r18_judged(0.7)
    assert r18_tells(0.02, 0.5, RATE) and not r18_tells(0.02, 0.5, RATE, late=0.1)
