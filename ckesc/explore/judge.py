"""Comparing what the DUT sent with what the oracle model predicts, only where the document is specific (sans-IO).

Observations compared (each a :class:`Finding` when they differ):
- **answers**: every request the model answers must be answered (4.1.1-2; R2 for MSG Control, R1 for
  GET_ESC_ID), with the model's payload: read-backs (214 read, 242, 241 option 2's counters, GET_ESC_ID) and the
  answers to accepted writes. A request the model rejects (R10-R12) is free: answered or not, with anything
  (``rejected_answer``). 240's identity and 241's run times and temperatures are the DUT's own: presence only.
- **answer slots** (R2, 4.4.2-4 / 4.4.3-4 "related to the current ESC ID"): a MSG Control or GET_ESC_ID answer
  starts no earlier than the slot of the node id the model has now (after a Set ID, the new one's).
- **streams**: per stretch between two events (a host frame other than throttle, a power switch) and per
  report (MSG1, MSG2, MSG3, the MSG_EXP frames as one, CAN Test), whether it flows, judged only after the
  stretch has settled (R9a's restart allowance of the longer interval, answer delay and the bench's error; a
  power-up's boot time); which MSG_EXP frames come is OBSERVE (R9-exp), only that some do.
- **intervals** (R9): from the gap to the third report after the event on (R9a: the gaps before are OBSERVE), the
  mean gap of MSG1/2/3 against the model's interval, held to R9's tolerance (1 ms plus twice the bench's error, here
  with a frame's bus access, over the gaps; the DUT's jitter never widens the mean).
- **status** (R7, R8): each MSG1's bits 15, 14 (under CAN throttle only), 13 and 8 against the model's MSG1s within one interval
  (R8's window for bit 13: the flag may come up to one MSG1 interval after the model's).
- **malformed and foreign frames** (R17): the model ignores them, so whatever the DUT does on one differs: an
  answer to one (a frame of its type, not a report, within the answer time, and for a response with its transfer
  id), a restart of its reports across one (a report's transfer id not counting on, F3, or a gap longer than R9a's
  restart bound: the ESC reset), and any other finding after the first of them in the program, which
  :func:`cite_r17` makes cite R17 too (a setting, mode, suspension, LED or comm-loss flag the DUT changed on one
  shows as its read-back, stream or MSG1 status finding; a power-up count grown, as 241's answer).
- **a loaded bus** (R18): under a foreign load of up to half the bus (the runner's load steps), R9's mean interval is
  widened by the queueing the load can put ahead of a report (:func:`~ckesc.protocol.judgements.r18_mean`), and a
  report's reach (MSG1 status, R8's clock, R17's restart bound) by that queueing
  (:func:`~ckesc.protocol.judgements.r18_queueing_s`); R2's slot and the answers are not widened (R18 widens R9
  only). Under a load above half, and in the stretch after one, nothing is judged (R18: OBSERVE).
The live bus rules (``evidence/live.py``) run beside this and are findings of their own (runner).
"""

from __future__ import annotations

import bisect
from dataclasses import asdict, dataclass, field
from typing import Any, Iterable

from ..protocol import catalogue as cat
from ..protocol.frame import Frame, frame_bits
from ..protocol.ids import Kind
from ..protocol.judgements import (
    SCHEDULING_TOLERANCE_S,
    asked_node,
    f4_mismatches,
    f4_pairs,
    r2_slot_start,
    r8_flag_due,
    r9_judged,
    r9_mean,
    r9a_limit_s,
    r13_read_back,
    r18_judged,
    r18_mean,
    r18_queueing_s,
)
from ..protocol.requirements import requirement
from .actions import asks_only
from .oracle import Malformed, Oracle, State

