"""Host actions an exploration program is made of, generated from the frame catalogue (sans-IO).

An :class:`Action` is plain data (JSON in a replay file): send one frame of the catalogue with given fields,
send a command malformed or foreign in one of R17's classes (:mod:`ckesc.protocol.malformed`: a multi-frame
fragment or transfer, a wrong length, a request to another node, a response frame; or, R17-toggle, a single frame
with toggle 1), start or stop a zero-throttle RawCommand stream, cycle the power, wait, wait out the 120 s Set
ID / Set Baud window (R11), or set the foreign load on the bus (R18: :class:`ckesc.protocol.load.LoadSource` at a
share of the bus's capacity up to half, which holds from then on; above half only for the step's seconds, what the
DUT does then being OBSERVE), when asked for (``ckesc explore --load``) and where the lane can play it; and, when
asked for (``ckesc explore --bus``), the bus as CAN hardware makes it (R20): a bus short (CANH to CANL) for one of
:data:`BUS_SHORTS` where the lane can cause one, and a power cycle with the host alone on the bus (a few reads or
settings writes sent while the ESC is off: a real adapter holds them, and the ESC meets them at its power-up,
taking them or not: OBSERVE) where it has power control. :func:`programs` is the Hypothesis strategy of whole programs; the values of every
request field come from the catalogue (:func:`ckesc.protocol.legality.field_cases`: each legal code, the
boundaries and their illegal neighbours) plus a random legal value, never written here by hand.

What is left out, and why (safety and what the oracle can follow):
- non-zero throttle (the explorer never spins a motor; ``allow_motor_spin`` is not used yet);
- Expand Set Part (222) and Clear Rec (224): they change motor settings or erase the temperature records,
  which no restore can put back; Get Rec (223): its payload and answer are OBSERVE (R15);
- a foreign load where the lane cannot play one as R18 judges it (a real bus, the real-time emulator: only the
  simulated lane's bus model queues it by arbitration, with the share exact); a replayed load step there is skipped,
  and said so;
- Set Baud malformed (a DUT that took one would move to another bit rate, which the host cannot follow: the model
  never does), and a single frame with toggle 1 of CAN Test or a RawCommand (R17-toggle leaves taking it free, and
  only an answer tells the runner which the DUT chose, so that the model follows it);
- Set Baud to another legal code where the host cannot follow the DUT to it (a real bus without
  ``--can-bitrate-cmd``, or no power control to bring it back); where it can (the simulated lane, a bit-rate
  command), it is sent, and the runner moves the host to the DUT's new rate at the power-up that brings it into
  force, and the next program's reset moves the DUT back;
- LED blink codes other than 0/1/2/5 and 242 with a non-zero option: what the ESC does is a freedom
  (``led_blink_other``, ``major_config_option``), never a finding; likewise every undefined code of a field no
  rule rejects (Set Freq or Set Led option 2, colour 8, throttle channel 21, 241 option 3): illegal values are
  sent only where R10 says what the ESC does with them (found against an ESC of another make, which leaves such
  a request unanswered: the document allows it).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any, Iterable

from ..protocol import catalogue as cat
from ..protocol import malformed as r17
from ..protocol.ids import DEFAULT_ESC_NODE_ID
from ..protocol.judgements import r18_judged
from ..protocol.legality import field_cases

#: how long the explorer reads for an answer: the 64 ms bound and a read window past it (the bench's error added)
ANSWER_READ_S = cat.ANSWER_DELAY_MAX_S + 0.006

#: The streams a program may start (zero on every channel; a stopped stream is a comm loss, R8)
STREAMS = cat.THROTTLE_FRAMES
#: Services a program may request of the DUT (addressed to the node id the oracle says it has)
SERVICES = ("set_id", "set_baud", "set_led", "set_rotation", "set_freq", "throttle_select", "self_test",
            "esc_information", "maintenance_information", "get_major_configuration")
#: Broadcast messages a program may send
BROADCASTS = ("msg_control", "can_test", "get_esc_id")
#: Fields a request always carries as the catalogue's default (one meaning only)
_FIXED = {"get_major_configuration": {"option": 0}, "get_esc_id": {"option": 0}, "esc_information": {"option": 0},
          "msg_control": {"option": 0}, "can_test": {"count": 0}, "self_test": {"option": 0}}
#: Frame types a program may send malformed or foreign (R17), each with a command that would show if taken
MALFORMED = tuple(n for n in (*BROADCASTS, *SERVICES, *STREAMS) if n != "set_baud")
#: Frame types whose single frame with toggle 1 a program may send (R17-toggle): those the DUT answers when it takes
#: one (the runner follows its choice)
TOGGLED = tuple(n for n in MALFORMED if n not in ("can_test", *STREAMS))
#: R18: the foreign load shares a program sets (of the bus's capacity; each holds until the next load step), and the
#: share above half it plays for a step's seconds only (OBSERVE: what the DUT does then is free)
LOAD_SHARES = (0.1, 0.3, 0.5)
ABOVE_HALF_SHARE = 0.7
#: how long an above-half load step plays
ABOVE_HALF_SECONDS = (0.3, 0.6)
#: R20: how long a bus short lasts (s): about one MSG1 interval at the catalogue's default (the ESC may meet it with
#: one report), about R20's recovery bound there (:func:`~ckesc.protocol.judgements.r20_bound_s`: 2.8 ms of bus-off
#: recovery and two 20 ms intervals), past R8's 200 ms (the commands lost raise the comm flag), and past what an ESC's
#: mailboxes hold of its reports at the default intervals (its first reports after recovery then skip transfer ids:
#: OBSERVE)
BUS_SHORTS = (0.02, 0.05, 0.3, 0.8)
#: a power cycle with the host alone sends at most this many frames while the ESC is off (SocketCAN's queue holds 11:
#: none is lost)
ALONE_FRAMES = 3
#: Codes a field must keep inside (what the document leaves free elsewhere; see the module docstring)
_ONLY = {("set_led", "blink"): tuple(cat.LED_BLINK)}


@dataclass(frozen=True)
class Action:
    """One step of a program. ``op``: send | malformed | stream | stop | power | wait | window | load | short | alone.
    ``short``: the bus shorted for ``seconds`` (R20). ``alone``: a power cycle during which the host sends
    ``fields["frames"]`` (each ``{"name", "fields"}``) while the ESC is off (R20). ``malformed``:
    the command ``name`` ``fields`` sent in R17's class ``form`` (:mod:`ckesc.protocol.malformed`). ``load``: foreign
    traffic at ``fields["share"]`` of the bus (0: none) and ``fields["priority"]`` (:data:`ckesc.protocol.load.PRIORITIES`)
    from now on; with ``seconds``, only for that long (then the load before it again)."""

    op: str
    name: str = ""
    fields: dict[str, Any] = field(default_factory=dict)
    seconds: float = 0.0
    form: str = ""

    def to_json(self) -> dict[str, Any]:
        return {k: v for k, v in asdict(self).items() if v not in ("", {}, 0.0) or k == "op"}

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> Action:
        return cls(op=data["op"], name=data.get("name", ""), fields=dict(data.get("fields", {})),
                   seconds=float(data.get("seconds", 0.0)), form=data.get("form", ""))

    @property
    def feature(self) -> str:
        """What feature the step exercises, for the 'feature pairs exercised' count: the frame and its mode."""
        if self.op == "malformed":
            return f"malformed:{self.form}"
        if self.op == "load":
            return f"load:{self.fields.get('share', 0):g}"
        if self.op == "short":
            return f"short:{self.seconds:g}"
        if self.op != "send":
            return self.op
        for key in ("command", "option", "source", "rotation"):
            if key in self.fields and self.name in ("msg_control", "can_test", "set_freq", "set_led"):
                return f"{self.name}:{self.fields[key]:#x}" if key == "command" else f"{self.name}:{self.fields[key]}"
        return self.name

    def describe(self) -> str:
        if self.op == "send":
            shown = ", ".join(f"{k}={_show(v)}" for k, v in self.fields.items())
            return f"{self.name}({shown})"
        if self.op == "malformed":
            shown = ", ".join(f"{k}={_show(v)}" for k, v in self.fields.items())
            return f"{self.name}({shown}) sent as: {r17.DESCRIPTIONS[self.form]}"
        if self.op == "stream":
            return f"stream {self.name} (zero throttle)"
        if self.op == "wait":
            return f"wait {self.seconds:g} s"
        if self.op == "load":
            share = self.fields.get("share", 0)
            if not share:
                return "foreign load off"
            said = f"foreign load {share:.0%} of the bus, {self.fields.get('priority', 'mixed')} priority"
            return said + (f", for {self.seconds:g} s" if self.seconds else "") + (
                " (above half: OBSERVE, R18)" if not r18_judged(share) else "")
        if self.op == "short":
            return f"bus short (CANH-CANL) for {self.seconds:g} s"
        if self.op == "alone":
            held = "; ".join(Action("send", f["name"], f.get("fields", {})).describe() for f in self.fields.get("frames", ()))
            return f"power cycle, the host alone on the bus sending while the ESC is off: {held}"
        return {"stop": "stop the throttle streams", "power": "power cycle",
                "window": "wait until the 120 s Set ID / Set Baud window has closed"}.get(self.op, self.op)


def _show(v: Any) -> str:
    return f"{v:#x}" if isinstance(v, int) and v > 0xFF else str(v)


def program_json(program: Iterable[Action]) -> list[dict[str, Any]]:
    return [a.to_json() for a in program]


def program_from_json(data: Iterable[dict[str, Any]]) -> list[Action]:
    return [Action.from_json(d) for d in data]


def field_values(name: str, field_name: str) -> list[int]:
    """The catalogue's interesting values of one request field: every legal code, the boundaries and their
    illegal neighbours (:func:`field_cases`), narrowed where the document leaves the answer free."""
    spec = cat.spec(name)
    layout = spec.request if spec.service else next(lay for lay in spec.layouts if lay.sender == "any" or lay.name in ("query", "command"))
    f = next(f for f in layout.fields if f.name == field_name)
    values = sorted({c.value for c in field_cases(spec, f)})
    if getattr(f, "rejected_by", None) is None:
        # an undefined code of a field no rule rejects (Set Freq / Set Led option 2, a colour above 7, channel 21):
        # what the ESC does with it the document does not say, so no answer or state after it is a finding
        values = [v for v in values if f.is_legal(v)]
    return [v for v in values if v in _ONLY[(name, field_name)]] if (name, field_name) in _ONLY else values


@dataclass(frozen=True)
class ProgramBench:
    """What a program may do on this bench: power control, the DUT's node id and bit rate code (Set ID / Set
    Baud values), whether the 120 s window may be waited out (in real time it costs two minutes), the
    functions the profile declares absent (R9b)."""

    power: bool = True
    node_id: int = 1
    baud_code: int = cat.DEFAULT_BAUD_CODE
    window_waits: bool = True
    #: whether Set Baud may change the bit rate (the runner follows the DUT to it and moves it back)
    bitrates: bool = False
    #: the DUT's settings every program starts from (Dut.settings()), as (key, value) pairs
    settings: tuple[tuple[str, int], ...] = ()
    absent: frozenset[str] = frozenset()
    waits: tuple[float, ...] = (0.05, 0.25, 0.6, 1.5, 3.0)
    #: whether the lane can play a foreign load as R18 judges it (the simulated lane: its bus queues it by arbitration)
    load: bool = False
    #: R20 steps asked for (``--bus``): bus shorts where the lane can cause one, a power cycle with the host alone where
    #: it has power control
    shorts: bool = False
    alone: bool = False


def _request_fields(name: str, bench: ProgramBench):
    """A Hypothesis strategy of the fields of one request."""
    from hypothesis import strategies as st

    spec = cat.spec(name)
    if name == "set_baud":  # the current code (a no-op write), an illegal one, another bit rate where allowed
        illegal = [v for v in field_values(name, "baud") if v not in cat.BAUD_RATES]
        return st.fixed_dictionaries({"baud": st.sampled_from([bench.baud_code, *illegal, *_other_bauds(bench)])})
    if name == "set_id":
        ids = sorted({*node_moves(bench), *field_values(name, "node_id")} - {DEFAULT_ESC_NODE_ID})
        return st.fixed_dictionaries({"node_id": st.sampled_from(ids),
                                      "throttle_channel": st.sampled_from(field_values(name, "throttle_channel"))})
    layout = spec.request if spec.service else next(lay for lay in spec.layouts if lay.sender == "any" or lay.name in ("query", "command"))
    out = {}
    for f in layout.fields:
        if f.name in _FIXED.get(name, {}):
            out[f.name] = st.just(_FIXED[name][f.name])
            continue
        values = field_values(name, f.name)
        legal = [v for v in values if f.is_legal(v)]
        illegal = st.sampled_from([v for v in values if not f.is_legal(v)] or legal)
        if f.legal is not None and (name, f.name) not in _ONLY:  # boundaries, any legal value, now and then an illegal one
            out[f.name] = st.one_of(st.sampled_from(legal), st.integers(*f.legal), st.integers(*f.legal), illegal)
        else:
            out[f.name] = st.one_of(st.sampled_from(legal), st.sampled_from(legal), illegal)
    return st.fixed_dictionaries(out)


def node_moves(bench: ProgramBench) -> list[int]:
    """The node ids a legal Set ID moves the DUT to: its own (a no-op write), its neighbour, and the one half the
    answer slots away (R2: (node_id % 32) x 2 ms), whose slot tells an ESC that kept its old one on any bench."""
    half = cat.ANSWER_SLOTS // 2
    far = bench.node_id + half if bench.node_id + half < DEFAULT_ESC_NODE_ID else bench.node_id - half
    return [bench.node_id, bench.node_id % (DEFAULT_ESC_NODE_ID - 1) + 1, far]


def _other_bauds(bench: ProgramBench) -> list[int]:
    """The legal Set Baud codes other than the bench's, where the runner can follow the DUT to them."""
    return [c for c in cat.BAUD_RATES if c != bench.baud_code] if bench.bitrates else []


