"""One trace, four consumers, one finding (issue #28): the frames of an emulated ESC judged by the conformance
suite's R9 check (:func:`conformance.telemetry` calls ``judgements.r9_judged`` / ``r9_mean``), the live bus rules
(:mod:`ckesc.evidence.rules`), ``ckesc explore``'s judge (against its faultless oracle) and ``ckesc check-log`` (the
command, over a candump log of the same frames). An ESC whose MSG1 comes every 30 ms instead of 20 (the emulator's
fault ``report_interval_wrong``) is R9 to all four; the faultless ESC is R9 to none.

F3 likewise (``judgements.f3_step``): an ESC whose message transfer ids never move (``transfer_id_stuck``) is F3 to
the suite's check (``conformance/test_s4_1_framing.py``), the bus rules and check-log, with the same words; the
faultless ESC is F3 to none. The explorer's judge does not judge F3: its runner hears the same frames through the live
bus rules (``evidence/live.LaneRules``, :class:`~ckesc.evidence.rules.BusRules`), whose F3 finding is the explorer's.

GET_ESC_ID pairing likewise (issue #35, :class:`~ckesc.evidence.pairing.QueryPairing`): with a flight controller's
queries interleaved with the host's, each reply answers the same query to the suite's helper
(``conformance.answers.esc_id_pairings``), the bus rules, check-log and the soak's AnswerWatch, with the host's own
frames timed by their echo or without one, the ESC answering the flight controller or not (F6).

The explorer's judge takes the reader's pairing (``_explorer_pairing``): it judges the reply the reader gives each host
query, none where the reply may be the flight controller's, and finds nothing on the faultless ESC. Service responses
and their requests (F4, by transfer id): ``test_one_judgement_answers``.

The other stateful rules have modules of their own, on the trace player and the consumers' runners here (:func:`play`,
:func:`request`, :func:`bus_rules`, :func:`check_log`): report restarts (R9a, ``test_one_judgement_restarts``), resets
(R19, ``test_one_judgement_resets``), the comm flag (R8, ``test_one_judgement_comm``) and a loaded bus (R18,
``test_one_judgement_load``)."""

from __future__ import annotations

import json

import can
import pytest

from ckesc.cli import main as cli_main
from ckesc.emulator.config import EscConfig
from ckesc.emulator.model import EscModel
from ckesc.evidence.rules import BusRules
from ckesc.explore.judge import Params, judge
from ckesc.explore.oracle import Oracle
from ckesc.protocol import catalogue as cat
from ckesc.protocol.errors import DecodeError
from ckesc.protocol.frame import Decoder, encode, frame_bits
from ckesc.protocol.judgements import R9_GAPS, r9_judged, r9_mean
from ckesc.soak.monitor import Monitor
from ckesc.soak.watch import WatchConfig
from conformance.answers import esc_id_pairings
from conformance.test_s4_1_framing import counter_streams, counting_problems
from conformance.wire import HeardFrame

NODE = 5
BOOT_S = 0.25
ASK_AT = 0.4  # the host reads the intervals (Set/Get Freq read): the node states its 20 ms
END_S = 1.6


def request(name: str, fields: dict, t: float, *, source: int = 0, destination: int | None = NODE, transfer_id: int = 0,
            layout: str | None = None) -> can.Message:
    """A host's frame at ``t`` (a service request to ``destination``; a message with ``layout``, or without one and
    ``destination`` None), as heard: the host's own (``is_rx`` False) when node 0 sends it, else another node's (a
    flight controller's)."""
    kw = {"layout": layout} if layout else {"kind": "request", "destination": destination} if destination else {}
    wire = encode(name, fields, source=source, transfer_id=transfer_id, **kw)
    return can.Message(arbitration_id=wire.arbitration_id, data=wire.data, is_extended_id=True, timestamp=t,
                       is_rx=source != 0)


def decoded(frames) -> list:
    """The CKESC frames among ``frames``, decoded (another node's frames, a flight controller's DroneCAN or a load
    source's, are none and left out)."""
    decoder, out = Decoder(), []
    for m in frames:
        try:
            out.append(decoder.decode(m))
        except DecodeError:
            pass
    return out


