"""Comparing what the DUT sent with what the oracle model predicts, only where the document is specific (sans-IO).

Observations compared (each a :class:`ExploreFinding` when they differ):
- **answers** (:mod:`.answers`): each request's answer, paired with it by the bus reader (F4; a GET_ESC_ID reply with
  its query), against the model's (paired by the same reader over the model's frames): answered at all and in time,
  with the model's payload, in its node's slot (R2); no answer to a malformed or foreign frame (R17).
- **streams**: per stretch between two events (a host frame other than throttle, a power switch) and per
  report (MSG1, MSG2, MSG3, the MSG_EXP frames as one, CAN Test), whether it flows, judged only after the
  stretch has settled (R9a's restart allowance of the longer interval, answer delay and the bench's error; a
  power-up's boot time); which MSG_EXP frames come is OBSERVE (R9-exp), only that some do.
- **intervals** (R9): from the gap to the third report after the event on (R9a: the gaps before are OBSERVE), the
  mean gap of MSG1/2/3 (the reports as the reader told them, a stretch cut where one's counter started again: a
  reset's gap is the reader's R19, never in a mean) against the model's interval, held to R9's tolerance as the suite holds it (1 ms plus twice
  the bench's error and the DUT's declared jitter, over the gaps; a mean whose bound exceeds a quarter of the interval
  is not judged).
- **status** (R7, R8): each MSG1's bits 15, 14 (under CAN throttle only) and 8 against the model's MSG1s within
  one interval and a report stamp's error (:func:`~ckesc.protocol.judgements.report_stamp_error_s`); bit 13 on R8's
  own clock, the reader's: the commands that address the ESC's throttle channel as the reader knows it
  (``evidence/commands.py``, the :class:`~ckesc.evidence.events.EventLog`'s ``commands``), against
  :func:`~ckesc.protocol.judgements.r8_flag_due`.
- **malformed and foreign frames** (R17): the model ignores them, so whatever the DUT does on one differs: an
  answer to one (:mod:`.answers`), and any other finding after the first of them in the program, which
  :func:`cite_r17` makes cite R17 too (a setting, mode, suspension, LED or comm-loss flag the DUT changed on one
  shows as its read-back, stream or MSG1 status finding; a power-up count grown, as 241's answer). A reset across
  one is the bus's own rule, not the model's: the reader finds it (``evidence/rules.py``, R19 with R17, over
  :class:`~ckesc.evidence.resets.ResetSigns`), taking a malformed frame of the host's as nothing the ESC acted on
  (:mod:`ckesc.evidence.taken`).
- **a loaded bus** (R18): under a foreign load of up to half the bus (the runner's load steps), R9's mean interval is
  widened by the queueing the load can put ahead of a report (:func:`~ckesc.protocol.judgements.r18_mean`), and a
  report's reach (MSG1 status, R8's clock) by that queueing
  (:func:`~ckesc.protocol.judgements.r18_queueing_s`); R2's slot and the answers are not widened (R18 widens R9
  only). Under a load above half, and in the stretch after one, nothing is judged (R18: OBSERVE).
- **a bus short** (R20, :mod:`.recovery`): the ESC's MSG1 again within R20's bound after the bus was freed; from the
  short's start until its reports are back on their grid nothing else of the reports is judged (their timing, what it
  held, their status: OBSERVE), and every finding after a short also cites R20-recovery.
The bus's own rules (``evidence/live.py``: F1..F7, R9 between two reports against the interval the node stated, R9a,
resets, pairing) are the reader's: the runner hears every frame through them and adds what they find.
"""

from __future__ import annotations

import bisect
from typing import Iterable

