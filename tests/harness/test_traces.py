"""Per-test traces: the lanes' listener hook, and the plugin's BLF/ASC file per test, read back
with python-can's own LogReader."""

from __future__ import annotations

import json
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import can
import pytest

from ckesc.bench.sim_lane import SimLane
from ckesc.bench.station import MULTI_NODES
from ckesc.protocol import DecodeError, Decoder, encode
from ckesc.protocol.ids import parse_can_id
from ckesc.session.trace_files import TRACE_FORMATS, TestTraces, trace_name


class _Collect(can.Listener):
    def __init__(self) -> None:
        self.msgs: list[can.Message] = []

    def on_message_received(self, msg: can.Message) -> None:
        self.msgs.append(msg)


def test_lane_listeners_hear_both_directions_and_frames_that_do_not_decode():
    lane = SimLane(nodes=(1,), esc_config={"boot_time": 0.0})
    try:
        heard = _Collect()
        lane.listeners.append(heard)
        wire = encode("get_esc_id", {"option": 0}, source=0, transfer_id=0, layout="query")
        lane.bus.send(can.Message(arbitration_id=wire.arbitration_id, data=wire.data, is_extended_id=True))
        junk = can.Message(arbitration_id=0x123, data=b"\x01\x02", is_extended_id=False)  # no CKESC frame at all
        lane.bus.send(junk)
        got = []
        while (msg := lane.recv(0.1 - lane.now())) is not None:
            got.append(msg)
    finally:
        lane.close()
    assert heard.msgs == got, "the listeners see exactly what the lane hands out, in order"
    own = [m for m in got if not m.is_rx]
    # both queued at once: the host's queue is SocketCAN's (first in, first out), so they go in the order sent
    assert [m.arbitration_id for m in own] == [wire.arbitration_id, 0x123], "the host's sends, as their echoes"
    decoded = [Decoder().decode(m) for m in got if m.is_extended_id]
    assert [(f.source, f.layout.name) for f in decoded if f.name == "get_esc_id"] == [(0, "query"), (1, "reply")]
    assert any(f.name == "msg1" and f.source == 1 for f in decoded), "the ESC's reports"
    assert all(m.timestamp > 0 for m in got) and [m.timestamp for m in got] == sorted(m.timestamp for m in got)


def test_a_lane_without_listeners_is_unchanged():
    lane = SimLane(nodes=(1,))
    try:
        assert lane.listeners == []
        assert lane.heard(None) is None
        other = SimLane(nodes=(1,))
        try:
            lane.listeners.append(_Collect())
            assert other.listeners == [], "each lane has its own listeners"
        finally:
            other.close()
    finally:
        lane.close()


# ------------------------------------------------------------------------------------------ TestTraces
@pytest.mark.parametrize("nodeid, name", [
    ("conformance/test_s4_4_22_set_freq.py::test_write_sets_the_report_intervals[10-50-250]",
     "test_s4_4_22_set_freq__test_write_sets_the_report_intervals_10-50-250.blf"),
    ("conformance/test_s4_1_framing.py::test_x[a/b c::d]", "test_s4_1_framing__test_x_a_b_c_d.blf"),
    ("conformance/test_m.py::test_illegal[msg1_interval=251 (max+1)]", "test_m__test_illegal_msg1_interval=251_max_1.blf"),
])
def test_trace_name_is_a_readable_safe_file_name(nodeid, name):
    assert trace_name(nodeid, "blf") == name


def test_long_and_clashing_ids_get_distinct_names(tmp_path):
    long_id = "conformance/test_m.py::test_x[" + "v" * 400 + "]"
    assert len(trace_name(long_id, "blf")) <= 160
    assert trace_name(long_id, "blf") != trace_name(long_id[:-2] + "w]", "blf")
    traces = TestTraces(tmp_path)
    msg = can.Message(arbitration_id=1, data=b"\x01")
    files = []
    for nodeid in ("conformance/test_m.py::test_x[a b]", "conformance/test_m.py::test_x[a/b]"):
        traces.begin(nodeid)
        traces.write("", msg)
        files += traces.end().values()
    assert len(set(files)) == 2 and all(f.is_file() for f in files)


