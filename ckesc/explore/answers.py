"""The explorer's judge on what the DUT answered (sans-IO), against what the oracle model answers.

Which frame answers which request is the bus reader's (:class:`~ckesc.evidence.pairing.RequestPairing`, told as
:meth:`~ckesc.evidence.events.ReaderEvents.response`): a response answers the open request whose service id,
transfer id and requester it carries (Set ID: from any node, R11), never the one before it because it came first
(F4, :func:`~ckesc.protocol.judgements.f4_answers`); a MSG Control answer (a message, which names no request) answers
the earliest command it has not answered within R2's reach. Which GET_ESC_ID query a reply answers, the host's or
another node's (a flight controller's, F6, with ``--foreign-traffic``), is the reader's too
(:class:`~ckesc.evidence.pairing.QueryPairing`): a host query whose reply may answer either is not judged. The judge
reads both pairings from the reader's :class:`~ckesc.evidence.events.EventLog` of the DUT's trace and of the model's
(one reader, two traces), and keeps only what the model alone knows: what the ESC should have answered, with what,
and by when (within :data:`ANSWER_WAIT_S` and the bench's error of its request). Paired so:

- every request the model answers must be answered (4.1.1-2; R2 for MSG Control, R1 for GET_ESC_ID), with the
  model's payload: read-backs (214 read, 242, 241 option 2's counters, GET_ESC_ID) and the answers to accepted
  writes. A request the model rejects (R10-R12) is free: answered or not, with anything (``rejected_answer``). 240's
  identity and 241's run times and temperatures are the DUT's own: presence only. 241's power-up count differs only
  modulo its 16 bits (:func:`~ckesc.protocol.judgements.r19_power_ups`), and grown with the power on it is a reset
  (R19's sign, and R17's after a malformed frame).
- **answer slots** (R2, 4.4.2-4 / 4.4.3-4 "related to the current ESC ID"): a MSG Control or GET_ESC_ID answer
  starts no earlier than the slot of the node id the model has now (after a Set ID, the new one's).
- **malformed and foreign frames** (R17): no answer to one: a response the reader pairs with it (it hears a malformed
  request as one the ESC ignores), or a frame of its type, not a report, within the answer time of it, that answers no
  host frame.
"""

from __future__ import annotations

from ..evidence.events import EventLog
from ..protocol import catalogue as cat
from ..protocol.frame import Frame, frame_bits
from ..protocol.ids import Kind
from ..protocol.judgements import r2_slot_start, r13_read_back, r19_power_ups
from ..protocol.requirements import requirement
from .actions import asks_only
from .finding import ExploreFinding, Params, stream_of
from .oracle import Oracle

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
#: fields compared per answer (None: all); () presence only
_COMPARED = {"esc_information": (), "maintenance_information": ("power_ups", "stops")}
_BROADCASTS = ("msg_control", "get_esc_id")
ANSWER_WAIT_S = cat.ANSWER_DELAY_MAX_S + 0.036  # what the runner reads for an answer, plus its error below


def check_tables() -> None:
    """At import: every requirement id of the tables is known (a typo raises here, rather than read as OBSERVE and
    its findings dropped), and every answered request has the requirement its answer comes from."""
    for rid in [*ANSWER_REQ.values(), *KEPT.values()]:
        requirement(rid)
    answered = {s.name for s in cat.CATALOGUE if s.service and s.responses} | set(_BROADCASTS)
    if missing := sorted(answered - ANSWER_REQ.keys()):
        raise KeyError(f"ANSWER_REQ names no requirement for the answers to {missing}")


check_tables()


# ------------------------------------------------------------------------------------------ the reader's pairing
def _asks(req: Frame) -> bool:
    """Whether a host frame may be answered: a service request, or a broadcast query (a throttle frame is not)."""
    return req.kind is Kind.REQUEST or (req.kind is Kind.MESSAGE and req.name in _BROADCASTS)


def _query(req: Frame) -> bool:
    return req.kind is Kind.MESSAGE and req.name == "get_esc_id"


