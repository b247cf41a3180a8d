"""The bus rules note a reset wherever one shows (R19, R17; issue #30 item 4): a 241 option 2 power-up count that grew,
an option 1 run time that went back, a report gap with a transfer id restart, each with no power switch by the host
between; never what the host made (a power switch it reported, MSG Control, CAN Test, Set ID). Hand-built frames
first, then the emulator's reset faults on a simulated bus (sans-IO: every frame fed to the engine)."""

from __future__ import annotations

import json
import subprocess
import sys

import can

from ckesc.cli import main
from ckesc.evidence import BusRules
from ckesc.protocol import catalogue as cat
from ckesc.protocol.frame import encode

from .test_rules import BITRATE, checks, feed, stated, stream
from .traffic import ScriptedHost


def engine(**kw) -> BusRules:
    return BusRules(bitrate=BITRATE, complete=True, power_known=True, **kw)


def maintenance(rules: BusRules, ts: float, option: int, fields: dict, tid: int, node: int = 1) -> list:
    """The host asks node 241 with ``option``; the node answers ``fields`` 2 ms later."""
    feed(rules, encode("maintenance_information", {"option": option}, source=0, destination=node, transfer_id=tid), ts)
    return feed(rules, encode("maintenance_information", fields, kind="response", source=node, destination=0,
                              transfer_id=tid, layout=f"response_option_{option}"), ts + 0.002)


def counters(ups: int) -> dict:
    return {"power_ups": ups, "stops": 0, "fault_code": 0, "option": 2}


def run_time(s: int) -> dict:
    return {"run_time": s, "runs": 1, "info_7": 0}


# ------------------------------------------------------------------------------------------ 241's counters
def test_power_up_count_grown_with_the_power_on_is_a_reset():
    rules = engine()
    assert maintenance(rules, 0.0, 2, counters(7), tid=0) == []
    assert maintenance(rules, 1.0, 2, counters(7), tid=1) == []
    [v] = maintenance(rules, 2.0, 2, counters(8), tid=2)
    assert v.check == "reset" and v.rules == ("R19", "R17") and v.node == 1
    assert "power-up count (241 option 2) went from 7 to 8" in v.message and "power_ups 8" in v.frames[0]


def test_power_up_count_across_a_power_switch_or_a_set_id_is_not_judged():
    rules = engine()
    maintenance(rules, 0.0, 2, counters(7), tid=0)
    rules.power_switched(0.5)
    rules.power_switched(0.6)
    assert maintenance(rules, 1.0, 2, counters(8), tid=1) == []
    feed(rules, encode("set_id", {"node_id": 1, "throttle_channel": 1}, source=0, destination=1, transfer_id=0), 1.5)  # maybe another ESC now
    assert maintenance(rules, 2.0, 2, counters(30), tid=2) == []
    assert checks(maintenance(rules, 3.0, 2, counters(31), tid=3)) == ["reset"]  # judged again from there


def test_power_up_count_grown_while_the_node_talked_throughout_is_no_reset():
    """A reset boots first: a count that grew with no silence of the node between counts something else (4.4.27-T's
    tests judge what it counts; the emulator's maintenance_counts_wrong swaps it with the stop count)."""
    rules = engine()
    maintenance(rules, 0.0, 2, counters(7), tid=0)
    stream(rules, 1, [0.01 + 0.02 * i for i in range(50)])
    assert maintenance(rules, 1.0, 2, counters(8), tid=1) == []


def test_a_capture_records_a_reset_it_cannot_tell_from_a_power_cycle():
    rules = BusRules(bitrate=BITRATE, complete=True)  # power_known False: a capture shows no power switch
    maintenance(rules, 0.0, 2, counters(7), tid=0)
    assert maintenance(rules, 1.0, 2, counters(8), tid=1) == []
    [o] = [o for o in rules.findings(observations=True) if o.check == "reset-unjudged"]
    assert o.rules == ("R19", "R17") and "unless the power was switched" in o.message