#: request field -> the setting it writes (Dut.settings() keys): a write that takes effect moves it off the baseline
_WRITES = {("set_rotation", "rotation"): "rotation", ("throttle_select", "source"): "throttle_source",
           ("set_led", "color"): "led_color", ("set_led", "blink"): "led_blink", ("set_id", "throttle_channel"): "throttle_channel"}


def asks_only(name: str, fields: dict[str, Any]) -> bool:
    """Whether a settings request only asks, writing nothing: a field at the code the catalogue names "query"
    (Set Rotation 0xFF), or an option other than the one it names "write" (Set Freq)."""
    spec = cat.spec(name)
    for f in spec.request.fields if spec.request is not None else ():
        codes = f.codes or {}
        meaning = codes.get(fields.get(f.name))
        if meaning == "query" or ("write" in codes.values() and meaning != "write"):
            return True
    return False


def asking() -> list[Action]:
    """The settings requests that only ask, one each (:func:`asks_only`; every other field 0): Set Rotation's query,
    Set Freq's read, 240's and 242's query, from the catalogue's code names. An ESC may handle one as a write (save
    its state block, restart its timers), which only its effect on what follows shows."""
    out = []
    for name in SERVICES:
        fields = cat.spec(name).request.fields
        for f in fields:
            for code, meaning in (f.codes or {}).items():
                if meaning in ("query", "read"):
                    out.append(Action("send", name, {g.name: code if g is f else 0 for g in fields}))
    return out


