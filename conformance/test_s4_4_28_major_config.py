"""Spec section 4.4.28: Get Major Configuration (242) - direction, throttle source and channel, LED
and report intervals in one answer, at the document's bit positions."""

from __future__ import annotations

import pytest

from ckesc.protocol import catalogue as cat
from ckesc.protocol.legality import field_cases

from .answers import BROADCAST_WINDOW_S, heard_instead
from .codes import code
from .telemetry import INTERVALS, read_request

SECTION = "4.4.28"

SPEC = cat.spec("get_major_configuration")
QUERY = {"option": code("get_major_configuration", "option", "query")}  # "Fixed to 0"
L = cat.LedColor
#: Two settings that differ in every field, each from the catalogue's codes; direction and throttle
#: source differ within each, so that a swap of bits 7 and 6 shows.
COMBOS = {
    "reverse-CAN": {"rotation": code("set_rotation", "rotation", "reverse"), "source": code("throttle_select", "source", "CAN"),
                    "color": int(L.RED | L.BLUE), "blink": next(k for k, v in cat.LED_BLINK.items() if v == "2 Hz"),
                    "intervals": (15, 45, 240)},
    "forward-PWM": {"rotation": code("set_rotation", "rotation", "forward"), "source": code("throttle_select", "source", "PWM+CAN"),
                    "color": int(L.GREEN | L.BLUE), "blink": next(k for k, v in cat.LED_BLINK.items() if v == "5 Hz"),
                    "intervals": (cat.REPORT_INTERVAL_RANGE[1], cat.REPORT_INTERVAL_RANGE[0], 100)},
}


def esc_id_reply(dut) -> dict | None:
    """The DUT's GET_ESC_ID reply: its node id and throttle channel (R1)."""
    sent = dut.broadcast("get_esc_id", {"option": 0}, layout="query")
    dut.wait(BROADCAST_WINDOW_S)
    replies = [f for f in dut.frames("get_esc_id", since=sent.time, source=dut.node_id) if f.layout and f.layout.name == "reply"]
    return replies[-1].fields if replies else None


@pytest.mark.requirement("4.4.28-1")
@pytest.mark.parametrize("combo", list(COMBOS))
def test_answer_shows_what_was_set(dut, combo):
    """After Set Rotation, Throttle Select, Set Led (not saved) and Set Freq, 242 answers the settings:
    payload[0] bit 7 direction, bit 6 throttle source, bits 5..0 the throttle channel (GET_ESC_ID's);
    payload[1] bits 7..3 LED blink, bits 2..0 colour; payload[2..4] the MSG1/MSG2/MSG3 intervals. A
    field may show what was set, or what the setting's own service reads back (a setting the DUT
    did not take is its service's verdict, not 242's)."""
    c = COMBOS[combo]
    intervals = dict(zip(INTERVALS, c["intervals"]))
    want = {"direction": {c["rotation"]}, "throttle_source": {c["source"]}, **{k: {v} for k, v in intervals.items()}}
    dut.ask("set_rotation", {"rotation": c["rotation"]})
    want["throttle_source"].add(dut.ask("throttle_select", {"source": c["source"]})["source"])
    if dut.profile.has("led"):
        dut.ask("set_led", {"option": code("set_led", "option", "do not save"), "color": c["color"], "blink": c["blink"]})
        want.update(led_color={c["color"]}, led_blink={c["blink"]})
    dut.ask("set_freq", {"option": code("set_freq", "option", "write"), **intervals})
    want["direction"].add(dut.ask("set_rotation", {"rotation": code("set_rotation", "rotation", "query")})["rotation"])
    for k, v in dut.ask("set_freq", read_request("set_freq")).items():
        if k in intervals:
            want[k].add(v)
    reply = esc_id_reply(dut)
    if reply is not None:
        want["throttle_channel"] = {reply["throttle_channel"]}
    ex = dut.request("get_major_configuration", QUERY)
    assert ex.response is not None, f"no 7-byte answer to 242 from node {dut.node_id}" + heard_instead(dut, SPEC)
    got = ex.response.fields
    dut.record.observe(f"242 after setting {combo}", {**ex.response.physical(), "payload": ex.response.data[:-1].hex(" ")})
    wrong = {k: (got[k], sorted(v)) for k, v in want.items() if got[k] not in v}
    assert not wrong, (f"242 payload {ex.response.data[:-1].hex(' ')} does not show the settings: "
                       + ", ".join(f"{k} {g} (set / read back: {' / '.join(map(str, v))})" for k, (g, v) in wrong.items()))


@pytest.mark.requirement("4.4.28-2")
def test_observe_answers_to_other_options(dut):
    """"Option: Fixed to 0", yet "Option indicates the ESC type": the answer to other options is recorded."""
    field = SPEC.request.field("option")  # type: ignore[union-attr]
    for case in (c for c in field_cases(SPEC, field) if not c.legal):
        ex = dut.request("get_major_configuration", {"option": case.value})
        dut.record.observe(f"242 option {case.value}", ex.response.physical() if ex.response else "no answer")
