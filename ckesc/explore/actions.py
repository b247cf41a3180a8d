"""Host actions an exploration program is made of, generated from the frame catalogue (sans-IO).

An :class:`Action` is plain data (JSON in a replay file): send one frame of the catalogue with given fields,
start or stop a zero-throttle RawCommand stream, cycle the power, wait, or wait out the 120 s Set ID / Set
Baud window (R11). :func:`programs` is the Hypothesis strategy of whole programs; the values of every
request field come from the catalogue (:func:`ckesc.protocol.legality.field_cases`: each legal code, the
boundaries and their illegal neighbours) plus a random legal value, never written here by hand.

What is left out, and why (safety and what the oracle can follow):
- non-zero throttle (the explorer never spins a motor; ``allow_motor_spin`` is not used yet);
- Expand Set Part (222) and Clear Rec (224): they change motor settings or erase the temperature records,
  which no restore can put back; Get Rec (223): its payload and answer are OBSERVE (R15);
- Set Baud to another legal code: the DUT would leave the host's bit rate at the next power-up (only the
  current code, an illegal one, in and after the window, are sent);
- LED blink codes other than 0/1/2/5 and 242 with a non-zero option: what the ESC does is a freedom
  (``led_blink_other``, ``major_config_option``), never a finding.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any, Iterable

from ..protocol import catalogue as cat
from ..protocol.ids import DEFAULT_ESC_NODE_ID
from ..protocol.legality import field_cases

#: The streams a program may start (zero on every channel; a stopped stream is a comm loss, R8)
STREAMS = ("raw_command_14b", "raw_command_12b", "raw_command_10b")
#: Services a program may request of the DUT (addressed to the node id the oracle says it has)
SERVICES = ("set_id", "set_baud", "set_led", "set_rotation", "set_freq", "throttle_select", "self_test",
            "esc_information", "maintenance_information", "get_major_configuration")
#: Broadcast messages a program may send
BROADCASTS = ("msg_control", "can_test", "get_esc_id")
#: Fields a request always carries as the catalogue's default (one meaning only)
_FIXED = {"get_major_configuration": {"option": 0}, "get_esc_id": {"option": 0}, "esc_information": {"option": 0},
          "msg_control": {"option": 0}, "can_test": {"count": 0}, "self_test": {"option": 0}}
#: Codes a field must keep inside (what the document leaves free elsewhere; see the module docstring)
_ONLY = {("set_led", "blink"): tuple(cat.LED_BLINK)}


@dataclass(frozen=True)
class Action:
    """One step of a program. ``op``: send | stream | stop | power | wait | window."""

    op: str
    name: str = ""
    fields: dict[str, Any] = field(default_factory=dict)
    seconds: float = 0.0

    def to_json(self) -> dict[str, Any]:
        return {k: v for k, v in asdict(self).items() if v not in ("", {}, 0.0) or k == "op"}

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> Action:
        return cls(op=data["op"], name=data.get("name", ""), fields=dict(data.get("fields", {})),
                   seconds=float(data.get("seconds", 0.0)))

    @property
    def feature(self) -> str:
        """What feature the step exercises, for the 'feature pairs exercised' count: the frame and its mode."""
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
        if self.op == "stream":
            return f"stream {self.name} (zero throttle)"
        if self.op == "wait":
            return f"wait {self.seconds:g} s"
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
    return [v for v in values if v in _ONLY[(name, field_name)]] if (name, field_name) in _ONLY else values


@dataclass(frozen=True)
class Bench:
    """What a program may do on this bench: power control, the DUT's node id and bit rate code (Set ID / Set
    Baud values), whether the 120 s window may be waited out (in real time it costs two minutes), the
    functions the profile declares absent (R9b)."""

    power: bool = True
    node_id: int = 1
    baud_code: int = cat.DEFAULT_BAUD_CODE
    window_waits: bool = True
    absent: frozenset[str] = frozenset()
    waits: tuple[float, ...] = (0.05, 0.25, 0.6, 1.5, 3.0)


def _request_fields(name: str, bench: Bench):
    """A Hypothesis strategy of the fields of one request."""
    from hypothesis import strategies as st

    spec = cat.spec(name)
    if name == "set_baud":  # the current code (a no-op write) or an illegal one: never another bit rate
        illegal = [v for v in field_values(name, "baud") if v not in cat.BAUD_RATES]
        return st.fixed_dictionaries({"baud": st.sampled_from([bench.baud_code, *illegal])})
    if name == "set_id":
        ids = sorted({bench.node_id, bench.node_id % 0x7C + 1, *field_values(name, "node_id")} - {DEFAULT_ESC_NODE_ID})
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


def legal_write(name: str, bench: Bench):
    """A write the document says takes effect (every field legal; Set ID to the baseline node or its neighbour):
    the settings a program changes, so that what clobbers or forgets them can show."""
    from hypothesis import strategies as st

    spec = cat.spec(name)
    fields = {}
    for f in spec.request.fields:
        legal = [v for v in field_values(name, f.name) if f.is_legal(v)]
        if name == "set_id" and f.name == "node_id":
            legal = [bench.node_id, bench.node_id % 0x7C + 1]
        elif name == "set_freq" and f.name == "option":
            legal = [1]
        if f.legal is not None and name != "set_id":
            fields[f.name] = st.one_of(st.sampled_from(legal), st.integers(*f.legal))
        else:
            fields[f.name] = st.sampled_from(legal)
    return st.fixed_dictionaries(fields).map(lambda v: Action("send", name, v))


def actions(bench: Bench):
    """A Hypothesis strategy of one action on ``bench``."""
    from hypothesis import strategies as st

    from ..protocol import functions

    def send(name: str):
        return _request_fields(name, bench).map(lambda fields: Action("send", name, fields))

    def claimed(a: Action) -> bool:
        return a.op != "send" or not bench.absent or functions.of_request(a.name, a.fields, bench.absent) is None

    # weights (an alternative listed n times is drawn n times as often): the mode changes and power cycles are
    # where features meet, so they come often; a read-back shows a clobbered setting; the 120 s window is dear
    reads = [send("get_major_configuration"), send("maintenance_information"),
             st.just(Action("send", "set_freq", {"option": 0, "msg1_interval": 0, "msg2_interval": 0, "msg3_interval": 0})),
             send("get_esc_id")]
    modes = [st.sampled_from([cat.MSG_CONTROL_SUSPEND, cat.MSG_CONTROL_RESUME, cat.MSG_CONTROL_RESUME_EXP]).map(
                 lambda c: Action("send", "msg_control", {"option": 0, "command": c})),
             st.sampled_from([cat.CAN_TEST_ON, cat.CAN_TEST_OFF]).map(
                 lambda o: Action("send", "can_test", {"option": o, "count": 0}))] * 3
    writes = [send(n) for n in SERVICES if n not in ("esc_information", "maintenance_information", "get_major_configuration")]
    writes += [legal_write(n, bench) for n in ("set_freq", "set_rotation", "set_led", "throttle_select", "set_id")] * 2
    others = [send("msg_control"), send("can_test"), send("esc_information"),
              st.sampled_from(STREAMS).map(lambda n: Action("stream", n)), st.just(Action("stop")),
              st.sampled_from(bench.waits).map(lambda s: Action("wait", seconds=s))] + [st.just(Action("wait", seconds=0.6))] * 2
    if bench.power:
        others += [st.just(Action("power"))] * 3
        if bench.window_waits:
            others.append(st.just(Action("window")))
    return st.one_of(*reads, *modes, *writes, *others).filter(claimed)


def programs(bench: Bench, max_size: int = 12):
    """A Hypothesis strategy of whole programs (the state they start from: :mod:`ckesc.explore.runner`)."""
    from hypothesis import strategies as st

    return st.lists(actions(bench), min_size=1, max_size=max_size)


def stream_fields(name: str) -> dict[str, Any]:
    """Zero on every channel of a RawCommand format (group 1 for the 12-bit one)."""
    if name == "raw_command_10b":
        return {"channels": [0] * 6}
    if name == "raw_command_12b":
        return {"channels": [0] * 4, "group": cat.THROTTLE_GROUPS[0]}
    return {"channels": [0] * 4}
