"""The bus rules one by one, on hand-built frames: each rule catches its violation and stays silent on
legal traffic. Frames are built from the catalogue (``encode``), one field changed where a test needs a
bad one. Timestamps are frame ends; at 500 kbit/s an 8-byte frame takes 262 us."""

from __future__ import annotations

import pytest

from ckesc.evidence import BusRules
from ckesc.evidence.rules import RESTART_SILENCE_S, SHORTEST_S, Intervals
from ckesc.protocol import catalogue as cat
from ckesc.protocol.frame import encode, frame_bits
from ckesc.protocol.ids import Priority, message_id, service_id
from ckesc.protocol.transfer import tail_byte

BITRATE = 500_000
MSG1 = {"speed": 0, "pwm": 0, "status": 0}
READ = {"option": 0, "msg1_interval": 0, "msg2_interval": 0, "msg3_interval": 0}
INTERVALS = {"msg1_interval": 10, "msg2_interval": 50, "msg3_interval": 250}  # 20 / 100 / 500 ms


def feed(rules: BusRules, wire, ts: float, **kw):
    return list(rules.feed(wire.arbitration_id, wire.data, ts, **kw))


def msg1(node: int, tid: int, **kw):
    return encode("msg1", MSG1, source=node, transfer_id=tid, **kw)


def checks(violations) -> list[str]:
    return [v.check for v in violations]


def stated(rules: BusRules, node: int, ts: float, intervals=INTERVALS, tid: int = 0) -> float:
    """The host reads node's intervals and node answers (R9 then knows its periods). Returns the time after."""
    feed(rules, encode("set_freq", READ, source=0, destination=node, transfer_id=tid), ts)
    feed(rules, encode("set_freq", {"option": 0, **intervals}, kind="response", source=node, destination=0, transfer_id=tid),
         ts + 0.001)
    return ts + 0.002


def stream(rules: BusRules, node: int, times, tids=None, start_tid: int = 0, **kw) -> list:
    out = []
    for i, t in enumerate(times):
        tid = (start_tid + i) % 32 if tids is None else tids[i]
        out += feed(rules, msg1(node, tid, **kw), t)
    return out


# ------------------------------------------------------------------------------------------ legal traffic
def test_a_steady_esc_is_silent():
    rules = BusRules(bitrate=BITRATE, complete=True)
    t = stated(rules, 1, 0.0)
    assert stream(rules, 1, [t + 0.02 * i for i in range(100)]) == []
    s = rules.summary()
    st = s["nodes"]["1"]["intervals"]["msg1"]
    assert st["count"] == 99 and st["min_ms"] == pytest.approx(20.0) and st["max_ms"] == pytest.approx(20.0)
    assert st["expected_ms"] == 20.0
    assert s["nodes"]["1"]["role"] == "esc" and s["nodes"]["0"]["role"] == "host"
    assert s["violations"]["count"] == 0


# ------------------------------------------------------------------------------------------ F2
@pytest.mark.parametrize(("tail", "rules_cited"), [(0xE0, {"F2", "4.1.3-toggle"}), (0x80, {"F2", "4.1.3-end"}),
                                                    (0x40, {"F2", "4.1.3-start"})])
def test_tail_byte_of_an_esc_frame(tail, rules_cited):
    rules = BusRules()
    good = msg1(1, 3)
    bad = good._replace(data=good.data[:-1] + bytes([tail | 4]))  # transfer id 3 + 4 = 7: F3 would count 4
    assert feed(rules, good, 0.0) == []
    (v,) = feed(rules, bad, 0.02 + 3 * 0.02)  # three frames missing from the capture: tid 3 -> 7
    assert v.check == "tail-byte" and set(v.rules) == rules_cited and v.strength == "SHALL" and v.node == 1
    assert f"{bad.arbitration_id:08X}#{bad.data.hex().upper()}" in v.frames[0]


def test_host_frames_are_not_judged():
    """The host's frames (a request with a broken tail, sent on purpose by a suite) move state only."""
    rules = BusRules()
    req = encode("set_freq", READ, source=0, destination=1)
    assert feed(rules, req._replace(data=req.data[:-1] + b"\x20"), 0.0) == []
    assert feed(rules, msg1(1, 0)._replace(data=b"\x00" * 6 + b"\xe0"), 0.01, own=True) == []  # our own echo


# ------------------------------------------------------------------------------------------ F3
def test_transfer_ids_count_per_type():
    rules = BusRules(complete=True)
    vs = stream(rules, 1, [0.02 * i for i in range(6)], tids=[30, 31, 0, 1, 1, 3])
    assert checks(vs) == ["transfer-id", "transfer-id"]
    assert "transfer id 1 after 1" in vs[0].message and set(vs[0].rules) == {"F3", "4.1.3-tid"}
    assert len(vs[0].frames) == 2  # the pair, quoted


