"""ESCs on one supply do not boot at one instant (issue #21): the real-time emulator staggers them as a bench
does (``ckesc emulate --boot-spread``), and an ESC still booting hears nothing. Discovery must list every
ESC of a bench just switched on, and after a power cycle the harness must wait for every ESC that was
reporting before it asks anything of the bench.

This was the cause of ``test_several_escs_are_set_to_the_same_id`` going INCONCLUSIVE or FAIL in the
real-time lane: no frame was lost (tests/emulator/test_realtime.py counts them), but discovery stopped at the
first GET_ESC_ID query any ESC answered, and that query sometimes came between node 1's boot and node 33's
(20 ms spread over three ESCs), so the bench was taken for nodes [1, 2]; the test's own query right after
its power cycle was then asked of a bench whose node 33 was still booting too.

A real ``ckesc emulate`` process through python-can's socketcand client (the real-time lane), with the spread
widened to 0.3 s so that the queries (one every 128 ms while nothing answers) always fall between two boots.
"""

from __future__ import annotations

import pytest

from ckesc.bench.dut import Dut
from ckesc.bench.profile import DEFAULT_BUS_ERROR_S, DutProfile
from ckesc.bench.realtime_lane import RealtimeEmulatorLane
from ckesc.bench.station import MULTI_NODES
from ckesc.protocol import catalogue as cat

pytestmark = pytest.mark.realtime  # wall-clock timing with real processes: one at a time under xdist (tests/conftest.py)

SPREAD_S = 0.3  # ESC k of 3 boots k x 0.1 s after the first: wider than the 128 ms between discovery's queries


def esc_id_sources(d: Dut) -> list[int]:
    sent = d.broadcast("get_esc_id", {"option": 0}, layout="query")
    d.wait(cat.ANSWER_DELAY_MAX_S * 2)
    return sorted(f.source for f in d.frames("get_esc_id", since=sent.host_time) if f.layout is not None
                  and f.layout.name == "reply")


def test_a_staggered_bench_is_found_whole_and_waited_for_after_a_power_cycle():
    lane = RealtimeEmulatorLane(nodes=MULTI_NODES, timing_error=DEFAULT_BUS_ERROR_S, esc_options={"boot_spread": SPREAD_S})
    try:
        profile = DutProfile.load("emulator")
        d = Dut(lane, profile, node_id=None)  # right after the bench was switched on: every ESC still booting
        assert (d.node_id, d.nodes) == (MULTI_NODES[0], sorted(MULTI_NODES))
        d.power_cycle(0.2, profile.boot_s)
        assert esc_id_sources(d) == sorted(MULTI_NODES)  # asked as soon as power_cycle() returned
    finally:
        lane.close()