#: MSG1 status bits compared (R7): direction, throttle source, comm fault (R8), running
STATUS_MASK = int(cat.STATUS_STATE_BITS)
#: the requirement an answer's payload comes from, per request
ANSWER_REQ = {
    "get_major_configuration": "4.4.28-1", "set_freq": "4.4.22-2", "maintenance_information": "4.4.27-T",
    "get_esc_id": "R1", "msg_control": "4.4.2-T", "set_led": "4.4.20-T", "set_rotation": "4.4.21-T",
    "set_id": "4.4.18-1", "set_baud": "4.4.19-T", "throttle_select": "4.4.23-1", "self_test": "4.4.24-1",
    "esc_information": "4.4.26-T", "get_rec": "R15-payload", "clear_rec": "R15-payload",
}
#: settings whose read-back after a power cycle R13 covers (where the persisted settings are read back)
_PERSISTED = {s.reader for s in cat.PERSISTED_SETTINGS if s.reader}
#: per setting field read back (242, 214, GET_ESC_ID) or shown (MSG1's direction bit): the clause of its own section
#: that says a written value is kept ("saved in FLASH ... not lost"); a value that changed where the model's did not
#: (a neighbour's save clobbered it, a power cycle lost it) breaks it
KEPT = {"direction": cat.PERSISTED["rotation"].clause,
        **{k: s.clause for s in cat.PERSISTED_SETTINGS if s.reader for k in s.keys}}
#: parameter changes R12 holds back while reporting is suspended
_WRITES_HELD = cat.SETTING_WRITERS
#: MSG1 status bits that show a setting (R7): bit 15 the direction of rotation
_STATUS_SETTING = {int(cat.Status.DIRECTION_CCW): "direction"}
_COMM = int(cat.Status.COMM_FAULT)  # R8's bit, judged on its own clock
#: fields compared per answer (None: all); () presence only
_COMPARED = {"esc_information": (), "maintenance_information": ("power_ups", "stops")}
_EXP = frozenset(cat.EXP_REPORT_FRAMES)
STREAMS = (*cat.REPORT_FRAMES, "exp", "can_test")
#: what flows in each mode of the model's ESC (4.4.2's table, R16; R9-exp: which MSG_EXP frames is OBSERVE)
_FLOWING = {"normal": cat.REPORT_FRAMES, "exp": ("exp",), "can_test": ("can_test",)}
_THROTTLE = cat.THROTTLE_FRAMES
#: events after which reporting restarts (R9a: power-up, resume, leaving MSG_EXP mode or CAN Test, a Set Freq write)
_RESTARTS = frozenset({"start", "power on", "ready", "msg_control", "can_test", "set_freq"})
ANSWER_WAIT_S = cat.ANSWER_DELAY_MAX_S + 0.036  # what the runner reads for an answer, plus its error below
#: how much later than the DUT heard it a host frame's echo may be stamped on a real bench (socketcand, a USB
#: adapter): the oracle hears it at its echo's time, so what the DUT did on it may show that much "early"
_ECHO_SLACK_S = 0.005
#: R9 on a stretch's mean interval only from this many gaps judged: fewer say little on a real bench
_MIN_GAPS = 3


@dataclass
class Finding:
    kind: str  # answer | stream | interval | status | reset | bus_rule
    requirements: list[str]
    what: str
    dut: str
    model: str
    at: float  # lane seconds from the program's start
    step: int | None = None  # the program step it follows (index), None: before any
    strength: str = field(default="")
    subject: str = ""  # what disagrees, without the numbers of this occurrence (the problem's key)

    def __post_init__(self) -> None:
        if not self.strength:
            strengths = [requirement(r).strength for r in self.requirements]  # an unknown id raises: never dropped
            self.strength = "SHALL" if "SHALL" in strengths else ("READING" if "READING" in strengths else "OBSERVE")

    @property
    def key(self) -> str:
        """The same problem, whatever program shows it (and however it got there): kind and subject."""
        return f"{self.kind}|{self.subject or self.what}"

    def to_json(self) -> dict[str, Any]:
        return {**asdict(self), "key": self.key}

    def text(self) -> str:
        where = f"after step {self.step + 1}" if self.step is not None else "before the first step"
        return (f"[{' '.join(self.requirements)} {self.strength}] {self.what} ({where}, t={self.at:.3f} s)\n"
                f"  DUT:   {self.dut}\n  model: {self.model}")