def legal_write(name: str, bench: ProgramBench, *, save: bool = False, same: bool = False):
    """A write the document says takes effect (every field legal; Set ID to one of :func:`node_moves`),
    to a value other than the baseline's where there is one (now and then the baseline's): the settings a program
    changes, so that what clobbers or forgets them can show. ``save``: Set Led with option 1 (saved in flash,
    R13); ``same``: the baseline's value of the settings read back by name (rotation, source, LED, channel): a write that
    changes nothing, which a firmware may still act on."""
    from hypothesis import strategies as st

    spec = cat.spec(name)
    baseline = dict(bench.settings)
    fields = {}
    for f in spec.request.fields:
        legal = [v for v in field_values(name, f.name) if f.is_legal(v)]
        rewrite = None
        if (name, f.name) in _WRITES:
            legal = [v for v in legal if not asks_only(name, {f.name: v})]
            other = [v for v in legal if v != baseline.get(_WRITES[name, f.name])]
            # now and then the value it has: a write that changes nothing may still re-initialise what it touches
            rewrite, legal = legal, other or legal
            if same and baseline.get(_WRITES[name, f.name]) is not None and f.is_legal(baseline[_WRITES[name, f.name]]):
                legal = [baseline[_WRITES[name, f.name]]]
        if name == "set_led" and f.name == "option" and save:
            legal = [code for code, meaning in (f.codes or {}).items() if meaning == "save"]
        if name == "set_id" and f.name == "node_id":
            legal = node_moves(bench)
        elif name == "set_baud":
            legal = _other_bauds(bench) or [bench.baud_code]
        elif name == "set_freq" and f.name == "option":
            legal = [1]
        if f.legal is not None and name not in ("set_id", "set_baud") and (name, f.name) not in _WRITES:
            fields[f.name] = st.one_of(st.sampled_from(legal), st.integers(*f.legal))
        elif rewrite is not None and rewrite != legal and not same:
            fields[f.name] = st.one_of(st.sampled_from(legal), st.sampled_from(legal), st.sampled_from(legal),
                                       st.sampled_from(rewrite))
        else:
            fields[f.name] = st.sampled_from(legal)
    return st.fixed_dictionaries(fields).map(lambda v: Action("send", name, v))


