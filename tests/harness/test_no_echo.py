"""An adapter that does not echo the host's own frames (issue #11): the lane finds out at the start, hands
out the host's frames itself (stamped by the host clock at send, throttle streams included), and no
verdict changes except where the host clock cannot judge: INCONCLUSIVE, saying "host clock".

Two real set-ups, nothing mocked:

* in-process: the real-time emulator on python-can's ``virtual`` bus, the lane's end opened with
  ``receive_own_messages`` False (the virtual interface then never echoes) beside one that echoes;
* a real ``ckesc run --dut bus`` through python-can's stock socketcand client, against ``ckesc emulate
  --no-echo-own`` (socketcand that never echoes a client's own frames: what a third-party adapter
  without echo looks like to python-can) beside ``ckesc emulate`` that echoes, on the sections that
  time the host's frames: comm loss (4.4.4), answer delays (4.4.2, 4.4.3) and report intervals (4.4.22).
"""

from __future__ import annotations

import itertools
import json
import os
import subprocess
import xml.etree.ElementTree as ET
from pathlib import Path

import can
import pytest
from procs import CKESC, Emulator, realtime_profile
from procs import env as _env

from ckesc.bench.dut import Dut, echo_probe
from ckesc.bench.lanes import BusLane, OwnFrame
from ckesc.bench.power import NoPower
from ckesc.bench.profile import DEFAULT_BUS_ERROR_S, DutProfile
from ckesc.emulator.emulated_bench import EmulatedBench
from ckesc.emulator.realtime import RealtimeEmulator
from ckesc.evidence.live import LaneRules

pytestmark = pytest.mark.realtime  # wall-clock timing with real processes: one at a time under xdist (tests/conftest.py)

_channels = itertools.count()


# ------------------------------------------------------------------------------------------ in-process
@pytest.fixture
def bench():
    """(lane, rules) on a fresh virtual channel with the real-time emulator (node 1) in a thread; the
    lane echoes or not as asked."""
    made = []

    def start(echo: bool):
        channel = f"ckesc-no-echo-{os.getpid()}-{next(_channels)}"
        emu_bus = can.Bus(interface="virtual", channel=channel, preserve_timestamps=True, ignore_config=True)
        emu = RealtimeEmulator(EmulatedBench((1,)), bus=emu_bus, own_bus=True).start()
        lane = BusLane({"interface": "virtual", "channel": channel, "receive_own_messages": echo, "ignore_config": True},
                       NoPower(), timing_error=DEFAULT_BUS_ERROR_S)
        rules = LaneRules(lane)
        lane.listeners.append(rules)
        made.append((emu, lane))
        return lane, rules

    yield start
    for emu, lane in made:
        lane.close()
        emu.close()


@pytest.mark.parametrize("echo", [True, False], ids=["echo", "no-echo"])
def test_the_lane_finds_out_whether_its_frames_come_back(bench, echo):
    lane, rules = bench(echo)
    assert lane.find_echo(echo_probe()) is echo
    assert lane.echo is echo
    assert lane.own_clock == ("bus timestamp" if echo else "host clock")
    assert lane.own_error == pytest.approx(DEFAULT_BUS_ERROR_S if echo else 2 * DEFAULT_BUS_ERROR_S)  # + the host's send error
    assert ("came back" in lane.echo_note) is echo


@pytest.mark.parametrize("echo", [True, False], ids=["echo", "no-echo"])
def test_without_echo_the_host_frames_are_handed_out_in_time_order_and_rules_learn_from_them(bench, echo):
    lane, rules = bench(echo)
    lane.find_echo(echo_probe())
    dut = Dut(lane, DutProfile.load("emulator"), node_id=1)
    assert dut.wait_for("msg1", 3.0) is not None  # the emulated ESC has booted
    heard: list[can.Message] = []
    lane.listeners.append(type("Keep", (can.Listener,), {"on_message_received": lambda self, m: heard.append(m)})())
    ex = dut.request("set_freq", {"option": 1, "msg1_interval": 25, "msg2_interval": 50, "msg3_interval": 100})
    assert ex.response is not None
    assert ex.sent.clock == ("bus timestamp" if echo else "host clock")
    assert ex.sent.error == pytest.approx(lane.own_error)
    task = dut.throttle_stream("raw_command_12b", {"channels": [0] * 4, "group": 0}, 0.0025)
    start = dut.now()
    dut.wait(0.2)
    dut.stop_throttle()
    dut.wait(0.05)
    streamed = dut.frames("raw_command_12b", since=start - 0.01, source=0)
    assert 40 <= len(streamed) <= 100, len(streamed)  # counted from the sending side without an echo
    assert task is not None
    # the host's frames are handed out in time order: never stamped before a frame already handed out
    # (the live rules would see the time jump back)
    assert all(m.timestamp >= max(x.timestamp for x in heard[:i + 1]) for i, m in enumerate(heard) if isinstance(m, OwnFrame))
    own = [m for m in heard if isinstance(m, OwnFrame)]
    assert bool(own) is not echo and all(m.is_rx is False for m in own)
    node = rules.rules.summary()["nodes"]["1"]
    # the report-interval rule learned the node's intervals from the write's answer, paired with its request
    assert "Set/Get Freq write answer" in (node["intervals_from"] or ""), node["intervals_from"]
    assert node["intervals"]["msg1"]["expected_ms"] == 50.0
    unmatched = [o for o in rules.rules.summary()["observations"] if o["check"] == "response-unmatched"]
    assert not unmatched, unmatched
    dut.ask("set_freq", {"option": 1, "msg1_interval": 10, "msg2_interval": 50, "msg3_interval": 250})