from ..evidence.events import EventLog
from ..evidence.rules import BusRules
from ..protocol import catalogue as cat
from ..protocol.frame import Frame
from ..protocol.ids import Kind
from ..protocol.judgements import (
    REACT_S,
    r8_flag_due,
    r9_judged,
    r9_mean,
    r9a_limit_s,
    r18_judged,
    r18_mean,
    r18_queueing_s,
    report_stamp_error_s,
)
from .answers import KEPT, answers
from .finding import STREAM_OF as _STREAM_OF
from .finding import STREAMS, ExploreFinding, Params, stream_of
from .oracle import Malformed, Oracle, State
from .recovery import UNJUDGED_STRETCHES, in_short, recovery

__all__ = ["ExploreFinding", "Params", "cite_r17", "cite_r18", "judge"]

#: MSG1 status bits compared (R7): direction, throttle source, comm fault (R8), running
STATUS_MASK = int(cat.STATUS_STATE_BITS)
#: MSG1 status bits that show a setting (R7): bit 15 the direction of rotation
_STATUS_SETTING = {int(cat.Status.DIRECTION_CCW): "direction"}
_COMM = int(cat.Status.COMM_FAULT)  # R8's bit, judged on its own clock
#: what flows in each mode of the model's ESC (4.4.2's table, R16; R9-exp: which MSG_EXP frames is OBSERVE)
_FLOWING = {"normal": cat.REPORT_FRAMES, "exp": ("exp",), "can_test": ("can_test",)}
_THROTTLE = cat.THROTTLE_FRAMES
#: events after which reporting restarts (R9a: power-up, resume, leaving MSG_EXP mode or CAN Test, a Set Freq write)
_RESTARTS = frozenset({"start", "power on", "ready", "msg_control", "can_test", "set_freq"})
#: R9 on a stretch's mean interval only from this many gaps judged: fewer say little on a real bench
_MIN_GAPS = 3


def judge(oracle: Oracle, dut: list[Frame], t0: float, t_end: float, p: Params,
          heard: EventLog | None = None) -> list[ExploreFinding]:
    """Every disagreement between the DUT's frames (decoded, from the ESC, bus timestamps) and the model's.
    ``heard``: what the bus reader told of the program's trace (the runner's live reader); None: the reader is fed
    the host's frames the oracle took and ``dut`` here (:func:`hear`)."""
    dut = sorted((f for f in dut if f.source != p.host_node and f.timestamp is not None), key=lambda f: f.timestamp)
    if heard is None:
        heard = hear(oracle, dut, p)
    # other nodes' GET_ESC_ID queries (a flight controller's, F6): the ESC answers them too, they are none of its frames
    dut = [f for f in dut if f.name != "get_esc_id" or f.layout is None or f.layout.name != "query"]
    out = answers(oracle, dut, t0, p, heard, hear(oracle, oracle.out, Params(host_node=p.host_node, bitrate=p.bitrate)))
    out += _streams(oracle, heard, t0, t_end, p)
    out += _status(oracle, dut, t0, p, heard)
    out += recovery(oracle, dut, t0, p)
    return [f for f in out if f.strength != "OBSERVE" and r18_judged(oracle.max_load(t0 + f.at, t0 + f.at))]


def hear(oracle: Oracle, frames: Iterable[Frame], p: Params) -> EventLog:
    """The bus reader (:class:`~ckesc.evidence.rules.BusRules`, with the bench's stated errors) fed the host's frames
    the oracle took, its power switches (the power-up the program runs in first: Set ID's window) and ``frames`` (the
    DUT's, or the model's own), in time order: what it tells (:class:`~ckesc.evidence.events.EventLog`): the one
    pairing, reports and restarts, each MSG1's flag, the commands that address the ESC (its throttle channel at the
    start told as read: the baseline's)."""
    rules = BusRules(tolerance=p.error, own_error=p.own_error, bitrate=p.bitrate, complete=True, power_known=True,
                     jitter=p.jitter, host_nodes=(p.host_node,))
    log = rules.events = EventLog()
    rules.clock.read(oracle.baseline["node_id"], oracle.start_channel)
    rules.power_switched(oracle.powered_at)
    power = [s.t for s in oracle.states if s.label in ("power on", "power off")]
    host = [f for f, _ in oracle.host]
    for f in sorted([*host, *frames], key=lambda f: (f.timestamp, f.source != p.host_node)):
        while power and power[0] <= f.timestamp:  # type: ignore[operator]
            rules.power_switched(power.pop(0))
        rules.feed(f.can_id, f.data, f.timestamp, own=f.source == p.host_node)  # type: ignore[arg-type]
    return log


