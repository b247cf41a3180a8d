"""Several ESCs on one bus (not a section: no tests here): the :func:`escs` fixture, with the run's
emulator faults, and :func:`several_escs`, the 'needs two or more ESCs' check.
"""

from __future__ import annotations

import pytest

from ckesc.bench.outcomes import Inconclusive

from .telemetry import node_settings


def with_emulator_faults(multi_dut, config):
    """``multi_dut`` with ``--emulator-faults`` switched on in its private emulated bench.

    Workaround: the plugin builds that bench without the run's faults, so no fault could make a
    multi_dut test fail. The faults go on after discovery (a GET_ESC_ID fault then fails the test
    instead of breaking the fixture). On a real bus, and in the real-time lane, this does nothing."""
    faults = [f for f in (config.getoption("emulator_faults") or "").split(",") if f]
    sim = getattr(multi_dut.lane, "sim", None)
    if faults and sim is not None and hasattr(sim, "set_fault"):
        for name in faults:
            sim.set_fault(name)
    for node in multi_dut.nodes:  # every node answers the requests the tests need: else an ERROR, not a FAIL
        node_settings(multi_dut, node)
        multi_dut.ask("get_major_configuration", {"option": 0}, destination=node)
    return multi_dut


@pytest.fixture
def escs(multi_dut, request):
    """Several ESCs on one bus (``multi_dut``), with the run's emulator faults."""
    return with_emulator_faults(multi_dut, request.config)


def several_escs(escs, what: str) -> list[int]:
    """The node ids on the bench, INCONCLUSIVE unless two or more answered GET_ESC_ID (``what`` is the
    clause's own words, e.g. 'all ESCs')."""
    if len(escs.nodes) < 2:
        raise Inconclusive(f"only node(s) {escs.nodes} answered GET_ESC_ID: '{what}' needs two or more")
    return escs.nodes