def _check_tables() -> None:
    """At import: every requirement id of the judge's tables is known (a typo raises here, rather than read as
    OBSERVE and its findings dropped), and every answered request has the requirement its answer comes from."""
    for rid in [*ANSWER_REQ.values(), *KEPT.values()]:
        requirement(rid)
    answered = {s.name for s in cat.CATALOGUE if s.service and s.responses} | {"msg_control", "get_esc_id"}
    if missing := sorted(answered - ANSWER_REQ.keys()):
        raise KeyError(f"ANSWER_REQ names no requirement for the answers to {missing}")


_check_tables()


@dataclass
class Params:
    error: float = 0.0  # the bench's timing error (s)
    own_error: float = 0.0  # the error of the host's own frames' times (the request an answer's delay counts from)
    jitter: float = 0.0  # the DUT's declared report jitter (profile jitter_s)
    boot_s: float = 0.5  # power-on to first report (profile)
    bitrate: int = cat.DEFAULT_BITRATE
    host_node: int = 0


def judge(oracle: Oracle, dut: list[Frame], t0: float, t_end: float, p: Params) -> list[Finding]:
    """Every disagreement between the DUT's frames (decoded, from the ESC, bus timestamps) and the model's."""
    dut = sorted((f for f in dut if f.source != p.host_node and f.timestamp is not None), key=lambda f: f.timestamp)
    paired: set[int] = set()
    out = _answers(oracle, dut, t0, p, paired)
    out += _streams(oracle, dut, t0, t_end, p)
    out += _status(oracle, dut, t0, p)
    out += _r17_answers(oracle, dut, t0, p, paired)
    out += _r17_restarts(oracle, dut, t0, t_end, p)
    return [f for f in out if f.strength != "OBSERVE" and r18_judged(_max_load(oracle, t0 + f.at, t0 + f.at))]


# ------------------------------------------------------------------------------------------ answers
def _answer_of(frames: Iterable[Frame], req: Frame, until: float, since: float | None = None,
               taken: set[int] | None = None) -> Frame | None:
    """The first answer to ``req`` in ``frames`` between ``since`` and ``until``, not one of ``taken`` (the ids of
    answers an earlier request got: with a look-back for late echoes, an earlier request's answer to another node
    with the same transfer id, F3 counting per destination, would otherwise pass for this one's)."""
    since = req.timestamp if since is None else since
    for f in frames:
        if f.timestamp < since or (taken is not None and id(f) in taken):
            continue
        if f.timestamp > until:
            return None
        if req.kind is Kind.REQUEST:  # paired as the host pairs it (F4): the service, and at most one field off
            if f.type_id == req.type_id and f4_pairs(f4_mismatches(
                    f, service=req.type_id, transfer_id=req.transfer_id, requester=req.source,
                    asked=asked_node(req.name, req.destination))):  # type: ignore[arg-type]
                return f
        elif f.kind is Kind.MESSAGE and f.type_id == req.type_id:  # (only the ESC's frames are given)
            return f
    return None


def _answered(req: Frame) -> bool:
    """Whether the document says this request is answered (and the model's answer is the DUT's to match)."""
    if req.kind is Kind.REQUEST:
        spec = req.spec
        if spec is None or not spec.responses:
            return False
        if req.name == "maintenance_information" and req.fields.get("option") not in (0, 1, 2):
            return False  # other options: not in the table
        return True
    if req.name == "msg_control":
        return req.fields.get("command") in (cat.MSG_CONTROL_SUSPEND, cat.MSG_CONTROL_RESUME, cat.MSG_CONTROL_RESUME_EXP)
    return req.name == "get_esc_id"


def _refusals(oracle: Oracle) -> list[tuple[float, str]]:
    """(when, the rule) of every write the model refused: R12 while suspended, R11 Set ID / Set Baud after the
    120 s window, R10 an illegal value. A read-back that differs after one is also that rule's business."""
    out = []
    ups = [s.t for s in oracle.states if s.label == "power on"]
    for req, _ in oracle.host:
        if (req.name, req.transfer_id or 0) not in oracle.free:
            continue
        state = _state_at(oracle, req.timestamp)
        up = max([oracle.powered_at] + [t for t in ups if t <= req.timestamp])
        if state.mode == "suspended":
            rule = "R12"
        elif req.name in ("set_id", "set_baud") and req.timestamp - up > cat.CONFIG_WINDOW_S:
            rule = "R11"
        else:
            rule = "R10"
        out.append((req.timestamp, rule))
    return out


