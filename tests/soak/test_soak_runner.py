"""The soak's runner in this process (the simulated lane): the throttle is zero on the way out of an interrupted run
that spun the motor."""

from __future__ import annotations

import io

from ckesc.bench.station import BenchOptions, Station
from ckesc.soak import runner


def test_an_interrupted_soak_that_spun_the_motor_leaves_its_throttle_at_zero(tmp_path, monkeypatch):
    seen: dict[str, list[int]] = {}
    close = Station.close

    def closing(self: Station) -> None:  # the emulated ESC's throttle as the lane closes
        if self.lane is not None:
            seen["throttle"] = [esc.state.can_throttle for esc in self.lane.sim.bench.escs]
        close(self)

    monkeypatch.setattr(Station, "close", closing)
    ticks = {"n": 0}

    def wall() -> float:  # Ctrl-C after a few hundred turns of the loop (the live line reads the wall clock)
        ticks["n"] += 1
        if ticks["n"] == 400:
            raise KeyboardInterrupt
        return 0.0

    spinning: list[int] = []
    feed = runner.Monitor.feed

    def watched(self, msg) -> None:
        feed(self, msg)
        if msg.arbitration_id & 0x7F == 1 and (msg.arbitration_id >> 8) & 0xFFFF == 20050:  # MSG1's PWM
            spinning.append(int.from_bytes(bytes(msg.data[2:4]), "little"))

    monkeypatch.setattr(runner.Monitor, "feed", watched)
    outcome = runner.run(BenchOptions(allow_motor_spin=True),
                         runner.SoakOptions(duration_s=600, rate_hz=50, throttle=((0.0, 800),), reports=str(tmp_path)),
                         out=io.StringIO(), wall=wall)
    assert outcome.status == runner.INTERRUPTED and outcome.where is not None
    assert max(spinning) == 800  # the profile's throttle reached the ESC
    assert seen["throttle"] == [0]
