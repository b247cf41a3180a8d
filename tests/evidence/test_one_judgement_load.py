"""One trace, every consumer that judges reports under a loaded bus, one finding (issue #35): R18 over the frames of
an ESC on the simulated bus (``ckesc-sim``, arbitration by id) while a foreign load takes half the bus
(:class:`~ckesc.protocol.load.LoadSource`, high priority: each load frame wins against every report). The faultless
ESC keeps R9 under it, widened by the queueing the load can cause, to every consumer; one that skips a report when
foreign frames took more than a third of the bus (the emulator's ``drops_reports_under_load``) breaks its report
interval to each:

* the suite's check (``conformance/test_robustness_r18_load.py``, as written there: ``judgements.r18_mean`` and
  ``r18_gap`` of each report's starts under the share; R18);
* ``ckesc explore``'s judge (``judge._interval_finding`` with the load step in its model: ``r18_mean``; R9 and R18);
* the live bus rules and ``ckesc check-log`` (each gap on the widest bounds the bus's own traffic allows, the load's
  frames heard: a gap that no queueing explains; R9);
* the soak's interval watch (the mean of the minute's gaps, ``judgements.r9_mean``; R9, R19).

The rule each names differs by what it knows, not by its verdict: the suite and the explorer play the load and know
its share, so they judge R18 (R9 widened by ``r18_queueing_s``); the bus rules, check-log and the soak are not told
a share and judge R9 on the queueing they can see (a single gap's bus-busy stretch) or that cancels out (a mean's
inner gaps). All of them must find the skipped reports, and none a report the load only delayed."""

from __future__ import annotations

import itertools

import can
import pytest

from ckesc.emulator import sim_bus
from ckesc.explore.judge import Params, judge
from ckesc.explore.oracle import Oracle
from ckesc.protocol import catalogue as cat
from ckesc.protocol.frame import classify, frame_bits
from ckesc.protocol.judgements import r18_gap, r18_mean
from ckesc.protocol.load import LoadSource
from ckesc.soak.monitor import Monitor
from ckesc.soak.watch import WatchConfig

from .test_one_judgement import NODE, bus_rules, check_log, decoded, request

RATE = cat.DEFAULT_BITRATE
#: the host reads the intervals at READ, the load plays from LOAD_FROM to the end; judged from JUDGE_FROM
START, READ, LOAD_FROM, JUDGE_FROM, LOAD_TO, END_S = 0.30, 0.40, 0.50, 0.60, 1.60, 2.30
INTERVAL = {"msg1": 0.020, "msg2": 0.100, "msg3": 0.500}
_CHANNELS = itertools.count()


def _trace(faults: tuple[str, ...], share: float) -> list:
    """Everything on the simulated bus as the host hears it (its own read by its echo), the load of ``share``
    playing from LOAD_FROM to LOAD_TO."""
    channel = f"one-judgement-load-{next(_CHANNELS)}"
    bus = can.Bus(interface="ckesc-sim", channel=channel, nodes=[NODE], faults=list(faults), receive_own_messages=True,
                  seed=1)
    try:
        heard = []

        def until(t: float) -> None:
            while bus.now() < t:
                m = bus.recv(t - bus.now())
                if m is not None:
                    heard.append(m)

        until(READ)
        bus.send(request("set_freq", {"option": 0, "msg1_interval": 0, "msg2_interval": 0, "msg3_interval": 0}, READ))
        until(LOAD_FROM)
        sim_bus.world(channel).add_source(LoadSource(share, RATE, priority="high", seed=5, exclude_nodes=[NODE]))
        until(LOAD_TO)
        sim_bus.world(channel).remove_source("load")
        until(END_S)
        return heard
    finally:
        bus.shutdown()
        sim_bus.discard(channel)


def _starts(frames, name: str) -> list[float]:
    return [f.timestamp - frame_bits(len(f.data)) / RATE for f in decoded(frames)
            if f.name == name and f.source == NODE and JUDGE_FROM < f.timestamp <= LOAD_TO]