def _traffic(lane: SimLane) -> list[can.Message]:
    """What a test might see: a request, its answer, the ESC's reports, a standard-id frame and an error
    frame (neither decodes)."""
    wire = encode("get_esc_id", {"option": 0}, source=0, transfer_id=0, layout="query")
    lane.bus.send(can.Message(arbitration_id=wire.arbitration_id, data=wire.data, is_extended_id=True))
    lane.bus.send(can.Message(arbitration_id=0x123, data=b"\x01\x02", is_extended_id=False))
    lane.bus.send(can.Message(arbitration_id=0x1FFFFFFF, is_extended_id=True, is_error_frame=True))
    got = []
    while (msg := lane.recv(0.1 - lane.now())) is not None:
        got.append(msg)
    return got


@pytest.mark.parametrize("fmt", [f for f in TRACE_FORMATS if f != "none"])
def test_one_file_per_test_that_python_can_reads_back(tmp_path, fmt):
    lane = SimLane(nodes=(1,), esc_config={"boot_time": 0.0})
    traces = TestTraces(tmp_path / "traces", fmt)
    lane.listeners.append(traces.listener())
    try:
        traces.begin("conformance/test_m.py::test_a")
        seen = _traffic(lane)
        files = traces.end()
        assert list(files) == [""]
        path = files[""]
        traces.begin("conformance/test_m.py::test_skipped_before_any_frame")
        assert traces.end() == {}
        lane.recv(0.05)  # between tests: in no file
    finally:
        lane.close()
    assert sorted(p.name for p in (tmp_path / "traces").iterdir()) == [f"test_m__test_a.{fmt}"], \
        "one file for the test with frames, none for the test without"
    back = list(can.LogReader(path))
    assert len(back) == len(seen)
    for a, b in zip(seen, back):
        assert b.is_error_frame == a.is_error_frame
        # intervals are kept to the microsecond (ASC stores its start to the millisecond; BLF exactly)
        assert b.timestamp - back[0].timestamp == pytest.approx(a.timestamp - seen[0].timestamp, abs=1e-6)
        if fmt == "blf":
            assert b.timestamp == pytest.approx(a.timestamp, abs=1e-9)
        if a.is_error_frame:
            continue  # BLF keeps no direction, candump no id for an error frame
        assert (b.arbitration_id, bytes(b.data), b.is_extended_id) == (a.arbitration_id, bytes(a.data), a.is_extended_id)
        if fmt != "log":  # candump -L lines carry no direction
            assert b.is_rx == a.is_rx
    assert {m.is_rx for m in seen} == {True, False}, "both directions"
    assert any(not m.is_extended_id for m in back) and any(m.is_error_frame for m in back), "frames that do not decode"


def test_each_lane_has_its_own_file(tmp_path):
    """A private bench's clock is its own: its frames go to <test>.bench.blf, never between the DUT's."""
    dut_lane, bench = SimLane(nodes=(1,), esc_config={"boot_time": 0.0}), SimLane(nodes=(1, 2), esc_config={"boot_time": 0.0})
    traces = TestTraces(tmp_path, "blf")
    dut_lane.listeners.append(traces.listener())
    bench.listeners.append(traces.listener("bench"))
    try:
        dut_lane.wait_power(1.0)  # the DUT lane's clock runs ahead of the bench's
        traces.begin("conformance/test_m.py::test_multi")
        on_dut, on_bench = _traffic(dut_lane), _traffic(bench)
        files = traces.end()
    finally:
        dut_lane.close()
        bench.close()
    assert {k: v.name for k, v in files.items()} == {"": "test_m__test_multi.blf", "bench": "test_m__test_multi.bench.blf"}
    for name, seen in (("", on_dut), ("bench", on_bench)):
        assert [m.timestamp for m in can.LogReader(files[name])] == pytest.approx([m.timestamp for m in seen], abs=1e-9)