def families(bench: ProgramBench) -> dict[str, Any]:
    """A Hypothesis strategy per family of actions (reads, modes, writes, streams, waits, power, episodes): of single
    actions (``[action]``) or of whole episodes. A program draws from a random subset of them (swarm testing, Groce
    et al. 2012), so that one feature comes many times in one program, as a second suspend needs."""
    from hypothesis import strategies as st

    from ..protocol import functions

    def send(name: str):
        return _request_fields(name, bench).map(lambda fields: Action("send", name, fields))

    def claimed(a: Action) -> bool:
        return a.op != "send" or not bench.absent or functions.of_request(a.name, a.fields, bench.absent) is None

    def one(*strategies):
        return st.one_of(*strategies).filter(claimed).map(lambda a: [a])

    mode_changes = [
        st.sampled_from([cat.MSG_CONTROL_SUSPEND, cat.MSG_CONTROL_RESUME, cat.MSG_CONTROL_RESUME_EXP]).map(
            lambda c: Action("send", "msg_control", {"option": 0, "command": c})),
        st.sampled_from([cat.CAN_TEST_ON, cat.CAN_TEST_OFF]).map(lambda o: Action("send", "can_test", {"option": o, "count": 0})),
        send("msg_control"), send("can_test")]
    writes = [send(n) for n in SERVICES if n not in ("esc_information", "maintenance_information", "get_major_configuration")]
    writes += [legal_write(n, bench) for n in ("set_freq", "set_rotation", "set_led", "throttle_select", "set_id")] * 2
    out = {
        # a read-back shows a clobbered setting
        "reads": one(send("maintenance_information"), st.sampled_from(asking()), send("get_esc_id")),
        "modes": one(*mode_changes),
        "writes": one(*writes),
        "streams": one(st.sampled_from(STREAMS).map(lambda n: Action("stream", n)), st.just(Action("stop"))),
        "waits": one(st.sampled_from(bench.waits).map(lambda s: Action("wait", seconds=s))),
        "episodes": st.one_of(*episodes(bench)).filter(lambda ep: all(claimed(a) for a in ep)),
        # R17: a command that would show if taken, sent in one of the classes the ESC ignores (or toggle 1)
        "malformed": malformed(bench).map(lambda a: [a]),
    }
    if bench.power:
        out["power"] = one(st.just(Action("power")), *([st.just(Action("window"))] if bench.window_waits else []))
    if bench.load:  # R18: a share up to half from now on, the bus quiet again, or above half for a while (OBSERVE)
        from ..protocol.load import PRIORITIES

        priority = st.sampled_from(PRIORITIES)
        out["load"] = one(
            st.builds(lambda s, p: Action("load", fields={"share": s, "priority": p}), st.sampled_from(LOAD_SHARES), priority),
            st.just(Action("load", fields={"share": 0})),
            st.builds(lambda t, p: Action("load", fields={"share": ABOVE_HALF_SHARE, "priority": p}, seconds=t),
                      st.sampled_from(ABOVE_HALF_SECONDS), priority))
    if bench.shorts or (bench.alone and bench.power):
        out["bus"] = bus_steps(bench).map(lambda a: [a])
    return out


