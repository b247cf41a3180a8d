"""The flight-controller player (sans-IO): its deadlines and its frames."""

from __future__ import annotations

import pytest

from ckesc.protocol import catalogue as cat
from ckesc.protocol.frame import decode
from ckesc.protocol.ids import Kind
from ckesc.soak.player import ESC_ID_PERIOD_S, MAINTENANCE_PERIOD_S, SETTINGS_PERIOD_S, FlightPlan, Player

HOST, NODE = 0, 5


def play(player: Player, until: float) -> list:
    """Everything the player sends until ``until``, each at its deadline, as a driver would."""
    out = []
    while (t := player.next_deadline()) <= until:
        out += [(t, p) for p in player.due(t)]
    return out


def test_the_stream_keeps_its_rate_and_its_transfer_ids_count():
    player = Player(FlightPlan(HOST, NODE, rate_hz=400), start=10.0)
    sent = play(player, 10.0 + 1.0)
    stream = [(t, p) for t, p in sent if p.what == "stream"]
    assert len(stream) == 401  # 0 s .. 1 s inclusive at 400 Hz
    assert all(t == p.due for t, p in stream)
    assert [round(p.due - 10.0, 9) for _, p in stream[:3]] == [0.0, 0.0025, 0.005]
    frames = [decode(p.wire) for _, p in stream]
    assert {f.name for f in frames} == {"raw_command_14b"} and all(f.source == HOST for f in frames)
    assert [f.transfer_id for f in frames[:34]] == [i % 32 for i in range(34)]  # F3: +1 modulo 32
    assert all(f.fields["channels"] == [0, 0, 0, 0] for f in frames)  # zero throttle: no motor spin allowed


def test_the_reads_come_at_their_periods_from_the_host_to_the_dut():
    player = Player(FlightPlan(HOST, NODE, rate_hz=50), start=0.0)
    sent = play(player, 2 * SETTINGS_PERIOD_S)
    by = {what: [p for _, p in sent if p.what == what] for what in ("get_esc_id", "maintenance", "settings")}
    assert [p.due for p in by["get_esc_id"][:3]] == [0.0, ESC_ID_PERIOD_S, 2 * ESC_ID_PERIOD_S]
    q = decode(by["get_esc_id"][0].wire)
    assert q.name == "get_esc_id" and q.kind is Kind.MESSAGE and q.layout.name == "query" and q.source == HOST
    m = [decode(p.wire) for p in by["maintenance"]]
    assert all(f.name == "maintenance_information" and f.kind is Kind.REQUEST and f.destination == NODE for f in m)
    assert [f.fields["option"] for f in m[:4]] == [1, 2, 1, 2]  # run time, power-up count, in turn
    assert len(m) == pytest.approx(2 * SETTINGS_PERIOD_S / MAINTENANCE_PERIOD_S * 2, abs=1)
    s = [decode(p.wire) for p in by["settings"]]
    assert len(s) == 2 and all(f.name == "get_major_configuration" and f.destination == NODE for f in s)


def test_a_late_driver_gets_one_stream_frame_and_the_missed_ones_are_skipped_not_burst():
    player = Player(FlightPlan(HOST, NODE, rate_hz=100), start=0.0)
    player.due(0.0)
    late = [p for p in player.due(0.105) if p.what == "stream"]  # the host was away for 10.5 periods
    assert len(late) == 1 and late[0].due == pytest.approx(0.01)
    assert player.skipped == 9
    assert player.next_deadline() == pytest.approx(0.11)


@pytest.mark.parametrize("fmt, channels, frames", [("14b", (1, 2, 3, 4), 1), ("10b", (1, 6), 1), ("12b", (1, 5, 9), 3)])
def test_the_formats_and_channels(fmt, channels, frames):
    plan = FlightPlan(HOST, NODE, format=fmt, rate_hz=50, channels=channels, allow_motor_spin=True,
                      throttle=((0.0, 100), (1.0, 0)))
    player = Player(plan, start=0.0)
    first = [decode(p.wire) for p in player.due(0.0) if p.what == "stream"]
    assert len(first) == frames == player.frames_per_tick and first[0].name == f"raw_command_{fmt}"
    values = [v for f in first for v in f.fields["channels"]]
    assert values.count(100) == len(channels)  # the profile's throttle on the channels asked, zero elsewhere
    after = [p for t, p in play(player, 1.5) if p.what == "stream" and p.due >= 1.0]
    assert all(v == 0 for p in after for v in decode(p.wire).fields["channels"])
    assert all(v == 0 for w in player.zero() for v in decode(w).fields["channels"])


def test_a_throttle_without_motor_spin_or_out_of_range_is_refused():
    with pytest.raises(ValueError, match="allow_motor_spin"):
        Player(FlightPlan(HOST, NODE, throttle=((0.0, 100),)), 0.0)
    with pytest.raises(ValueError, match="50-500 Hz"):
        Player(FlightPlan(HOST, NODE, rate_hz=1000), 0.0)
    with pytest.raises(ValueError, match="channels 1..4"):
        Player(FlightPlan(HOST, NODE, channels=(5,)), 0.0)
    assert FlightPlan(HOST, NODE, throttle=((0.0, cat.THROTTLE_MAX),)).throttle_at(1.0) == 0  # no spin: zero