def cite_r17(findings: list[ExploreFinding], oracle: Oracle, t0: float, late: float = 0.0) -> list[ExploreFinding]:
    """Every finding after a malformed or foreign frame of the program also cites R17 (the model ignored the
    frame; a DUT that took it differs from then on), and says which came last before it. ``late``: how much later
    than the DUT heard it a host frame may be stamped (:attr:`Params.host_late`)."""
    if not oracle.malformed:
        return findings
    for f in findings:
        before = [m for m in oracle.malformed if m.t - t0 <= f.at + late]
        if before and "R17" not in f.requirements:
            f.requirements.append("R17")
            f.model += f" (R17: the model ignored {_step_of(before[-1])})"
    return findings


def cite_r18(findings: list[ExploreFinding], oracle: Oracle, t0: float) -> list[ExploreFinding]:
    """Every finding while (or just after) a foreign load played also cites R18 (the ESC keeps R9, R2, the 64 ms bound
    and obeys its commands under it), and says the load."""
    for f in findings:
        share = oracle.max_load(t0 + f.at, t0 + f.at)
        if share and "R18" not in f.requirements:
            f.requirements.append("R18")
            f.model += f" (R18: under {share:.0%} foreign load)"
    return findings


def _step_of(m: Malformed) -> str:
    where = f" at step {m.step + 1}" if m.step is not None else ""
    return f"the malformed frame{where}: {m.what}"


# ------------------------------------------------------------------------------------------ streams
def _segments(oracle: Oracle, t_end: float) -> list[tuple[State, State | None, float]]:
    """(the state a stretch starts in, the state before it, its end)."""
    states = oracle.states
    return [(s, states[i - 1] if i else None, states[i + 1].t if i + 1 < len(states) else t_end)
            for i, s in enumerate(states)]


def _interval(state: State, stream: str) -> float:
    if stream in state.intervals:
        return state.intervals[stream]
    return max(state.intervals.values())  # MSG_EXP frames, CAN Test: at most the longest (R9-exp: OBSERVE)


