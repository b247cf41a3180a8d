"""What a DUT reports on its own, as the report sections (4.4.1 - 4.4.14) read it (not a section: no
tests here).

- timing: :func:`ms`, :func:`frame_start` / :func:`frame_end`, :data:`REACT_S` / :func:`react_s`, :func:`interval_s`;
- which reports came, decodable or not: :func:`reported`, :func:`report_starts`, and the ones that
  did not decode: :func:`garbled`, :func:`describe_garbled`, :func:`need_decoded`;
- MSG Control (4.4.2): :func:`msg_control`, :func:`resume`, :func:`check_suspended`, and capturing
  what a DUT sends in MSG_EXP mode: :func:`exp_capture`, :func:`exp_reports`;
- Set Freq (4.4.22) as the reports follow it: :func:`check_interval_follows_set_freq`;
- the reports after a restart (R9a: a resume, leaving MSG_EXP mode, CAN Test off, a Set Freq write):
  :func:`check_restart`, its limit :func:`restart_limit_s`, and placing the stimulus off the DUT's report
  grid: :func:`at_report_phase`, :func:`next_report_start`.
"""

from __future__ import annotations

import math
from contextlib import contextmanager

from ckesc.bench.outcomes import Inconclusive
from ckesc.evidence.live import LaneRules
from ckesc.protocol import catalogue as cat
from ckesc.protocol.errors import TailError
from ckesc.protocol.frame import classify, frame_bits
from ckesc.protocol.ids import Kind
from ckesc.protocol.judgements import (
    R9_GAPS,
    R9A_UNJUDGED,
    REACT_S,
    r9_gaps_needed,
    r9_judged,
    r9_mean,
    r9a_first,
    r9a_limit_s,
)

from .codes import code

INTERVALS = cat.INTERVAL_FIELDS
REPORTS = cat.REPORT_FRAMES
EXP_FRAMES = tuple(s.name for s in cat.CATALOGUE if s.name.startswith("msg_exp"))
#: The longest legal report interval
LONGEST_INTERVAL_S = cat.REPORT_INTERVAL_RANGE[1] * cat.INTERVAL_UNIT_S
#: The longest a reporting DUT can be silent: one MSG1 interval at its largest legal setting
REPORT_SILENCE_S = LONGEST_INTERVAL_S + REACT_S


def ms(seconds: float) -> float:
    """Seconds to milliseconds, rounded to the nanosecond (float noise must not decide a verdict)."""
    return round(seconds * 1000, 6)


def on_bus_s(dut, frame) -> float:
    """How long ``frame`` took on the bus: an extended frame of n data bytes takes frame_bits(n) bit times (on a
    real bus stuff bits make it up to ~20 % longer, inside the lane's stated error)."""
    return frame_bits(len(frame.data)) / dut.lane.bitrate


def frame_start(dut, frame) -> float:
    """When a frame started on the bus: its timestamp less its time on the bus where the lane's stamps mark a
    frame's end (SocketCAN, socketcand, both emulators), its timestamp where they mark its start (the DUT
    profile's [timing] stamp)."""
    return frame.timestamp - (on_bus_s(dut, frame) if dut.lane.stamp == "end" else 0.0)


def frame_end(dut, frame) -> float:
    """When a frame ended on the bus (its last bit: when a receiver has it): :func:`frame_start`'s counterpart."""
    return frame.timestamp + (on_bus_s(dut, frame) if dut.lane.stamp == "start" else 0.0)


def interval_s(settings: dict, which: str) -> float:
    return settings[f"{which}_interval"] * cat.INTERVAL_UNIT_S


def node_settings(dut, node: int) -> dict:
    """Report intervals of any node on the bus (Set/Get Freq read)."""
    return dut.ask("set_freq", cat.FREQ_READ,
                   destination=node)


def read_request(frame: str) -> dict[str, int]:
    """Set/Get Freq's read (option "read"): the intervals sent are ignored (4.4.22-2)."""
    return {"option": code(frame, "option", "read"), **dict.fromkeys(INTERVALS, 0)}


def longest_interval_s(dut, node: int | None = None) -> float:
    s = node_settings(dut, dut.node_id if node is None else node)
    return max(s[k] for k in INTERVALS) * cat.INTERVAL_UNIT_S


def msg_control(dut, command: int):
    return dut.broadcast("msg_control", {"option": 0, "command": command})