def test_transfer_ids_restart_after_a_silence():
    """A power cycle restarts the counter: frames across a silence are not compared."""
    rules = BusRules(complete=True)
    t = RESTART_SILENCE_S + 0.01
    assert stream(rules, 1, [0.0, 0.02, 0.02 + t, 0.04 + t], tids=[7, 8, 0, 1]) == []
    assert rules.summary()["nodes"]["1"]["silences"] == 1


def test_a_lost_frame_is_an_observation_unless_the_capture_is_complete():
    lossy = BusRules(bitrate=BITRATE)
    t = stated(lossy, 1, 0.0)
    assert stream(lossy, 1, [t, t + 0.02, t + 0.06], tids=[0, 1, 3]) == []  # one MSG1 missing: tid +2 after 40 ms
    assert {o["check"] for o in lossy.summary()["observations"]} >= {"lost-frames"}
    complete = BusRules(bitrate=BITRATE, complete=True)
    t = stated(complete, 1, 0.0)
    assert "transfer-id" in checks(stream(complete, 1, [t, t + 0.02, t + 0.06], tids=[0, 1, 3]))


# ------------------------------------------------------------------------------------------ F4
def test_response_keeps_the_request_transfer_id():
    rules = BusRules()
    feed(rules, encode("self_test", {}, source=0, destination=1, transfer_id=5), 0.0)
    ok = encode("self_test", {"status": 0}, kind="response", source=1, destination=0, transfer_id=5)
    assert feed(rules, ok, 0.001) == []
    feed(rules, encode("self_test", {}, source=0, destination=1, transfer_id=6), 0.1)
    (v,) = feed(rules, ok._replace(data=ok.data[:-1] + bytes([tail_byte(7)])), 0.101)
    assert v.check == "response-match" and v.rules == ("F4",) and "transfer id 7" in v.message


def test_response_to_a_node_that_asked_nothing():
    answer = encode("self_test", {"status": 0}, kind="response", source=1, destination=127, transfer_id=0)
    lossy = BusRules()
    feed(lossy, encode("self_test", {}, source=0, destination=1, transfer_id=0), 0.0)
    assert feed(lossy, answer, 0.001) == []  # the request may be missing from a capture: observed
    assert any(o["check"] == "response-unmatched" for o in lossy.summary()["observations"])
    complete = BusRules(complete=True)
    feed(complete, encode("self_test", {}, source=0, destination=1, transfer_id=0), 0.0)
    (v,) = feed(complete, answer, 0.001)
    assert v.check == "response-match" and "node(s) [0] did" in v.message


def test_set_id_is_answered_by_every_esc():
    """Set ID is a pseudo-broadcast (R11): any ESC answers, from its new node id."""
    rules = BusRules(complete=True)
    feed(rules, encode("set_id", {"node_id": 9, "throttle_channel": 1}, source=0, destination=3, transfer_id=2), 0.0)
    for node in (9, 4):
        answer = encode("set_id", {"node_id": node, "throttle_channel": 1}, kind="response", source=node, destination=0,
                        transfer_id=2)
        assert feed(rules, answer, 0.001 * node) == []


# ------------------------------------------------------------------------------------------ F1
def test_an_esc_sends_no_requests_and_no_remote_frames():
    rules = BusRules()
    feed(rules, msg1(1, 0), 0.0)  # node 1 is an ESC
    (v,) = feed(rules, encode("self_test", {}, kind="request", source=1, destination=0), 0.01)
    assert v.check == "frame-layout" and set(v.rules) == {"F1", "F4"}
    (v,) = feed(rules, msg1(1, 1)._replace(data=b""), 0.02, remote=True)
    assert v.check == "frame-layout" and "remote frame" in v.message and v.frames[0].split()[1].endswith("#R")


# ------------------------------------------------------------------------------------------ F5
def test_priority_is_the_tables():
    rules = BusRules()
    (v,) = feed(rules, msg1(1, 0, priority=Priority.MEDIUM), 0.0)
    assert v.check == "priority" and v.rules == ("F5",) and "31 (LOWEST)" in v.message
    feed(rules, encode("esc_information", {"option": 0}, source=0, destination=1), 0.1)
    answer = encode("esc_information", dict.fromkeys(cat.spec("esc_information").response.field_names, 1), kind="response",
                    source=1, destination=0, priority=Priority.LOW)
    assert feed(rules, answer, 0.101) == []  # 240 lists no priority: recorded, never failed
    (o,) = [o for o in rules.summary()["observations"] if o["check"] == "priority-unlisted"]
    assert o["rules"] == ["F5-unlisted"] and o["strength"] == "OBSERVE"


