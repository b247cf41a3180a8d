"""Every interaction fault (``faults.INTERACTION``) changes the behaviour it names, and only where two features
meet: each scenario drives the sans-IO model directly (frames and a time in, frames out; no bus, no lane) through
a short program of host actions, once on the faultless model and once with the fault, and compares one
observation. A scenario also shows the feature on its own is unaffected where that is the fault's point (a save
that clobbers a neighbour only after the neighbour moved, a nested suspend only after two suspends).

The single faults have theirs in test_faults.py; an interaction fault with no scenario here fails
``test_every_interaction_fault_has_a_scenario``.
"""

from __future__ import annotations

from typing import Any, Callable

import pytest

from ckesc.emulator.faults import FAULTS, INTERACTION
from ckesc.emulator.model import EscConfig, EscModel
from ckesc.protocol import Decoder, Frame, Kind, Status, encode
from ckesc.protocol.catalogue import DEFAULT_REPORT_INTERVALS, MSG_CONTROL_RESUME, MSG_CONTROL_SUSPEND

INTERACTIONS = sorted(n for n, f in FAULTS.items() if f.kind == INTERACTION)
READ = {"option": 0, "msg1_interval": 10, "msg2_interval": 10, "msg3_interval": 10}


class Esc:
    """One model driven on its own clock: ``send`` a host frame now, ``run`` until a time (collecting what the
    ESC sends), ``call`` a service and get its answer, ``power_cycle``."""

    def __init__(self, faults: tuple[str, ...] = ()) -> None:
        self.model = EscModel(EscConfig(node_id=1, faults=frozenset(faults)))
        self.now = 0.0
        self.heard: list[Frame] = []
        self.decoder = Decoder()  # remembers the requests, so 241 answers decode by their option
        self.tid = 0
        self.model.power_on(0.0)
        self.run(0.3)

    def run(self, until: float) -> list[Frame]:
        start = len(self.heard)
        while (deadline := self.model.next_deadline()) is not None and deadline <= until:
            self.now = max(self.now, deadline)
            self.heard += [self.decoder.decode(w) for w in self.model.poll(self.now)]
        self.now = until
        self.heard += [self.decoder.decode(w) for w in self.model.poll(until)]
        return self.heard[start:]

    def wait(self, seconds: float) -> list[Frame]:
        return self.run(self.now + seconds)

    def send(self, name: str, fields: dict[str, Any] | None = None, destination: int | None = None) -> list[Frame]:
        self.tid = (self.tid + 1) % 32
        wire = encode(name, fields or {}, source=0, destination=destination, transfer_id=self.tid)
        self.decoder.decode(wire)
        self.model.receive(wire, self.now)
        return self.wait(0.02)

    def call(self, name: str, fields: dict[str, Any] | None = None) -> dict[str, Any]:
        [answer] = [f for f in self.send(name, fields, destination=self.model.node_id)
                    if f.kind is Kind.RESPONSE and f.name == name]
        return answer.fields

    def power_cycle(self) -> None:
        before = self.call("maintenance_information", {"option": 2})["power_ups"]
        self.model.power_off(self.now)
        self.wait(0.5)
        self.model.power_on(self.now)
        self.wait(0.3)
        assert self.call("maintenance_information", {"option": 2})["power_ups"] > before  # a real power cycle

    def settings(self) -> dict[str, Any]:
        f = self.call("get_major_configuration", {"option": 0})
        return {k: f[k] for k in ("direction", "throttle_source", "led_color", "led_blink", "msg1_interval",
                                  "msg2_interval", "msg3_interval")}

    def gap(self, report: str, seconds: float = 1.0) -> float:
        """The mean gap between ``report`` frames over ``seconds`` (from the third report on: R9a's restart)."""
        stamps = [f.timestamp for f in self.wait(seconds) if f.name == report][2:]
        assert len(stamps) >= 3, f"too few {report} in {seconds} s"
        return round((stamps[-1] - stamps[0]) / (len(stamps) - 1), 6)

    def msg_control(self, command: int) -> None:
        self.send("msg_control", {"option": 0, "command": command})


# --------------------------------------------------------------------------------------------------
# scenarios: name -> (program returning an observation, faultless value, faulty value)

