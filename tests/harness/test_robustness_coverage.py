"""R17 says "for every frame type the ESC takes": the robustness section sends every frame type of the catalogue that
the ESC takes from the host in every malformed form R17 names that the frame type can be sent in (issue #30 item 1),
read from the section's own builders without a suite run. A frame type added to the catalogue, or a form dropped
from a builder, fails here, naming both."""

from __future__ import annotations

from types import SimpleNamespace

import pytest

import conformance.test_robustness_r17_malformed as r17
from ckesc.protocol import Kind
from ckesc.protocol import catalogue as cat
from ckesc.protocol import malformed as mf
from ckesc.protocol.frame import encode
from ckesc.protocol.ids import parse_can_id
from ckesc.protocol.transfer import parse_tail

#: a DUT as the builders read it: node 1, the host at 0, alone on its bus
DUT = SimpleNamespace(node_id=1, host_node=0, nodes=[1], profile=SimpleNamespace(nibble_order="lsb"))
#: R17's forms: the tail's (start, middle, end of a multi-frame transfer, the whole of one), the lengths', the
#: destination's and the response
FORMS = ("start", "middle", "end", "whole", "empty", "short", "long", "other node", "response")
#: frame types deliberately not sent, each with the reason the section's docstring gives
NOT_SENT = {"clear_rec": "destructive: taken, it erases the temperature records"}


def _taken_from_host() -> list[str]:
    return [s.name for s in cat.CATALOGUE if mf.host_layout(s) is not None]


def _form(b: r17.Bad, spec: cat.FrameSpec, size: int) -> str:
    """Which of :data:`FORMS` the malformed frame ``b`` is, read from its bytes and id (not from its label)."""
    if len(b.frames) > 1:
        return "whole"
    w = b.frames[0]
    i = parse_can_id(w.arbitration_id)
    if spec.service and i.kind is Kind.RESPONSE:
        return "response"
    if spec.service and i.destination != DUT.node_id:
        return "other node"
    if not w.data:
        return "empty"
    if len(w.data) != size:
        return "short" if len(w.data) < size else "long"
    t = parse_tail(w.data[-1])
    return "start" if t.start and not t.end else "end" if t.end else "middle"


def _expected(spec: cat.FrameSpec, size: int | None, valid_len: int) -> set[str]:
    """R17's forms a frame type can be sent in: the tail's only with a tail byte (10-bit RawCommand has none, R5), a
    wrong length only where its table fixes one (and one byte long only where classic CAN's 8 bytes allow), a request
    to another node only for a service that heeds its destination (Set ID does not, R11), a response for a service."""
    out = {"empty"}
    if spec.has_tail:
        out |= {"start", "middle", "end", "whole"}
    if size is not None and size:
        out.add("short")
    if size is not None and valid_len < mf.MAX_DATA:
        out.add("long")
    if spec.service:
        out.add("response")
        if spec.name not in cat.PSEUDO_BROADCAST:
            out.add("other node")
    return out


#: the settings the builders' commands move away from (the catalogue's defaults)
SETTINGS = {"rotation": 0, "throttle_source": 0, "throttle_channel": cat.THROTTLE_CHANNELS[0], "led_color": cat.DEFAULT_LED_COLOR,
            "led_blink": 0, **cat.DEFAULT_REPORT_INTERVALS}


def _command(name: str) -> dict:
    """The command the section sends of ``name`` malformed (a window writer's: each field at its least legal value)."""
    if name in r17.WINDOW_WRITERS:
        return {f.name: f.legal[0] if f.legal else min(f.codes) for f in cat.spec(name).request.fields}
    return r17.command(DUT, name, SETTINGS)


@pytest.mark.parametrize("name", [n for n in _taken_from_host() if n not in NOT_SENT])
def test_every_form_r17_names_is_sent(name):
    spec, fields = cat.spec(name), _command(name)
    bads = r17.window_malformed(DUT, name, fields) if name in r17.WINDOW_WRITERS else r17.malformed(DUT, name, fields)
    valid = len(encode(spec, fields, kind=Kind.REQUEST if spec.service else Kind.MESSAGE, source=DUT.host_node,
                           destination=DUT.node_id if spec.service else None, transfer_id=0,
                           layout="query" if name == "get_esc_id" else None).data)
    got = {_form(b, spec, valid) for b in bads}
    expected = _expected(spec, mf.host_layout(spec).size, valid)
    assert got == expected, f"{name}: forms missing {sorted(expected - got)}, unexpected {sorted(got - expected)}"


def test_every_frame_type_the_esc_takes_is_sent_malformed():
    tested = set(r17.TAKEN) | r17.WINDOW_WRITERS
    missing = [n for n in _taken_from_host() if n not in tested and n not in NOT_SENT]
    assert missing == [], f"frame types the ESC takes that the robustness section never sends malformed: {missing}"
    assert set(NOT_SENT) <= set(_taken_from_host()) - tested, "a frame type listed as not sent is sent after all"