# ------------------------------------------------------------------------------------------ F7
def test_reserved_and_default_node_ids():
    rules = BusRules()
    (v,) = feed(rules, msg1(0x7F, 0), 0.0)
    assert v.check == "reserved-node" and set(v.rules) == {"F7", "4.1.2-N2"}
    (v,) = feed(rules, msg1(0x7D, 0), 0.01)
    assert v.check == "default-node-reports" and v.rules == ("F7",)
    feed(rules, encode("set_freq", READ, source=0, destination=0x7D), 0.02)
    answer = encode("set_freq", {"option": 0, **INTERVALS}, kind="response", source=0x7D, destination=0)
    assert feed(rules, answer, 0.021) == []  # answering at 0x7D is fine: only reports on its own are not


# ------------------------------------------------------------------------------------------ R9
def test_report_interval_as_the_node_stated():
    rules = BusRules(bitrate=BITRATE)
    t = stated(rules, 1, 0.0, {"msg1_interval": 15, "msg2_interval": 50, "msg3_interval": 250})  # 30 ms
    vs = stream(rules, 1, [t, t + 0.03, t + 0.05, t + 0.08, t + 0.115])
    assert checks(vs) == ["report-interval", "report-interval"]  # 20 ms: early; 35 ms: late
    assert "expected 30.000 ms" in vs[0].message and "read answer" in vs[0].message
    assert set(vs[0].rules) == {"R9", "4.4.22-2"}  # or the read answer was wrong


def test_report_interval_allows_bus_queueing():
    """A report that waited for the bus is late by the wait, never judged late or early for it."""
    rules = BusRules(bitrate=BITRATE)
    t = stated(rules, 1, 0.0)
    d8 = frame_bits(8) / BITRATE
    assert stream(rules, 1, [t, t + 0.02]) == []
    d7 = frame_bits(7) / BITRATE
    due = t + 0.04 - d7  # the reports so far started (were due) at t - d7, t + 0.02 - d7
    # three throttle frames back to back from the next due time: MSG1 goes after them, 786 us late
    for i in range(3):
        feed(rules, encode("raw_command_12b", {"channels": [0] * 4, "group": 1}, source=0), due + (i + 1) * d8)
    assert feed(rules, msg1(1, 2), due + 3 * d8 + d7) == []
    assert feed(rules, msg1(1, 3), t + 0.06) == []  # back on time: 19.2 ms after the delayed one


def test_a_missing_report_in_a_lossy_capture_is_observed():
    rules = BusRules(bitrate=BITRATE)
    t = stated(rules, 1, 0.0)
    assert stream(rules, 1, [t, t + 0.02, t + 0.06], tids=[0, 1, 3]) == []
    complete = BusRules(bitrate=BITRATE, complete=True)
    t = stated(complete, 1, 0.0)
    assert "report-interval" in checks(stream(complete, 1, [t, t + 0.02, t + 0.06], tids=[0, 1, 2]))


def test_without_a_stated_interval_only_the_shortest_legal_one_is_judged():
    rules = BusRules(bitrate=BITRATE)
    assert stream(rules, 1, [0.0, 0.03, 0.06, 0.4]) == []  # any legal interval: 30 ms, then 340 ms
    (v,) = stream(rules, 1, [0.41], start_tid=4)
    assert v.check == "report-interval" and f"{SHORTEST_S * 1000:.3f} ms" in v.message


def test_cadence_restarts_with_what_the_host_says():
    """Suspend and resume (MSG Control), and a Set Freq write, restart the cadence they concern."""
    rules = BusRules(bitrate=BITRATE, complete=True)
    t = stated(rules, 1, 0.0)
    stream(rules, 1, [t, t + 0.02])
    feed(rules, encode("msg_control", {"option": 0, "command": cat.MSG_CONTROL_SUSPEND}, source=0), t + 0.025)
    feed(rules, encode("msg_control", {"option": 0, "command": cat.MSG_CONTROL_RESUME}, source=0), t + 0.03)
    assert stream(rules, 1, [t + 0.031, t + 0.051], start_tid=2) == []  # "immediate recovery": 11 ms after the last
    feed(rules, encode("set_freq", {"option": 1, **INTERVALS, "msg1_interval": 25}, source=0, destination=1, transfer_id=1),
         t + 0.06)
    assert stream(rules, 1, [t + 0.0605], start_tid=4) == []  # the new interval counts from the write
    feed(rules, encode("set_freq", {"option": 1, **INTERVALS, "msg1_interval": 25}, kind="response", source=1, destination=0,
                       transfer_id=1), t + 0.061)
    assert stream(rules, 1, [t + 0.1105, t + 0.1605], start_tid=5) == []  # 50 ms now
    assert rules.summary()["nodes"]["1"]["intervals"]["msg1"]["expected_ms"] == 50.0


def test_set_id_makes_every_interval_unknown():
    rules = BusRules(bitrate=BITRATE)
    t = stated(rules, 1, 0.0, {"msg1_interval": 15, "msg2_interval": 50, "msg3_interval": 250})
    feed(rules, encode("set_id", {"node_id": 1, "throttle_channel": 1}, source=0, destination=2), t)
    assert stream(rules, 1, [t + 0.001, t + 0.021, t + 0.041]) == []  # 20 ms is legal; 30 ms was only said before