def _answers(oracle: Oracle, dut: list[Frame], t0: float, p: Params, paired: set[int] | None = None) -> list[Finding]:
    """``paired``: filled with the ids of the DUT's frames that answer a host frame (judged or not)."""
    out = []
    refused = _refusals(oracle)
    model = [f for f in oracle.out if f.source != p.host_node]
    powered = False  # a power cycle came before (a read-back is then also R13's)
    taken: set[int] = set()  # the DUT's answers an earlier request got
    for req, step in oracle.host:
        if req.name in _THROTTLE:
            continue
        if req.kind is Kind.MESSAGE and req.name not in ("msg_control", "get_esc_id"):
            continue
        if any(s.label == "power on" and s.t <= req.timestamp and s.t > t0 for s in oracle.states):
            powered = True
        got = _answer_of(dut, req, req.timestamp + ANSWER_WAIT_S + 2 * p.error,
                         since=req.timestamp - (_ECHO_SLACK_S + 2 * p.error if p.error else 0.0), taken=taken)
        if got is not None and req.kind is Kind.REQUEST:  # the DUT's answer to this request, judged or not
            taken.add(id(got))
        if got is not None and paired is not None:
            paired.add(id(got))
        if not _answered(req) or (req.name, req.transfer_id or 0) in oracle.free:
            continue
        want = _answer_of(model, req, req.timestamp + ANSWER_WAIT_S)
        if want is None:  # the model's ESC does not answer it (not addressed to it, off, booting): nothing to compare
            continue
        reqs = [ANSWER_REQ[req.name]]
        if req.kind is Kind.REQUEST and req.name not in ("get_esc_id", "msg_control"):
            reqs.append("4.1.1-2")
        earlier = list(dict.fromkeys(rule for t, rule in refused if t < req.timestamp))
        if got is None:  # (after a write the model refused and the DUT took, a Set ID, it answers at another id)
            out.append(Finding("answer", reqs + [r for r in earlier if r not in reqs], f"{req.name} {_fields(req)} not answered", "no answer",
                               f"{_fields(want)}", req.timestamp - t0, step, subject=f"{req.name} not answered"))
            continue
        if req.kind is Kind.MESSAGE:
            out += _slot(req, got, want, step, t0, p, _state_at(oracle, req.timestamp).bitrate)
        keys = _COMPARED.get(req.name)
        a = {k: v for k, v in got.fields.items() if keys is None or k in keys}
        b = {k: v for k, v in want.fields.items() if keys is None or k in keys}
        rids = reqs[:1] + (["R13"] if powered and req.name in _PERSISTED else [])
        if req.name in _WRITES_HELD and not asks_only(req.name, req.fields) and _state_at(oracle, req.timestamp).mode == "suspended":
            rids.append("R12")  # the model's answer tells the setting it kept: R12 holds the change back
        rids += [rule for rule in earlier if rule not in rids]
        for d in r13_read_back(b, a, b):  # the answer read back against the model's (R13's after a power cycle)
            k = d.key
            kept = [KEPT[k]] if req.name in _PERSISTED and k in KEPT and KEPT[k] not in rids else []
            out.append(Finding("answer", rids + kept, f"{req.name} {_fields(req)} answered {k}={d.read}, the model {d.expected}",
                               _fields(got), _fields(want), req.timestamp - t0, step, subject=f"{req.name}.{k}"))
    return out


def _slot(req: Frame, got: Frame, want: Frame, step: int | None, t0: float, p: Params, bitrate: int) -> list[Finding]:
    """R2: a broadcast's answer (MSG Control, GET_ESC_ID) starts no earlier than its node's slot, (node_id % 32) x
    2 ms after the request, for the node id the model says the DUT has now (after a Set ID, its new one). Judged
    with the bench's error given to the DUT, as the suite's slot tests do; only the early side: an answer late in
    its slot is the 64 ms bound's (a real-time bench's stall makes one late, never early)."""
    node = want.source
    slot = cat.answer_slot_s(node)
    error = max(p.error, p.own_error)
    start = got.timestamp - frame_bits(len(got.data)) / bitrate - req.timestamp  # (its timestamp is its end)
    if r2_slot_start(start, node, error=error).ok:
        return []
    reqs = ["R2", "4.4.2-4" if req.name == "msg_control" else "4.4.3-4"]
    return [Finding("answer", reqs, f"{req.name} answered {start * 1000:.1f} ms after the request, before node {node}'s "
                    "slot", f"answer from node {got.source} starting {start * 1000:.2f} ms after the request",
                    f"node {node}: slot {slot * 1000:g}..{(slot + cat.ANSWER_SLOT_S) * 1000:g} ms (bench error "
                    f"+-{error * 1000:g} ms)", req.timestamp - t0, step, strength="READING",
                    subject=f"{req.name} answer before its slot")]