def _streams(oracle: Oracle, heard: EventLog, t0: float, t_end: float, p: Params) -> list[ExploreFinding]:
    out = []
    by: dict[str, tuple[list[float], list[float]]] = {k: ([], []) for k in STREAMS}
    restarts: dict[str, list[float]] = {k: [] for k in STREAMS}  # the DUT's reports whose counter started again
    for (node, name), reports in heard.reports.items():  # the DUT's reports as the reader read them
        s = _STREAM_OF.get(name)
        if s is not None and node != p.host_node:
            by[s][0].extend(t for t, _ in reports)
            restarts[s].extend(t for t, again in reports if again)
    for f in oracle.out:
        s = stream_of(f)
        if s is not None and f.source != p.host_node:
            by[s][1].append(f.timestamp)
    for s in STREAMS:
        by[s][0].sort()
        restarts[s].sort()
    stamp = report_stamp_error_s(error=p.error, bitrate=p.bitrate)  # how far a report's stamp strays from its schedule
    restart: State | None = None  # the latest event after which a report restarts (R9a), and the state before it
    restart_before: State | None = None
    for state, before, end in _segments(oracle, t_end):
        if state.label in _RESTARTS and (state.label != "set_freq" or before is None or before.intervals != state.intervals):
            restart, restart_before = state, before  # (a Set Freq read, or a write that changed nothing, restarts nothing)
        share = max(state.load, before.load if before is not None else 0.0)  # (a load's queue outlasts it a little)
        if not r18_judged(share):
            continue  # R18: above half load (and the stretch after one) what the DUT does is OBSERVE
        if state.label in UNJUDGED_STRETCHES:
            continue  # R20: a short, and after it until the reports settle: only its recovery is judged (.recovery)
        for stream in STREAMS:
            iv = _interval(state, stream)
            old = _interval(before, stream) if before is not None else iv
            late = cat.ANSWER_DELAY_MAX_S + stamp  # the command may be answered first, and the report's stamp stray
            lo = state.t + r9a_limit_s(iv, old, jitter=p.jitter) + late + (p.boot_s if state.label == "power on" else 0.0)
            if restart is not None:  # R9a's allowance counts from the restart, over the longer of its old and new interval
                r_old = _interval(restart_before, stream) if restart_before is not None else iv
                lo = max(lo, restart.t + r9a_limit_s(iv, r_old, jitter=p.jitter) + late
                         + (p.boot_s if restart.label == "power on" else 0.0))
            hi = end - stamp
            if hi <= lo:
                continue
            d = _between(by[stream][0], lo, hi)
            m = _between(by[stream][1], lo, hi)
            rids = _stream_reqs(state, stream) + (["R18"] if share else [])
            on = stream in _FLOWING.get(state.mode, ())
            if on and m and hi - lo >= 2 * iv and not d:
                if _between(by[stream][0], hi, end + 2 * iv):  # it came, late: the first report after a restart (R9a)
                    rids = ["R9a", *rids]
                out.append(ExploreFinding("stream", rids, f"{_label(stream)} stopped ({state.mode} since {state.cause})",
                                   f"no {_label(stream)} for {hi - lo:.3f} s", f"{len(m)} frames",
                                   lo - t0, state.step, subject=f"{stream} stopped, {state.mode}"))
            elif not on and d:
                out.append(ExploreFinding("stream", rids, f"{_label(stream)} sent ({state.mode} since {state.cause})",
                                   f"{len(d)} frames, the first at t={d[0] - t0:.3f} s", "none", d[0] - t0, state.step,
                                   subject=f"{stream} sent, {state.mode}"))
            elif stream in cat.REPORT_FRAMES and len(m) >= 2:
                out += _interval_finding(state, stream, by[stream][0], end, iv, t0, p, share, restarts[stream])
    return out


def _interval_finding(state: State, stream: str, stamps: list[float], end: float, iv: float, t0: float, p: Params,
                      share: float = 0.0, restarts: list[float] = ()) -> list[ExploreFinding]:  # type: ignore[assignment]
    """R9 on the DUT's reports of one stretch against the model's interval (what the model alone knows: across a
    Set ID, a refused write or a power cycle, where the node stated none since), the gap to its third report and on
    (R9a: the gaps before are OBSERVE), on the mean of their gaps as the suite judges it
    (:func:`~ckesc.protocol.judgements.r9_mean`, the bench's error and the DUT's declared jitter, nothing of the
    judge's own). Under a foreign load of ``share`` (R18, up to half), widened by the queueing it can cause
    (:func:`~ckesc.protocol.judgements.r18_mean`). Each single gap against the interval the node stated is the
    reader's (the bus rules' R9). A report whose counter started again (the reader's ``restarted``: a reset,
    R19's) starts a stretch of its own (R9a), as the soak's trend is cut."""
    lo, hi = state.t, end - report_stamp_error_s(error=p.error, bitrate=p.bitrate)
    seen = _between(stamps, lo, hi)
    cuts = [0, *(bisect.bisect_left(seen, t) for t in _between(restarts, lo, hi)), len(seen)]
    for a, b in zip(cuts, cuts[1:]):  # (each restarted report starts the next piece)
        if found := _mean_finding(state, stream, seen[a:b], iv, t0, p, share):
            return found
    return []


