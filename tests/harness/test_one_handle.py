"""The bench's own frames on one handle of the adapter (issue #35, item 4): what the bench plays (a flight
controller's traffic, a load) goes out on the host's handle and is read back by the lane like every other frame,
by its echo or, without one, as the lane's copy; no second ``can.Bus`` is opened on the DUT's channel.

Most USB adapters' handles do not hear each other's frames, and some allow one handle only; SocketCAN's loopback,
socketcand and python-can's ``virtual`` bus hide both. ``ckesc emulate --handles separate|one`` plays such an
adapter: the clients that open one name are handles of one adapter (``separate``: they do not hear each other;
``one``: a second is refused). On those benches the old player (a bus of its own) FAILed a faultless ESC's
robustness section ("the ESC sent get_esc_id message": its replies to a flight controller's queries the host never
heard), ERRORed it where a second handle is refused, and a soak found "a GET_ESC_ID reply that answers no query"
once a second.

Every part is a real process or a real python-can bus: the hub through python-can's stock socketcand client, and
``ckesc run`` / ``ckesc soak`` as a user runs them.
"""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import can
import pytest
from procs import CKESC, Emulator, realtime_profile
from procs import env as _env

from ckesc.bench.dut import echo_probe
from ckesc.bench.lanes import BusLane, OwnFrame
from ckesc.bench.power import NoPower
from ckesc.bench.profile import DEFAULT_BUS_ERROR_S
from ckesc.bench.traffic_player import TrafficPlayer
from ckesc.protocol.frame import WireFrame
from ckesc.protocol.traffic import PeriodicFrames

pytestmark = pytest.mark.realtime  # real processes on the wall clock: one at a time under xdist (tests/conftest.py)

#: how long a test reads for a frame a hub forwards at once (a loaded machine may hold it back for a while)
HEAR_S = 1.0


def _client(port: int, channel: str = "can0", **kwargs) -> can.BusABC:
    return can.Bus(interface="socketcand", host="127.0.0.1", port=port, channel=channel, tcp_tune=True,
                   ignore_config=True, **kwargs)


def _heard(bus: can.BusABC, can_id: int, seconds: float = HEAR_S) -> bool:
    """Whether ``bus`` receives a frame with ``can_id`` within ``seconds`` (the hub's other traffic read past)."""
    import time

    end = time.monotonic() + seconds
    while (left := end - time.monotonic()) > 0:
        msg = bus.recv(left)
        if msg is not None and msg.arbitration_id == can_id and not msg.is_error_frame:
            return True
    return False


def _open_all(port: int, *channels: str) -> list[can.BusABC]:
    buses = [_client(port, ch) for ch in channels]
    for bus in buses:  # the hub forwards nothing to a client for 50 ms after its rawmode, unless it sends first
        bus.send(can.Message(arbitration_id=0x1FFFFF00, data=b"", is_extended_id=True))
    return buses


def test_separate_handles_do_not_hear_each_other_and_another_node_hears_them_all(tmp_path):
    with Emulator(tmp_path, "--nodes", "none", "--handles", "separate", "--no-echo-own") as emu:
        a, b, esc = _open_all(emu.port, "can0", "can0", "esc")
        try:
            a.send(can.Message(arbitration_id=0x1000_0A0A, data=b"\x01", is_extended_id=True))
            assert _heard(esc, 0x1000_0A0A), "another node (another name) hears a handle's frame"
            assert not _heard(b, 0x1000_0A0A, 0.3), "a second handle of the same adapter heard the first's frame"
            esc.send(can.Message(arbitration_id=0x1000_0B0B, data=b"\x02", is_extended_id=True))
            assert _heard(a, 0x1000_0B0B) and _heard(b, 0x1000_0B0B), "every handle hears another node's frame"
        finally:
            for bus in (a, b, esc):
                bus.shutdown()


def test_one_handle_refuses_a_second_and_takes_one_again_once_the_first_is_closed(tmp_path):
    with Emulator(tmp_path, "--handles", "one") as emu:
        first = _client(emu.port)
        try:
            with pytest.raises(can.CanError, match="error"):
                _client(emu.port)
            other = _client(emu.port, "esc")  # another name: another node on the bus, not a handle of this adapter
            other.shutdown()
        finally:
            first.shutdown()
        again = _client(emu.port)
        again.shutdown()