def _fields(f: Frame) -> str:
    return "{" + ", ".join(f"{k}={v:#x}" if isinstance(v, int) and v > 0xFFFF else f"{k}={v}"
                           for k, v in f.fields.items()) + "}"


# ------------------------------------------------------------------------------------------ malformed frames (R17)
def _r17_answers(oracle: Oracle, dut: list[Frame], t0: float, p: Params, paired: set[int]) -> list[Finding]:
    """R17: no answer to a malformed or foreign frame. A frame of the DUT of its type, not a report, within the answer
    time of it, that answers no host frame (``paired``: the valid command's answer, judged or free); a response only
    with the malformed frame's transfer id (F4's pairing)."""
    out = []
    seen: set[int] = set()
    slack = _ECHO_SLACK_S + 2 * p.error if p.error else 0.0
    for m in oracle.malformed:
        for f in _frames_between(dut, m.t - slack, m.t + ANSWER_WAIT_S + 2 * p.error):
            if (id(f) in seen or id(f) in paired or f.type_id != m.type_id or _stream_of(f) is not None
                    or f.kind is Kind.REQUEST or (f.kind is Kind.RESPONSE and m.transfer_id is not None
                                                  and f.transfer_id != m.transfer_id)):
                continue
            seen.add(id(f))
            out.append(Finding("answer", ["R17"], f"{f.name} {f.kind.label} to a malformed frame: {m.what}",
                               f"{f.kind.label} {_fields(f)} (transfer id {f.transfer_id})",
                               "no answer (R17: a malformed or foreign frame gets none)", f.timestamp - t0, m.step,
                               subject=f"{m.name} answered, {m.form}"))
    return out


def _r17_restarts(oracle: Oracle, dut: list[Frame], t0: float, t_end: float, p: Params) -> list[Finding]:
    """R17: a malformed frame never resets the ESC. After one, in normal reporting and with no event of the model's
    around it that restarts reports (a power switch, a mode, a Set Freq write), each report goes on: the DUT's next
    one comes within R9a's restart bound of its interval (a reset's boot stops it longer), and its transfer id counts
    on from the one before (F3: a restart begins it anew)."""
    out: list[Finding] = []
    marks = {m.t for m in oracle.malformed}
    frame_s = frame_bits(8) / p.bitrate
    others = [st for st in oracle.states if st.t not in marks]
    said: set[str] = set()
    for m in oracle.malformed:
        state = _state_at(oracle, m.t)
        if state.mode != "normal":
            continue
        longest = cat.restart_limit_s(max(state.intervals.values())) + p.boot_s + 2 * p.error
        queueing = _queueing(oracle, m.t - longest, m.t + longest, state.bitrate)
        if queueing is None:
            continue  # R18: a load above half around it, its reports OBSERVE
        # (a Set Freq read, or a write that changed nothing, restarts nothing; the program's start is no restart)
        restarts = [st.t for st in others if st.label in _RESTARTS - {"start", "set_freq"} or st.label == "power off"
                    or st.mode != state.mode or st.intervals != state.intervals]
        for stream in cat.REPORT_FRAMES:
            limit = cat.restart_limit_s(state.intervals[stream]) + 2 * p.error + p.jitter + frame_s + queueing
            if m.t + limit > t_end - 2 * p.error or stream in said or _between(restarts, m.t - longest, m.t + limit):
                continue
            mine = [f for f in dut if f.name == stream and f.kind is Kind.MESSAGE]
            k = bisect.bisect_right([f.timestamp for f in mine], m.t)
            before, after = (mine[k - 1] if k else None), (mine[k] if k < len(mine) else None)
            late = after is None or after.timestamp - m.t > limit
            jump = (not late and before is not None and before.transfer_id is not None and after.transfer_id is not None
                    and (before.transfer_id + 1) % 32 != after.transfer_id)
            if not late and not jump:
                continue
            said.add(stream)
            got = (f"no {stream.upper()} for {limit * 1000:.1f} ms after it" if late else
                   f"{stream.upper()} transfer id {before.transfer_id} -> {after.transfer_id}")
            out.append(Finding("reset", ["R17"], f"{stream.upper()} restarted after a malformed frame: {m.what}", got,
                               f"{stream.upper()} every {state.intervals[stream] * 1000:g} ms, its transfer id counting "
                               "on (R17: a malformed frame never resets the ESC)", m.t - t0, m.step,
                               subject=f"{stream} restarted, {m.form}"))
    return out