def bus_steps(bench: ProgramBench):
    """A Hypothesis strategy of one R20 step: a bus short for one of :data:`BUS_SHORTS` (where the lane can cause
    one), or a power cycle with the host alone sending one to :data:`ALONE_FRAMES` frames while the ESC is off (where
    it has power control): reads (answered or not, nothing changes) and legal settings writes (the runner tells the
    model which the ESC took: those it answered). Left out of them: a RawCommand (taken or not, nothing answers it,
    and R8's clock would hold the ESC to one choice), Set ID and Set Baud (where the ESC then is, the runner finds by
    asking), a suspend (a DUT left suspended refuses what the reset writes)."""
    from hypothesis import strategies as st

    def send(name: str):
        return _request_fields(name, bench).map(lambda fields: Action("send", name, fields))

    held = st.one_of(send("maintenance_information"), st.sampled_from(asking()), send("get_esc_id"),
                     *[legal_write(n, bench) for n in ("set_freq", "set_rotation", "set_led", "throttle_select")])
    steps = []
    if bench.shorts:
        steps.append(st.sampled_from(BUS_SHORTS).map(lambda t: Action("short", seconds=t)))
    if bench.alone and bench.power:
        steps.append(st.lists(held, min_size=1, max_size=ALONE_FRAMES).map(
            lambda sends: Action("alone", fields={"frames": [{"name": a.name, "fields": a.fields} for a in sends]})))
    return st.one_of(*steps)