def test_an_esc_moved_away_and_back_by_set_id_counts_its_transfer_ids_on():
    """F3 counts transfer ids at the sender: an ESC at node 1 moved to node 2 and back by two Set IDs sent MSG1
    from node 2 meanwhile, so node 1's next MSG1 skips a transfer id (found by ``ckesc explore``: a false FAIL).
    After the next frame the stream is held to F3 again."""
    rules = BusRules(bitrate=BITRATE, complete=True)
    t = stated(rules, 1, 0.0)
    assert stream(rules, 1, [t, t + 0.02], start_tid=15) == []  # tids 15, 16
    feed(rules, encode("set_id", {"node_id": 2, "throttle_channel": 1}, source=0, destination=1, transfer_id=1), t + 0.021)
    feed(rules, encode("set_id", {"node_id": 2, "throttle_channel": 1}, kind="response", source=2, destination=0,
                       transfer_id=1), t + 0.022)
    assert stream(rules, 2, [t + 0.04], start_tid=17) == []
    feed(rules, encode("set_id", {"node_id": 1, "throttle_channel": 1}, source=0, destination=2, transfer_id=2), t + 0.041)
    feed(rules, encode("set_id", {"node_id": 1, "throttle_channel": 1}, kind="response", source=1, destination=0,
                       transfer_id=2), t + 0.042)
    assert stream(rules, 1, [t + 0.06, t + 0.08], start_tid=18) == []  # 18 after node 1's 16: the ESC's own count
    (v,) = stream(rules, 1, [t + 0.10], tids=[21])  # 21 after 19, no Set ID between: caught
    assert v.check == "transfer-id"


def test_reports_between_a_set_freq_write_and_its_late_answer_are_not_judged_on_the_old_interval():
    """A service answer may come up to 64 ms after the request (a conforming variant, service_delay): an ESC that
    applies the write on receipt reports on the new interval before its answer says what it is."""
    rules = BusRules(bitrate=BITRATE, complete=True)
    t = stated(rules, 1, 0.0, {**INTERVALS, "msg1_interval": 25})  # 50 ms
    stream(rules, 1, [t, t + 0.05])
    write = {"option": 1, **INTERVALS}  # to 20 ms
    feed(rules, encode("set_freq", write, source=0, destination=1, transfer_id=1), t + 0.06)
    assert stream(rules, 1, [t + 0.061, t + 0.081, t + 0.101, t + 0.121], start_tid=2) == []
    feed(rules, encode("set_freq", write, kind="response", source=1, destination=0, transfer_id=1), t + 0.124)
    assert stream(rules, 1, [t + 0.141, t + 0.161], start_tid=6) == []
    (v,) = stream(rules, 1, [t + 0.191], start_tid=8)  # 30 ms where the answer said 20: still caught
    assert "20.000 ms" in v.message


def test_two_escs_taking_one_id_before_their_late_answers_are_not_compared():
    """Set ID is a pseudo-broadcast (R11): every ESC may take the new id at once and answer up to 64 ms later,
    so two ESCs' reports from it come before the answers show the id is shared."""
    rules = BusRules(bitrate=BITRATE, complete=True)
    feed(rules, encode("set_id", {"node_id": 34, "throttle_channel": 1}, source=0, destination=1, transfer_id=0), 1.0)
    assert stream(rules, 34, [1.001, 1.0013, 1.021, 1.0213], tids=[0, 0, 1, 1]) == []  # two ESCs, one id
    assert stream(rules, 34, [1.2, 1.21], tids=[5, 7])  # later, a single ESC's frames are compared again


def test_an_illegal_interval_in_an_answer_stops_the_floor():
    """An answer to an illegal write may say anything (R10-answer, OBSERVE): nothing is judged on it."""
    rules = BusRules(bitrate=BITRATE)
    t = stated(rules, 1, 0.0, {"msg1_interval": 5, "msg2_interval": 50, "msg3_interval": 250})
    assert stream(rules, 1, [t + 0.01 * i for i in range(5)]) == []


# ------------------------------------------------------------------------------------------ not CKESC
def test_foreign_traffic_is_counted_not_judged():
    rules = BusRules(bitrate=1_000_000)
    node_status = message_id(Priority.LOW, 341, 50)  # DroneCAN NodeStatus from a GPS
    ardupilot_safety = message_id(Priority.MEDIUM, 20000, 10)  # ArduPilot SafetyState: 20000, 1 byte + tail
    battery = message_id(Priority.MEDIUM, 20010, 10)  # ArduPilot BatteryContinuous: 20010, a multi-frame transfer
    get_node_info = service_id(Priority.LOW, 1, True, 50, 10)
    frames = [(node_status, bytes(7) + bytes([0xC0])), (ardupilot_safety, b"\xff\xc1"),
              (battery, bytes(7) + bytes([0x82])), (battery, bytes(7) + bytes([0x22])), (battery, b"\x00" * 5 + bytes([0x42])),
              (get_node_info, bytes([0xC3]))]
    out = []
    for i, (can_id, data) in enumerate(frames * 20):
        out += rules.feed(can_id, data, 0.001 * i)
    assert out == []
    s = rules.summary()
    assert s["nodes"]["50"]["by_type"] == {"foreign message 341": 20}
    assert s["nodes"]["10"]["by_type"]["msg_control"] == 60 and s["nodes"]["10"]["by_type"]["can_test"] == 20


