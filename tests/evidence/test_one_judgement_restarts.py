"""One trace, every consumer that judges report restarts, one finding (issue #35): R9a over the frames of an emulated
ESC that the host suspends and resumes (MSG Control 0x55555555, 0xAAAAAAAA), then writes new intervals to (Set/Get
Freq), then power cycles. The faultless ESC is R9a to none; one whose first report after a resume or a write comes 1.5
intervals late (the emulator's fault ``report_restart_late``) is R9a to each that judges the first report:

* the suite's check (:func:`conformance.telemetry.check_restart`, as written there: the first report's start against
  ``judgements.r9a_limit_s`` of the longer of its old and new interval, ``judgements.r9a_first``);
* the live bus rules (:class:`~ckesc.evidence.rules.BusRules`, a suite's lane and ``ckesc explore``'s runner);
* ``ckesc check-log --power-on`` (a capture judges a late first report only when the power is known to stay on).

Who does not judge it, and why:

* ``ckesc explore``'s own judge leaves the stretch after a restart unjudged until R9a's allowance and an answer's
  time have passed (``judge._streams``), so a late first report is its runner's live bus rules' finding (above); it
  must find nothing on either trace (a late first report is no stopped stream, and R9 holds from the third report on);
* the soak's watches: a soak sends no MSG Control, Set Freq or power switch. Its interval watch excuses the gaps R9a
  leaves unjudged after a restart its reports' counters show (:mod:`.test_one_judgement_resets`).

After the reported power cycle, every consumer leaves the first gaps unjudged (R9a-gaps) and judges R9 again from the
third report: no finding from the faultless ESC."""

from __future__ import annotations

import re

import pytest

from ckesc.explore.judge import Params, judge
from ckesc.explore.oracle import Oracle
from ckesc.protocol import catalogue as cat
from ckesc.protocol.frame import Decoder, frame_bits
from ckesc.protocol.judgements import r9a_first, r9a_limit_s

from .test_one_judgement import BOOT_S, NODE, bus_rules, check_log, play, request

READ, SUSPEND, RESUME, WRITE = 0.30, 0.40, 0.50, 1.50
POWER_OFF, POWER_ON, END_S = 2.60, 2.70, 3.80
#: the intervals (2 ms units) the write sets: MSG1 and MSG3 longer, MSG2 shorter
WRITTEN = {"msg1_interval": 15, "msg2_interval": 40, "msg3_interval": 150}
DEFAULT = {k: v * cat.INTERVAL_UNIT_S for k, v in
           (("msg1", 10), ("msg2", 50), ("msg3", 250))}
#: how the bus rules name each event
EVENTS = {RESUME: "msg_control 0xaaaaaaaa", WRITE: "a Set Freq write"}
NEW = {k.removesuffix("_interval"): v * cat.INTERVAL_UNIT_S for k, v in WRITTEN.items()}


def _host_frames() -> list:
    msg_control = [request("msg_control", {"option": 0, "command": c}, t, layout="command", transfer_id=k)
                   for k, (t, c) in enumerate(((SUSPEND, cat.MSG_CONTROL_SUSPEND), (RESUME, cat.MSG_CONTROL_RESUME)))]
    read = request("set_freq", {"option": 0, "msg1_interval": 0, "msg2_interval": 0, "msg3_interval": 0}, READ,
                   transfer_id=1)  # the intervals the node states: what the bus rules know them by
    return [read, *msg_control, request("set_freq", {"option": 1, **WRITTEN}, WRITE)]


def _trace(faults: tuple[str, ...]) -> list:
    events = [(m.timestamp, m) for m in _host_frames()] + [(POWER_OFF, "off"), (POWER_ON, "on")]
    return play(events, END_S, faults=faults)


def _suite(frames) -> set[str]:
    """As ``check_restart`` judges each report after the resume (the intervals unchanged) and after the write (the
    longer of its old and new interval): the first report's start from the event."""
    decoder = Decoder()
    reports = [f for f in map(decoder.decode, frames) if f.name in DEFAULT and f.source == NODE]
    out = set()
    for event, until, new, old in ((RESUME, WRITE, DEFAULT, None), (WRITE, POWER_OFF, NEW, DEFAULT)):
        for name in DEFAULT:
            first = next((f for f in reports if f.name == name and event < f.timestamp < until), None)
            if first is None:  # none before the next event: R9a broken (check_restart's "no MSGn within ...")
                out.add(f"R9a: {name} after {EVENTS[event]}")
                continue
            start = first.timestamp - frame_bits(len(first.data)) / cat.DEFAULT_BITRATE
            j = r9a_first(start - event, r9a_limit_s(new[name], None if old is None else old[name]))
            if not j.ok:
                out.add(f"{j.rule}: {name} after {EVENTS[event]}")
    return out


def _said(rules, message: str) -> str:
    """A finding as ``RULE: REPORT after EVENT`` (an R9a finding's words), else whole."""
    m = re.match(r"the first (msg\d) [\d.]+ ms after (msg_control 0xaaaaaaaa|a Set Freq write)", message)
    return f"{' '.join(rules)}: {m[1]} after {m[2]}" if m else f"{' '.join(rules)}: {message}"


def _bus_rules(frames) -> set[str]:
    return {_said(v.rules, v.message) for v in bus_rules(frames, power_switched=(POWER_OFF, POWER_ON)) if v.fails}


def _check_log(frames, tmp_path, capsys) -> set[str]:
    """check-log does not see the power switched: the trace up to the power cycle (a flight's capture)."""
    _, _, summary = check_log([m for m in frames if m.timestamp < POWER_OFF], tmp_path, capsys, "--power-on")
    return {_said(v["rules"], v["message"]) for v in summary["violations"]["first"]}


def _explorer(frames) -> set[str]:
    """``ckesc explore``'s judge against its faultless model, fed the host's frames and the power switches."""
    baseline = {"node_id": NODE, "throttle_channel": NODE, **cat.DEFAULT_REPORT_INTERVALS}
    oracle = Oracle(baseline, powered_at=0.0, start=BOOT_S)
    events = [(m.timestamp, m) for m in frames if not m.is_rx] + [(POWER_OFF, False), (POWER_ON, True)]
    for t, what in sorted(events, key=lambda e: e[0]):
        if isinstance(what, bool):
            oracle.power(what, t)
        else:
            oracle.host_frame(what)
    oracle.finish(END_S)
    decoder = Decoder()
    found = judge(oracle, [decoder.decode(m) for m in frames if m.is_rx and m.timestamp >= BOOT_S], BOOT_S, END_S,
                  Params(boot_s=BOOT_S))
    return {f"{f.subject}: {' '.join(f.requirements)}" for f in found}


@pytest.mark.parametrize("faults, expected", [((), set()), (("report_restart_late",), {
    f"R9a: {name} after {event}" for name in DEFAULT for event in EVENTS.values()})],
                         ids=["faultless", "first report late"])
def test_one_trace_the_same_r9a_finding_from_the_suite_the_bus_rules_and_check_log(faults, expected, tmp_path, capsys):
    frames = _trace(faults)
    got = {"suite": _suite(frames), "bus rules": _bus_rules(frames), "check-log": _check_log(frames, tmp_path, capsys)}
    assert got == dict.fromkeys(got, expected)


@pytest.mark.parametrize("faults", [(), ("report_restart_late",)], ids=["faultless", "first report late"])
def test_the_explorers_judge_finds_nothing_on_either_trace(faults):
    """Its judge leaves R9a's first report to the live bus rules (module docstring): no stopped stream, no R9."""
    assert _explorer(_trace(faults)) == set()
