"""Foreign traffic (issue #30 item 2, R17): a flight controller's and a smart battery's frames, encoded by the
``dronecan`` package, played during a run (``--foreign-traffic ardupilot``): the frames are dronecan's and what the
docs say, the ESC ignores what is not for it, the suite's verdicts with the traffic playing equal those on a
quiet bus, and a fault that takes a foreign frame turns the traffic run into a FAIL."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import dronecan
import pytest
from dronecan import transport

from ckesc.bench import foreign
from ckesc.emulator.model import EscConfig, EscModel
from ckesc.protocol import catalogue as cat
from ckesc.protocol.frame import classify
from ckesc.protocol.ids import Kind
from ckesc.protocol.transfer import parse_tail

#: a representative part of the suite (GET_ESC_ID's answers and their timing, MSG Control, comm loss, the framing
#: checks over the whole run's frames): its verdicts with the traffic playing must equal a quiet bus's
SELECTION = ("conformance/test_s4_4_3_get_esc_id.py::test_reply_comes_in_the_node_slot",
             "conformance/test_s4_4_2_msg_control.py::test_answer_is_command_zero_in_the_node_slot",
             "conformance/test_s4_4_4_msg1.py::test_comm_loss_flag_sets_after_200ms_and_clears", "--", "-k",
             "test_reply_comes or suspend or 14b")
#: the one test whose subject is the traffic itself (on a quiet bus it plays the traffic itself for its watch)
FOREIGN_TEST = "conformance/test_robustness_r17_foreign.py::test_foreign_traffic_is_ignored"


def _transfers(traffic: foreign.ForeignTraffic, seconds: float) -> list[list]:
    """The frames due in ``seconds``, grouped into transfers (a multi-frame transfer's frames share a due time)."""
    out: list[list] = []
    for w in traffic.take_due(seconds):
        if out and out[-1][0].timestamp == w.timestamp and out[-1][0].arbitration_id == w.arbitration_id:
            out[-1].append(w)
        else:
            out.append([w])
    return out


def test_every_frame_is_dronecans_and_the_throttle_is_zero():
    """Each transfer decodes with dronecan's own transport (CAN id, tail bytes, the multi-frame CRC) into the type
    and values the docs list; BatteryCells on 20010 is a true multi-frame transfer; every RawCommand channel is 0."""
    traffic = foreign.ardupilot()
    seen: dict[tuple[int, str], int] = {}
    cells_t = foreign.battery_cells_type()
    for frames in _transfers(traffic, 2.0):
        type_id, source = (frames[0].arbitration_id >> 8) & 0xFFFF, frames[0].arbitration_id & 0x7F
        if type_id == 20010:  # ArduPilot's BatteryCells: dronecan's table has BatteryContinuous there (the module says why)
            tails = [parse_tail(f.data[-1]) for f in frames]
            assert len(frames) >= 2 and tails[0].start and not tails[0].end and tails[-1].end
            assert [t.toggle for t in tails] == [i % 2 for i in range(len(frames))]
            data = b"".join(f.data[:-1] for f in frames)
            crc, payload = data[0] | data[1] << 8, data[2:]
            assert crc == dronecan.dsdl.crc16_from_bytes(payload, initial=cells_t.base_crc)
            value = transport.CompoundValue(cells_t)
            value._unpack(transport.bits_from_bytes(bytearray(payload)), True)
            assert list(value.voltages) == [3900.0] * 12
            name = "ardupilot.equipment.power.BatteryCells"
        else:
            tr = transport.Transfer()
            tr.from_frames([transport.Frame(f.arbitration_id, f.data) for f in frames])
            name = dronecan.get_dronecan_data_type(tr.payload).full_name
            if name == "uavcan.equipment.esc.RawCommand":
                assert list(tr.payload.cmd) == [0, 0, 0, 0], "the flight controller's throttle is ZERO, always"
            if name == "com.hobbywing.esc.GetEscID":
                assert list(tr.payload.payload) == [0]
        seen[(source, name)] = seen.get((source, name), 0) + 1
    assert seen == {(10, "ardupilot.indication.SafetyState"): 4, (10, "uavcan.protocol.NodeStatus"): 2,
                    (10, "com.hobbywing.esc.GetEscID"): 2, (10, "uavcan.equipment.esc.RawCommand"): 800,
                    (40, "ardupilot.equipment.power.BatteryCells"): 2, (40, "uavcan.protocol.NodeStatus"): 2}
    # SafetyState is a 2-byte frame on CAN Test's id, as INTERPRETATIONS' facts say
    safety = next(f for fr in _transfers(foreign.ardupilot(), 0.5) for f in fr if (f.arbitration_id >> 8) & 0xFFFF == 20000)
    assert len(safety.data) == 2


def test_the_esc_ignores_what_is_not_for_it():
    """R17 on the model: ten seconds of the traffic change no setting, refresh no command, reset nothing; the only
    frames the ESC sends besides its reports are its GET_ESC_ID replies, one per node 10 query, each in its slot."""
    esc = EscModel(EscConfig(slot=0, boot_time=0.0))
    esc.power_on(0.0)
    before = dict(esc.nvm)
    traffic = foreign.ardupilot()
    queries, replies = [], []
    for frames in _transfers(traffic, 10.0):
        for w in frames:
            esc.receive(w, w.timestamp)
            if classify(w.arbitration_id)[4] is cat.spec("get_esc_id"):
                queries.append(w.timestamp)
        for out in esc.poll(frames[0].timestamp):
            kind, _, source, _, spec = classify(out.arbitration_id)
            assert kind is Kind.MESSAGE and source == esc.node_id
            if spec is not None and spec.name == "get_esc_id":
                replies.append(out.timestamp)
            else:
                assert spec is not None and spec.name in cat.ESC_REPORT_FRAMES, f"the ESC answered a foreign frame: {out}"
    assert esc.nvm == before, "a foreign frame changed a setting"
    assert esc.state.last_command is None, "a foreign frame counted as a command (no comm refresh, R17/R8)"
    assert esc.counters["rx_foreign"] > 0 and esc.counters["rx_malformed"] > 0
    assert len(queries) == 10 and len(replies) == 10
    assert all(0 < r - q <= cat.ANSWER_DELAY_MAX_S for q, r in zip(queries, replies))


def _run(reports: Path, *args: str) -> dict[str, str]:
    done = subprocess.run([sys.executable, "-m", "ckesc", "run", "-q", "--trace-format", "none", "--reports", str(reports),
                           *args], capture_output=True, text=True, timeout=1800)
    results = reports / "latest" / "results.json"
    assert results.is_file(), done.stdout[-3000:] + done.stderr[-3000:]
    doc = json.loads(results.read_text())
    return {"verdicts": {r["nodeid"]: r["outcome"] for r in doc["results"]}, "info": doc["info"]}


def _same_verdicts(tmp_path: Path, *selection: str) -> dict:
    quiet = _run(tmp_path / "quiet", *selection)
    played = _run(tmp_path / "ardupilot", "--foreign-traffic", "ardupilot", *selection)
    assert "foreign_traffic" not in quiet["info"]
    assert quiet["verdicts"].get(FOREIGN_TEST, "PASS") == "PASS"
    assert played["verdicts"] == quiet["verdicts"], {k: (v, played["verdicts"].get(k)) for k, v in quiet["verdicts"].items()
                                                     if played["verdicts"].get(k) != v}
    return played


@pytest.mark.timeout(600)
def test_verdicts_with_ardupilot_traffic_equal_a_quiet_bus(tmp_path):
    played = _same_verdicts(tmp_path, *SELECTION)
    assert len(played["verdicts"]) == 3 and set(played["verdicts"].values()) == {"PASS"}
    ft = played["info"]["foreign_traffic"]
    assert ft["profile"] == "ardupilot" and ft["frames"] > 0 and 0.05 < ft["load"] < 0.2  # ~11 % at 500 kbit/s


@pytest.mark.slow
@pytest.mark.timeout(3600)  # two whole runs: ~1 min quiet, ~4 min with the traffic (its 400 Hz command) alone
def test_whole_suite_verdicts_with_ardupilot_traffic_equal_a_quiet_bus(tmp_path):
    _same_verdicts(tmp_path)


@pytest.mark.slow  # two runs, ~30 s
@pytest.mark.timeout(600)
def test_a_fault_that_takes_a_foreign_frame_fails_the_foreign_traffic_test(tmp_path):
    """Teeth: an ESC that resets on a multi-frame start (BatteryCells on 20010) FAILs R17's foreign-traffic test, which
    plays the traffic itself on a quiet bus."""
    fault = ("--emulator-faults", "reset_on_multi_frame_start", FOREIGN_TEST.split("::")[0])
    quiet = _run(tmp_path / "quiet", *fault)
    assert quiet["verdicts"] == {FOREIGN_TEST: "FAIL"}
    doc = json.loads((tmp_path / "quiet" / "latest" / "results.json").read_text())
    message = doc["results"][0]["message"]
    assert message.startswith("[R17") and "the ESC reset" in message and "power-up count" in message, message


@pytest.mark.slow  # `ckesc emulate` in its own process, ~20 s
@pytest.mark.timeout(600)
@pytest.mark.realtime
def test_real_time_lane_plays_it_from_its_own_thread(tmp_path):
    """In real time a player sends the traffic on a bus of its own (socketcand to the emulator): the verdicts hold and
    the reports say the load and lateness it reached."""
    played = _run(tmp_path / "rt", "--lane", "realtime", "--foreign-traffic", "ardupilot",
                  "conformance/test_s4_4_3_get_esc_id.py::test_reply_comes_in_the_node_slot", FOREIGN_TEST.split("::")[0])
    assert set(played["verdicts"].values()) == {"PASS"}, played["verdicts"]
    ft = played["info"]["foreign_traffic"]
    assert ft["frames"] > 0 and ft["send_errors"] == 0 and 0.05 < ft["load"] < 0.2 and ft["late_max_ms"] >= ft["late_mean_ms"] > 0


def test_the_host_leaves_another_nodes_answer_alone():
    """Another host on the bus (a flight controller at node 10) asks the ESC the same service with the same transfer id
    as this host: the ESC's answer to node 10 is node 10's (F4: addressed to it, answering its request), never paired
    with this host's request as a misaddressed answer; the answer to this host still is."""
    from ckesc.protocol.frame import encode
    from ckesc.protocol.host import HostProtocol, Overheard, Response

    host = HostProtocol(0)
    fields = dict(cat.FREQ_READ)
    _, pending = host.request("set_freq", fields, destination=1, now=0.0, timeout=0.1, transfer_id=3)
    theirs = encode("set_freq", fields, kind=Kind.REQUEST, source=10, destination=1, transfer_id=3)
    answer = {"option": 0, "msg1_interval": 10, "msg2_interval": 50, "msg3_interval": 250}
    to_them = encode("set_freq", answer, kind=Kind.RESPONSE, source=1, destination=10, transfer_id=3)
    to_us = encode("set_freq", answer, kind=Kind.RESPONSE, source=1, destination=0, transfer_id=3)
    assert isinstance(host.receive(theirs)[0], Overheard)
    assert isinstance(host.receive(to_them)[0], Overheard) and host.pending == [pending]
    got = host.receive(to_us)[0]
    assert isinstance(got, Response) and got.pending is pending and got.mismatch == []


def test_the_bus_rules_expect_a_reply_to_each_query_of_each_host():
    """A flight controller's GET_ESC_ID query and the host's within 64 ms: the ESC answers both (R2), which is no
    sign of two ESCs sharing its node id (4.4.18-2): the rules keep comparing its reports; a third reply is."""
    from ckesc.evidence.rules import BusRules
    from ckesc.protocol.frame import encode

    rules = BusRules(complete=True)
    query = {"option": 0}
    reply = {"node_id": 1, "throttle_channel": 1}
    frames = [(0.000, encode("get_esc_id", query, source=0, transfer_id=0, layout="query")),
              (0.001, encode("get_esc_id", query, source=10, transfer_id=0, layout="query")),
              (0.002, encode("get_esc_id", reply, source=1, transfer_id=0, layout="reply")),
              (0.003, encode("get_esc_id", reply, source=1, transfer_id=1, layout="reply"))]
    for ts, w in frames:
        list(rules.feed(w.arbitration_id, w.data, ts))
    assert not rules._nodes[1].shared
    w = encode("get_esc_id", reply, source=1, transfer_id=2, layout="reply")
    list(rules.feed(w.arbitration_id, w.data, 0.004))
    assert rules._nodes[1].shared
