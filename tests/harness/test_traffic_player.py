"""The real-time traffic player: a source's frames go out on a real python-can bus (the in-process
``virtual`` interface), in order, each once, and the player reports what it reached."""

import can

from ckesc.bench.traffic_player import TrafficPlayer
from ckesc.protocol.frame import WireFrame
from ckesc.protocol.traffic import PeriodicFrames


def test_the_player_sends_every_due_frame_once_in_order_and_measures_its_load():
    with can.Bus(interface="virtual", channel="player-test") as tx, can.Bus(interface="virtual", channel="player-test") as rx:
        src = PeriodicFrames("seq", [WireFrame(0x1000 + i, bytes([i])) for i in range(10)], period=0.005, until=0.05)
        with TrafficPlayer(tx.send, [src], bitrate=500000) as player:
            got = [rx.recv(2.0) for _ in range(10)]
        stats = player.stats
    assert [m.arbitration_id - 0x1000 for m in got] == list(range(10))
    assert stats.frames == 10 and stats.send_errors == 0
    assert stats.bits == 10 * 75
    assert 0 < stats.load < 10 * 75 / 500000 / 0.045
    assert stats.late_max_s >= 0.0


def test_stop_returns_at_once_when_the_next_frame_is_far_off():
    with can.Bus(interface="virtual", channel="player-test-2") as tx:
        src = PeriodicFrames("slow", [WireFrame(1, b"")], period=3600.0)
        player = TrafficPlayer(tx.send, [src], bitrate=500000).start()
        stats = player.stop()
    assert stats.frames == 1
    assert not player._thread.is_alive()