def answer_to(log: EventLog, req: Frame, frames: dict[tuple[int, float], Frame], within: float) -> Frame | None:
    """The answer the reader paired with host frame ``req`` (its :class:`~ckesc.evidence.events.EventLog`), among
    ``frames`` (by CAN id and time), if it came within ``within`` of it (later: not the answer the model wants)."""
    if _query(req):
        hit = log.replies.get((req.timestamp, req.source))  # type: ignore[arg-type]
    else:
        hit = log.answers.get(log.key(req.timestamp, req.type_id, req.transfer_id, req.source))  # type: ignore[arg-type]
    if hit is None or hit[1] - req.timestamp > within:  # type: ignore[operator]
        return None
    return frames.get(hit[:2])  # type: ignore[arg-type]


# ------------------------------------------------------------------------------------------ answers
def answers(oracle: Oracle, dut: list[Frame], t0: float, p: Params, heard: EventLog, model: EventLog) -> list[ExploreFinding]:
    """The findings on what the DUT answered (the module's list). ``dut``: the ESC's frames in time order; ``heard``
    and ``model``: the reader's log of the DUT's trace and of the model's."""
    host = [(req, step) for req, step in oracle.host if _asks(req)]
    mine = {(f.can_id, f.timestamp): f for f in dut}
    models = {(f.can_id, f.timestamp): f for f in oracle.out}
    late = ANSWER_WAIT_S + 2 * p.error
    got: list[Frame | None] = []
    want: list[Frame | None] = []
    for req, _ in host:
        if _query(req) and (req.timestamp, req.source) in heard.ambiguous:
            got.append(None)  # its reply may answer another node's query as well: which, cannot be told
            want.append(None)
            continue
        got.append(answer_to(heard, req, mine, late))
        want.append(answer_to(model, req, models, ANSWER_WAIT_S))
    out = _answered_as_modelled(oracle, host, got, want, t0, p)
    return out + _r17_answers(oracle, dut, t0, p, heard, mine)


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
        state = oracle.state_at(req.timestamp)
        up = max([oracle.powered_at] + [t for t in ups if t <= req.timestamp])
        if state.mode == "suspended":
            rule = "R12"
        elif req.name in ("set_id", "set_baud") and req.timestamp - up > cat.CONFIG_WINDOW_S:
            rule = "R11"
        else:
            rule = "R10"
        out.append((req.timestamp, rule))
    return out


def _answered_as_modelled(oracle: Oracle, host: list[tuple[Frame, int | None]], got: list[Frame | None],
                          want: list[Frame | None], t0: float, p: Params) -> list[ExploreFinding]:
    """Each host frame the model answers, against the DUT's answer to it (``got``, paired as ``want`` is)."""
    out = []
    refused = _refusals(oracle)
    powered = False  # a power cycle came before (a read-back is then also R13's)
    for (req, step), mine, model in zip(host, got, want):
        if any(s.label == "power on" and s.t <= req.timestamp and s.t > t0 for s in oracle.states):
            powered = True
        if model is None or not _answered(req) or (req.name, req.transfer_id or 0) in oracle.free | oracle.held:
            continue  # the model's ESC does not answer it (not addressed to it, off, booting; refused), or the host sent
            # it alone on the bus (R20: the ESC met it at its power-up, its answer OBSERVE): nothing to compare
        reqs = [ANSWER_REQ[req.name]]
        if req.kind is Kind.REQUEST and req.name not in _BROADCASTS:
            reqs.append("4.1.1-2")
        earlier = list(dict.fromkeys(rule for t, rule in refused if t < req.timestamp))
        if mine is None:  # (after a write the model refused and the DUT took, a Set ID, it answers at another id)
            out.append(ExploreFinding("answer", reqs + [r for r in earlier if r not in reqs], f"{req.name} {fields(req)} not answered", "no answer",
                               f"{fields(model)}", req.timestamp - t0, step, subject=f"{req.name} not answered"))
            continue
        if req.kind is Kind.MESSAGE:
            out += _slot(req, mine, model, step, t0, p, oracle.state_at(req.timestamp).bitrate)
        keys = _COMPARED.get(req.name)
        a = {k: v for k, v in mine.fields.items() if keys is None or k in keys}
        b = {k: v for k, v in model.fields.items() if keys is None or k in keys}
        rids = reqs[:1] + (["R13"] if powered and req.name in _PERSISTED else [])
        if req.name in _WRITES_HELD and not asks_only(req.name, req.fields) and oracle.state_at(req.timestamp).mode == "suspended":
            rids.append("R12")  # the model's answer tells the setting it kept: R12 holds the change back
        rids += [rule for rule in earlier if rule not in rids]
        for d in r13_read_back(b, a, b):  # the answer read back against the model's (R13's after a power cycle)
            k = d.key
            cited = [KEPT[k]] if req.name in _PERSISTED and k in KEPT and KEPT[k] not in rids else []
            if k == "power_ups" and isinstance(d.expected, int) and isinstance(d.read, int):
                if (reset := r19_power_ups(d.expected, d.read)) is None:
                    continue  # the same count modulo its 16 bits
                cited += [] if powered else [reset.rule]  # grown with the power on since the program's start: a reset
            out.append(ExploreFinding("answer", rids + cited, f"{req.name} {fields(req)} answered {k}={d.read}, the model {d.expected}",
                               fields(mine), fields(model), req.timestamp - t0, step, subject=f"{req.name}.{k}"))
    return out