def play(events, end: float, *, nvm: dict | None = None, **config) -> list[can.Message]:
    """An emulated ESC at node NODE (``EscConfig`` ``config``: faults, ...; ``nvm``: its flash before, e.g.
    ``power_ups``) powered at 0, fed ``events`` in time order, each ``(t, what)``: a ``can.Message`` it hears (the
    host's or another node's), or ``"off"`` / ``"on"`` (its power switched: a reset when nobody says so), up to
    ``end``. Returns everything on the bus, in order: the frames
    fed as given, the ESC's one at a time (the lowest id first) stamped at their end, as SocketCAN does."""
    esc = EscModel(EscConfig(**{"node_id": NODE, "boot_time": BOOT_S, **config}))
    esc.nvm.update(nvm or {})  # (its flash as a long life left it: a power-up count near its wrap, say)
    esc.power_on(0.0)
    out, fed = [], []

    def run(until: float) -> None:
        while (d := esc.next_deadline()) is not None and d <= until:
            out.extend(esc.poll(d))
        out.extend(esc.poll(until))

    for t, what in events:
        run(t)
        if what == "off":
            esc.power_off(t)
        elif what == "on":
            esc.power_on(t)
        else:
            esc.receive(what, t)
            fed.append(what)
    run(end)
    heard, bus_free = [], 0.0
    for w in sorted(out, key=lambda w: (w.timestamp, w.arbitration_id)):
        bus_free = max(w.timestamp, bus_free) + frame_bits(len(w.data)) / cat.DEFAULT_BITRATE
        heard.append(can.Message(arbitration_id=w.arbitration_id, data=w.data, is_extended_id=True, timestamp=bus_free))
    return sorted(heard + fed, key=lambda m: m.timestamp)


def _trace(faults: tuple[str, ...]) -> tuple[can.Message, list[can.Message]]:
    """The host's Set/Get Freq read at ASK_AT and everything the emulated ESC sends up to END_S, as heard."""
    ask = request("set_freq", {"option": 0, "msg1_interval": 0, "msg2_interval": 0, "msg3_interval": 0}, ASK_AT)
    return ask, [m for m in play([(ASK_AT, ask)], END_S, faults=faults) if m is not ask]


def _conformance(ask, heard) -> set[str]:
    """As ``conformance.telemetry.check_restart`` judges a report's interval: the mean of R9_GAPS gaps from the second
    report after the event on, against the interval the node's answer states."""
    decoder = Decoder()
    frames = [decoder.decode(m) for m in heard]
    answer = next(f for f in frames if f.name == "set_freq" and f.timestamp >= ASK_AT)
    target = answer.fields["msg1_interval"] * cat.INTERVAL_UNIT_S
    starts = [f.timestamp - frame_bits(len(f.data)) / cat.DEFAULT_BITRATE for f in frames
              if f.name == "msg1" and f.timestamp > answer.timestamp]
    j = r9_mean(r9_judged(starts)[:R9_GAPS + 1], target, error=0.0)
    assert j is not None
    return set() if j.ok else {j.rule}


def _bus_rules(ask, heard) -> set[str]:
    rules = BusRules(tolerance=0.0, complete=True, power_known=True)
    out = set()
    for m in sorted([ask, *heard], key=lambda m: m.timestamp):
        for v in rules.feed_message(m):
            out.update(r for r in v.rules if v.message.startswith("msg1 "))
    return out


def _explorer(ask, heard) -> set[str]:
    baseline = {"node_id": NODE, "throttle_channel": NODE, **cat.DEFAULT_REPORT_INTERVALS}
    oracle = Oracle(baseline, powered_at=0.0, start=BOOT_S)
    oracle.host_frame(ask, 0)
    oracle.finish(END_S)
    decoder = Decoder()
    found = judge(oracle, [decoder.decode(m) for m in heard if m.timestamp >= BOOT_S], BOOT_S, END_S, Params(boot_s=BOOT_S))
    return {r for f in found if f.subject == "msg1 interval" for r in f.requirements}


