"""The device under test as the suites see it: a host on a lane, talking to one ESC.

Everything a test needs goes through :class:`Dut`: send a broadcast or a request, wait on the
lane's clock, look at what came (every frame is kept in ``dut.trace`` with its bus timestamp),
power-cycle with proof, change throttle safely, snapshot and restore settings. It is a
:class:`.link.Link` (sending, reading, answers, throttle safety) with a :class:`.supply.Supply` (power
cycles and the 120 s window), and the operations the suites share.
"""

from __future__ import annotations

import itertools
from typing import Any, Iterable, Mapping

from ..protocol import catalogue as cat
from ..protocol.frame import Frame, classify
from ..protocol.ids import Kind
from .epochs import WINDOW_MARGIN_S, PowerEpoch
from .lanes import Lane
from .link import MAX_GARBLED, DutError, DutUnreachable, Exchange, Link, Sent, echo_probe, restoring
from .outcomes import Inconclusive
from .profile import DutProfile
from .supply import Supply

__all__ = ["MAX_GARBLED", "Dut", "DutError", "DutUnreachable", "Exchange", "Link", "Sent", "Supply", "echo_probe",
           "restoring"]

#: type ids of the frames that change how the DUT reports (MSG Control, CAN Test): restore resumes after them
_MODE_IDS = frozenset(cat.spec(name).type_id for name in ("msg_control", "can_test"))
#: the settings 242 gives as one bit each, side by side in its first byte (4.4.28-1), by their names in 242's answer
_MAJOR_BITS = {"rotation": "direction", "throttle_source": "throttle_source"}