SCENARIOS: dict[str, tuple[Callable[[Esc], Any], Any, Any]] = {}


def scenario(fault: str, off: Any, on: Any):
    def register(program: Callable[[Esc], Any]):
        assert fault not in SCENARIOS
        SCENARIOS[fault] = (program, off, on)
        return program
    return register


RED, BLUE = 4, 1  # LED colours other than the factory default (green)


@scenario("led_save_reverts_rotation", off=(1, 1), on=(1, 0))
def _(esc: Esc):
    """Rotation set after power-up, then a saved LED: the direction is right until the power cycle only."""
    esc.call("set_rotation", {"rotation": 1})
    esc.call("set_led", {"option": 1, "color": RED, "blink": 0})
    before = esc.settings()["direction"]
    esc.power_cycle()
    return before, esc.settings()["direction"]


@scenario("freq_save_resets_led", off=((RED, 1), (RED, 1)), on=((RED, 1), (2, 0)))
def _(esc: Esc):
    esc.call("set_led", {"option": 1, "color": RED, "blink": 1})
    esc.call("set_freq", {"option": 1, "msg1_interval": 20, "msg2_interval": 60, "msg3_interval": 80})
    before = esc.settings()
    esc.power_cycle()
    after = esc.settings()
    return (before["led_color"], before["led_blink"]), (after["led_color"], after["led_blink"])


@scenario("rotation_save_resets_intervals", off=(20, 60, 80), on=tuple(DEFAULT_REPORT_INTERVALS.values()))
def _(esc: Esc):
    esc.call("set_freq", {"option": 1, "msg1_interval": 20, "msg2_interval": 60, "msg3_interval": 80})
    esc.call("set_rotation", {"rotation": 1})
    esc.power_cycle()
    f = esc.call("set_freq", READ)
    return f["msg1_interval"], f["msg2_interval"], f["msg3_interval"]


@scenario("source_save_reverts_led", off=(BLUE, BLUE), on=(BLUE, RED))
def _(esc: Esc):
    """A saved LED (red), power cycle, another saved LED (blue), then Throttle Select: the LED is blue until the
    next power cycle, then red again (the power-up's copy)."""
    esc.call("set_led", {"option": 1, "color": RED, "blink": 0})
    esc.power_cycle()
    esc.call("set_led", {"option": 1, "color": BLUE, "blink": 0})
    esc.call("throttle_select", {"source": 1})
    before = esc.settings()["led_color"]
    esc.power_cycle()
    return before, esc.settings()["led_color"]


@scenario("set_id_resets_source", off=(1, 1), on=(1, 0))
def _(esc: Esc):
    esc.call("throttle_select", {"source": 1})
    before = esc.settings()["throttle_source"]
    esc.call("set_id", {"node_id": 1, "throttle_channel": 1})  # inside the window, the same id
    return before, esc.settings()["throttle_source"]


@scenario("second_suspend_latches", off=(True, True), on=(True, False))
def _(esc: Esc):
    """One suspend and a resume: reports come back either way. Two suspends and a resume: not with the fault."""
    def resumed_after(suspends: int) -> bool:
        for _ in range(suspends):
            esc.msg_control(MSG_CONTROL_SUSPEND)
        esc.wait(0.1)
        esc.msg_control(MSG_CONTROL_RESUME)
        return any(f.name == "msg1" for f in esc.wait(0.1))
    return resumed_after(1), resumed_after(2)


@scenario("resume_reloads_default_intervals", off=(0.04, 0.04, 0.04), on=(0.04, 0.04, 0.02))
def _(esc: Esc):
    """MSG1 at 40 ms: before a suspension, after one, and after a suspension and resume (then 20 ms, the default)."""
    esc.call("set_freq", {"option": 1, "msg1_interval": 20, "msg2_interval": 50, "msg3_interval": 250})
    before = esc.gap("msg1")
    esc.msg_control(MSG_CONTROL_SUSPEND)
    read = esc.call("set_freq", READ)["msg1_interval"] * 0.002
    esc.msg_control(MSG_CONTROL_RESUME)
    return before, read, esc.gap("msg1")