def check_log(frames, tmp_path, capsys, *flags: str) -> tuple[int, str, dict]:
    """``ckesc check-log --complete FLAGS`` over a candump log of ``frames``: its exit code, what it printed, its
    JSON summary."""
    log, out = tmp_path / "trace.log", tmp_path / "summary.json"
    log.write_text("".join(f"({m.timestamp:.6f}) can0 {m.arbitration_id:08X}#{bytes(m.data).hex().upper()}\n"
                           for m in sorted(frames, key=lambda m: m.timestamp)))
    code = cli_main(["check-log", "--complete", *flags, "--json", str(out), str(log)])
    text = capsys.readouterr().out
    assert code in (0, 1), text
    return code, text, json.loads(out.read_text())


def bus_rules(frames, **kw) -> list:
    """The live bus rules over ``frames`` (a suite's lane: every frame heard, every power switch reported): the
    violations they find (``kw``: e.g. the ``power_switched`` times to report, as the lane does)."""
    switches = sorted(kw.pop("power_switched", ()))
    rules = BusRules(tolerance=0.0, complete=True, power_known=True, **kw)
    out = []
    for m in sorted(frames, key=lambda m: m.timestamp):
        while switches and switches[0] <= m.timestamp:
            rules.power_switched(switches.pop(0))
        out.extend(rules.feed_message(m))
    return out


def _check_log_run(ask, heard, tmp_path, capsys) -> tuple[int, str]:
    """``ckesc check-log --complete`` over a candump log of the frames: its exit code and what it printed."""
    code, text, _ = check_log([ask, *heard], tmp_path, capsys)
    return code, text


def _check_log(ask, heard, tmp_path, capsys) -> set[str]:
    code, text = _check_log_run(ask, heard, tmp_path, capsys)
    if code == 0:
        return set()
    return {"R9"} if "R9" in text and "msg1 30.000 ms after the previous one" in text else {"other: " + text[-300:]}


@pytest.mark.parametrize("faults, expected", [((), False), (("report_interval_wrong",), True)],
                         ids=["20 ms", "30 ms instead of 20"])
def test_one_trace_the_same_r9_finding_from_all_four(faults, expected, tmp_path, capsys):
    ask, heard = _trace(faults)
    got = {
        "conformance": "R9" in _conformance(ask, heard),
        "bus rules": "R9" in _bus_rules(ask, heard),
        "explorer": "R9" in _explorer(ask, heard),
        "check-log": "R9" in _check_log(ask, heard, tmp_path, capsys),
    }
    assert got == dict.fromkeys(got, expected)


# ------------------------------------------------------------------------------------------ F3
#: the words every consumer's F3 finding carries for a stuck MSG1 counter (judgements.F3Step's fields; the bus rules
#: put the gap between them)
STUCK, EXPECTED = "transfer id 0 after 0", "expected 1"


def _f3_conformance(heard) -> set[str]:
    """As ``test_transfer_ids_count_per_frame_type`` judges one unbroken capture: every counter's consecutive frames."""
    decoder = Decoder()
    frames = [HeardFrame.of_frame(decoder.decode(m)) for m in heard]
    msg1 = counter_streams(frames)[(NODE, cat.spec("msg1").type_id)]
    problems, pairs, _ = counting_problems(msg1)
    assert pairs > 32
    return {"F3"} if problems and problems[0][1] == f"{STUCK}, {EXPECTED}" else {str(p) for _, p in problems}


def _f3_bus_rules(ask, heard) -> set[str]:
    rules = BusRules(tolerance=0.0, complete=True, power_known=True)
    out = set()
    for m in sorted([ask, *heard], key=lambda m: m.timestamp):
        for v in rules.feed_message(m):
            if v.message.startswith("msg1: "):
                out.update(r for r in v.rules if r == "F3" and STUCK in v.message and EXPECTED in v.message)
    return out


def _f3_check_log(ask, heard, tmp_path, capsys) -> set[str]:
    _, text = _check_log_run(ask, heard, tmp_path, capsys)
    return {"F3"} if "F3" in text and f"msg1: {STUCK}" in text and EXPECTED in text else set()


@pytest.mark.parametrize("faults, expected", [((), False), (("transfer_id_stuck",), True)],
                         ids=["counting", "stuck"])