class Dut(Link):
    """The test author's DUT: a :class:`.link.Link` to it, its :attr:`supply`, its settings, and the
    operations the suites share."""

    def __init__(self, lane: Lane, profile: DutProfile, *, node_id: int | None = None, host_node: int = 0,
                 allow_motor_spin: bool = False) -> None:
        super().__init__(lane, profile, node_id=node_id, host_node=host_node, allow_motor_spin=allow_motor_spin)
        self.supply = Supply(self)

    # ------------------------------------------------------------------ settings
    def settings(self) -> dict[str, int]:
        """The settings tests may change (242 and Set/Get Freq read)."""
        cfg = self.ask("get_major_configuration", {"option": 0})
        freq = self.ask("set_freq", cat.FREQ_READ)
        return {
            "rotation": cfg["direction"],
            "throttle_source": cfg["throttle_source"],
            "throttle_channel": cfg["throttle_channel"],
            "led_color": cfg["led_color"],
            "led_blink": cfg["led_blink"],
            "msg1_interval": freq["msg1_interval"],
            "msg2_interval": freq["msg2_interval"],
            "msg3_interval": freq["msg3_interval"],
        }

    def restore(self, snapshot: Mapping[str, int]) -> list[str]:
        """Put back what a test changed; returns what could not be restored (after verifying). Normal reporting
        is resumed (MSG Control) unless nothing the test sent can have left it and the DUT's MSG1 still comes."""
        interval = snapshot["msg1_interval"] * cat.INTERVAL_UNIT_S
        still = self.frames("msg1", since=self.now() - 2 * interval - self.lane.timing_error, source=self.node_id)
        if not still or self.sent_types & _MODE_IDS:
            self.broadcast("msg_control", {"option": 0, "command": cat.MSG_CONTROL_RESUME})
            self.wait(cat.ANSWER_DELAY_MAX_S)
        now = self.settings()
        if any(now[k] != snapshot[k] for k in cat.INTERVAL_FIELDS):
            self.ask("set_freq", {"option": 1, **{k: snapshot[k] for k in cat.INTERVAL_FIELDS}})
        if now["rotation"] != snapshot["rotation"]:
            self.ask("set_rotation", {"rotation": snapshot["rotation"]})
        if now["throttle_source"] != snapshot["throttle_source"]:
            self.ask("throttle_select", {"source": snapshot["throttle_source"]})
        if self.profile.has("led") and (now["led_color"], now["led_blink"]) != (snapshot["led_color"], snapshot["led_blink"]):
            self.ask("set_led", {"option": 1, "color": snapshot["led_color"], "blink": snapshot["led_blink"]})
        after = self.settings()
        if any(after[k] != snapshot[k] for k in _MAJOR_BITS) and all(after[k] == snapshot[k] for k in snapshot
                                                                    if k not in _MAJOR_BITS):
            after = self._restore_major_bits(snapshot)
        return [f"{k}: {after[k]} (was {snapshot[k]})" for k in snapshot if after[k] != snapshot[k]]

    def _restore_major_bits(self, snapshot: Mapping[str, int]) -> dict[str, int]:
        """Rotation and throttle source put back by what 242 reads, whatever its bits are said to mean: each pair of
        their values is set in turn until 242 reads as the test found it. A DUT whose 242 places the two bits
        otherwise than 4.4.28-1 says (which 4.4.28's own tests judge) is then put back as it was, where setting the
        values 242 seemed to show wrote the wrong setting (and left the run's later tests a DUT changed under them);
        it holds as long as different settings read differently. Returns the settings read last."""
        layout = cat.spec("get_major_configuration").response_for({"option": 0})
        codes = [sorted(layout.field(_MAJOR_BITS[k]).codes or ()) for k in ("rotation", "throttle_source")]
        after = dict(snapshot)
        for rotation, source in itertools.product(*codes):
            self.ask("set_rotation", {"rotation": rotation})
            self.ask("throttle_select", {"source": source})
            after = self.settings()
            if after == dict(snapshot):
                break
        return after

    # ------------------------------------------------------------------ power (the supply's)
    def power_up_count(self) -> int | None:
        return self.supply.power_up_count()

    def power_cycle(self, off_time: float = 1.0, boot_wait: float = 1.0) -> None:
        self.supply.power_cycle(off_time, boot_wait)

    def proved_power_up(self, on: float, before: int, after: int) -> None:
        self.supply.proved_power_up(on, before, after)

    def window_left(self) -> float:
        return self.supply.window_left()

    def open_window(self, left_s: float = 60.0) -> PowerEpoch:
        return self.supply.open_window(left_s)

    def at_window_moment(self, kind: str, margin: float = WINDOW_MARGIN_S) -> PowerEpoch:
        return self.supply.at_window_moment(kind, margin)

    def switch_power(self, off_time: float | None = None, boot_wait: float | None = None) -> float:
        return self.supply.switch_power(off_time, boot_wait)

    def ready_bound_s(self, boot: float | None = None) -> float:
        return self.supply.ready_bound_s(boot)

    def await_reports(self, since: float, until: float, others: Iterable[int] = ()) -> dict[str, float]:
        return self.supply.await_reports(since, until, others)

    def heard_from(self, since: float) -> bool:
        return self.supply.heard_from(since)

    # ------------------------------------------------------------------ operations the suites share
    #: How long a motor may take to start or to spin down: a test allowance, not a protocol fact
    MOTOR_STOP_S = 5.0
    #: Time given to the throttle output to follow a new command (a real ESC may ramp): not a protocol fact
    OUTPUT_SETTLE_S = 0.2

    def reports_heard(self, seconds: float) -> int:
        """How many report frames the DUT sends in the next ``seconds``, decoded or not (their format is
        4.4.4 - 4.4.14's business; here only whether it reports counts)."""
        report_ids = {s.type_id for s in cat.CATALOGUE if any(lay.name == "report" for lay in s.layouts)}
        start = self.now()
        self.wait(seconds)
        heard = [f for f in self.frames(source=self.node_id, kind=Kind.MESSAGE, since=start) if f.type_id in report_ids]
        heard += [g for g in self.undecoded(source=self.node_id, kind=Kind.MESSAGE, since=start)
                  if classify(g.msg.arbitration_id)[1] in report_ids]
        return len(heard)

    def suspend_reporting(self) -> None:
        """MSG Control 0x55555555, verified: INCONCLUSIVE (reporting resumed first) unless the reports
        stop, for whether they do is 4.4.2's verdict, not the verdict of a test that needs them stopped."""
        interval = self.settings()["msg1_interval"] * cat.INTERVAL_UNIT_S
        self.broadcast("msg_control", {"option": 0, "command": cat.MSG_CONTROL_SUSPEND})
        self.wait(cat.ANSWER_DELAY_MAX_S)
        if self.reports_heard(2 * interval):
            self.resume_reporting()
            raise Inconclusive("MSG Control 0x55555555 did not stop the reports (see 4.4.2): suspension cannot be tested")

    def resume_reporting(self) -> None:
        """MSG Control 0xAAAAAAAA, verified: if the reports do not come back (4.4.2's verdict) the DUT is
        power-cycled back to reporting where the lane can (suspension is not kept, R13) and the test is
        INCONCLUSIVE."""
        self.broadcast("msg_control", {"option": 0, "command": cat.MSG_CONTROL_RESUME})
        self.wait(cat.ANSWER_DELAY_MAX_S)
        if self.reports_heard(2 * self.settings()["msg1_interval"] * cat.INTERVAL_UNIT_S):
            return
        if self.lane.power.available:
            self.power_cycle(self.profile.off_s, self.profile.boot_s)
        raise Inconclusive("MSG Control 0xAAAAAAAA did not bring the reports back (see 4.4.2): this test cannot be judged")

    def wait_motor_stopped(self) -> Frame | None:
        """Zero throttle, then read until MSG1 shows the motor stopped (speed and pwm 0): that MSG1, or
        None when none did within MOTOR_STOP_S (the motor may have stopped unseen)."""
        self.zero_throttle()
        return self.wait_for("msg1", self.MOTOR_STOP_S, where=lambda f: f.fields["speed"] == 0 and f.fields["pwm"] == 0)

    def stop_motor(self) -> None:
        """:meth:`wait_motor_stopped`, INCONCLUSIVE when no MSG1 shows the motor stopped."""
        if self.wait_motor_stopped() is None:
            raise Inconclusive(f"the motor still runs {self.MOTOR_STOP_S} s after zero throttle (MSG1 speed, pwm)")

    def start_motor(self, name: str, fields: Mapping[str, Any]) -> None:
        """Stream throttle frame ``name`` with ``fields`` until MSG1 shows the motor running (the run bit or
        a speed: either will do, R7 is 4.4.4's business); when none does within MOTOR_STOP_S, the motor is
        let spin down and the test is INCONCLUSIVE. The caller stops it (:meth:`stop_motor`)."""
        self.throttle_stream(name, fields)
        if self.wait_for("msg1", self.MOTOR_STOP_S,
                         where=lambda f: bool(f.fields["status"] & cat.Status.RUNNING) or f.fields["speed"] > 0) is None:
            self.wait_motor_stopped()
            raise Inconclusive("the motor did not start (no MSG1 showed it running): the test cannot be judged")

    def msg1_interval(self, node: int | None = None) -> float:
        """The MSG1 report interval (s) of ``node`` (default: the DUT), read with Set/Get Freq."""
        freq = self.ask("set_freq", cat.FREQ_READ,
                        destination=self.node_id if node is None else node)
        return freq["msg1_interval"] * cat.INTERVAL_UNIT_S

    def read_output(self, *, nodes: list[int] | None = None, intervals: Mapping[int, float] | None = None
                    ) -> dict[int, list[int]]:
        """The throttle output (MSG1 ``pwm``, 4.4.4) of each of ``nodes`` (default: the DUT) under whatever
        commands them now: OUTPUT_SETTLE_S and one MSG1 interval for it to settle, then {node: [pwm, ...]}
        of the next three intervals' MSG1. INCONCLUSIVE when a node's MSG1 did not decode. ``intervals``:
        the nodes' MSG1 intervals where already read (else asked)."""
        nodes = [self.node_id] if nodes is None else nodes
        known = intervals or {}
        interval = max(known[n] if n in known else self.msg1_interval(n) for n in nodes)
        self.wait(self.OUTPUT_SETTLE_S + interval)
        start = self.now()
        self.wait(3 * interval + cat.INTERVAL_UNIT_S)
        out = {n: [f.fields["pwm"] for f in self.frames("msg1", since=start, source=n)] for n in nodes}
        for n, pwms in out.items():
            if not pwms:
                raise Inconclusive(f"no MSG1 decoded from node {n}: its throttle output cannot be read (see 4.4.4)")
        return out

    def throttle_output(self, name: str, frames: list[Mapping[str, Any]], *, nodes: list[int] | None = None,
                        intervals: Mapping[int, float] | None = None) -> dict[int, list[int]]:
        """:meth:`read_output` while each field dict of ``frames`` is streamed as throttle frame ``name``
        (in that order, every period); the streams are stopped afterwards."""
        nodes = [self.node_id] if nodes is None else nodes
        known = intervals or {}
        known = {n: known[n] if n in known else self.msg1_interval(n) for n in nodes}  # read before the throttle runs
        for fields in frames:
            self.throttle_stream(name, fields)
        try:
            return self.read_output(nodes=nodes, intervals=known)
        finally:
            self.stop_throttle()