def _suite(frames, share: float) -> set[str]:
    """As ``test_reports_keep_their_intervals_under_load`` judges: each report's mean and single gaps under the share,
    and none missing."""
    out = set()
    for which, interval in INTERVAL.items():
        starts = _starts(frames, which)
        mean = r18_mean(starts, interval, share=share, bitrate=RATE, what=which)
        expected = int((LOAD_TO - JUDGE_FROM) / interval)
        gaps = [r18_gap(b - a, interval, share=share, bitrate=RATE, what=which) for a, b in zip(starts, starts[1:])]
        if mean is None or len(starts) < expected - 1 or not (mean.ok or not mean.judged) or not all(g.ok for g in gaps):
            out.add(f"R18: {which}")
    return out


def _explorer(frames, share: float) -> set[str]:
    baseline = {"node_id": NODE, "throttle_channel": NODE, **cat.DEFAULT_REPORT_INTERVALS}
    oracle = Oracle(baseline, powered_at=0.0, start=START)
    for m in frames:
        if not m.is_rx:
            oracle.host_frame(m)
    oracle.load(LOAD_FROM, share)
    oracle.load(LOAD_TO, 0.0)
    oracle.finish(END_S)
    found = judge(oracle, decoded(m for m in frames if m.is_rx and m.timestamp >= START), START, END_S,
                  Params(boot_s=START))
    return {f"{rule}: {f.subject.split()[0]}" for f in found for rule in f.requirements}


def _soak(frames) -> set[str]:
    """The soak's monitor over the trace but the host's Set/Get Freq read and its answer (a soak reads no intervals:
    its configuration says them)."""
    monitor = Monitor(WatchConfig(node_id=NODE, host_node=0, intervals=INTERVAL), t0=0.0)
    for m in frames:
        if (spec := classify(m.arbitration_id)[4]) is None or spec.name != "set_freq":
            monitor.feed(m)
    monitor.close(END_S)
    return {f"{rule}: {name}" for f in monitor.findings for rule in f.rules for name in INTERVAL if f" {name} " in f.message}


def _bus_rules(frames) -> set[str]:
    return {f"{rule}: {v.message.split()[0]}" for v in bus_rules(frames) if v.fails for rule in v.rules}


def _named(found: set[str]) -> dict[str, set[str]]:
    """Each report named, with the rules it is named under."""
    out: dict[str, set[str]] = {}
    for f in found:
        rule, name = f.split(": ")
        out.setdefault(name, set()).add(rule)
    return out


@pytest.mark.parametrize("share", [0.35, 0.5], ids=["35 %", "50 %"])
@pytest.mark.parametrize("faults", [(), ("drops_reports_under_load",)], ids=["faultless", "drops reports"])
def test_one_trace_the_same_finding_under_load_from_the_suite_the_explorer_the_bus_rules_check_log_and_the_soak(
        faults, share, tmp_path, capsys):
    """MSG1 (its 20 ms gaps the most, each skipped report a gap of 40 ms or more) is named by every consumer, under R18
    where the consumer knows the load's share (the suite, the explorer) and R9 where it does not; nothing else is
    found, and nothing at all on the faultless ESC, the load only delaying its reports. (MSG2 and MSG3 are named where
    the consumer sees a gap of theirs: the bus rules compare no frames across a silence of the node longer than 40 ms,
    which may be the bench's power cycle or a disturbed bus (R20); the explorer judges a stream stopped only over
    two of its intervals in a settled stretch.)"""
    frames = _trace(faults, share)
    # (the simulated lane's stamps are exact, and its power stayed on)
    _, _, summary = check_log(frames, tmp_path, capsys, "--tolerance", "0", "--power-on")
    check = {f"{rule}: {v['message'].split()[0]}" for v in summary["violations"]["first"] for rule in v["rules"]}
    got = {"suite": _named(_suite(frames, share)), "explorer": _named(_explorer(frames, share)), "bus rules": _named(_bus_rules(frames)),
           "check-log": _named(check), "soak": _named(_soak(frames))}
    if not faults:
        assert got == dict.fromkeys(got, {})
        return
    assert {k: "msg1" in v for k, v in got.items()} == dict.fromkeys(got, True)
    knows_share = {"suite", "explorer"}
    for consumer, named in got.items():
        for rules in named.values():
            assert ("R18" in rules) == (consumer in knows_share) and ("R9" in rules or "R18" in rules), (consumer, named)