def episodes(bench: ProgramBench) -> list[Any]:
    """Strategies of short action sequences that take one feature through a whole round trip (on, effect, off,
    effect): two of them in one program meet where one's state change is the other's context (a comm loss after a
    resume, a save before a bit rate change), which single steps drawn at random rarely line up."""
    from hypothesis import strategies as st

    def msg_control(command: int) -> Action:
        return Action("send", "msg_control", {"option": 0, "command": command})

    comm_loss = st.sampled_from(STREAMS).map(lambda n: [Action("stream", n), Action("wait", seconds=0.25), Action("stop"),
                                                         Action("wait", seconds=0.6), Action("stream", n),
                                                         Action("wait", seconds=0.6), Action("stop")])
    settings = ["set_freq", "set_rotation", "set_led", "throttle_select", "set_id"]
    write = st.sampled_from(settings).flatmap(lambda n: legal_write(n, bench))
    # a settings request: one that only asks, a legal write, or any (boundaries, illegal values)
    request = st.one_of(st.sampled_from(asking()), write,
                        st.sampled_from(settings).flatmap(lambda n: _request_fields(n, bench).map(lambda f: Action("send", n, f))))
    ends = [st.just(False), st.just(True)] if bench.power else [st.just(False)]

    def round_trip(on: Action, off: Action):
        """``on`` once or repeated (a handler that is not idempotent: the second suspend that latches), one or two
        settings requests in the mode (R12 holds writes back while suspended; a query may be handled as a save),
        then ``off``, or a power cycle where the bench has one (the mode is not kept, R13: what the requests in it
        did to flash shows after it)."""
        def trip(n: int, inside: list[Action], power: bool) -> list[Action]:
            end = [Action("power")] if power else [Action("wait", seconds=0.25), off, Action("wait", seconds=0.6)]
            return [on] * n + inside + end
        return st.builds(trip, st.integers(1, 2), st.lists(request, min_size=1, max_size=2), st.one_of(*ends))

    resume = msg_control(cat.MSG_CONTROL_RESUME)
    suspend = round_trip(msg_control(cat.MSG_CONTROL_SUSPEND), resume)
    exp = round_trip(msg_control(cat.MSG_CONTROL_RESUME_EXP), resume)
    can_test = round_trip(Action("send", "can_test", {"option": cat.CAN_TEST_ON, "count": 0}),
                          Action("send", "can_test", {"option": cat.CAN_TEST_OFF, "count": 0}))
    # a settings write, then RawCommands of every format in turn (the decoder after a write: a table rebuilt without
    # one format shows as a comm loss under it, R8); half the time a write of the value the setting has, which
    # changes nothing a read-back could show, so that only what it re-initialises shows
    formats = [step for n in STREAMS for step in (Action("stream", n), Action("wait", seconds=0.3))]
    same = st.sampled_from(settings).flatmap(lambda n: legal_write(n, bench, same=True))
    decode = st.one_of(write, same).map(lambda w: [w, *formats, Action("stop")])
    # R17 and R8: a comm loss, then a malformed zero-throttle RawCommand; one taken clears the flag (a comm refresh)
    refresh = st.sampled_from(STREAMS).flatmap(
        lambda n: malformed(bench, names=(n,), toggle=False).map(
            lambda bad: [Action("stream", n), Action("wait", seconds=0.25), Action("stop"), Action("wait", seconds=0.6),
                         bad, Action("wait", seconds=0.25)]))
    out = [comm_loss, suspend, exp, can_test, decode]
    if bench.power:
        counters = Action("send", "maintenance_information", {"option": 2})
        saves = settings + (["set_baud"] if bench.bitrates else [])
        # one or two saves, then a power-up: a save that clobbers the other's flash word shows after it
        save = st.sampled_from(saves).flatmap(lambda n: legal_write(n, bench, save=True))
        out.append(st.lists(save, min_size=1, max_size=2).map(lambda writes: [*writes, Action("power"), counters]))
    out.append(refresh)
    return out