def cite_r17(findings: list[Finding], oracle: Oracle, t0: float) -> list[Finding]:
    """Every finding after a malformed or foreign frame of the program also cites R17 (the model ignored the
    frame; a DUT that took it differs from then on), and says which came last before it."""
    if not oracle.malformed:
        return findings
    for f in findings:
        before = [m for m in oracle.malformed if m.t - t0 <= f.at + _ECHO_SLACK_S]
        if before and "R17" not in f.requirements:
            f.requirements.append("R17")
            f.model += f" (R17: the model ignored {_step_of(before[-1])})"
    return findings


def cite_r18(findings: list[Finding], oracle: Oracle, t0: float) -> list[Finding]:
    """Every finding while (or just after) a foreign load played also cites R18 (the ESC keeps R9, R2, the 64 ms bound
    and obeys its commands under it), and says the load."""
    for f in findings:
        share = _max_load(oracle, t0 + f.at, t0 + f.at)
        if share and "R18" not in f.requirements:
            f.requirements.append("R18")
            f.model += f" (R18: under {share:.0%} foreign load)"
    return findings


def _step_of(m: Malformed) -> str:
    where = f" at step {m.step + 1}" if m.step is not None else ""
    return f"the malformed frame{where}: {m.what}"


def _frames_between(frames: list[Frame], lo: float, hi: float) -> list[Frame]:
    return [f for f in frames if lo <= f.timestamp <= hi]


# ------------------------------------------------------------------------------------------ streams
def _stream_of(f: Frame) -> str | None:
    n = f.name
    if n in (*cat.REPORT_FRAMES, "can_test"):
        return n if f.kind is Kind.MESSAGE else None
    return "exp" if n in _EXP else None


def _segments(oracle: Oracle, t_end: float) -> list[tuple[State, State | None, float]]:
    """(the state a stretch starts in, the state before it, its end)."""
    states = oracle.states
    return [(s, states[i - 1] if i else None, states[i + 1].t if i + 1 < len(states) else t_end)
            for i, s in enumerate(states)]


def _interval(state: State, stream: str) -> float:
    if stream in state.intervals:
        return state.intervals[stream]
    return max(state.intervals.values())  # MSG_EXP frames, CAN Test: at most the longest (R9-exp: OBSERVE)