def _slot(req: Frame, got: Frame, want: Frame, step: int | None, t0: float, p: Params, bitrate: int) -> list[ExploreFinding]:
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
    return [ExploreFinding("answer", reqs, f"{req.name} answered {start * 1000:.1f} ms after the request, before node {node}'s "
                    "slot", f"answer from node {got.source} starting {start * 1000:.2f} ms after the request",
                    f"node {node}: slot {slot * 1000:g}..{(slot + cat.ANSWER_SLOT_S) * 1000:g} ms (bench error "
                    f"+-{error * 1000:g} ms)", req.timestamp - t0, step, strength="READING",
                    subject=f"{req.name} answer before its slot")]


def fields(f: Frame) -> str:
    return "{" + ", ".join(f"{k}={v:#x}" if isinstance(v, int) and v > 0xFFFF else f"{k}={v}"
                           for k, v in f.fields.items()) + "}"


# ------------------------------------------------------------------------------------------ malformed frames (R17)
def _r17_answers(oracle: Oracle, dut: list[Frame], t0: float, p: Params, heard: EventLog,
                 mine: dict[tuple[int, float], Frame]) -> list[ExploreFinding]:
    """R17: no answer to a malformed or foreign frame. To a request sent malformed, the response the reader pairs with
    it (it hears it as a request the ESC ignores); to another, a frame of the DUT of its type, not a report, within the
    answer time of it (and the stamps' errors before it), that the reader pairs with no host frame, a response only with
    its transfer id."""
    out = []
    seen: set[int] = set()
    slack = p.host_late
    for m in oracle.malformed:
        if m.kind is Kind.REQUEST:
            hit = heard.answers.get(heard.key(m.t, m.type_id, m.transfer_id, p.host_node))
            answer = mine.get(hit[:2]) if hit is not None else None  # type: ignore[arg-type]
            near = [answer] if answer is not None else []
        else:
            near = [f for f in dut if m.t - slack <= f.timestamp <= m.t + ANSWER_WAIT_S + 2 * p.error  # type: ignore[operator]
                    and f.type_id == m.type_id and stream_of(f) is None and f.kind is not Kind.REQUEST
                    and (f.can_id, f.timestamp) not in heard.paired and (f.kind is not Kind.RESPONSE or m.transfer_id is None
                                                                        or f.transfer_id == m.transfer_id)]
        for f in near:
            if id(f) in seen:
                continue
            seen.add(id(f))
            out.append(ExploreFinding("answer", ["R17"], f"{f.name} {f.kind.label} to a malformed frame: {m.what}",
                               f"{f.kind.label} {fields(f)} (transfer id {f.transfer_id})",
                               "no answer (R17: a malformed or foreign frame gets none)", f.timestamp - t0, m.step,
                               subject=f"{m.name} answered, {m.form}"))
    return out
