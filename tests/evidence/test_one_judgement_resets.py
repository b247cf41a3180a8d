"""One trace, every consumer that judges resets, one finding (issue #35): R19 (and R17's "never resets") over the
frames of an emulated ESC that the host reads 241 of (option 2, the power-up count; option 1, the run time) before and
after a while of reporting. The faultless ESC shows no reset to any consumer; an ESC that resets meanwhile (its power
cut and back for 20 ms, as a watchdog reset looks, nobody saying so) shows R19 to each:

* the suite's helper (:func:`conformance.resets.reset_signs`, which the R17 tests call: a report gap with a transfer
  id restart, the power-up count grown modulo its u16 width);
* the live bus rules (:class:`~ckesc.evidence.rules.BusRules` with every power switch reported, as a suite's lane and
  ``ckesc explore``'s runner run them: ``evidence/live.LaneRules``);
* ``ckesc check-log --power-on`` (a flight's capture, the power known to stay on);
* the soak's reset watch (:class:`~ckesc.soak.reset_watch.ResetWatch`, fed by its :class:`~ckesc.soak.monitor.Monitor`).

Who does not judge what, and why:

* the suite's helper does not read the run time (241 option 1): the R17 tests read the power-up count and the reports;
* ``ckesc explore``'s own judge judges a reset only across a malformed frame (R17, ``judge._r17_restarts``) and 241's
  power-up count against its model's; a reset in a program without either is its runner's live bus rules' finding
  (the bus rules above), as F3 is (:mod:`.test_one_judgement`).

The power-up count's u16 wrap (65535 then 0) is a power-up like any other (``judgements.r19_power_ups``): a reset to
every consumer, and an unchanged 65535 none."""

from __future__ import annotations

from types import SimpleNamespace

import pytest

from ckesc.evidence.tracker import RESET_FIELDS
from ckesc.protocol.frame import Decoder
from ckesc.soak.monitor import Monitor
from ckesc.soak.watch import WatchConfig
from conformance.resets import reset_signs

from .test_one_judgement import NODE, bus_rules, check_log, play, request

#: the host reads 241 option 2, then option 1, at these times: before the reset and after it
READS = (0.40, 1.40)
#: the watchdog reset: the power gone for 20 ms, nobody saying so; the trace's end
RESET_AT, END_S = 0.80, 1.80
INTERVAL = {"msg1": 0.020, "msg2": 0.100, "msg3": 0.500}


def _trace(reset: bool, *, power_ups: int = 7, run_time: tuple[int, int] | None = None, faults: tuple[str, ...] = ()) -> list:
    """The host's 241 reads around ``RESET_AT`` (a reset there, or none) of an ESC whose power-up count reads
    ``power_ups`` before it; ``run_time``: the run time (s) the two option 1 answers say instead of the ESC's own."""
    events = []
    for k, t in enumerate(READS):
        events += [(t, request("maintenance_information", {"option": 2}, t, transfer_id=2 * k)),
                   (t + 0.05, request("maintenance_information", {"option": 1}, t + 0.05, transfer_id=2 * k + 1))]
    if reset:
        events += [(RESET_AT, "off"), (RESET_AT + 0.02, "on")]
    frames = play(sorted(events, key=lambda e: e[0]), END_S, nvm={"power_ups": power_ups - 1}, faults=faults)
    if run_time is not None:  # the option 1 answers (their request's transfer id odd) rewritten: a run time gone back
        field = RESET_FIELDS[1]
        answers = [m for m in frames if m.is_rx and (m.arbitration_id >> 16) & 0xFF == 241 and m.data[-1] & 1]
        assert len(answers) == 2
        for m, value in zip(answers, run_time):
            m.data[field.offset:field.offset + field.size] = value.to_bytes(field.size, "little")
    return frames