def _streams(oracle: Oracle, dut: list[Frame], t0: float, t_end: float, p: Params) -> list[Finding]:
    out = []
    by = {k: ([], []) for k in STREAMS}
    for i, frames in enumerate((dut, oracle.out)):
        for f in frames:
            s = _stream_of(f)
            if s is not None and f.source != p.host_node:
                by[s][i].append(f.timestamp)
    frame_s = frame_bits(8) / p.bitrate
    restart: State | None = None  # the latest event after which a report restarts (R9a), and the state before it
    restart_before: State | None = None
    for state, before, end in _segments(oracle, t_end):
        if state.label in _RESTARTS and (state.label != "set_freq" or before is None or before.intervals != state.intervals):
            restart, restart_before = state, before  # (a Set Freq read, or a write that changed nothing, restarts nothing)
        share = max(state.load, before.load if before is not None else 0.0)  # (a load's queue outlasts it a little)
        if not r18_judged(share):
            continue  # R18: above half load (and the stretch after one) what the DUT does is OBSERVE
        for stream in STREAMS:
            iv = _interval(state, stream)
            old = _interval(before, stream) if before is not None else iv
            late = cat.ANSWER_DELAY_MAX_S + 2 * p.error  # the command may be answered first, stamps off by the error
            lo = state.t + r9a_limit_s(iv, old, jitter=p.jitter) + late + (p.boot_s if state.label == "power on" else 0.0)
            if restart is not None:  # R9a's allowance counts from the restart, over the longer of its old and new interval
                r_old = _interval(restart_before, stream) if restart_before is not None else iv
                lo = max(lo, restart.t + r9a_limit_s(iv, r_old, jitter=p.jitter) + late
                         + (p.boot_s if restart.label == "power on" else 0.0))
            hi = end - 2 * p.error - frame_s
            if hi <= lo:
                continue
            d = _between(by[stream][0], lo, hi)
            m = _between(by[stream][1], lo, hi)
            rids = _stream_reqs(state, stream) + (["R18"] if share else [])
            on = stream in _FLOWING.get(state.mode, ())
            if on and m and hi - lo >= 2 * iv and not d:
                if _between(by[stream][0], hi, end + 2 * iv):  # it came, late: the first report after a restart (R9a)
                    rids = ["R9a", *rids]
                out.append(Finding("stream", rids, f"{_label(stream)} stopped ({state.mode} since {state.cause})",
                                   f"no {_label(stream)} for {hi - lo:.3f} s", f"{len(m)} frames",
                                   lo - t0, state.step, subject=f"{stream} stopped, {state.mode}"))
            elif not on and d:
                out.append(Finding("stream", rids, f"{_label(stream)} sent ({state.mode} since {state.cause})",
                                   f"{len(d)} frames, the first at t={d[0] - t0:.3f} s", "none", d[0] - t0, state.step,
                                   subject=f"{stream} sent, {state.mode}"))
            elif stream in cat.REPORT_FRAMES and len(m) >= 2:
                out += _interval_finding(state, stream, by[stream][0], end, iv, t0, p, frame_s, share)
    return out


