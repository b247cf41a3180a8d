"""Throttle helpers the suites share (not a section: no tests here).

- :class:`RawCommand`: one throttle format as its section (4.4.15 - 4.4.17) tests it, and the checks
  those sections make alike, each for its own format (each section module keeps its own tests, ids
  and citations; it calls these for the bodies).
- :func:`motor_stopped`: an autouse fixture for the modules that import it - the motor stopped before
  each test (settings need it, R12) and after it.
- :data:`RUN_VALUE` / :func:`start_motor`: a modest run throttle on the DUT's own channel.
- :func:`command_for`: the fields of a throttle frame that commands one channel, in any format;
  :data:`STREAM_PERIOD_S`, the period of a throttle stream; :func:`can_throttle`, CAN throttle selected.
"""

from __future__ import annotations

from collections.abc import Mapping
from contextlib import contextmanager
from dataclasses import dataclass

import pytest

from ckesc.bench.dut import restoring
from ckesc.bench.errors import RestoreFailed
from ckesc.bench.outcomes import Inconclusive
from ckesc.protocol import catalogue as cat
from ckesc.protocol.frame import classify
from ckesc.protocol.ids import Kind

#: a modest throttle whose 12-bit packing is the same in both nibble orders (bits 11..8 and 3..0 zero),
#: so that running the motor does not depend on R4
RUN_VALUE = 0xF0
REPORTS = frozenset(cat.ESC_REPORT_FRAMES)
#: what an ESC sends on its own or to answer the broadcasts of 4.4.1 - 4.4.3 (judged there, and such
#: an answer may come late into the window): not an answer to a RawCommand
NOT_ANSWERS = REPORTS | {"can_test", "msg_control", "get_esc_id"}
NOT_ANSWER_IDS = frozenset(cat.spec(name).type_id for name in NOT_ANSWERS)
#: One throttle frame per period, as a flight controller sends it (400 Hz)
STREAM_PERIOD_S = 0.0025
#: Throttle formats by the channels they carry: 4.4.15-4 (1-4), 4.4.17-4 (1-6); 12-bit: the DUT's group
#: (4.4.16-3): the catalogue's
FORMAT_CHANNELS = cat.FORMAT_CHANNELS


# ------------------------------------------------------------------------------------------ throttle frames
def _group(channel: int) -> int:
    """4.4.16-3: group g carries channels 4g-3..4g."""
    per = FORMAT_CHANNELS["raw_command_12b"]
    return (channel - 1) // per + 1


def command_for(name: str, channel: int, value: int = 0) -> dict | None:
    """Fields of a throttle frame that commands ``value`` on ``channel`` (0 elsewhere); None when the
    format cannot address that channel."""
    n = FORMAT_CHANNELS[name]
    if name == "raw_command_12b":
        if _group(channel) not in cat.THROTTLE_GROUPS:
            return None
        channels = [0] * n
        channels[(channel - 1) % n] = value
        return {"channels": channels, "group": _group(channel)}
    if not 1 <= channel <= n:
        return None
    channels = [0] * n
    channels[channel - 1] = value
    return {"channels": channels}


def can_throttle(dut) -> dict:
    """The DUT's settings, with CAN throttle selected first if it was not."""
    s = dut.settings()
    if s["throttle_source"] != 0:
        dut.ask("throttle_select", {"source": 0})  # "under CAN throttle condition"; the fixture restores it
        s = dut.settings()
    return s


# ------------------------------------------------------------------------------------------ the motor
@pytest.fixture(autouse=True)
def motor_stopped(request):
    """The motor stopped before each test (settings need it, R12) and after it (the DUT left as found)."""
    if "dut" not in request.fixturenames:
        yield
        return
    dut = request.getfixturevalue("dut")
    dut.wait_motor_stopped()
    yield
    dut.wait_motor_stopped()


def run_command(dut) -> dict:
    """RawCommand_12b fields that command RUN_VALUE on the DUT's own channel (0 on the others of its group)."""
    return command_for("raw_command_12b", dut.settings()["throttle_channel"], RUN_VALUE)


def start_motor(dut) -> None:
    """RUN_VALUE on the DUT's own channel until MSG1 says the motor runs (INCONCLUSIVE if it never does)."""
    dut.start_motor("raw_command_12b", run_command(dut))