def _suite(frames) -> set[str]:
    """As the R17 tests ask :func:`~conformance.resets.reset_signs`: MSG1's frames and the power-up counts read."""
    decoder = Decoder()
    decoded = [decoder.decode(m) for m in frames]
    ups = [f.fields["power_ups"] for f in decoded if f.name == "maintenance_information" and "power_ups" in f.fields
           and f.source == NODE]
    dut = SimpleNamespace(lane=SimpleNamespace(timing_error=0.0), profile=SimpleNamespace(jitter_s=0.0))
    msg1 = [f for f in decoded if f.name == "msg1"]
    signs = reset_signs(dut, msg1, INTERVAL["msg1"]) + reset_signs(dut, [], INTERVAL["msg1"], ups=(ups[0], ups[1]))
    return {"R19"} if signs else set()


def _bus_rules(frames) -> set[str]:
    return {r for v in bus_rules(frames) if v.fails and v.check == "reset" for r in v.rules}


def _check_log(frames, tmp_path, capsys) -> set[str]:
    _, _, summary = check_log(frames, tmp_path, capsys, "--power-on")
    return {r for v in summary["violations"]["first"] if "a reset the host did not make" in v["message"] for r in v["rules"]}


def _soak(frames) -> tuple[set[str], int]:
    """The soak's monitor: the rules of its reset watch's findings, and how many resets it counted."""
    monitor = Monitor(WatchConfig(node_id=NODE, host_node=0, intervals=INTERVAL), t0=0.0)
    for m in frames:
        monitor.feed(m)
    monitor.close(END_S)
    found = [f for f in monitor.findings if f.watch == monitor.resets.name]
    signs = monitor.rules.reset_signs(NODE)  # the reader's bookkeeping, which the soak's reset watch takes
    return {r for f in found for r in f.rules}, signs.resets if signs is not None else 0


@pytest.mark.parametrize("reset", [False, True], ids=["no reset", "watchdog reset"])
def test_one_trace_the_same_reset_finding_from_the_suite_the_bus_rules_check_log_and_the_soak(reset, tmp_path, capsys):
    """A reset shows in each report's gap with its transfer id starting again and in the power-up count grown: R19 (and
    R17, which a reset in a test that asked for none breaks too) to every consumer, counted once by the soak."""
    frames = _trace(reset)
    soak, resets = _soak(frames)
    got = {"suite": _suite(frames) >= {"R19"}, "bus rules": _bus_rules(frames) >= {"R19", "R17"},
           "check-log": _check_log(frames, tmp_path, capsys) >= {"R19", "R17"}, "soak": soak >= {"R19", "R17"}}
    assert got == dict.fromkeys(got, reset)
    assert resets == reset  # one reset, however many signs show it


def _power_up_signs(frames, tmp_path, capsys) -> dict[str, object]:
    """What each consumer makes of the power-up counts alone: the suite's helper given the two counts, the bus rules'
    and check-log's findings on them, and the soak's signs of resets (a grown count is one more sign of the reset its
    reports' gaps showed first)."""
    decoder = Decoder()
    ups = [f.fields["power_ups"] for f in map(decoder.decode, frames) if f.name == "maintenance_information"
           and "power_ups" in f.fields and f.source == NODE]
    dut = SimpleNamespace(lane=SimpleNamespace(timing_error=0.0), profile=SimpleNamespace(jitter_s=0.0))
    monitor = Monitor(WatchConfig(node_id=NODE, host_node=0, intervals=INTERVAL), t0=0.0)
    for m in frames:
        monitor.feed(m)
    _, _, summary = check_log(frames, tmp_path, capsys, "--power-on")
    counted = "the power-up count (241 option 2)"
    return {"ups": ups, "suite": bool(reset_signs(dut, [], INTERVAL["msg1"], ups=(ups[0], ups[1]))),
            "bus rules": any(counted in v.message for v in bus_rules(frames) if v.fails),
            "check-log": any(counted in v["message"] for v in summary["violations"]["first"]),
            "soak signs": monitor.resets.more_signs + monitor.resets.events}


@pytest.mark.parametrize("reset", [False, True], ids=["65535 twice", "65535 then 0"])
def test_the_power_up_counts_wrap_is_a_power_up_to_every_consumer(reset, tmp_path, capsys):
    """241 option 2's count is a u16: 65535 then 0 is one power-up (a reset with the power on: the same signs as 7
    then 8), 65535 twice none (the same as 7 twice). A reading that takes only a larger count for a grown one fails."""
    wrap = _power_up_signs(_trace(reset, power_ups=65535), tmp_path, capsys)
    plain = _power_up_signs(_trace(reset, power_ups=7), tmp_path, capsys)
    assert wrap.pop("ups") == ([65535, 0] if reset else [65535, 65535])
    assert plain.pop("ups") == ([7, 8] if reset else [7, 7])
    assert wrap == plain
    assert plain == {"suite": reset, "bus rules": reset, "check-log": reset, "soak signs": 3 if reset else 0}