def test_one_trace_the_same_f3_finding_from_the_suite_the_bus_rules_and_check_log(faults, expected, tmp_path, capsys):
    ask, heard = _trace(faults)
    got = {
        "conformance": "F3" in _f3_conformance(heard),
        "bus rules": "F3" in _f3_bus_rules(ask, heard),
        "check-log": "F3" in _f3_check_log(ask, heard, tmp_path, capsys),
    }
    assert got == dict.fromkeys(got, expected)


# ------------------------------------------------------------------------------------------ GET_ESC_ID pairing
#: a flight controller (F6) querying GET_ESC_ID beside the host
FC = 10
#: (when, who) of each query: alone, 2 ms before the host's, 30 ms after it, 50 and 90 ms before it (node 5's slot is
#: 10 ms: the ESC that answers both sends the flight controller's answer first)
QUERIES = ((0.40, FC), (0.60, 0), (0.800, FC), (0.802, 0), (1.000, 0), (1.030, FC), (1.200, FC), (1.250, 0),
           (1.400, FC), (1.490, 0))
#: what each reply answers, as the host sees it: the ESC answering the flight controller too, or not (F6 leaves it free)
PAIRED = {
    "accept": ["another node", "host", "ambiguous", "host", "host", "another node", "another node", "host",
               "another node", "host"],
    # the host's answers: the second may be the flight controller's (2 ms before), the fourth too (50 ms before); the
    # fifth cannot (90 ms before: only as a late answer, and one that is in time is there)
    "ignore": ["host", "ambiguous", "host", "ambiguous", "host"],
}


def _pairing_trace(foreign_host: str, echo: bool) -> list[can.Message]:
    """Everything on the bus while the host and the flight controller query an emulated ESC at node 5, as the host's
    handle hears it: its own queries (``is_rx`` False) stamped at their end on the bus by their echo, or without an
    echo at the host's send, one frame's time before."""
    esc = EscModel(EscConfig(node_id=NODE, boot_time=BOOT_S, foreign_host=foreign_host))
    esc.power_on(0.0)
    out: list[can.Message] = []

    def run(until: float) -> None:
        while (d := esc.next_deadline()) is not None and d <= until:
            out.extend(as_message(w) for w in esc.poll(d))
        out.extend(as_message(w) for w in esc.poll(until))

    def as_message(w, **kw) -> can.Message:
        return can.Message(arbitration_id=w.arbitration_id, data=w.data, is_extended_id=True, timestamp=w.timestamp, **kw)

    queries = []
    for k, (t, source) in enumerate(QUERIES):
        wire = encode("get_esc_id", {"option": 0}, source=source, transfer_id=k, layout="query")
        q = can.Message(arbitration_id=wire.arbitration_id, data=wire.data, is_extended_id=True, timestamp=t,
                        is_rx=source != 0)
        run(t)
        esc.receive(q, t)
        queries.append(q)
    run(END_S)
    heard, bus_free = [], 0.0  # the ESC's frames on the bus one at a time, stamped at their end
    for m in sorted(out, key=lambda m: (m.timestamp, m.arbitration_id)):
        bus_free = max(m.timestamp, bus_free) + frame_bits(len(m.data)) / cat.DEFAULT_BITRATE
        m.timestamp = bus_free
        heard.append(m)
    for q in queries:
        if not echo and not q.is_rx:
            q.timestamp -= frame_bits(len(q.data)) / cat.DEFAULT_BITRATE
        heard.append(q)
    return sorted(heard, key=lambda m: m.timestamp)


def _suite_pairing(heard) -> list[str]:
    """The suite's helper (``conformance.answers``, which ``query_esc_id`` and the R17 tests ask)."""
    decoder = Decoder()
    paired = esc_id_pairings([decoder.decode(m) for m in heard], host=0, error=0.0)
    return [p.outcome(0) for _, p in paired]


def _bus_rules_pairing(heard) -> tuple[list[str], dict]:
    rules = BusRules(tolerance=0.0, complete=True, power_known=True)
    for m in heard:
        rules.feed_message(m)
    return [p.outcome(0) for p in rules.queries.kept], rules.summary()["get_esc_id"]