def test_error_and_standard_frames_are_counted():
    rules = BusRules()
    assert list(rules.feed(0x123, b"\x01", 0.0, extended=False)) == []
    assert list(rules.feed(0x20000004, bytes(8), 0.01, error=True)) == []
    s = rules.summary()
    assert s["standard_id_frames"] == 1 and s["error_frames"] == {"count": 1, "first": [0.01]}


def test_time_going_back_restarts_the_comparisons():
    rules = BusRules(complete=True)
    assert stream(rules, 1, [10.0, 10.02, 5.0, 5.02], tids=[0, 1, 0, 1]) == []
    assert rules.summary()["time_jumps"] == 1


def test_two_frames_stamped_in_the_other_order_within_the_stated_error_are_no_time_jump():
    """A bench's stamps may reorder two frames by less than its stated error (two handles, a hub stamping on arrival:
    16 us seen): that is no clock going back, so the comparisons across it are not restarted."""
    rules = BusRules(tolerance=0.002, complete=True)
    rules.feed(0x1E321A32, b"\x01", 1.07)
    rules.feed(0x1E321A32, b"\x01", 1.07 - 0.000016)  # back by 16 us: within the 2 ms stated
    rules.feed(0x1E321A32, b"\x01", 1.07 - 0.5)  # back by half a second: the clock went back
    assert rules.summary()["time_jumps"] == 1


# ------------------------------------------------------------------------------------------ comm loss and memory
def test_comm_loss_events():
    rules = BusRules()
    fault = int(cat.Status.COMM_FAULT)
    for i, status in enumerate([0, 0, fault, fault, 0]):
        feed(rules, encode("msg1", {**MSG1, "status": status}, source=1, transfer_id=i), 0.02 * i)
    events = rules.summary()["nodes"]["1"]["comm_loss"]
    assert [e["event"] for e in events] == ["set", "cleared"]
    assert [e["timestamp"] for e in events] == [pytest.approx(0.04), pytest.approx(0.08)]


def test_intervals_are_the_one_histogram_read_by_its_bins_middles():
    """The bus rules' intervals are the project's one Histogram (issue #35), read by a bin's middle within [min, max]
    as check-log's figures always were; the soak's reading of the same values is the bin's upper edge. A gap of
    20 ms computed with float noise counts in the 20.0 bin."""
    from ckesc.protocol.histogram import Histogram

    stats, upper = Intervals(), Histogram(0.0005, 1200)
    assert isinstance(stats, Histogram)
    for gap in (0.0201, 0.0202, 0.0203, 0.0204, 0.021 - 1e-12):
        stats.add(gap)
        upper.add(gap)
    assert stats.quantile(0.5) == pytest.approx(0.02025) and upper.quantile(0.5) == pytest.approx(0.0205)
    assert stats.to_json()["histogram"] == {"20.0": 4, "21.0": 1} and stats.to_json()["p50_ms"] == 20.25
    low, high = Intervals(), Intervals()
    low.add(0.0204), low.add(0.0204), high.add(0.0201), high.add(0.0201)
    assert low.quantile(0.5) == pytest.approx(0.0204), "never above the maximum"
    high.add(0.0209)
    assert high.quantile(0.0) == pytest.approx(0.02025) and Intervals().quantile(0.5) is None


def test_memory_is_bounded():
    """Statistics are fixed-size; a capture of ever new CAN ids does not grow the id cache without bound."""
    from ckesc.evidence import findings, tracker

    stats = Intervals()
    for i in range(10_000):
        stats.add(i * 0.001)
    assert len(stats.counts) == findings.HIST_BINS + 1 and stats.to_json()["histogram"]["overflow"] == 9400
    engine = BusRules()
    for i in range(tracker.ID_CACHE + 1000):
        engine.feed(0x10000000 | i << 8 | 5, b"\xc0", i * 1e-4)
    assert len(engine._ids) == tracker.ID_CACHE


