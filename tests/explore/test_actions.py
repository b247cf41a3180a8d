"""What the explorer's programs are made of (sans-IO): the values come from the catalogue, and the shapes a
firmware's interaction defects need can be drawn."""

from __future__ import annotations

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from ckesc.explore.actions import ProgramBench, asking, asks_only, episodes, legal_write, node_moves
from ckesc.protocol import catalogue as cat

BENCH = ProgramBench(node_id=1, settings=(("led_blink", 0), ("led_color", 2), ("msg1_interval", 10), ("msg2_interval", 50),
                                   ("msg3_interval", 250), ("rotation", 0), ("throttle_channel", 1), ("throttle_source", 0)))
SOME = settings(max_examples=60, database=None, deadline=None, suppress_health_check=list(HealthCheck))


def test_node_moves_include_one_whose_answer_slot_is_half_the_64_ms_away():
    """R2: an ESC that keeps its old slot after Set ID shows on any bench only at a node whose slot is far from its
    own (at +-2 ms of bench error a neighbour's 2 ms slot does not tell)."""
    for node in (1, 2, 31, 100, 124):
        moves = node_moves(ProgramBench(node_id=node))
        assert moves[0] == node and all(1 <= m < 0x7D for m in moves)
        assert any(abs(m % 32 - node % 32) == 16 for m in moves), moves


def test_asking_requests_only_ask_and_include_the_rotation_query():
    asked = {(a.name, tuple(sorted(a.fields.items()))) for a in asking()}
    assert ("set_rotation", (("rotation", 0xFF),)) in asked
    assert all(asks_only(a.name, a.fields) or a.name in ("esc_information", "get_major_configuration") for a in asking())


@SOME
@given(st.sampled_from(["set_rotation", "throttle_select", "set_led"]).flatmap(lambda n: legal_write(n, BENCH, same=True)))
def test_a_same_write_writes_the_value_the_setting_has(action):
    baseline = dict(BENCH.settings)
    key = {"set_rotation": ("rotation", "rotation"), "throttle_select": ("source", "throttle_source"),
           "set_led": ("color", "led_color")}[action.name]
    assert action.fields[key[0]] == baseline[key[1]]


def test_a_mode_round_trip_can_carry_a_query_and_end_in_a_power_cycle():
    """A suspension with Set Rotation's query inside it, then a power-up (a query handled as a save of the state
    block shows after it), is a shape the suspend episode draws."""
    suspend = episodes(BENCH)[1]
    seen = []

    @SOME
    @given(suspend)
    def draw(steps):
        seen.append(steps)
    draw()
    assert all(s[0].fields.get("command") == cat.MSG_CONTROL_SUSPEND for s in seen)
    assert any(s[-1].op == "power" for s in seen) and any(s[-1].op == "wait" for s in seen)
    assert all(len([a for a in s if a.name not in ("msg_control",) and a.op == "send"]) >= 1 for s in seen)