def test_run_time_going_back_is_a_reset_standing_still_is_not():
    rules = engine()
    assert maintenance(rules, 0.0, 1, run_time(100), tid=0) == []
    assert maintenance(rules, 5.0, 1, run_time(100), tid=1) == []  # the motor stopped: it stands still
    assert maintenance(rules, 8.0, 1, run_time(103), tid=2) == []  # it ran 3 s of the 3 s
    [v] = maintenance(rules, 9.0, 1, run_time(2), tid=3)
    assert v.check == "reset" and "went back from 103 s to 2 s" in v.message
    # option 2 and option 1 are apart: a power-up count read between run times is not a run time
    assert maintenance(rules, 10.0, 2, counters(3), tid=4) == [] and maintenance(rules, 11.0, 1, run_time(3), tid=5) == []


# ------------------------------------------------------------------------------------------ report restarts
def test_a_report_gap_with_a_transfer_id_restart_is_a_reset():
    rules = engine()
    t = stated(rules, 1, 0.0)
    assert stream(rules, 1, [t + 0.02 * i for i in range(10)], start_tid=5) == []  # tids 5..14
    after = stream(rules, 1, [t + 0.2 + 0.25 + 0.02 * i for i in range(3)], start_tid=0)  # a 250 ms boot, then 0
    [v] = [v for v in after if v.check == "reset"]
    assert v.rules == ("R19", "R17") and "msg1 stopped for" in v.message and "transfer id 0 after 14" in v.message


def test_a_power_switch_noted_before_the_reports_around_it_are_read_is_the_hosts():
    """A lane hands frames over as the host reads them: ``ckesc explore`` switched the power while the reports
    stamped before the switch were still unread. The switch's time decides, not the order the engine heard of it."""
    rules = engine()
    t = stated(rules, 1, 0.0)
    assert stream(rules, 1, [t + 0.02 * i for i in range(10)], start_tid=5) == []
    rules.power_switched(t + 0.3)  # off and on, noted before the last report before it is read
    rules.power_switched(t + 0.5)
    assert stream(rules, 1, [t + 0.2], start_tid=15) == []  # stamped before the switch, read after it
    assert [v for v in stream(rules, 1, [t + 0.75 + 0.02 * i for i in range(3)], start_tid=0) if v.check == "reset"] == []


def test_report_restarts_the_host_made_are_not_resets():
    """The same gap and restart across a power switch the host reported, a suspend and resume, CAN Test on and off."""
    def after(event) -> list:
        rules = engine()
        t = stated(rules, 1, 0.0)
        stream(rules, 1, [t + 0.02 * i for i in range(10)], start_tid=5)
        event(rules, t + 0.2)
        return checks(stream(rules, 1, [t + 0.45 + 0.02 * i for i in range(3)], start_tid=0))

    def switch(rules, ts):
        rules.power_switched(ts)
        rules.power_switched(ts + 0.01)

    def host(name, first, second):
        def event(rules, ts):
            for i, value in enumerate((first, second)):
                feed(rules, encode(name, {"option": 0, "command": value} if name == "msg_control" else
                                   {"option": value, "count": 0}, source=0, transfer_id=i), ts + 0.1 * i)
        return event

    assert "reset" in after(lambda rules, ts: None)
    for event in (switch, host("msg_control", cat.MSG_CONTROL_SUSPEND, cat.MSG_CONTROL_RESUME),
                  host("can_test", cat.CAN_TEST_ON, cat.CAN_TEST_OFF)):
        assert "reset" not in after(event), event


def test_a_late_report_counting_on_is_no_reset_but_r9s():
    """A silence with no power switch (every one reported) and the counter counting on: a late report, R9's (issue
    #35: the losing reading took any silence for a possible power cycle and judged nothing across it); with a power
    switch reported meanwhile, nothing is compared across it."""
    rules = engine()
    t = stated(rules, 1, 0.0)
    late = stream(rules, 1, [t + 0.02 * i for i in range(10)] + [t + 0.5], start_tid=5)
    assert checks(late) == ["report-interval"] and "R9" in late[0].rules  # a silence, no restart
    rules = engine()
    t = stated(rules, 1, 0.0)
    rules.power_switched(t + 0.3)
    assert stream(rules, 1, [t + 0.02 * i for i in range(10)] + [t + 0.5], start_tid=5) == []