def _command(name: str, bench: ProgramBench):
    """A Hypothesis strategy of a command of ``name`` that shows if it is taken: a mode change, a settings write (or
    any request, its boundaries and illegal values), a read that is answered, zero on every channel."""
    from hypothesis import strategies as st

    if name in STREAMS:
        return st.just(stream_fields(name))
    if name == "msg_control":  # each answered (R2): a DUT that took one shows by its answer, R17-toggle's by it too
        return st.sampled_from([cat.MSG_CONTROL_SUSPEND, cat.MSG_CONTROL_RESUME, cat.MSG_CONTROL_RESUME_EXP]).map(
            lambda c: {"option": 0, "command": c})
    if name == "can_test":
        return st.sampled_from([cat.CAN_TEST_ON, cat.CAN_TEST_OFF]).map(lambda o: {"option": o, "count": 0})
    sent = _request_fields(name, bench)
    if name in ("set_freq", "set_rotation", "set_led", "throttle_select", "set_id"):
        return st.one_of(legal_write(name, bench).map(lambda a: a.fields), legal_write(name, bench).map(lambda a: a.fields),
                         sent)
    return sent


def malformed(bench: ProgramBench, names: tuple[str, ...] = MALFORMED, toggle: bool = True):
    """A Hypothesis strategy of one malformed step: a command of one of ``names`` (:func:`_command`) in one of R17's
    classes that applies to it (:func:`ckesc.protocol.malformed.applies`), or with ``toggle`` a single frame with
    toggle 1 of a frame type the DUT answers (R17-toggle)."""
    from hypothesis import strategies as st

    def names_of(form: str) -> list[str]:
        return [n for n in (TOGGLED if form == r17.TOGGLE else names) if n in names and r17.applies(cat.spec(n), form)]

    # the class first, then a frame type it applies to: each class as often as another (a request to another node,
    # a response frame: services only, as often as a start frame, which every frame type with a tail has)
    forms = [f for f in (*r17.FORMS, *((r17.TOGGLE,) if toggle else ())) if names_of(f)]
    return st.sampled_from(forms).flatmap(lambda form: st.sampled_from(names_of(form)).flatmap(lambda n: _command(n, bench).map(
        lambda fields: Action("malformed", n, fields, form=form))))


def programs(bench: ProgramBench, max_size: int = 12):
    """A Hypothesis strategy of whole programs (the state they start from: :mod:`ckesc.explore.runner`): a random
    subset of the action families (swarm testing), then up to ``max_size`` items from them, an episode counting as
    one item (its steps are flattened into the program)."""
    from hypothesis import strategies as st

    strategies = families(bench)
    # (R17's, then R18's last: the order seed 1 was counted in; a bench that cannot play a load draws as before)
    # (R20's bus steps after them, where asked for)
    last = [n for n in ("load", "bus") if n in strategies]
    names = sorted(n for n in strategies if n not in ("malformed", *last)) + ["malformed"] + last

    def from_subset(chosen: frozenset[str]):
        # an episode is a whole round trip where a single step is one action: drawn twice as often as one family; a
        # bus step (a short costs a second of lane time and more, a lone-host power cycle a power cycle) half as often
        others = [strategies[n] for n in names if n in chosen and n != "bus"]
        weighted = others + ([strategies["episodes"]] if "episodes" in chosen else [])
        if "bus" in chosen:
            weighted = weighted * 2 + [strategies["bus"]]
        return st.lists(st.one_of(*weighted), min_size=1, max_size=max_size)

    swarm = st.frozensets(st.sampled_from(names), min_size=1)
    return swarm.flatmap(from_subset).map(lambda items: [a for item in items for a in item])


def stream_fields(name: str) -> dict[str, Any]:
    """Zero on every channel of a RawCommand format (group 1 for the 12-bit one)."""
    if name == "raw_command_10b":
        return {"channels": [0] * 6}
    if name == "raw_command_12b":
        return {"channels": [0] * 4, "group": cat.THROTTLE_GROUPS[0]}
    return {"channels": [0] * 4}