def test_two_escs_sharing_a_node_id_are_not_compared():
    """Set ID sets every ESC on the bus (4.4.18-2): two answers from one node id mean two ESCs report from
    it, two transfer-id counters and two cadences in one stream: observed, not judged."""
    rules = BusRules(bitrate=BITRATE, complete=True)
    feed(rules, encode("set_id", {"node_id": 9, "throttle_channel": 1}, source=0, destination=1, transfer_id=0), 0.0)
    for i in range(2):
        answer = encode("set_id", {"node_id": 9, "throttle_channel": 1}, kind="response", source=9, destination=0)
        assert feed(rules, answer, 0.001 + 0.0003 * i) == []
    assert stream(rules, 9, [0.01, 0.013, 0.03, 0.033], tids=[0, 5, 1, 6]) == []
    (o,) = [o for o in rules.summary()["observations"] if o["check"] == "shared-node-id"]
    assert o["node"] == 9


def test_set_id_while_several_escs_report_takes_the_id_as_shared():
    """Two ESCs that take one id answer alike in the same slot (one frame on the bus): that they share it is
    known from there being two ESCs reporting when the Set ID went out; a single ESC's new id is still judged."""
    rules = BusRules(bitrate=BITRATE, complete=True)
    for i in range(2):
        stream(rules, 1, [0.02 * i], start_tid=i)
        stream(rules, 2, [0.02 * i + 0.001], start_tid=i)
    feed(rules, encode("set_id", {"node_id": 9, "throttle_channel": 1}, source=0, destination=1, transfer_id=0), 0.03)
    feed(rules, encode("set_id", {"node_id": 9, "throttle_channel": 1}, kind="response", source=9, destination=0), 0.049)
    assert stream(rules, 9, [0.06, 0.0603, 0.08, 0.0803], tids=[0, 0, 1, 1]) == []
    assert [o["check"] for o in rules.summary()["observations"]] == ["shared-node-id"]
    single = BusRules(bitrate=BITRATE, complete=True)  # one ESC moved to 9 and back: node 1 is not a second ESC
    stream(single, 1, [0.0, 0.02])
    feed(single, encode("set_id", {"node_id": 9, "throttle_channel": 1}, source=0, destination=1, transfer_id=0), 0.03)
    assert checks(stream(single, 9, [0.06, 0.0603], tids=[0, 0])) == ["transfer-id", "report-interval"]
    feed(single, encode("set_id", {"node_id": 1, "throttle_channel": 1}, source=0, destination=9, transfer_id=1), 0.07)
    assert checks(stream(single, 1, [0.1, 0.1003], tids=[2, 2])) == ["transfer-id", "report-interval"]


# ------------------------------------------------------------------------------------------ R9a restarts
def _resume(rules: BusRules, ts: float) -> None:
    feed(rules, encode("msg_control", {"option": 0, "command": cat.MSG_CONTROL_RESUME}, source=0), ts)


def test_r9a_an_esc_that_keeps_its_grid_is_not_judged_on_the_first_two_gaps():
    """R9a: after a resume the ESC may report at once and then go on on its old grid (a 3 ms gap): the gaps
    up to the second report are OBSERVE; from the third report on R9 holds."""
    rules = BusRules(bitrate=BITRATE, complete=True)
    t = stated(rules, 1, 0.0)
    stream(rules, 1, [t, t + 0.02])
    feed(rules, encode("msg_control", {"option": 0, "command": cat.MSG_CONTROL_SUSPEND}, source=0), t + 0.025)
    _resume(rules, t + 0.057)
    assert stream(rules, 1, [t + 0.0575, t + 0.06, t + 0.08, t + 0.10], start_tid=2) == []
    (v,) = stream(rules, 1, [t + 0.11], start_tid=6)  # the third gap on: R9
    assert v.check == "report-interval" and "R9" in v.rules


def test_r9a_the_first_report_after_a_restart_comes_within_one_interval():
    rules = BusRules(bitrate=BITRATE, complete=True)
    t = stated(rules, 1, 0.0)
    stream(rules, 1, [t, t + 0.02])
    feed(rules, encode("can_test", {"option": cat.CAN_TEST_ON, "count": 0}, source=0), t + 0.025)
    feed(rules, encode("can_test", {"option": cat.CAN_TEST_OFF, "count": 0}, source=0), t + 0.05)
    (v,) = stream(rules, 1, [t + 0.08], start_tid=2)  # 30 ms after CAN Test off, the interval is 20 ms
    assert v.check == "first-report" and v.rules[0] == "R9a" and v.strength == "READING"
    assert "can_test 0x55" in v.message and "expected within one interval plus a slack, 25.000 ms" in v.message


D7 = frame_bits(7) / BITRATE  # an MSG1 frame (6 payload bytes + tail) on the bus
EDGE = 1e-6  # just inside or just outside a limit (the simulated lane is exact: its tolerance is 0)


def _can_test_off(rules: BusRules, ts: float) -> None:
    feed(rules, encode("can_test", {"option": cat.CAN_TEST_ON, "count": 0}, source=0), ts - 0.01)
    feed(rules, encode("can_test", {"option": cat.CAN_TEST_OFF, "count": 0}, source=0), ts)


