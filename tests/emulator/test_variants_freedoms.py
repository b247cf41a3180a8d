"""Each conforming variant (``ckesc/emulator/variants.py``) really changes what the emulated ESC does, as
its description says: a variant that did nothing would prove nothing when the suite passes it.

Driven on the sans-IO model directly: frames and a time in, frames out."""

from __future__ import annotations

from typing import Any

import pytest

from ckesc.emulator import variants
from ckesc.emulator.model import EscConfig, EscModel
from ckesc.protocol import Decoder, Frame, Kind, encode
from ckesc.protocol.catalogue import CAN_TEST_OFF, CAN_TEST_ON, MSG_CONTROL_RESUME_EXP
from ckesc.protocol.ids import Priority

NODE = 1
READY = 0.3  # past the default boot time


class Esc:
    """One model at node 1, powered up at 0, and a host (node 0, or ``source``) talking to it."""

    def __init__(self, **options: Any) -> None:
        self.model = EscModel(EscConfig(node_id=NODE, **options))
        self.model.power_on(0.0)
        self.decoder = Decoder()
        self.now = 0.0
        self.tid = 0
        self.run(READY)

    def run(self, until: float) -> list[Frame]:
        out: list[Frame] = []
        while True:
            due = self.model.next_deadline()
            if due is None or due > until:
                break
            out += [self.decoder.decode(w) for w in self.model.poll(max(due, self.now))]
            self.now = max(due, self.now)
        self.now = until
        out += [self.decoder.decode(w) for w in self.model.poll(until)]
        return out

    def send(self, name: str, fields: dict, *, source: int = 0, service: bool = True, **kw: Any) -> list[Frame]:
        """Send a frame now; what the ESC sends in the next 100 ms."""
        self.tid = (self.tid + 1) % 32
        wire = encode(name, fields, source=source, destination=NODE if service else None, transfer_id=self.tid, **kw)
        self.decoder.decode(wire)  # remember the request (241 answers decode by its option)
        self.model.receive(wire, self.now)
        return self.run(self.now + 0.1)

    @staticmethod
    def answers(frames: list[Frame], name: str) -> list[Frame]:
        return [f for f in frames if f.kind is Kind.RESPONSE and f.name == name]


def test_every_freedom_is_an_esc_config_field_whose_default_is_its_first_value():
    default = EscConfig()
    for f in variants.FREEDOMS.values():
        value = getattr(default, f.name)
        if f.choices:
            assert value == f.choices[0], f.name
        else:
            assert f.span[0] <= value <= f.span[1], f.name  # type: ignore[index]


def test_report_phase_staggered_sends_msg2_and_msg3_after_msg1():
    def firsts(phase: str) -> dict[str, float]:
        m = EscModel(EscConfig(node_id=NODE, report_phase=phase))
        m.power_on(0.0)
        out: dict[str, float] = {}
        for w in m.poll(0.5):
            out.setdefault(Decoder().decode(w).name, w.timestamp)
        return out

    together, staggered = firsts("together"), firsts("staggered")
    assert together["msg1"] == together["msg2"] == together["msg3"]
    assert staggered["msg2"] == pytest.approx(staggered["msg1"] + 0.007)
    assert staggered["msg3"] == pytest.approx(staggered["msg1"] + 0.013)


def test_transfer_id_start_random_starts_somewhere_and_counts_by_one():
    def msg1_tids(**options: Any) -> list[int]:
        m = EscModel(EscConfig(node_id=NODE, **options))
        m.power_on(0.0)
        return [f.transfer_id for f in map(Decoder().decode, m.poll(0.5)) if f.name == "msg1"]

    starts = set()
    for seed in range(6):
        tids = msg1_tids(transfer_id_start="random", seed=seed)
        assert all((b - a) % 32 == 1 for a, b in zip(tids, tids[1:]))
        starts.add(tids[0])
    assert starts - {0}, "a random start that is always 0"
    assert msg1_tids()[0] == 0  # zero: 0 at power-up


