"""The explorer's judge on what the DUT answered (sans-IO), against what the oracle model answers.

Which frame answers which request is F4's (:func:`~ckesc.protocol.judgements.f4_answers`): a response answers the
open request whose service id, transfer id and requester it carries (Set ID: from any node, R11), never the one
before it because it came first; a broadcast's answer (MSG Control, GET_ESC_ID: a message, which names no request)
is the first message of its type within the query's answer time. Where another node queries GET_ESC_ID too (a
flight controller, F6, with ``--foreign-traffic``), which query a reply answers is the one owner's
(:class:`~ckesc.evidence.pairing.QueryPairing`, as the suite, the bus rules and the soak take it): a reply that answers
another node's query is not the host's, and a host query whose reply may answer either is not judged. Paired so, for
the DUT's frames and the model's:

- every request the model answers must be answered (4.1.1-2; R2 for MSG Control, R1 for GET_ESC_ID), with the
  model's payload: read-backs (214 read, 242, 241 option 2's counters, GET_ESC_ID) and the answers to accepted
  writes. A request the model rejects (R10-R12) is free: answered or not, with anything (``rejected_answer``). 240's
  identity and 241's run times and temperatures are the DUT's own: presence only. 241's power-up count differs only
  modulo its 16 bits (:func:`~ckesc.protocol.judgements.r19_power_ups`), and grown with the power on it is a reset
  (R19's sign, and R17's after a malformed frame).
- **answer slots** (R2, 4.4.2-4 / 4.4.3-4 "related to the current ESC ID"): a MSG Control or GET_ESC_ID answer
  starts no earlier than the slot of the node id the model has now (after a Set ID, the new one's).
- **malformed and foreign frames** (R17): no answer to one: a response F4 pairs with it, or a frame of its type, not
  a report, within the answer time of it, that answers no host frame.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Iterable, Sequence

from ..evidence.pairing import HOST, NONE, QueryPairing
from ..protocol import catalogue as cat
from ..protocol.frame import Frame, frame_bits
from ..protocol.ids import Kind
from ..protocol.judgements import asked_node, f4_answers, r2_slot_start, r13_read_back, r19_power_ups
from ..protocol.requirements import requirement
from .actions import asks_only
from .finding import ExploreFinding, Params, stream_of
from .oracle import Malformed, Oracle

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


# ------------------------------------------------------------------------------------------ pairing (F4)
@dataclass(frozen=True)
class Ask:
    """A frame the DUT may answer (a request, a broadcast query, one sent malformed): when it was heard and what F4
    pairs its answer by (a broadcast's: its type only)."""

    t: float
    kind: Kind
    type_id: int
    transfer_id: int | None
    requester: int
    asked: int | None

    @classmethod
    def of(cls, req: Frame) -> Ask:
        asked = asked_node(req.name, req.destination) if req.kind is Kind.REQUEST else None  # type: ignore[arg-type]
        return cls(req.timestamp, req.kind, req.type_id, req.transfer_id, req.source, asked)  # type: ignore[arg-type]

    @classmethod
    def malformed(cls, m: Malformed, host: int) -> Ask:
        return cls(m.t, m.kind, m.type_id, m.transfer_id, host, asked_node(m.name, m.destination))  # type: ignore[arg-type]


def pair(asks: Sequence[Ask], frames: Iterable[Frame], *, before: float, after: float) -> list[Frame | None]:
    """The answer to each of ``asks`` among ``frames`` (the ESC's, in time order), from ``before`` ahead of the ask (a
    late echo's stamp) to ``after`` it. A response (or a request-kind frame, F1's mistake) of a requested service goes
    to the open request F4 pairs it with (:func:`~ckesc.protocol.judgements.f4_answers`, the requests in the order
    sent), each request's answer one frame; a message of a broadcast's type answers every query whose window holds it
    and has none yet."""
    got: list[Frame | None] = [None] * len(asks)
    order = sorted(range(len(asks)), key=lambda i: asks[i].t)
    requests = [i for i in order if asks[i].kind is Kind.REQUEST]
    services = {asks[i].type_id for i in requests}
    broadcasts = {asks[i].type_id for i in order if asks[i].kind is Kind.MESSAGE}
    for f in frames:
        if f.kind is not Kind.MESSAGE and f.type_id in services:
            open_ = [i for i in requests if got[i] is None and asks[i].t - before <= f.timestamp <= asks[i].t + after]
            k = f4_answers(f, [(asks[i].type_id, asks[i].transfer_id, asks[i].requester, asks[i].asked) for i in open_])
            if k is not None:
                got[open_[k]] = f
        elif f.kind is Kind.MESSAGE and f.type_id in broadcasts:
            for i in order:
                a = asks[i]
                if a.kind is Kind.MESSAGE and a.type_id == f.type_id and got[i] is None and a.t - before <= f.timestamp <= a.t + after:
                    got[i] = f
    return got


def _asks(req: Frame) -> bool:
    """Whether a host frame may be answered: a service request, or a broadcast query (a throttle frame is not)."""
    return req.kind is Kind.REQUEST or (req.kind is Kind.MESSAGE and req.name in _BROADCASTS)


# ------------------------------------------------------------------------------------------ answers
def answers(oracle: Oracle, dut: list[Frame], t0: float, p: Params, slack: float,
            queries: Sequence[Frame] = ()) -> list[ExploreFinding]:
    """The findings on what the DUT answered (the module's list). ``dut``: the ESC's frames in time order; ``slack``:
    how much earlier than its request an answer may be stamped (a real bench's late echo); ``queries``: other nodes'
    GET_ESC_ID queries heard meanwhile (a flight controller's)."""
    host = [(req, step) for req, step in oracle.host if _asks(req)]
    malformed = [m for m in oracle.malformed if m.kind is Kind.REQUEST]
    unjudged: set[int] = set()
    if queries:
        dut, unjudged = _the_hosts_replies([req for req, _ in host if req.name == "get_esc_id"], queries, dut, p)
    asks = [Ask.of(req) for req, _ in host]
    got = pair(asks + [Ask.malformed(m, p.host_node) for m in malformed], dut, before=slack, after=ANSWER_WAIT_S + 2 * p.error)
    want = pair(asks, [f for f in oracle.out if f.source != p.host_node], before=0.0, after=ANSWER_WAIT_S)
    for i, (req, _) in enumerate(host):
        if id(req) in unjudged:  # its reply may answer another node's query as well: which, cannot be told
            got[i] = want[i] = None
    out = _answered_as_modelled(oracle, host, got, want, t0, p)
    paired = {id(f) for f in got[:len(host)] if f is not None}
    return out + _r17_answers(oracle, dut, t0, p, slack, paired, dict(zip(map(id, malformed), got[len(host):])))


def _the_hosts_replies(asked: Sequence[Frame], queries: Sequence[Frame], dut: list[Frame],
                       p: Params) -> tuple[list[Frame], set[int]]:
    """``dut`` less the GET_ESC_ID replies that answer another node's query than the host's (``asked``), or may
    (:class:`~ckesc.evidence.pairing.QueryPairing`: the decision every mode takes), and the ids of the host's
    queries such an ambiguous reply may answer: they are not judged."""
    pairing = QueryPairing(error=max(p.error, p.own_error), host=p.host_node)
    events = sorted([(q.timestamp, 0, q) for q in (*asked, *queries)]
                    + [(f.timestamp, 1, f) for f in dut if f.name == "get_esc_id" and f.layout is not None
                       and f.layout.name == "reply"], key=lambda e: (e[0], e[1]))
    of_query: dict[int, int] = {}
    others: set[int] = set()
    unjudged: set[int] = set()
    for t, is_reply, f in events:
        if not is_reply:
            of_query[pairing.query(t, f.source).seq] = id(f)
            continue
        paired = pairing.reply(t, f.source)
        outcome = paired.outcome(p.host_node)
        if outcome in (HOST, NONE):
            continue
        others.add(id(f))
        unjudged.update(of_query[q.seq] for q in paired.could if q.source == p.host_node)
    return [f for f in dut if id(f) not in others], unjudged


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
        if model is None or not _answered(req) or (req.name, req.transfer_id or 0) in oracle.free:
            continue  # the model's ESC does not answer it (not addressed to it, off, booting; refused): nothing to compare
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
def _r17_answers(oracle: Oracle, dut: list[Frame], t0: float, p: Params, slack: float, paired: set[int],
                 to_request: dict[int, Frame | None]) -> list[ExploreFinding]:
    """R17: no answer to a malformed or foreign frame. To a request sent malformed, the response F4 pairs with it
    (``to_request``, by the id of its :class:`Malformed`); to another, a frame of the DUT of its type, not a report,
    within the answer time of it, that answers no host frame (``paired``: the valid command's answer, judged or free),
    a response only with its transfer id."""
    out = []
    seen: set[int] = set()
    for m in oracle.malformed:
        if m.kind is Kind.REQUEST:
            answer = to_request.get(id(m))
            near = [answer] if answer is not None else []
        else:
            near = [f for f in dut if m.t - slack <= f.timestamp <= m.t + ANSWER_WAIT_S + 2 * p.error
                    and f.type_id == m.type_id and stream_of(f) is None and f.kind is not Kind.REQUEST
                    and id(f) not in paired and (f.kind is not Kind.RESPONSE or m.transfer_id is None
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