def _set_freq_write(rules: BusRules, ts: float, msg1_interval: int) -> None:
    fields = {"option": 1, **INTERVALS, "msg1_interval": msg1_interval}
    feed(rules, encode("set_freq", fields, source=0, destination=1, transfer_id=1), ts)
    feed(rules, encode("set_freq", fields, kind="response", source=1, destination=0, transfer_id=1), ts + 0.001)


def _first_msg1_after(event, limit: float, inside: bool, before: int = 10) -> list:
    """The violations of an MSG1 that starts ``limit`` (+- EDGE) after ``event(rules, ts)``, on a bus that was
    idle (so it was due when it started); MSG1 stated at ``before`` x 2 ms."""
    rules = BusRules(bitrate=BITRATE, complete=True)
    t = stated(rules, 1, 0.0, {**INTERVALS, "msg1_interval": before})
    stream(rules, 1, [t, t + before * 0.002])
    ev = t + before * 0.002 + 0.005
    event(rules, ev)
    return checks(stream(rules, 1, [ev + limit + (-EDGE if inside else EDGE) + D7], start_tid=2))


@pytest.mark.parametrize("inside", [True, False], ids=["inside", "outside"])
@pytest.mark.parametrize("event, before, limit", [
    (_resume, 10, 0.025),  # 20 ms + a quarter of it (5 ms > 3 ms)
    (_resume, 250, 0.625),  # 500 ms + 125 ms
    (_can_test_off, 10, 0.025),
    (_can_test_off, 100, 0.25),  # 200 ms + 50 ms
], ids=["resume-20ms", "resume-500ms", "can-test-off-20ms", "can-test-off-200ms"])
def test_r9a_the_first_report_after_a_restart_within_one_interval_and_a_quarter(event, before, limit, inside):
    """R9a: within one interval plus a slack of max(3 ms, a quarter interval) (for every legal interval, 20 ms
    and up, the quarter is the larger); exact timestamps: a report just inside passes, just outside fails."""
    assert _first_msg1_after(event, limit, inside, before) == ([] if inside else ["first-report"])


@pytest.mark.parametrize("inside", [True, False], ids=["inside", "outside"])
@pytest.mark.parametrize("before, after, limit", [
    (10, 25, 0.0625),  # 20 -> 50 ms: the new one is the longer, 50 + 12.5 ms
    (25, 10, 0.0625),  # 50 -> 20 ms: the report already due on the old 50 ms may go first
    (10, 250, 0.625),  # 20 -> 500 ms
    (250, 10, 0.625),  # 500 -> 20 ms
], ids=["20-to-50ms", "50-to-20ms", "20-to-500ms", "500-to-20ms"])
def test_r9a_after_a_set_freq_write_within_the_longer_of_old_and_new_interval(before, after, limit, inside):
    """R9a: after a Set Freq write the first report comes within the longer of its old and new interval plus
    the same slack (the old interval is what the node last said)."""
    found = _first_msg1_after(lambda rules, ts: _set_freq_write(rules, ts, after), limit, inside, before)
    assert found == ([] if inside else ["first-report"])


def test_r9a_a_set_freq_write_to_a_node_that_stated_no_interval_allows_the_longest_legal_one():
    """Without an old interval the node said, the first report after a write may come as late as the longest
    legal interval and its slack (500 + 125 ms) allow."""
    rules = BusRules(bitrate=BITRATE, complete=True)
    stream(rules, 1, [0.0, 0.02])
    _set_freq_write(rules, 0.025, 10)
    assert stream(rules, 1, [0.025 + 0.625 - EDGE + D7], start_tid=2) == []
    rules = BusRules(bitrate=BITRATE, complete=True)
    stream(rules, 1, [0.0, 0.02])
    _set_freq_write(rules, 0.025, 10)
    (v,) = stream(rules, 1, [0.025 + 0.625 + EDGE + D7], start_tid=2)
    assert v.check == "first-report" and "the longer of its old and new interval" in v.message


def test_r9a_after_a_set_freq_write_the_gaps_up_to_the_second_report_are_not_judged():
    """The ESC that lets the report due on the old interval go first (MSG1 at 50 ms, then 20 ms): the first
    within the old interval, the gap to the second not judged, R9 with the new interval from the third on."""
    rules = BusRules(bitrate=BITRATE, complete=True)
    t = stated(rules, 1, 0.0, {**INTERVALS, "msg1_interval": 25})
    stream(rules, 1, [t, t + 0.05])
    _set_freq_write(rules, t + 0.052, 10)  # 50 -> 20 ms; the next report was due at t + 0.1 on the old grid
    assert stream(rules, 1, [t + 0.1, t + 0.113, t + 0.133], start_tid=2) == []  # first; 13 ms: not judged; 20 ms
    (v,) = stream(rules, 1, [t + 0.163], start_tid=5)  # 30 ms: the third gap on is R9's
    assert v.check == "report-interval" and "expected 20.000 ms" in v.message