def _soak_pairing(heard) -> list[str]:
    """The soak's AnswerWatch (the Monitor feeds every frame to its bus reader, the host's own by its source, and the
    watch takes the reader's pairing of each reply)."""
    monitor = Monitor(WatchConfig(node_id=NODE, host_node=0, intervals={}), t0=0.0)
    for m in heard:
        monitor.feed(m)
    assert not [f.line() for f in monitor.findings if f.watch == monitor.answers.name]
    assert monitor.answers.foreign_answers + monitor.answers.ambiguous + monitor.answers.delays.n == len(monitor.rules.queries.kept)
    return [p.outcome(0) for p in monitor.rules.queries.kept]


def _check_log_pairing(heard, tmp_path, capsys) -> dict:
    out = tmp_path / "summary.json"
    log = tmp_path / "trace.log"
    log.write_text("".join(f"({m.timestamp:.6f}) can0 {m.arbitration_id:08X}#{bytes(m.data).hex().upper()}\n" for m in heard))
    code = cli_main(["check-log", "--complete", "--json", str(out), str(log)])
    assert code in (0, 1), capsys.readouterr().out
    return json.loads(out.read_text())["get_esc_id"]


def _explorer_pairing(heard) -> tuple[list[str], list[str]]:
    """``ckesc explore``'s judge (against its faultless oracle, fed the host's queries), hearing the trace through the
    one reader as its runner does: what it takes each host query's reply to be ("host": the reply it judges;
    "ambiguous": it judges none, the reply may be the flight controller's), and what it finds."""
    from ckesc.evidence.events import EventLog
    from ckesc.explore.answers import ANSWER_WAIT_S, answer_to

    oracle = Oracle({"node_id": NODE, "throttle_channel": NODE, **cat.DEFAULT_REPORT_INTERVALS}, powered_at=0.0, start=BOOT_S)
    rules = BusRules(tolerance=0.0, complete=True, power_known=True)
    log = rules.events = EventLog()
    for m in heard:
        rules.feed_message(m)
        if not m.is_rx:
            oracle.host_frame(m, 0)
    oracle.finish(END_S)
    dut = decoded(m for m in heard if m.is_rx)
    found = judge(oracle, dut, BOOT_S, END_S, Params(boot_s=BOOT_S), heard=log)
    frames = {(f.can_id, f.timestamp): f for f in dut}
    taken = ["ambiguous" if (q.timestamp, 0) in log.ambiguous else
             "host" if answer_to(log, q, frames, ANSWER_WAIT_S) is not None else "none" for q, _ in oracle.host]
    return taken, [f.text() for f in found]


@pytest.mark.parametrize("echo", [True, False], ids=["echo", "no echo"])
@pytest.mark.parametrize("foreign_host", ["accept", "ignore"], ids=["answers the FC", "ignores the FC"])
def test_one_trace_the_same_get_esc_id_pairing_from_the_suite_the_bus_rules_check_log_and_the_soak(
        foreign_host, echo, tmp_path, capsys):
    """A flight controller's GET_ESC_ID queries interleaved with the host's, an ESC answering both or the host's only:
    each reply answers the same query (the host's, the flight controller's, either, or none) to the suite's helper,
    the bus rules, check-log and the soak's AnswerWatch, with the host's own queries timed by their echo or not."""
    heard = _pairing_trace(foreign_host, echo)
    expected = PAIRED[foreign_host]
    rules, tally = _bus_rules_pairing(heard)
    got = {"suite": _suite_pairing(heard), "bus rules": rules, "soak": _soak_pairing(heard)}
    assert got == dict.fromkeys(got, expected)
    counts = {k: expected.count(k) for k in ("host", "another node", "ambiguous", "none")}
    assert tally == _check_log_pairing(heard, tmp_path, capsys) == {"queries": len(QUERIES), **counts}
    # the explorer's judge: each host query's reply as the reader paired it (the host's, or either), and no finding
    hosts = [k for k, (_, source) in enumerate(QUERIES) if source == 0]
    ambiguous = {q.seq for p in rules_pairings(heard) if p.outcome(0) == "ambiguous" for q in p.could if q.source == 0}
    assert _explorer_pairing(heard) == (["ambiguous" if k in ambiguous else "host" for k in hosts], [])


def rules_pairings(heard) -> list:
    rules = BusRules(tolerance=0.0, complete=True, power_known=True)
    for m in heard:
        rules.feed_message(m)
    return rules.queries.kept