def _mean_finding(state: State, stream: str, stamps: list[float], iv: float, t0: float, p: Params,
                  share: float) -> list[ExploreFinding]:
    seen = r9_judged(stamps)
    if len(seen) <= _MIN_GAPS:
        return []
    if share:
        j = r18_mean(seen, iv, share=share, bitrate=state.bitrate, error=p.error, jitter=p.jitter, what=stream)
    else:
        j = r9_mean(seen, iv, error=p.error, jitter=p.jitter)
    if j is None or j.ok:
        return []
    gaps = len(seen) - 1
    mean = (seen[-1] - seen[0]) / gaps
    tol = j.limit + j.error
    loaded = f", under {share:.0%} load" if share else ""
    return [ExploreFinding("interval", ["R9", "R18"] if share else ["R9"], f"{_label(stream)} every {mean * 1000:.1f} ms, "
                    f"not {iv * 1000:g} ms ({state.mode} since {state.cause}{loaded})", f"mean of {gaps} gaps {mean * 1000:.2f} ms",
                    f"{iv * 1000:g} ms (+-{tol * 1000:.2f})", seen[0] - t0, state.step, subject=f"{stream} interval")]


def _stream_reqs(state: State, stream: str) -> list[str]:
    """The requirement a stream's flowing or not comes from, by the mode the model is in and what led there."""
    if state.cause in ("power on", "ready"):
        return ["R13", "4.4.1-4"] if stream == "can_test" else ["R13"]
    if state.cause == "can_test" or state.mode == "can_test":
        return ["R16", "4.4.1-3"] if state.mode != "can_test" else ["R16", "4.4.1-2"]
    if stream == "exp" or state.mode == "exp":
        return ["4.4.2-T"]
    if state.mode == "suspended" or state.cause == "msg_control":
        return ["4.4.2-1", "4.4.2-T"]
    return ["R9"]


def _label(stream: str) -> str:
    return {"exp": "MSG_EXP reporting", "can_test": "CAN Test frames"}.get(stream, stream.upper())


def _between(stamps: list[float], lo: float, hi: float) -> list[float]:
    return stamps[bisect.bisect_left(stamps, lo):bisect.bisect_right(stamps, hi)]


