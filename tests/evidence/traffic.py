"""Emulator traffic for the bus-rule tests: a scripted host on a ``ckesc-sim`` bus, every frame heard
(the host's own included, as their echo) handed to a :class:`BusRules` and kept.

The script does what a host does to a bench in a suite run: reads and writes report intervals,
streams throttle, queries services, suspends and resumes reporting, switches to MSG_EXP mode and CAN
Test mode, asks GET_ESC_ID and the temperature records, probes with a DroneCAN request, and cycles the
power. Each step waits on the lane's simulated clock.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field

import can

from ckesc.emulator import sim_bus
from ckesc.evidence import BusRules, Violation
from ckesc.protocol import catalogue as cat
from ckesc.protocol.frame import FALLBACK_PRIORITY, WireFrame
from ckesc.protocol.host import HostProtocol
from ckesc.protocol.ids import service_id
from ckesc.protocol.transfer import tail_byte

BITRATE = 500_000
_CHANNELS = itertools.count()
READ = {"option": 0, "msg1_interval": 0, "msg2_interval": 0, "msg3_interval": 0}


@dataclass
class Run:
    rules: BusRules
    violations: list[Violation] = field(default_factory=list)
    messages: list[can.Message] = field(default_factory=list)

    @property
    def checks(self) -> dict[str, set[str]]:
        """check name -> the requirement ids its violations cited."""
        out: dict[str, set[str]] = {}
        for v in self.violations:
            out.setdefault(v.check, set()).update(v.rules)
        return out


class ScriptedHost:
    def __init__(self, nodes=(1, 2), faults=(), *, bitrate: int = BITRATE, keep: bool = False) -> None:
        self.channel = f"evidence-{next(_CHANNELS)}"
        # the bus as the suite's simulated lane opens it: SocketCAN's defaults (acknowledgement, a queue of 10)
        self.bus = can.Bus(interface="ckesc-sim", channel=self.channel, nodes=list(nodes), faults=list(faults),
                           bitrate=bitrate, receive_own_messages=True, ignore_config=True)
        self.nodes = list(nodes)
        self.host = HostProtocol(0)
        self.run = Run(BusRules(tolerance=0.0, bitrate=bitrate, complete=True))
        self.keep = keep
        self.lost = 0

    def close(self) -> None:
        self.bus.shutdown()
        sim_bus.discard(self.channel)

    def pump(self, seconds: float) -> None:
        end = self.bus.now() + seconds
        while (msg := self.bus.recv(max(end - self.bus.now(), 0.0))) is not None:
            if self.keep:
                self.run.messages.append(msg)
            self.run.violations.extend(self.run.rules.feed_message(msg))

    def send(self, wire: WireFrame) -> None:
        """Send ``wire``; while no ESC acknowledges (one rebooting) a full queue loses the frame, as SocketCAN's BCM
        loses a stream's (``lost`` counts them)."""
        try:
            self.bus.send(can.Message(arbitration_id=wire.arbitration_id, data=wire.data, is_extended_id=True))
        except can.CanOperationError:
            if not self.bus.controller.full:
                raise
            self.lost += 1

    def broadcast(self, name: str, fields: dict, **kw) -> None:
        self.send(self.host.message(name, fields, **kw))

    def request(self, name: str, fields: dict, node: int, wait: float = 0.02) -> None:
        wire, _ = self.host.request(name, fields, destination=node, now=self.bus.now(), timeout=0.1)
        self.send(wire)
        self.pump(wait)

    def script(self) -> Run:
        """The whole script: about 8 s of lane time."""
        self.pump(0.5)  # boot
        for n in self.nodes:
            self.request("set_freq", READ, n)
        self.request("set_freq", {"option": 1, "msg1_interval": 15, "msg2_interval": 45, "msg3_interval": 240}, self.nodes[0])
        self.pump(1.0)
        for i in range(200):  # 400 Hz throttle, zero (the emulator needs no propeller, but keep it still)
            self.broadcast("raw_command_12b", {"channels": [0, 0, 0, 0], "group": 1})
            if i % 50 == 0:
                self.broadcast("raw_command_14b", {"channels": [0, 0, 0, 0]})
            self.pump(0.0025)
        for n in self.nodes:
            for name, fields in (("esc_information", {"option": 0}), ("get_major_configuration", {"option": 0}),
                                 ("self_test", {}), ("maintenance_information", {"option": 2}), ("set_rotation", {"rotation": 0xFF})):
                self.request(name, fields, n)
        for command in (cat.MSG_CONTROL_SUSPEND, cat.MSG_CONTROL_RESUME, cat.MSG_CONTROL_RESUME_EXP, cat.MSG_CONTROL_RESUME):
            self.broadcast("msg_control", {"option": 0, "command": command})
            self.pump(0.6)
        self.broadcast("can_test", {"option": cat.CAN_TEST_ON, "count": 0})
        self.pump(0.3)
        self.broadcast("can_test", {"option": cat.CAN_TEST_OFF, "count": 0})
        self.pump(0.3)
        self.broadcast("get_esc_id", {"option": 0}, layout="query")
        self.pump(0.2)
        self.request("get_rec", {"payload": []}, self.nodes[0], wait=0.1)
        probe = service_id(FALLBACK_PRIORITY, 1, True, self.nodes[0], 0)  # DroneCAN GetNodeInfo: foreign
        self.send(WireFrame(probe, bytes((tail_byte(0),))))
        self.pump(0.2)
        self.bus.power_cycle(1.0)
        self.pump(1.0)
        for n in self.nodes:
            self.request("set_freq", READ, n)
        self.pump(1.0)
        return self.run


def scripted_run(nodes=(1, 2), faults=(), **kw) -> Run:
    host = ScriptedHost(nodes, faults, **kw)
    try:
        return host.script()
    finally:
        host.close()