@pytest.mark.parametrize("choice, priority", [("request", Priority.HIGH), ("medium", Priority.MEDIUM),
                                              ("low", Priority.LOW), ("lowest", Priority.LOWEST)])
def test_unlisted_priority_sets_the_priority_of_240_to_242_answers(choice, priority):
    esc = Esc(unlisted_priority=choice)
    got = esc.answers(esc.send("esc_information", {}, priority=Priority.HIGH), "esc_information")
    assert [f.priority for f in got] == [priority]


def test_foreign_host_ignore_ignores_a_non_zero_host():
    write = {"option": 1, "msg1_interval": 12, "msg2_interval": 50, "msg3_interval": 250}
    for choice, applied in (("accept", True), ("ignore", False)):
        esc = Esc(foreign_host=choice)
        answered = esc.answers(esc.send("set_freq", write, source=10), "set_freq")
        assert bool(answered) is applied and (esc.model.nvm["msg1_interval"] == 12) is applied
        assert esc.answers(esc.send("set_freq", write), "set_freq")  # node 0 is always heard
        assert esc.model.nvm["msg1_interval"] == 12


@pytest.mark.parametrize("delay", [0.0002, 0.064])
def test_service_delay_places_the_answer(delay):
    esc = Esc(service_delay=delay)
    sent = esc.now
    (answer,) = esc.answers(esc.send("esc_information", {}), "esc_information")
    assert answer.timestamp == pytest.approx(sent + delay)


@pytest.mark.parametrize("choice", ["current", "none", "echo"])
def test_rejected_answer_answers_an_illegal_or_refused_request_so_and_applies_nothing(choice):
    esc = Esc(rejected_answer=choice)
    heard = []  # the model's public hook hears every rejected request, whatever its answer (the explorer's oracle)
    esc.model.on_rejected = lambda req: heard.append(req.name)
    illegal = {"option": 1, "msg1_interval": 9, "msg2_interval": 60, "msg3_interval": 250}
    got = esc.answers(esc.send("set_freq", illegal), "set_freq")
    assert (esc.model.nvm["msg1_interval"], esc.model.nvm["msg2_interval"]) == (10, 50)  # nothing applied
    expected = {"current": [{"option": 1, "msg1_interval": 10, "msg2_interval": 50, "msg3_interval": 250}],
                "none": [], "echo": [illegal]}[choice]
    assert [{k: f.fields[k] for k in illegal} for f in got] == expected
    # refused: Set ID outside the 120 s window
    esc.run(121.0)
    got = esc.answers(esc.send("set_id", {"node_id": 5, "throttle_channel": 5}), "set_id")
    assert esc.model.node_id == NODE
    assert [(f.fields["node_id"], f.fields["throttle_channel"]) for f in got] == {
        "current": [(1, 1)], "none": [], "echo": [(5, 5)]}[choice]
    assert heard == ["set_freq", "set_id"]
    # a legal, accepted request is answered as before, and not heard as rejected
    legal = {"option": 1, "msg1_interval": 11, "msg2_interval": 50, "msg3_interval": 250}
    assert [f.fields["msg1_interval"] for f in esc.answers(esc.send("set_freq", legal), "set_freq")] == [11]
    assert heard == ["set_freq", "set_id"]


@pytest.mark.parametrize("choice, throttle", [("clamp", 2000), ("hold", 500), ("zero", 0)])
def test_over_max_throttle(choice, throttle):
    esc = Esc(over_max_throttle=choice)
    esc.send("raw_command_14b", {"channels": [500, 0, 0, 0]}, service=False)
    assert esc.model.state.can_throttle == 500
    esc.send("raw_command_14b", {"channels": [3000, 0, 0, 0]}, service=False)
    assert esc.model.state.can_throttle == throttle
    assert not esc.model.state.comm_fault  # the frame still counts as a command
    esc.send("raw_command_10b", {"channels": [250, 0, 0, 0, 0, 0]}, service=False)
    esc.send("raw_command_10b", {"channels": [1010, 0, 0, 0, 0, 0]}, service=False)
    assert esc.model.state.can_throttle == {"clamp": 2000, "hold": 500, "zero": 0}[choice]