def resume(dut) -> None:
    """Normal reporting again (0xAAAAAAAA), and the DUT left reporting: if no report comes back within
    the longest interval there can be, the DUT is power-cycled where the lane can (suspension does not
    survive it, R13), so that one broken resume does not fail every later test for the wrong reason."""
    sent = msg_control(dut, cat.MSG_CONTROL_RESUME)
    dut.wait(cat.ANSWER_DELAY_MAX_S)
    if dut.wait_for("msg1", REPORT_SILENCE_S) is not None or reported(dut, sent.time, source=dut.node_id, names=REPORTS):
        return
    dut.record.observe("after 0xAAAAAAAA", f"no report in {ms(REPORT_SILENCE_S)} ms")
    if dut.lane.power.available:
        try:
            dut.power_cycle(dut.profile.off_s, dut.profile.boot_s)
            dut.record.observe("recovery", "power cycle to leave the DUT reporting")
        except Inconclusive as exc:
            dut.record.observe("recovery failed", str(exc))


def undecoded(dut) -> list:
    """The frames heard that did not decode, but for those whose only fault is the tail byte's
    start/end/toggle bits (F2): the harness reads those as the single frames they must be (they are in
    ``dut.trace`` too), and the framing tests (4.1) judge the tail."""
    return [g for g in dut.garbled if not isinstance(g.error, TailError)]


def garbled(dut, name: str, *, source: int, since: float | None = None) -> list:
    """Frames of message ``name`` from ``source`` that did not decode (wrong length, ...; see undecoded)."""
    return [g for g in dut.undecoded(name, source=source, since=since, kind=Kind.MESSAGE) if not isinstance(g.error, TailError)]


def describe_garbled(gs: list) -> str:
    return "; ".join(f"{len(g.msg.data)} data bytes: {g.error}" for g in gs[:3])


def reported(dut, since: float, *, source: int, names=REPORTS + EXP_FRAMES) -> list[tuple[str, float]]:
    """(name, start) of every report frame from ``source`` that started REACT_S or more after
    ``since``, decodable or not (a malformed report is still a report), in time order."""
    out = [(f.name, frame_start(dut, f)) for f in dut.frames(since=since, source=source) if f.name in names]
    for g in undecoded(dut):
        kind, _, src, _, spec = classify(g.msg.arbitration_id)
        if kind is Kind.MESSAGE and spec is not None and spec.name in names and src == source:
            out.append((spec.name, frame_start(dut, g.msg) if g.msg.timestamp else 0.0))
    return sorted((x for x in out if x[1] >= since + REACT_S), key=lambda x: x[1])


def need_decoded(dut, name: str, frames: list, since: float, what: str) -> list:
    """``frames`` (of ``name`` since ``since``), or INCONCLUSIVE when there are none because the DUT's
    ones do not decode (their own test fails that): ``what`` cannot be read from them."""
    if not frames:
        bad = garbled(dut, name, source=dut.node_id, since=since)
        if bad:
            raise Inconclusive(f"{cat.spec(name).title} frames do not decode ({describe_garbled(bad)}): {what} cannot be read")
    return frames


def report_starts(dut, name: str, since: float) -> list[float]:
    """Start times of the DUT's ``name`` reports since ``since``, decodable or not (timing is the question)."""
    return [t for n, t in reported(dut, since - REACT_S, source=dut.node_id, names=(name,))]


def react_s(dut) -> float:
    """REACT_S plus the lane's stated timing error: how long after a command a frame may still be one
    the DUT had due before it (on a lane that cannot time better, a frame may leave that much late)."""
    return REACT_S + dut.lane.timing_error


def check_suspended(dut, since: float, settings: dict) -> None:
    """Precondition: MSG1 has stopped after 0x55555555 (else nothing about suspension can be shown)."""
    dut.wait(max(0.0, since + 2 * interval_s(settings, "msg1") + react_s(dut) - dut.now()))
    if reported(dut, since + dut.lane.timing_error, source=dut.node_id, names=("msg1",)):  # not held against it: react_s()
        raise Inconclusive("MSG1 continues after 0x55555555: the DUT is not suspended, nothing can be shown in that state")


@contextmanager
def exp_mode(dut):
    """MSG_EXP reporting (MSG Control 0xEEEEEEEE) for the ``with`` block; normal reporting after it, always."""
    try:
        yield msg_control(dut, cat.MSG_CONTROL_RESUME_EXP)
    finally:
        resume(dut)