@pytest.mark.parametrize("run_time, back", [((100, 100), False), ((100, 3), True)], ids=["standing", "gone back"])
def test_a_run_time_gone_back_is_a_reset_to_the_bus_rules_check_log_and_the_soak(run_time, back, tmp_path, capsys):
    """241 option 1's run time read 100 s and then 3 s (a hand-built answer) with no other sign: a reset to every consumer
    that reads it (the suite's helper does not); standing still (a motor not running) is none."""
    frames = _trace(False, run_time=run_time)
    got = {"bus rules": _bus_rules(frames), "check-log": _check_log(frames, tmp_path, capsys), "soak": _soak(frames)[0]}
    assert got == dict.fromkeys(got, {"R19", "R17"} if back else set())


def test_a_transfer_id_that_skips_without_a_gap_is_f3s_and_no_reset_to_any_consumer(tmp_path, capsys):
    """An ESC whose message transfer ids never move (``transfer_id_stuck``): every report's id is off by one, with no
    gap longer than a restart may take. Not a reset to any consumer (the losing reading: "any transfer id jump is a
    reset", which the R17 tests held); F3 to the bus rules and check-log (:mod:`.test_one_judgement`)."""
    frames = _trace(False, faults=("transfer_id_stuck",))
    soak, resets = _soak(frames)
    got = {"suite": _suite(frames), "bus rules": _bus_rules(frames), "check-log": _check_log(frames, tmp_path, capsys),
           "soak": soak}
    assert got == dict.fromkeys(got, set()) and resets == 0
    assert {r for v in bus_rules(frames) for r in v.rules} >= {"F3"}


def test_a_reset_s_gap_is_no_part_of_the_explorer_s_r9_mean_the_reader_s_reading():
    """Where the readings disagreed (issue #35): the explorer's judge held the mean of a stretch's report gaps to R9
    across a reset inside it (the 270 ms restart gap in the mean: MSG1 every ~24 ms, R9), finding one reset twice, as
    the soak's minute did; the reader cuts a report stream where its counter starts again (``restarted``, R9a), and
    its reading won: the judge takes the reports and their restarts from the reader's events and judges each piece
    on its own. The reset itself stays a finding, the reader's (R19), which the explorer's runner reports."""
    from ckesc.evidence.events import EventLog
    from ckesc.evidence.rules import BusRules
    from ckesc.explore.judge import Params, judge
    from ckesc.explore.oracle import Oracle
    from ckesc.protocol import catalogue as cat
    from ckesc.protocol.judgements import r9_judged, r9_mean

    from .test_one_judgement import BOOT_S, decoded

    frames = _trace(True)
    rules = BusRules(tolerance=0.0, complete=True, power_known=True)
    log = rules.events = EventLog()
    resets = [v.check for m in frames for v in rules.feed_message(m) if v.check == "reset"]
    oracle = Oracle({"node_id": NODE, "throttle_channel": NODE, **cat.DEFAULT_REPORT_INTERVALS}, powered_at=0.0, start=BOOT_S)
    for m in frames:
        if not m.is_rx:
            oracle.host_frame(m, 0)
    oracle.finish(END_S)
    found = judge(oracle, decoded(m for m in frames if m.is_rx and m.timestamp >= BOOT_S), BOOT_S, END_S,
                  Params(boot_s=BOOT_S), heard=log)
    assert resets and [f.text() for f in found if f.kind == "interval"] == []  # the reset: the reader's R19, once
    stamps = [t for t, _ in log.reports[(NODE, "msg1")] if t > BOOT_S]
    assert [t for t, again in log.reports[(NODE, "msg1")] if again] and not r9_mean(r9_judged(stamps), 0.020).ok  # (uncut)