@pytest.mark.parametrize("choice, names, exp1_gap, exp7_gap", [
    ("msg3", {"msg_exp1", "msg_exp7", "msg_exp8", "msg_exp9", "msg_exp10", "msg_exp11"}, 0.02, 0.5),
    ("msg2", {"msg_exp1", "msg_exp7", "msg_exp8", "msg_exp9", "msg_exp10", "msg_exp11"}, 0.1, 0.1),
    ("exp1_only", {"msg_exp1"}, 0.02, None),
    ("no_exp1", {"msg_exp7", "msg_exp8", "msg_exp9", "msg_exp10", "msg_exp11"}, None, 0.5),
])
def test_exp_frames_chooses_which_msg_exp_frames_come_and_how_often(choice, names, exp1_gap, exp7_gap):
    esc = Esc(exp_frames=choice)
    esc.send("msg_control", {"option": 0, "command": MSG_CONTROL_RESUME_EXP}, service=False)
    frames = esc.run(esc.now + 1.2)
    assert {f.name for f in frames if f.name.startswith("msg_exp")} == names
    assert not {"msg1", "msg2", "msg3"} & {f.name for f in frames}
    for name, gap in (("msg_exp1", exp1_gap), ("msg_exp7", exp7_gap)):
        times = [f.timestamp for f in frames if f.name == name]
        if gap:
            assert times[-1] - times[-2] == pytest.approx(gap)


@pytest.mark.parametrize("choice, temperature, voltage", [("mixed", 25, 5057), ("round", 26, 5057),
                                                          ("truncate", 25, 5056)])
def test_value_rounding(choice, temperature, voltage):
    esc = Esc(value_rounding=choice)
    esc.model.state.temps["mos"] = 25.6
    esc.model._electrical = lambda: (50.5678, 0.0)  # a voltage between two hundredths, without noise
    msg2 = [f for f in esc.run(esc.now + 0.11) if f.name == "msg2"][-1]
    assert (msg2.fields["temperature"], msg2.fields["voltage"]) == (temperature, voltage)


@pytest.mark.parametrize("choice", ["from_zero", "from_random", "zero_each_session"])
def test_can_test_count_start(choice):
    esc = Esc(can_test_count=choice, seed=3)

    def session() -> list[int]:
        counts = [f.fields["count"] for f in esc.send("can_test", {"option": CAN_TEST_ON}, service=False)
                  if f.name == "can_test"]
        esc.send("can_test", {"option": CAN_TEST_OFF}, service=False)
        return counts

    first, second = session(), session()
    for counts in (first, second):
        assert len(counts) > 3 and all(b - a == 1 for a, b in zip(counts, counts[1:]))
    assert (first[0] == 0) is (choice != "from_random")
    assert (second[0] == 0) is (choice == "zero_each_session")
    if choice != "zero_each_session":
        assert second[0] == first[-1] + 1  # on across sessions


@pytest.mark.parametrize("choice", ["no_blink", "no_operation"])
def test_led_blink_other(choice):
    esc = Esc(led_blink_other=choice)
    esc.send("set_led", {"option": 0, "color": 4, "blink": 1})
    (answer,) = esc.answers(esc.send("set_led", {"option": 0, "color": 2, "blink": 3}), "set_led")
    expected = (2, 0) if choice == "no_blink" else (4, 1)
    assert (esc.model.state.led_color, esc.model.state.led_blink) == expected
    assert (answer.fields["color"], answer.fields["blink"]) == expected


def test_major_config_option_ignore_answers_only_option_0():
    for choice, answered in (("answer", True), ("ignore", False)):
        esc = Esc(major_config_option=choice)
        assert bool(esc.answers(esc.send("get_major_configuration", {"option": 1}), "get_major_configuration")) is answered
        assert esc.answers(esc.send("get_major_configuration", {"option": 0}), "get_major_configuration")