def exp_capture(dut, seconds: float | None = None, *, if_claimed: bool = False) -> tuple[list, list, float, float]:
    """Everything the DUT sends in ``seconds`` of MSG_EXP mode (default: twice the longest report
    interval): (decoded frames, garbled ones, window start, window length). Used by other modules too:
    keep its signature. A DUT whose profile declares MSG_EXP mode absent (R9b) ends the test as not
    claimed; with ``if_claimed`` (a caller that only compares MSG_EXP frames with other reports, when
    there are some) the capture is empty instead."""
    if if_claimed and not dut.profile.claims("msg_exp_mode"):
        dut.record.observe("MSG_EXP mode", "not claimed (R9b): the DUT profile declares it absent")
        return [], [], dut.now(), 0.0
    return exp_capture_during(dut, seconds)[:4]


def exp_capture_during(dut, seconds: float | None = None, during=None) -> tuple[list, list, float, float, object]:
    """:func:`exp_capture`, and what ``during(dut)`` returned: called at the end of the window, still in
    MSG_EXP mode, to read what the frames are compared with (before the resume, which may power-cycle)."""
    window = 2 * longest_interval_s(dut) + 2 * REACT_S if seconds is None else seconds
    with exp_mode(dut) as sent:
        dut.wait(window + dut.lane.timing_error)
        end = dut.now()
        seen = during(dut) if during is not None else None
    start = sent.time + react_s(dut)  # a frame that starts sooner may have been due before the command
    frames = [f for f in dut.frames(since=start, until=end, source=dut.node_id) if frame_start(dut, f) >= start]
    bad = [g for g in undecoded(dut) if start <= (g.msg.timestamp or 0.0) <= end and classify(g.msg.arbitration_id)[2] == dut.node_id]
    return frames, bad, start, window, seen


def exp_reports(dut, name: str, seconds: float | None = None, during=None) -> tuple[list, object]:
    """The ``name`` frames of an MSG_EXP mode capture, and what ``during`` returned (see exp_capture).
    Any frame that does not decode with its table layout fails the test; none at all makes it
    INCONCLUSIVE (which MSG_EXP frames come is OBSERVE, R9-exp)."""
    frames, bad, _, window, seen = exp_capture_during(dut, seconds, during)
    wrong = [g for g in bad if (s := classify(g.msg.arbitration_id)[4]) is not None and s.name == name]
    title = cat.spec(name).title
    assert not wrong, f"{len(wrong)} {title} frames do not decode with the table's layout: {describe_garbled(wrong)}"
    got = [f for f in frames if f.name == name]
    dut.record.observe(f"{title} frames in {window:.3f} s of MSG_EXP mode", len(got))
    if not got:
        raise Inconclusive(f"the DUT sent no {title} in {window:.3f} s of MSG_EXP mode (which MSG_EXP frames come is OBSERVE, R9-exp)")
    return got, seen


def check_interval_follows_set_freq(dut, report: str, interval: int) -> None:
    """After Set Freq sets ``report``'s interval (the others as they are), ``report`` comes every ``interval`` x
    2 ms (R9, on the mean of R9_GAPS gaps from its third report on), its first frame within the longer of its
    old and new interval plus a slack (R9a)."""
    s = dut.settings()
    fields = {k: s[k] for k in INTERVALS} | {f"{report}_interval": interval}
    at_report_phase(dut, report, s)
    ex = dut.request("set_freq", {"option": 1, **fields})
    assert ex.response is not None, "no answer to Set/Get Freq write"
    check_restart(dut, ex.sent.time, fields, "the Set Freq write", names=(report,), gaps=R9_GAPS, old=s,
                  clock=ex.sent.clock, error_ms=ex.sent.error * 1000)


# R9A_UNJUDGED (R9a-gaps), R9_GAPS (a test whose purpose is R9) and R9's tolerance: ckesc.protocol.judgements


def bus_access_s(dut) -> float:
    """How long a report that fell due may wait for the bus: two of the longest frames at the lane's bit rate."""
    return 2 * frame_bits(8) / dut.lane.bitrate


def restart_limit_s(dut, settings: dict, which: str, old: dict | None = None) -> float:
    """R9a: how long after a restart ``which``'s first report may start: its interval (after a Set Freq write,
    the longer of its ``old`` and new one) plus the slack, bus access and the DUT's declared jitter on top."""
    return r9a_limit_s(interval_s(settings, which), None if old is None else interval_s(old, which),
                       jitter=dut.profile.jitter_s) + bus_access_s(dut)