@pytest.mark.parametrize("echo", [True, False], ids=["echo", "no-echo"])
def test_frames_played_on_the_lane_are_read_back_by_it(tmp_path, echo):
    """A TrafficPlayer on the lane's own handle (``BusLane.play``): every frame it played is read back by the lane,
    once, in order: its echo, or without one the lane's :class:`OwnFrame`; on a one-handle adapter."""
    args = ["--nodes", "none", "--handles", "one"] + ([] if echo else ["--no-echo-own"])
    with Emulator(tmp_path, *args) as emu:
        lane = BusLane({"interface": "socketcand", "host": "127.0.0.1", "port": emu.port, "channel": "can0",
                        "tcp_tune": True, "ignore_config": True}, NoPower(), timing_error=DEFAULT_BUS_ERROR_S)
        try:
            lane.find_echo(echo_probe())
            assert lane.echo is echo
            frames = [WireFrame(0x1000_2800 + i, bytes([i])) for i in range(10)]
            with TrafficPlayer(lane.play, [PeriodicFrames("seq", frames, period=0.005, until=0.05)],
                               bitrate=lane.bitrate) as player:
                got = []
                end = lane.now() + 5.0
                while len(got) < 10 and lane.now() < end:
                    msg = lane.recv(0.5)
                    if msg is not None and msg.arbitration_id & ~0xFF == 0x1000_2800:
                        got.append(msg)
            assert player.stats.frames == 10 and player.stats.send_errors == 0
            assert [m.arbitration_id & 0xFF for m in got] == list(range(10))
            assert all(isinstance(m, OwnFrame) is not echo for m in got)
            stamps = [m.timestamp for m in got]
            assert stamps == sorted(stamps)
        finally:
            lane.close()


def _bench(emu: Emulator, tmp: Path) -> list[str]:
    # --allow-motor-spin: the emulator has no motor, and --lane realtime (an emulator) allows it by default
    return [*emu.bench(realtime_profile(tmp)), "--allow-motor-spin", "--foreign-traffic", "ardupilot"]


@pytest.mark.timeout(300)
@pytest.mark.parametrize("handles,echo", [("one", True), ("separate", False)], ids=["one-handle-echo", "separate-no-echo"])
def test_a_faultless_esc_passes_the_foreign_traffic_test_on_an_adapter_whose_handles_do_not_hear_each_other(
        tmp_path, handles, echo):
    args = ["--handles", handles] + ([] if echo else ["--no-echo-own"])
    reports = tmp_path / "reports"
    with Emulator(tmp_path, *args) as emu:
        done = subprocess.run([*CKESC, "run", "robustness", "-q", *_bench(emu, tmp_path), "--trace-format", "none",
                               "--reports", str(reports), "--", "-k", "foreign_traffic"],
                              cwd=tmp_path, env=_env(tmp_path), capture_output=True, text=True, timeout=240)
    doc = json.loads((reports / "latest" / "results.json").read_text())
    assert doc["info"]["echo"] is echo
    outcomes = {r["nodeid"].split("::")[-1]: (r["outcome"], r.get("message")) for r in doc["results"]}
    assert outcomes == {"test_foreign_traffic_is_ignored": ("PASS", outcomes["test_foreign_traffic_is_ignored"][1])}, (
        outcomes, done.stdout[-2000:], done.stderr[-2000:])
    assert done.returncode == 0
    played = doc["info"]["foreign_traffic"]
    assert played["frames"] > 0 and played["send_errors"] == 0
    # the flight controller's queries were heard and answered: the watch saw the ESC's replies to them
    watched = [o for r in doc["results"] for o in r.get("observations", []) if "foreign traffic watched" in str(o)]
    assert watched and "replies to the flight controller's queries: 0" not in str(watched), watched


@pytest.mark.timeout(300)
def test_a_soak_with_a_flight_controller_finds_nothing_on_an_adapter_whose_handles_do_not_hear_each_other(tmp_path):
    reports = tmp_path / "soak"
    with Emulator(tmp_path, "--handles", "separate", "--no-echo-own") as emu:
        done = subprocess.run([*CKESC, "soak", "-q", *_bench(emu, tmp_path), "--duration", "12s", "--reports",
                               str(reports)], cwd=tmp_path, env=_env(tmp_path), capture_output=True, text=True, timeout=240)
    doc = json.loads(next(reports.rglob("results.json")).read_text())
    assert done.returncode == 0, (done.stdout[-3000:], done.stderr[-2000:])
    assert not doc["findings"], doc["findings"][:3]
    answers = doc["watches"]["GET_ESC_ID answers"]["statistics"]
    assert answers["other_nodes_queries"] >= 5 and answers["answers_to_other_nodes"] >= 5, answers