@scenario("set_freq_moves_other_stream", off=(0.1, 0.1), on=(0.1, 0.04))
def _(esc: Esc):
    """MSG2 at its default 100 ms; a write of all three leaves it; one moving only MSG1 moves it too (the fault)."""
    esc.call("set_freq", {"option": 1, "msg1_interval": 10, "msg2_interval": 50, "msg3_interval": 100})
    alone = esc.gap("msg2", 1.5)
    esc.call("set_freq", {"option": 1, "msg1_interval": 20, "msg2_interval": 50, "msg3_interval": 100})
    return alone, esc.gap("msg2", 1.5)


def _comm_fault_after_command(esc: Esc) -> bool:
    """Commands stop until the comm-loss flag is up, then one command: is the flag still up in the next MSG1?"""
    esc.wait(0.3)
    assert any(f.fields["status"] & Status.COMM_FAULT for f in esc.wait(0.05) if f.name == "msg1")
    esc.send("raw_command_14b", {"channels": [0, 0, 0, 0]})
    return bool([f for f in esc.wait(0.05) if f.name == "msg1"][-1].fields["status"] & Status.COMM_FAULT)


@scenario("comm_loss_sticky_after_resume", off=(False, False), on=(False, True))
def _(esc: Esc):
    plain = _comm_fault_after_command(esc)
    esc.msg_control(MSG_CONTROL_SUSPEND)
    esc.msg_control(MSG_CONTROL_RESUME)
    return plain, _comm_fault_after_command(esc)


@scenario("baud_change_counts_power_up_twice", off=(1, 1), on=(1, 2))
def _(esc: Esc):
    """The power-up count goes up by one per power cycle; with the fault by two at the one a Set Baud took effect."""
    def counted() -> int:
        before = esc.call("maintenance_information", {"option": 2})["power_ups"]
        esc.power_cycle()
        return esc.call("maintenance_information", {"option": 2})["power_ups"] - before
    plain = counted()
    esc.call("set_baud", {"baud": 2})
    esc.model.state.bitrate = 250_000  # (the model's bit rate is the adapter's business: this driver has none)
    return plain, counted()


@scenario("answer_slot_from_boot_node", off=(2, 34), on=(2, 2))
def _(esc: Esc):
    """GET_ESC_ID's answer starts in node 1's slot (2 ms); after Set ID to node 17 in node 17's (34 ms), or with the
    fault still in node 1's (the ms from the request to the answer's start, at the model's place: the slot's start)."""
    def slot_ms() -> int:
        sent = esc.now
        esc.model.receive(encode("get_esc_id", {"option": 0}, source=0, layout="query"), sent)
        [reply] = [f for f in esc.wait(0.07) if f.name == "get_esc_id"]
        return round((reply.timestamp - sent) * 1000)
    plain = slot_ms()
    assert esc.call("set_id", {"node_id": 17, "throttle_channel": 1})["node_id"] == 17
    return plain, slot_ms()


@scenario("throttle_select_drops_10b", off=(1000, 1000), on=(1000, 0))
def _(esc: Esc):
    """RawCommand_10b 500 (doubled: 1000) is followed; after Throttle Select to CAN it is ignored with the fault."""
    def pwm() -> int:
        esc.send("raw_command_10b", {"channels": [500] * 6, "tail_bits": 0b1100})
        out = [f for f in esc.wait(0.05) if f.name == "msg1"][-1].fields["pwm"]
        esc.send("raw_command_10b", {"channels": [0] * 6, "tail_bits": 0b1100})
        return out
    plain = pwm()
    esc.wait(1.5)  # the motor stopped: Throttle Select needs it (R12)
    assert esc.call("throttle_select", {"source": 0})["source"] == 0
    return plain, pwm()


# --------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", INTERACTIONS)
def test_interaction_fault_changes_the_behaviour_it_names(name):
    program, off, on = SCENARIOS[name]
    got_off = program(Esc())
    assert got_off == off, f"{name} off: the faultless model shows {got_off!r}, expected {off!r}"
    got_on = program(Esc((name,)))
    assert got_on == on, f"{name} on: {FAULTS[name].description}: expected {on!r}, got {got_on!r}"


def test_every_interaction_fault_has_a_scenario():
    assert sorted(set(INTERACTIONS) ^ set(SCENARIOS)) == []


def test_there_are_interaction_faults_of_at_least_eight_kinds():
    assert len(INTERACTIONS) >= 8