# ------------------------------------------------------------------------------------------ RawCommand
@dataclass(frozen=True)
class RawCommand:
    """A throttle format as its section tests it: the frames that carry a set of channel values
    ({channel: value}) and what a DUT on a channel must output for them."""

    name: str
    per_frame: int  # channels one frame carries
    groups: tuple[int, ...] = ()  # 12-bit: the group ids; frame g carries channels 4g-3..4g (4.4.16-3)
    scale: int = 1  # the output for a value: 10-bit doubles it (4.4.17-2, R5)
    requirement: str = ""  # the clause that names the channels the format carries

    @property
    def title(self) -> str:
        return cat.spec(self.name).title

    @property
    def channels(self) -> range:
        return range(1, self.per_frame * max(len(self.groups), 1) + 1)

    def group_of(self, channel: int) -> int:
        return (channel - 1) // self.per_frame + 1

    def frame(self, group: int, values: Mapping[int, int]) -> dict:
        """The command of ``group`` carrying ``values``."""
        first = (group - 1) * self.per_frame + 1
        return {"channels": [values.get(first + i, 0) for i in range(self.per_frame)], "group": group}

    def frames(self, values: Mapping[int, int], own: int | None = None, **fields) -> list[dict]:
        """One command cycle carrying ``values``. Grouped: one frame per group, the group of channel
        ``own`` first (an ESC that ignores the group id takes its value from the last frame, which is then
        not its own). ``fields``: further fields of every frame."""
        if not self.groups:
            return [{"channels": [values.get(c, 0) for c in self.channels], **fields}]
        first = [] if own is None else [self.group_of(own)]
        return [{**self.frame(g, values), **fields} for g in first + [g for g in self.groups if g not in first]]

    def expected(self, channel: int, values: Mapping[int, int]) -> int | None:
        """What the DUT on ``channel`` must output for a cycle carrying ``values`` (None: not addressed)."""
        return self.scale * values[channel] if channel in self.channels else None

    def own_channel(self, dut) -> int:
        """The DUT's throttle channel; the test is skipped when the format does not carry it."""
        channel = dut.settings()["throttle_channel"]
        if channel not in self.channels:
            pytest.skip(f"the DUT is on throttle channel {channel}, which {self.title} does not carry ({self.requirement}); "
                        "the power-cycle tests move it")
        return channel

    def output(self, dut, frames: list[dict], nodes: list[int] | None = None) -> dict[int, list[int]]:
        """{node: [MSG1 pwm, ...]} while ``frames`` stream (``dut.throttle_output``)."""
        return dut.throttle_output(self.name, frames, nodes=nodes, intervals=getattr(dut, "intervals", None))

    def own_output(self, dut, frames: list[dict]) -> list[int]:
        return self.output(dut, frames)[dut.node_id]

    # ---------------------------------------------------------------------- checks the sections share
    def check_not_answered(self, dut, values: Mapping[int, int]) -> None:
        """A RawCommand is a broadcast without an answer: while a 400 Hz stream runs the DUT sends its
        reports at their intervals and nothing else."""
        interval = dut.msg1_interval()
        span = 10 * interval
        start = dut.now()
        for fields in self.frames(values):
            dut.throttle_stream(self.name, fields)
        try:
            dut.wait(span)
        finally:
            dut.stop_throttle()
        end = dut.now()
        # since= is inclusive and now() right after a request is its answer's timestamp: strictly after start
        own = [f for f in dut.frames(since=start, until=end, source=dut.node_id) if f.timestamp > start]
        # a RawCommand is a message: an answer would be a message too (a response answers some request)
        answers = [f for f in own if f.kind is Kind.MESSAGE and f.name not in NOT_ANSWERS]
        garbled = [g.msg for g in dut.garbled if (g.msg.arbitration_id & 0x7F) == dut.node_id
                   and start < (g.msg.timestamp or 0.0) <= end
                   and could_answer(g.msg)]
        assert not answers and not garbled, f"the DUT answered a {self.title} stream: {answers or garbled}"
        msg1 = [f for f in own if f.name == "msg1"]
        limit = 2 * int(span / interval) + 1  # room for any report jitter (R9's business); an answer per command is 8x
        assert len(msg1) <= limit, (f"{len(msg1)} MSG1 in {span * 1000:.0f} ms at a {interval * 1000:.0f} ms interval "
                                    f"(at most {limit}): the commands are being answered")

    def check_every_esc(self, escs, values: Mapping[int, int]) -> None:
        """Every ESC on the bench outputs its own channel's value of the one command cycle."""
        channels = escs.channels
        escs.record.observe("node -> throttle channel", channels)
        got = self.output(escs, self.frames(values), nodes=escs.nodes)
        for node, pwms in got.items():
            check(pwms, self.expected(channels[node], values), f"node {node} on channel {channels[node]}")

    def check_follows(self, dut, values: Mapping[int, int], channel: int, *, note: str = "", **fields) -> None:
        """The DUT on ``channel`` outputs what the format gives that channel (0 when not addressed).
        ``fields``: further fields of every frame; ``note``: what the failure message adds about them."""
        check(self.own_output(dut, self.frames(values, channel, **fields)), self.expected(channel, values),
              f"channel {channel} of {dict(values)}{note}")

    def check_on_channel(self, dut, values: Mapping[int, int], channel: int) -> None:
        """:meth:`check_follows` with the DUT moved to ``channel`` (:func:`on_channel`)."""
        with on_channel(dut, channel):
            self.check_follows(dut, values, channel)

    def check_value_is_output(self, dut, values: Mapping[int, int], value: int) -> None:
        """``value`` on the DUT's channel (the others carry ``values``) is output (scaled); 0 from a running
        output, so that 0 is a change."""
        channel = self.own_channel(dut)
        changed = {**values, channel: value}
        if value == 0:
            self.own_output(dut, self.frames(values, channel))
        check(self.own_output(dut, self.frames(changed, channel)), self.scale * value, f"channel {channel} of {changed}")

    def check_above_valid_range(self, dut, values: Mapping[int, int], value: int) -> None:
        """``value`` above the valid range on the DUT's channel: the output is recorded (R6) and expected
        clamped to THROTTLE_MAX."""
        channel = self.own_channel(dut)
        pwms = self.own_output(dut, self.frames({**values, channel: value}, channel))
        dut.record.observe(f"MSG1 pwm for {value}", sorted(set(pwms)))
        assert set(pwms) <= {cat.THROTTLE_MAX}, f"{value} gave pwm {sorted(set(pwms))} (clamping to 2000 was expected)"