@pytest.mark.parametrize("choice", ["none", "echo"])
def test_rec_answer(choice):
    esc = Esc(rec_answer=choice)
    frames = esc.send("get_rec", {"payload": b"\x00"})
    assert len([f for f in frames if f.name == "msg_exp12"]) == 4  # the records come either way
    assert len(esc.answers(frames, "get_rec")) == (choice == "echo")
    assert len(esc.answers(esc.send("clear_rec", {"payload": b"\x00"}), "clear_rec")) == (choice == "echo")


def test_the_slowest_conforming_boot_still_reports_within_the_emulator_profiles_boot_s():
    """boot_time and report_delay at their ends, the first reports staggered and ``ckesc emulate
    --boot-spread``'s 20 ms: the last first report still comes within the emulator profile's boot_s."""
    import tomllib
    from importlib import resources

    profile = tomllib.loads(resources.files("ckesc.bench").joinpath("profiles/emulator.toml").read_text())
    boot_s = profile["timing"]["boot_s"]
    m = EscModel(EscConfig(node_id=NODE, boot_time=variants.FREEDOMS["boot_time"].span[1],  # type: ignore[index]
                           report_delay=variants.FREEDOMS["report_delay"].span[1],  # type: ignore[index]
                           report_phase="staggered"))
    m.power_on(0.0)
    firsts: dict[str, float] = {}
    for w in m.poll(1.0):
        firsts.setdefault(Decoder().decode(w).name, w.timestamp)
    assert max(firsts[k] for k in ("msg1", "msg2", "msg3")) + 0.020 <= boot_s


@pytest.mark.parametrize("choice", ["ignore", "take"])
def test_toggle_single_frame(choice):
    """A single frame with toggle 1 (R17-toggle): taken only by ``take``; a multi-frame start frame never."""
    from ckesc.protocol.transfer import tail_byte

    esc = Esc(toggle_single_frame=choice)
    wire = encode("set_rotation", {"rotation": 1}, source=0, destination=NODE, transfer_id=3)
    start = wire._replace(data=wire.data[:-1] + bytes((tail_byte(3, end=False),)))
    esc.model.receive(start, esc.now)
    assert not esc.answers(esc.run(esc.now + 0.1), "set_rotation") and esc.model.nvm["rotation"] == 0
    esc.model.receive(wire._replace(data=wire.data[:-1] + bytes((tail_byte(3, toggle=True),))), esc.now)
    assert bool(esc.answers(esc.run(esc.now + 0.1), "set_rotation")) is (choice == "take")
    assert esc.model.nvm["rotation"] == (choice == "take")


@pytest.mark.parametrize("choice", ["keep", "drop"])
def test_above_half_load(choice):
    """R18-above-half: at half load (R18's most, in its worst bursts) every MSG1 comes; at 70 % ``drop`` skips them
    (the window it measures over filled), ``keep`` does not."""
    from ckesc.protocol.load import LoadSource

    def msg1s(share: float) -> int:
        esc = Esc(above_half_load=choice)
        start = esc.now
        load = LoadSource(share, esc.model.state.bitrate, priority="high", seed=3, exclude_nodes=[NODE])
        frames: list[Frame] = []
        t = 0.0
        while t < 0.5:  # the load's frames fed at their due times, the ESC run between them
            t = load.next_due()
            for w in load.take_due(t):
                frames += esc.run(start + t)
                esc.model.receive(w, start + t)
        return len([f for f in frames if f.name == "msg1" and f.timestamp > start + 0.15])

    from ckesc.protocol.catalogue import INTERVAL_UNIT_S

    expected = int(0.35 / (EscModel(EscConfig()).nvm["msg1_interval"] * INTERVAL_UNIT_S))  # in the 0.35 s counted
    assert msg1s(0.5) >= expected - 1, f"{choice}: MSG1 dropped at half load"
    assert (msg1s(0.7) < expected / 2) is (choice == "drop"), f"{choice}: {msg1s(0.7)} MSG1 at 70 %, {expected} due"