def mean_gaps(dut, gaps: int | None, interval: float) -> int:
    """How many gaps a report's mean ``interval`` is judged on (:func:`~ckesc.protocol.judgements.r9_gaps_needed`,
    with the bench's error and the DUT's declared jitter, which count at the mean's two ends): where R9 is the test's
    purpose (``gaps`` given), at least ``gaps`` and as many as keep the jitter's part of the bound within 1 ms;
    otherwise (None) the fewest over which it is judged at all (two on an exact bench, ten at most)."""
    n = r9_gaps_needed(interval, error=dut.lane.timing_error, jitter=dut.profile.jitter_s, purpose=gaps is not None)
    return max(n, gaps or 0)


def at_report_phase(dut, which: str, settings: dict, fraction: float = 0.5, last: float | None = None) -> None:
    """Wait until ``fraction`` of an interval after a point of ``which``'s report grid (``last``: a report's start
    seen before, whose grid a suspended or otherwise busy timer may keep; None: the next report read now), so that
    a stimulus sent then has the DUT's next grid point half an interval away: a DUT that keeps its grid reports
    first mid-interval, well inside R9a's limit on a coarse bench. A DUT that sends nothing in time is left as it is
    (the test judges it)."""
    interval = interval_s(settings, which)
    if last is None:
        last = next_report_start(dut, which)
        if last is None:
            return
    k = max(0, math.ceil(round((dut.now() - last) / interval - fraction, 9)))
    dut.read_until(last + (k + fraction) * interval)


def settle_reports(dut, names=REPORTS) -> dict[str, float]:
    """Read until each of ``names`` has reported once from now (or as long as R9a lets a first report wait at the
    longest): a report that an earlier Set Freq write (a previous test's restore) left due on its old interval has
    gone, so a new event starts from a settled timer. The start of each one's report (those that came)."""
    now = dut.now()
    return _first_reports(dut, now, names, dict.fromkeys(names, now + cat.restart_limit_s(LONGEST_INTERVAL_S) + react_s(dut)))


def next_report_start(dut, which: str) -> float | None:
    """The start of the DUT's next ``which`` report, read now (None: none within R9a's longest limit): a point of
    its report grid, for :func:`at_report_phase` after a suspension or another mode."""
    return settle_reports(dut, (which,)).get(which)