def rotated(values: Mapping[int, int], shift: int) -> dict[int, int]:
    """``values`` moved ``shift`` channels down (channel 1 gets channel 1+shift's value, and so on round)."""
    vs = list(values.values())
    return dict(zip(values, vs[shift:] + vs[:shift]))


def could_answer(msg) -> bool:
    """A malformed frame that may be an answer: a message of no type in NOT_ANSWERS (a malformed report
    is 4.4.4 - 4.4.14's business)."""
    kind, type_id = classify(msg.arbitration_id)[:2]
    return kind is Kind.MESSAGE and type_id not in NOT_ANSWER_IDS


def check(pwms: list[int], expected: int | None, what: str) -> None:
    want = 0 if expected is None else expected
    assert all(p == want for p in pwms), (
        f"{what}: MSG1 pwm {pwms}, expected {want}" + (" (not addressed to the DUT's channel)" if expected is None else ""))


#: lane seconds of the current window that must be left to move the DUT's channel in it without a power cycle
SETUP_IN_WINDOW_S = 30.0


@contextmanager
def on_channel(dut, channel: int):
    """The DUT on throttle ``channel`` for the block: Set ID (same node id) inside the 120 s window of the
    DUT's current power-up while enough of it is left, else (or when it did not take there) of a proven
    power cycle (R11); the original channel is put back and verified afterwards."""
    before = dut.settings()["throttle_channel"]
    if channel == before:
        yield
        return
    fresh = dut.window_left() < SETUP_IN_WINDOW_S  # else Set ID goes in the window still open (R11)
    if fresh:
        dut.open_window()
    try:
        dut.request("set_id", {"node_id": dut.node_id, "throttle_channel": channel})
        now = dut.settings()["throttle_channel"]
        if now != channel and not fresh:  # not taken in a window other commands went into: a fresh one, as before
            dut.open_window()
            dut.request("set_id", {"node_id": dut.node_id, "throttle_channel": channel})
            now = dut.settings()["throttle_channel"]
        if now != channel:
            raise Inconclusive(f"Set ID did not move the DUT to throttle channel {channel} (it is on {now}): "
                               "that channel cannot be tested (see the 4.4.18 results)")
        yield
    finally:
        dut.zero_throttle()
        with restoring(f"the DUT's throttle channel {before}"):
            dut.request("set_id", {"node_id": dut.node_id, "throttle_channel": before})
            if dut.settings()["throttle_channel"] != before:
                raise RestoreFailed(f"could not put the DUT back on throttle channel {before}")


@pytest.fixture
def escs_on_channels(multi_dut):
    """``multi_dut`` with ``.channels`` (each ESC's throttle channel) and ``.intervals`` (its
    MSG1 interval), read here: an ESC that cannot say is a setup error, not a verdict."""
    multi_dut.channels = {n: multi_dut.ask("get_major_configuration", {"option": 0}, destination=n)["throttle_channel"]
                          for n in multi_dut.nodes}
    multi_dut.intervals = {n: multi_dut.msg1_interval(n) for n in multi_dut.nodes}
    return multi_dut