@pytest.mark.parametrize("echo", [True, False], ids=["echo", "no-echo"])
def test_a_requests_wait_ends_in_the_bus_clock(bench, echo):
    """The emulator stamps a frame at its end (its start plus its time on the bus), as an adapter does, so the host
    reads an answer before its own clock reaches the answer's stamp. A request's wait ends in the bus's clock
    (``Exchange.until``, ``Link.bus_now``): every frame read by then is stamped no later, so the framing section's
    "answered while the host waited" compares stamps with stamps (the host's clock there FAILed 4.1.1-2 without echo)."""
    lane, rules = bench(echo)
    lane.find_echo(echo_probe())
    dut = Dut(lane, DutProfile.load("emulator"), node_id=1)
    assert dut.wait_for("msg1", 3.0) is not None
    for option in (0, 1, 2) * 3:
        ex = dut.request("maintenance_information", {"option": option})
        assert ex.response is not None and ex.until is not None
        assert max(f.timestamp for f in dut.trace) <= ex.until
        assert ex.sent.time <= ex.response.timestamp <= ex.until


# ------------------------------------------------------------------------------------------ ckesc run
#: the sections that time the host's own frames: comm loss (4.4.4), answer delays (4.4.2, 4.4.3) and report
#: intervals (4.4.22)
SECTIONS = "comm_loss_flag_sets_after or test_s4_4_2_msg_control or test_s4_4_3_get_esc_id or test_s4_4_22_set_freq"


def _run(tmp: Path, port: int, name: str, k: str) -> tuple[dict, str, ET.Element, int]:
    reports = tmp / name
    done = subprocess.run([*CKESC, "run", "--dut", "bus", "--can-interface", "socketcand", "--can-channel", "can0",
                           "--can-config", "host=127.0.0.1", "--can-config", f"port={port}",
                           # TCP_NODELAY: python-can's socketcand client otherwise holds a frame back (Nagle)
                           "--can-config", "tcp_tune=True", "--node-id", "1", "--profile", str(realtime_profile(tmp)), "-q",
                           "--trace-format", "none", "--reports", str(reports), "--", "-k", k],
                          cwd=tmp, env=_env(tmp), capture_output=True, text=True, timeout=600)
    run = reports / "latest"
    doc = json.loads((run / "results.json").read_text())
    return doc, (run / "summary.txt").read_text(), ET.parse(run / "junit.xml").getroot(), done.returncode


def test_a_bench_without_echo_judges_what_one_with_echo_judges(tmp_path):
    echoing, silent = Emulator(tmp_path), Emulator(tmp_path, "--no-echo-own")
    try:
        with_echo, summary_echo, _, _ = _run(tmp_path, echoing.port, "echo", SECTIONS)
        without, summary, junit, code = _run(tmp_path, silent.port, "no-echo", SECTIONS)
    finally:
        echoing.close()
        silent.close()
    assert with_echo["info"]["echo"] is True and without["info"]["echo"] is False
    assert "echo: yes" in summary_echo and "echo: NO" in summary and "host clock" in summary
    props = {p.get("name"): p.get("value") for p in junit.iter("property")}
    assert props.get("echo") == "False" and props.get("own_frames_clock") == "host clock"
    before = {r["nodeid"]: r for r in with_echo["results"]}
    after = {r["nodeid"]: r for r in without["results"]}
    assert set(before) == set(after) and len(after) > 30
    bad = [f"{n}: {r['outcome']} {r['message'][:300]}" for n, r in after.items() if r["outcome"] in ("FAIL", "ERROR")]
    assert not bad, "\n".join(bad)
    for nodeid, r in after.items():
        was = before[nodeid]["outcome"]
        if (was, r["outcome"]) == ("INCONCLUSIVE", "PASS"):
            continue  # real time on a loaded machine: the echo run's margin fell inside the stated error that time
        if r["outcome"] != was:  # only what the host clock cannot judge, and saying so
            assert (was, r["outcome"]) == ("PASS", "INCONCLUSIVE") and "host clock" in r["message"], (nodeid, was, r)
    comm = [r for n, r in after.items() if "comm_loss" in n]
    assert len(comm) == 3
    for r in comm:  # the 200 ms comm-loss timing is measured, from the stream's last frame as the host sent it
        clocks = {v for k, v in r["properties"].items() if k.endswith(".clock")}
        assert r["outcome"] in ("PASS", "INCONCLUSIVE") and clocks == {"host clock"}, r
    assert code == 0 or not bad


def test_a_comm_loss_fault_is_caught_without_echo(tmp_path):
    emu = Emulator(tmp_path, "--no-echo-own", "--faults", "comm_loss_early")
    try:
        doc, summary, _, code = _run(tmp_path, emu.port, "fault", "comm_loss_flag_sets_after")
    finally:
        emu.close()
    assert doc["info"]["echo"] is False
    comm = doc["results"]
    assert len(comm) == 3 and code == 1
    for r in comm:
        assert r["outcome"] == "FAIL" and "R8" in r["message"] and "host clock" in r["message"], r