def test_r9a_a_restart_before_the_first_report_after_a_set_freq_write_keeps_its_limit():
    """A resume right after a write from 500 to 20 ms (a test's restore): the report still due on the old 500 ms
    may come first, as the write allowed (within 625 ms of it), though later than 25 ms after the resume; once it
    has come, the next resume is judged on its own again."""
    rules = BusRules(bitrate=BITRATE, complete=True, power_known=True)
    t = stated(rules, 1, 0.0, {**INTERVALS, "msg1_interval": 250})
    stream(rules, 1, [t, t + 0.5])
    _set_freq_write(rules, t + 0.51, 10)
    _resume(rules, t + 0.52)
    assert stream(rules, 1, [t + 0.51 + 0.625 - EDGE + D7], start_tid=2) == []
    _resume(rules, t + 1.2)
    (v,) = stream(rules, 1, [t + 1.2 + 0.025 + EDGE + D7], start_tid=3)
    assert v.check == "first-report" and "expected within one interval plus a slack, 25.000 ms" in v.message
    rules = BusRules(bitrate=BITRATE, complete=True, power_known=True)
    t = stated(rules, 1, 0.0, {**INTERVALS, "msg1_interval": 250})
    stream(rules, 1, [t, t + 0.5])
    _set_freq_write(rules, t + 0.51, 10)
    _resume(rules, t + 0.52)
    (v,) = stream(rules, 1, [t + 0.51 + 0.625 + EDGE + D7], start_tid=2)
    assert v.check == "first-report" and "what an earlier restart still allowed" in v.message


def test_r9a_a_set_freq_write_counts_from_the_write_with_the_new_interval():
    rules = BusRules(bitrate=BITRATE, complete=True)
    t = stated(rules, 1, 0.0)
    stream(rules, 1, [t, t + 0.02])
    feed(rules, encode("set_freq", {"option": 1, **INTERVALS, "msg1_interval": 25}, source=0, destination=1, transfer_id=1),
         t + 0.03)
    feed(rules, encode("set_freq", {"option": 1, **INTERVALS, "msg1_interval": 25}, kind="response", source=1, destination=0,
                       transfer_id=1), t + 0.031)
    (v,) = stream(rules, 1, [t + 0.095], start_tid=2)  # 65 ms after the write: later than the new 50 ms + 12.5 ms
    assert v.check == "first-report" and "a Set Freq write" in v.message


def test_r9a_a_power_cycle_voids_the_event():
    """The first report after a power-up is the boot's: a resume before it is not what it answers; the first
    two gaps after the power-up are not judged either."""
    rules = BusRules(bitrate=BITRATE, complete=True)
    t = stated(rules, 1, 0.0)
    stream(rules, 1, [t, t + 0.02])
    feed(rules, encode("msg_control", {"option": 0, "command": cat.MSG_CONTROL_SUSPEND}, source=0), t + 0.025)
    _resume(rules, t + 0.03)
    rules.power_switched(t + 0.031)
    assert stream(rules, 1, [t + 1.5, t + 1.503, t + 1.523], start_tid=0) == []


def test_r9a_in_a_capture_a_very_late_first_report_is_only_recorded():
    """A capture does not show power cycles: a first report more than two intervals after the event may follow
    one, and is recorded, not judged."""
    rules = BusRules(bitrate=BITRATE, complete=True)
    t = stated(rules, 1, 0.0)
    stream(rules, 1, [t, t + 0.02])
    _resume(rules, t + 0.03)
    assert stream(rules, 1, [t + 2.0], start_tid=2) == []
    assert [v.check for v in rules.findings(observations=True)] == ["first-report-unjudged"]


def test_the_hosts_own_frames_ahead_of_the_bus_stretch_no_report_interval():
    """The bench matrix without echo (fb825ac): the host's own frame, timed by its send, is handed to the reader
    before the ESC's report stamped 5 ms earlier that it had not read yet. The busy stretch the own frame opened
    began after that report's start, the report took it as its own, and its next 20 ms gap was judged against
    'bus queueing allows up to 15 ms': an R9 FAIL on a conforming emulator in 13 tests. A report's busy stretch
    never starts after the report."""
    rules = BusRules(bitrate=BITRATE, complete=True, tolerance=0.002)
    t = stated(rules, 1, 0.0)
    out = stream(rules, 1, [t + 0.02 * i for i in range(4)])
    own = encode("get_esc_id", {"option": 0}, source=0, transfer_id=1, layout="query")
    out += feed(rules, own, t + 0.085, own=True)  # sent at 85 ms, handed out before the report of 80 ms
    out += stream(rules, 1, [t + 0.02 * i for i in range(4, 10)], start_tid=4)
    assert checks(out) == [], [str(v) for v in out]