def test_an_unknown_format_is_refused(tmp_path):
    with pytest.raises(ValueError, match="blf, asc, log"):
        TestTraces(tmp_path, "pcap")


# ------------------------------------------------------------------------------------------ in a run
def _ckesc_run(reports: Path, *args: str) -> Path:
    subprocess.run([sys.executable, "-m", "ckesc", "run", "-q", "--reports", str(reports), *args],
                   capture_output=True, text=True, timeout=300)
    runs = [p for p in reports.iterdir() if p.is_dir() and not p.is_symlink()]
    assert len(runs) == 1, f"one run directory expected in {reports}: {runs}"
    return runs[0]


def test_a_run_writes_each_tests_traffic_and_junit_links_it(tmp_path):
    out = _ckesc_run(tmp_path, "--emulator-faults", "tail_not_single_frame", "--",
                     "-k", "test_s4_1_framing and tail_byte or test_s4_4_22 and read_answers_the_current "
                           "or test_every_esc_replies_in_its_slot")
    results = {r["nodeid"]: r for r in json.loads((out / "results.json").read_text())["results"]}
    assert len(results) == 4 and "FAIL" in {r["outcome"] for r in results.values()}, "failing tests keep their traces"
    multi = next(r for n, r in results.items() if "every_esc_replies" in n)
    assert set(multi["traces"]) == {"bench"}, "multi_dut's private bench has its own trace"
    bench = {parse_can_id(m.arbitration_id).source for m in can.LogReader(out / multi["traces"]["bench"])}
    assert bench == {0, *MULTI_NODES}
    traced = {n: r["traces"][""] for n, r in results.items() if "" in r["traces"]}
    files = [out / t for r in results.values() for t in r["traces"].values()]
    assert sorted((out / "traces").iterdir()) == sorted(files), "one file per test and lane with frames"
    assert any("set_freq" in n for n in traced) and any("tail_byte" in n for n in traced)

    cases = {c.get("name"): c for c in ET.parse(out / "junit.xml").getroot().iter("testcase")}
    for nodeid, trace in traced.items():
        case = next(c for name, c in cases.items() if name.startswith(results[nodeid]["name"] + " "))
        assert case.find("properties/property[@name='trace']").get("value") == trace
        attached = [ln for ln in case.findtext("system-out").splitlines() if ln.startswith("[[ATTACHMENT|")]
        assert attached == [f"[[ATTACHMENT|{(out / trace).resolve()}]]"] and (out / trace).is_file()
    multi_case = next(c for name, c in cases.items() if name.startswith(multi["name"] + " "))
    assert multi_case.find("properties/property[@name='trace.bench']").get("value") == multi["traces"]["bench"]

    decoder = Decoder()
    frames = [m for t in traced.values() for m in can.LogReader(out / t)]
    host = [m for m in frames if not m.is_rx]
    assert host and all(parse_can_id(m.arbitration_id).source == 0 for m in host if m.is_extended_id), "the host's frames"
    garbled = []
    for m in frames:
        try:
            decoder.decode(m)
        except DecodeError:
            garbled.append(m)
    assert any(m.is_rx and parse_can_id(m.arbitration_id).source == 1 for m in garbled), \
        "the faulty ESC's frames that do not decode are in the trace"


def test_trace_format_none_writes_no_traces(tmp_path):
    out = _ckesc_run(tmp_path, "--", "-k", "test_s4_4_22 and read_answers_the_current", "--ckesc-trace-format", "none")
    assert not (out / "traces").exists()
    assert all(r["traces"] == {} for r in json.loads((out / "results.json").read_text())["results"])
    assert "ATTACHMENT" not in (out / "junit.xml").read_text()