# ------------------------------------------------------------------------------------------ the emulator's faults
def emulated(faults, play, *, keep: bool = False):
    """The checks the bus rules (told of no power switch: none is made) find while ``play`` drives the emulator (with
    ``keep``: and the frames)."""
    host = ScriptedHost((1,), faults, keep=keep)
    host.run.rules = engine()
    try:
        host.pump(0.5)
        host.request("maintenance_information", {"option": 2}, 1)
        play(host)
        host.request("maintenance_information", {"option": 2}, 1)
        host.pump(0.1)
        return (checks(host.run.violations), host.run.messages) if keep else checks(host.run.violations)
    finally:
        host.close()


def multi_frame_start(host) -> None:
    wire = host.host.request("self_test", {}, destination=1, now=host.bus.now(), timeout=0.1)[0]
    host.send(wire._replace(data=wire.data[:-1] + bytes((wire.data[-1] & 0x1F | 0x80,))))  # start=1 end=0
    host.pump(0.5)


def stream_for(seconds: float):
    def play(host) -> None:
        for _ in range(int(seconds / 0.01)):  # 100 Hz, zero throttle: one unbroken stream
            host.broadcast("raw_command_14b", {"channels": [0, 0, 0, 0]})
            host.pump(0.01)
    return play


def test_a_reset_on_a_multi_frame_start_is_found():
    assert emulated((), multi_frame_start) == []
    assert emulated(("reset_on_multi_frame_start",), multi_frame_start).count("reset") >= 2  # reports and 241


def test_a_reset_after_a_stream_is_found():
    """The soak fault with its onset moved to 5 s of stream (docs/emulator.md)."""
    assert emulated(("reset_after_streaming=5",), stream_for(4.5)) == []  # before its onset
    assert emulated(("reset_after_streaming=5",), stream_for(5.5)).count("reset") >= 2


def test_a_conformance_run_shows_the_reset_in_results_json(tmp_path):
    """End to end: R17's malformed-frame test on an ESC that resets on a multi-frame start; results.json names the live
    rule's reset (its own check FAILs it on R17 too; the bus rules add R19 and R17). The frames the host sent while the
    ESC rebooted wait in its queue and meet the ESC at its boot (R20), where the whole transfer's start resets it
    again: the test's own check says it did not answer then, where a bus without acknowledgement had lost them and
    the count was read (1 to 2)."""
    test = "conformance/test_robustness_r17_malformed.py::test_malformed_frames_are_ignored[can_test]"
    done = subprocess.run([sys.executable, "-m", "ckesc", "run", "-q", "--trace-format", "none", "--reports", str(tmp_path),
                           "--emulator-faults", "reset_on_multi_frame_start", test], capture_output=True, text=True,
                          timeout=600)
    results = tmp_path / "latest" / "results.json"
    assert results.is_file(), done.stdout[-3000:] + done.stderr[-3000:]
    [r] = json.loads(results.read_text())["results"]
    assert r["outcome"] == "FAIL" and r["bus_rules"][:2] == ["R19", "R17"], r
    assert "afterwards it did not answer" in done.stdout + results.read_text()  # (the test's own check, on R17)
    causes = [c["first"] for c in r["bus_causes"] if c["check"] == "reset"]
    # and the reports' restart across it: the malformed frame switched nothing (R17, evidence/taken.py), so the
    # reader judges the gap (before, it took the frame for CAN Test on and judged no report across it)
    assert any("stopped for" in c and "its counter started again" in c for c in causes), causes


def test_check_log_reports_a_reset_in_a_capture(tmp_path, capsys):
    """A capture with a reset: an observation (a power cycle would look the same), a violation with --power-on."""
    _, messages = emulated(("reset_on_multi_frame_start",), multi_frame_start, keep=True)
    path = tmp_path / "reset.log"
    with can.Logger(str(path)) as writer:
        for msg in messages:
            writer.on_message_received(msg)
    assert main(["check-log", str(path), "--complete"]) == 0
    out = capsys.readouterr().out
    assert "a reset, unless the power was switched (a capture does not show it): the power-up count" in out, out
    assert main(["check-log", str(path), "--complete", "--power-on"]) == 1
    out = capsys.readouterr().out
    assert "[R19 R17 " in out and "a reset the host did not make: the power-up count (241 option 2) went from 1 to 2" in out, out