# ------------------------------------------------------------------------------------------ MSG1 status
def _status(oracle: Oracle, dut: list[Frame], t0: float, p: Params, heard: EventLog) -> list[ExploreFinding]:
    model = [f for f in oracle.out if f.name == "msg1" and f.kind is Kind.MESSAGE]
    stamps = [f.timestamp for f in model]
    host_times = [f.timestamp for f, _ in oracle.host if f.name not in _THROTTLE]
    by_node = {node: sorted(times) for node, times in heard.commands.items()}  # R8's clock: the reader's
    ups = [st.t for st in oracle.states if st.label in ("start", "power on")]
    out: list[ExploreFinding] = []
    seen: set[int] = set()
    for f in dut:
        if f.name != "msg1" or f.kind is not Kind.MESSAGE or "status" not in f.fields:
            continue
        t = f.timestamp
        if in_short(oracle, t):
            continue  # R20: a short, what the DUT held through it and sent late, until its reports settle: OBSERVE
        if _between(host_times, t - cat.ANSWER_DELAY_MAX_S - 2 * p.error, t + p.host_late):
            continue  # a setting just sent (its echo may be stamped late): when within its answer time it shows is not written
        state = oracle.state_at(t)
        queueing = _queueing(oracle, t - 2 * state.intervals["msg1"], t, state.bitrate)  # R18: a load may hold it back
        if queueing is None:
            continue  # R18: above half load, OBSERVE
        reach = state.intervals["msg1"] + p.jitter + report_stamp_error_s(error=p.error, bitrate=p.bitrate, queueing=queueing)
        near = model[bisect.bisect_left(stamps, t - reach):bisect.bisect_right(stamps, t + reach)]
        if not near:
            continue
        mask = STATUS_MASK & ~_COMM  # bit 13 is judged on R8's own clock below
        if state.source != 0:
            # bit 14 under PWM+CAN: 4.4.4 names it "throttle signal source" without saying configured or in use
            # (4.2: PWM+CAN falls back to CAN by itself), and ESCs of other makes show either: not compared
            mask &= ~int(cat.Status.THROTTLE_PWM)
        commands = by_node.get(f.source, [])
        comm = _comm_fault_expected(t, commands, ups, state, p, queueing)
        if comm is not None and bool(f.fields["status"] & _COMM) != comm:
            bits = _COMM
            if bits not in seen:
                seen.add(bits)
                out.append(ExploreFinding("status", ["R8", "R7"], f"MSG1 comm-loss bit {'clear' if comm else 'set'} "
                                   f"{(t - _last(commands, t)) * 1000:.0f} ms after the last command ({state.mode})",
                                   f"status {f.fields['status']:#06x}", f"bit 13 {'set' if comm else 'clear'} "
                                   f"(R8: set 200 ms to 200 ms + one MSG1 interval after the last command)", t - t0,
                                   state.step, subject="status 0x2000"))
        got = f.fields["status"] & mask
        if any(m.fields["status"] & mask == got for m in near):
            continue
        want = near[len(near) // 2].fields["status"] & mask
        bits = got ^ want
        if bits in seen:
            continue  # one finding per kind of wrong bit
        seen.add(bits)
        rids = ["R8", "R7"] if bits & _COMM else ["R7"]
        for bit, setting in _STATUS_SETTING.items():  # a bit showing a setting: the setting's own keeping, and R13's
            if bits & bit:                            # after a power cycle in the program
                rids += [KEPT[setting]] + (["R13"] if any(u > t0 for u in ups if u <= t) else [])
        out.append(ExploreFinding("status", rids, f"MSG1 status bits {bits:#06x} differ ({state.mode} since {state.cause})",
                           f"status {f.fields['status']:#06x}", f"status {want:#06x} (bits {STATUS_MASK:#06x} compared)",
                           t - t0, state.step, subject=f"status {bits:#06x}"))
    return out


def _last(stamps: list[float], t: float) -> float:
    k = bisect.bisect_right(stamps, t)
    return stamps[k - 1] if k else float("-inf")


def _comm_fault_expected(t: float, commands: list[float], ups: list[float], state: State, p: Params,
                         queueing: float = 0.0) -> bool | None:
    """What MSG1's comm-loss bit must be at ``t`` (R8), or None where it is free: before any command since the
    power-up (when its boot ends is the DUT's own), inside R8's window, near a command, or not under CAN throttle.
    ``commands``: the reader's, the commands that addressed the MSG1's node's throttle channel
    (:meth:`~ckesc.evidence.events.ReaderEvents.command`: R8's clock, the soak's too), in time order: those stamped up
    to the bench's stated error after the MSG1 included. ``queueing``: how long a foreign load may have held the MSG1
    back (R18)."""
    if state.source != 0 or state.mode == "off":
        return None
    up = ups[max(0, bisect.bisect_right(ups, t) - 1)] if ups else float("-inf")
    last = _last(commands, t + p.host_late)
    if last < up:
        return None
    since = t - last
    error = report_stamp_error_s(error=p.error, bitrate=p.bitrate, queueing=queueing)  # MSG1's stamp is its end
    if since < -(error + p.jitter) or abs(since) <= REACT_S + p.host_late:
        return None  # a command as the MSG1 went out: queued before the DUT could act on it, or which came first is
        # within the bench's stated errors
    return r8_flag_due(since, state.intervals["msg1"], jitter=p.jitter, error=error)


def _queueing(oracle: Oracle, lo: float, hi: float, bitrate: int) -> float | None:
    """How long a foreign load between ``lo`` and ``hi`` may hold a report back (R18's queueing), None above half
    (R18: OBSERVE)."""
    share = oracle.max_load(lo, hi)
    if not r18_judged(share):
        return None
    return r18_queueing_s(share, bitrate) if share else 0.0