def check_restart(dut, event: float, settings: dict, what: str, names=REPORTS, gaps: int | None = None, *,
                  old: dict | None = None, silent_is: str | None = None, clock: str | None = None,
                  error_ms: float | None = None) -> None:
    """R9a after ``what`` at lane time ``event`` (a resume, leaving MSG_EXP mode, CAN Test off, a Set Freq write),
    with the intervals of ``settings`` in force: each report of ``names`` starts within one interval plus a slack
    of max(3 ms, a quarter interval) of the event (READING R9a; after a Set Freq write, ``old`` the intervals before
    it, within the longer of its old and new interval plus that slack; bus access and the DUT's declared jitter
    on top); the gaps up to its second frame are recorded, never judged (R9a-gaps: whether the ESC restarts its
    timer, keeps its grid or lets the report due on the old interval go first is not written); from the third
    frame on, the mean of ``gaps`` gaps (:func:`mean_gaps`) is the interval (R9: 1 ms plus twice the bench's error
    and the DUT's declared jitter over the number of gaps, not judged where that exceeds a quarter of the interval;
    the live bus rules judge single gaps).
    Reads until the first frame of each has come (or its limit passed) and then its next ones.
    ``clock`` / ``error_ms``: what timed ``event`` when not the lane's bus clock (a bench without echo times
    the host's command by the host clock at send, ``Sent.clock`` / ``Sent.error``).
    When none of ``names`` comes back at all, whether reporting resumes is another clause's verdict: INCONCLUSIVE
    naming ``silent_is``'s test (a description), or FAIL when ``silent_is`` is None."""
    n = {w: mean_gaps(dut, gaps, interval_s(settings, w)) for w in names}  # (per report: its interval's own)
    limit = {w: restart_limit_s(dut, settings, w, old) for w in names}
    first = _first_reports(dut, event, names, {w: event + limit[w] + react_s(dut) for w in names})
    if not first:
        longest = max(max(limit.values()), max(interval_s(settings, w) for w in names))
        dut.wait(max(0.0, event + (R9A_UNJUDGED + max(n.values())) * longest + react_s(dut) - dut.now()))  # late, or none?
        if silent_is is not None and not any(report_starts(dut, which, event) for which in names):
            raise Inconclusive(f"no {'/'.join(w.upper() for w in names)} at all within {ms(dut.now() - event)} ms of "
                               f"{what} ({silent_is}): how they come back cannot be judged")
    else:  # the next n + 1 of each (R9A_UNJUDGED - 1 not judged), half an interval and the DUT's jitter to spare
        end = max(t + (R9A_UNJUDGED - 1 + n[w] + 0.5) * interval_s(settings, w) for w, t in first.items())
        dut.wait(max(0.0, end + dut.profile.jitter_s + react_s(dut) - dut.now()))
    err = dut.lane.timing_error * 1000
    broken = []  # what the measurements cannot say (they fail the test themselves), SHALL first
    for which in names:
        target = interval_s(settings, which)
        stamps = report_starts(dut, which, event)
        w = which.upper()
        if not stamps:
            longer = "the longer of its old and new interval" if old is not None else "one interval"
            broken.append(f"[R9a READING] no {w} within {ms(dut.now() - event)} ms of {what} (R9a: within {longer} "
                          f"plus a slack, {ms(limit[which])} ms)")
            continue
        first_report = r9a_first(stamps[0] - event, limit[which])
        dut.record.measure(f"first {w} after {what}", ms(first_report.measured), limit=ms(first_report.limit), unit="ms",
                           clock=clock or dut.clock, error=err if error_ms is None else max(err, error_ms),
                           requirement=first_report.rule, strength="READING")
        if len(stamps) > 1:
            dut.record.observe(f"{w} gaps up to the second after {what} (R9a-gaps)",
                               f"{ms(stamps[0] - event)} ms, {ms(stamps[1] - stamps[0])} ms")
        judged = r9_judged(stamps)[:n[which] + 1]
        if len(judged) < 2:
            broken.insert(0, f"[R9 SHALL] only {len(stamps)} {w} in {ms(dut.now() - event)} ms after {what}, the first "
                             f"{ms(stamps[0] - event)} ms after it: every {ms(target)} ms there would be {R9A_UNJUDGED + n[which]}")
            continue
        k = len(judged) - 1
        mean = (judged[-1] - judged[0]) / k
        single = [b - a for a, b in zip(judged, judged[1:])]
        dut.record.observe(f"{w} gaps from the third after {what} (single gaps: the bus rules')",
                           f"{k} gaps, {ms(min(single))} .. {ms(max(single))} ms, mean {ms(mean)} ms")
        j = r9_mean(judged, target, error=dut.lane.timing_error, jitter=dut.profile.jitter_s)
        label = f"{w} mean interval error over {k} gaps from the third after {what}"
        if not j.judged:  # type: ignore[union-attr]
            dut.record.observe(label, f"{ms(j.measured)} ms: not judged (R9: over {k} gaps the bench's error and the "  # type: ignore[union-attr]
                               f"DUT's declared jitter leave a bound of {ms(j.limit + j.error)} ms, more than a quarter "  # type: ignore[union-attr]
                               f"of the {ms(target)} ms interval)")
            continue
        dut.record.measure(label, ms(j.measured), limit=ms(j.limit + j.error), unit="ms", clock=dut.clock,  # type: ignore[union-attr]
                           error=ms(j.error), requirement="R9")  # type: ignore[union-attr]
    assert not broken, "; ".join(broken)


def _first_reports(dut, event: float, names, until: dict) -> dict[str, float]:
    """Read until each of ``names`` has reported since ``event`` or its time in ``until`` has passed: the start
    of each one's first report (those that came)."""
    first: dict[str, float] = {}
    while True:
        for which in names:
            if which not in first and (stamps := report_starts(dut, which, event)):
                first[which] = stamps[0]
        waiting = [w for w in names if w not in first and dut.now() < until[w]]
        if not waiting:
            return first
        dut.read_until(min(until[w] for w in waiting),
                       stop=lambda f, waiting=tuple(waiting): f.name in waiting and f.source == dut.node_id)


@contextmanager
def timing_unjudged(dut, what: str, rules: frozenset[str], why: str):
    """While the block runs, the live bus rules' violations of ``rules`` (report timing: R9, R9a) fail no test: a
    reading makes them OBSERVE while the test's stimulus lasts (``why``: R18 above half load, R20's reports held through
    a bus fault). What they found is recorded."""
    watchers = [w for w in dut.lane.listeners if isinstance(w, LaneRules)]
    for w in watchers:
        w.excuse(rules)
    try:
        yield
    finally:
        excused = [v for w in watchers for v in w.excuse(frozenset())]
        if excused:
            dut.record.observe(f"bus rules' report timing {what} ({why})",
                               f"{len(excused)}: " + "; ".join(v.message for v in excused[:3]))