def _interval_finding(state: State, stream: str, stamps: list[float], end: float, iv: float, t0: float, p: Params,
                      frame_s: float, share: float = 0.0) -> list[Finding]:
    """R9 on the DUT's reports of one stretch, the gap to its third report and on (R9a: the gaps before are
    OBSERVE), on the mean of their gaps (:func:`~ckesc.protocol.judgements.r9_mean`): its stamps are the frames'
    ends, each late by up to a frame's bus access besides the bench's error. Under a foreign load of ``share`` (R18,
    up to half), widened by the queueing it can cause (:func:`~ckesc.protocol.judgements.r18_mean`)."""
    seen = r9_judged(_between(stamps, state.t, end - 2 * p.error))
    if len(seen) <= _MIN_GAPS:
        return []
    if share:
        j = r18_mean(seen, iv, share=share, bitrate=state.bitrate, error=p.error + frame_s, what=stream)
    else:
        j = r9_mean(seen, iv, error=p.error + frame_s)
    if j is None or j.ok:
        return []
    gaps = len(seen) - 1
    mean = (seen[-1] - seen[0]) / gaps
    tol = j.limit + j.error
    loaded = f", under {share:.0%} load" if share else ""
    return [Finding("interval", ["R9", "R18"] if share else ["R9"], f"{_label(stream)} every {mean * 1000:.1f} ms, "
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
def _status(oracle: Oracle, dut: list[Frame], t0: float, p: Params) -> list[Finding]:
    model = [f for f in oracle.out if f.name == "msg1" and f.kind is Kind.MESSAGE]
    stamps = [f.timestamp for f in model]
    host_times = [f.timestamp for f, _ in oracle.host if f.name not in _THROTTLE]
    commands = oracle.commands
    ups = [st.t for st in oracle.states if st.label in ("start", "power on")]
    out: list[Finding] = []
    seen: set[int] = set()
    for f in dut:
        if f.name != "msg1" or f.kind is not Kind.MESSAGE or "status" not in f.fields:
            continue
        t = f.timestamp
        if _between(host_times, t - cat.ANSWER_DELAY_MAX_S - 2 * p.error, t + _ECHO_SLACK_S + 2 * p.error):
            continue  # a setting just sent (its echo may be stamped late): when within its answer time it shows is not written
        state = _state_at(oracle, t)
        queueing = _queueing(oracle, t - 2 * state.intervals["msg1"], t, state.bitrate)  # R18: a load may hold it back
        if queueing is None:
            continue  # R18: above half load, OBSERVE
        reach = state.intervals["msg1"] + SCHEDULING_TOLERANCE_S + 2 * p.error + p.jitter + frame_bits(8) / p.bitrate + queueing
        near = model[bisect.bisect_left(stamps, t - reach):bisect.bisect_right(stamps, t + reach)]
        if not near:
            continue
        mask = STATUS_MASK & ~_COMM  # bit 13 is judged on R8's own clock below
        if state.source != 0:
            # bit 14 under PWM+CAN: 4.4.4 names it "throttle signal source" without saying configured or in use
            # (4.2: PWM+CAN falls back to CAN by itself), and ESCs of other makes show either: not compared
            mask &= ~int(cat.Status.THROTTLE_PWM)
        comm = _comm_fault_expected(t, commands, ups, state, p, queueing)
        if comm is not None and bool(f.fields["status"] & _COMM) != comm:
            bits = _COMM
            if bits not in seen:
                seen.add(bits)
                out.append(Finding("status", ["R8", "R7"], f"MSG1 comm-loss bit {'clear' if comm else 'set'} "
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
        out.append(Finding("status", rids, f"MSG1 status bits {bits:#06x} differ ({state.mode} since {state.cause})",
                           f"status {f.fields['status']:#06x}", f"status {want:#06x} (bits {STATUS_MASK:#06x} compared)",
                           t - t0, _state_at(oracle, t).step, subject=f"status {bits:#06x}"))
    return out


def _last(stamps: list[float], t: float) -> float:
    k = bisect.bisect_right(stamps, t)
    return stamps[k - 1] if k else float("-inf")


def _comm_fault_expected(t: float, commands: list[float], ups: list[float], state: State, p: Params,
                         queueing: float = 0.0) -> bool | None:
    """What MSG1's comm-loss bit must be at ``t`` (R8), or None where it is free: before any command since the
    power-up (when its boot ends is the DUT's own), inside R8's window, near a command, or not under CAN throttle.
    ``queueing``: how long a foreign load may have held the MSG1 back (R18)."""
    if state.source != 0 or state.mode == "off":
        return None
    up = ups[max(0, bisect.bisect_right(ups, t) - 1)] if ups else float("-inf")
    last = _last(commands, t + _ECHO_SLACK_S + 2 * p.error)
    if last < up:
        return None
    since = t - last
    error = SCHEDULING_TOLERANCE_S + 2 * p.error + frame_bits(8) / p.bitrate + queueing  # MSG1's stamp is its end
    if since < -(error + p.jitter) or abs(since) <= _ECHO_SLACK_S + 2 * p.error:
        return None  # a command as the MSG1 went out: which came first is within the bench's error
    return r8_flag_due(since, state.intervals["msg1"], jitter=p.jitter, error=error)


def _max_load(oracle: Oracle, lo: float, hi: float) -> float:
    """The highest foreign load (R18's share) on the bus between lane times ``lo`` and ``hi``, or in the stretch
    before (a load's queue outlasts it a little)."""
    times = [s.t for s in oracle.states]
    first = max(0, bisect.bisect_right(times, lo) - 2)
    return max((s.load for s in oracle.states[first:bisect.bisect_right(times, hi)]), default=0.0)


def _queueing(oracle: Oracle, lo: float, hi: float, bitrate: int) -> float | None:
    """How long a foreign load between ``lo`` and ``hi`` may hold a report back (R18's queueing), None above half
    (R18: OBSERVE)."""
    share = _max_load(oracle, lo, hi)
    if not r18_judged(share):
        return None
    return r18_queueing_s(share, bitrate) if share else 0.0


def _state_at(oracle: Oracle, t: float) -> State:
    times = [s.t for s in oracle.states]
    return oracle.states[max(0, bisect.bisect_right(times, t) - 1)]
