"""The lane a run's options ask for: the emulator in simulated or real time, or a python-can bus with its power
control (command, manual, labgrid, none); the python-can arguments and labgrid power the preflight checks first."""

from __future__ import annotations

from typing import Any

import pytest

from ..bench import proof
from ..bench.errors import PreflightError
from ..bench.lanes import BusLane, Lane, SimLane
from ..bench.power import PowerControl, open_power
from ..bench.profile import DutProfile
from ..bench.realtime_lane import RealtimeEmulatorLane
from . import preflight
from .state import state

_LABGRID = pytest.StashKey[PowerControl]()

#: The private bench of the ``multi_dut`` fixture in the emulator lanes: node ids chosen so that
#: node_id % 32 covers 1, 2 and wraps (33 -> slot 1).
MULTI_NODES = (1, 2, 33)


def bus_kwargs(config: pytest.Config) -> dict[str, Any]:
    """python-can's arguments for --dut bus: the options, then CAN_* and can.conf (a mistake: PreflightError)."""
    import can

    kwargs: dict[str, Any] = {}
    if config.getoption("can_interface"):
        kwargs["interface"] = config.getoption("can_interface")
    if config.getoption("can_channel"):
        kwargs["channel"] = config.getoption("can_channel")
    if config.getoption("can_bitrate"):
        kwargs["bitrate"] = config.getoption("can_bitrate")
    for kv in config.getoption("can_config"):
        key, sep, value = kv.partition("=")
        if not sep:
            raise preflight.PreflightError(f"--can-config takes KEY=VALUE, got {kv!r}")
        kwargs[key] = can.util.cast_from_string(value)
    try:
        resolved = can.util.load_config(config=kwargs)  # explicit options, then CAN_* and can.conf
    except (can.CanInterfaceNotImplementedError, ValueError, TypeError) as exc:
        if not kwargs.get("interface") and '"None"' in str(exc):  # none given anywhere: python-can's 'Unknown ... "None"'
            raise preflight.PreflightError(no_interface()) from None
        raise preflight.PreflightError(f"the CAN bus configuration {kwargs}: {exc} (known interfaces: "
                                       f"{', '.join(sorted(can.interfaces.VALID_INTERFACES))})") from None
    if not resolved.get("interface"):
        raise preflight.PreflightError(no_interface())
    return dict(resolved)


#: interfaces that need no adapter (a daemon over TCP/IP, a process's own buses) or whose detection lists
#: every serial port (serial): not probed, named as always there
_NO_ADAPTER = ("socketcand", "udp_multicast", "virtual")
_NOT_PROBED = (*_NO_ADAPTER, "serial", "ckesc-sim")
#: how long the adapters are looked for (python-can asks each driver in turn)
_PROBE_S = 5.0


def adapters_here() -> list[str]:
    """The CAN adapters python-can finds on this machine (``interface channel``), looked for at most
    :data:`_PROBE_S`; the drivers' complaints about what they lack stay off the console."""
    import logging
    import threading

    import can

    found: list[dict[str, Any]] = []
    names = [n for n in sorted(can.interfaces.VALID_INTERFACES) if n not in _NOT_PROBED]

    def probe() -> None:
        found.extend(can.detect_available_configs(interfaces=names))

    level = logging.root.manager.disable
    logging.disable(logging.CRITICAL)
    try:
        t = threading.Thread(target=probe, name="ckesc-adapters", daemon=True)
        t.start()
        t.join(_PROBE_S)
    finally:
        logging.disable(level)
    return [f"{c.get('interface')} {c.get('channel')}" for c in list(found)]


def no_interface() -> str:
    """The one line for ``--dut bus`` with no interface given anywhere: what to give, and what there is."""
    found = adapters_here()
    return ("--dut bus needs --can-interface NAME (with its --can-channel / --can-config; or CAN_INTERFACE / can.conf): "
            f"adapters python-can finds here: {', '.join(found) if found else 'none'}; needing no adapter: "
            f"{', '.join(_NO_ADAPTER)} (socketcand: a socketcand daemon, e.g. ckesc emulate --socketcand 0)")


def open_labgrid(config: pytest.Config) -> None:
    """--power labgrid: its driver (and place, acquired), released by pytest's cleanup on every way out."""
    power = open_power("labgrid", config.getoption, _prompt(config))
    config.add_cleanup(power.close)
    config.stash[_LABGRID] = power
    state(config).info["power_labgrid"] = power.where


def _prompt(config: pytest.Config):
    def ask(text: str) -> None:
        capman = config.pluginmanager.getplugin("capturemanager")
        with capman.global_and_fixture_disabled() if capman else _null():
            input(f"\n>>> {text} ")

    return ask


class _null:
    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False


def emulator_options(config: pytest.Config) -> dict[str, Any]:
    """The conforming variant the emulated ESCs play: --emulator-variants SEED's draw with --emulator-option
    NAME=VALUE on top, checked (preflight): {EscConfig field: value}."""
    return preflight.emulator_options(config.getoption("emulator_option"), config.getoption("emulator_variants"))


def emulator_faults(config: pytest.Config) -> list[str]:
    return preflight.fault_names(config.getoption("emulator_faults"))


def make_lane(config: pytest.Config, profile: DutProfile) -> Lane:
    dut_kind = config.getoption("dut")
    faults = emulator_faults(config)
    nodes = preflight.node_list(config.getoption("nodes") or "1")
    options = emulator_options(config)
    if dut_kind == "emulator":
        if config.getoption("lane") == "realtime":
            return RealtimeEmulatorLane(nodes=nodes, faults=faults, temp_flash=True, esc_options=options,
                                        seed=config.getoption("emulator_seed"), timing_error=max(profile.error_s, 0.002))
        # in one process the emulated ESCs keep their flash contents across power cycles: no file needed
        lane = SimLane(nodes=nodes, faults=faults, seed=config.getoption("emulator_seed"),
                       esc_config={"boot_time": 0.25, **options})
        # exact timestamps; a profile may still state a bench's error (0 for the emulator's own): margins below it
        # are then INCONCLUSIVE as on that bench, e.g. to see what a 2 ms bench can tell
        lane.timing_error = profile.error_s
        return lane
    power_kind = config.getoption("power") or "none"
    if power_kind == "labgrid":
        power = config.stash[_LABGRID]  # opened by the preflight
    else:
        try:
            power = open_power(power_kind, config.getoption, _prompt(config))
        except PreflightError as exc:
            raise pytest.UsageError(str(exc)) from None
    return BusLane(bus_kwargs(config), power, timing_error=profile.error_s, bitrate_cmd=config.getoption("can_bitrate_cmd"),
                   host_send_error=config.getoption("host_send_error") / 1000, stamp=profile.stamp)


def make_multi_lane(config: pytest.Config, timing_error: float) -> Lane:
    """The emulator lanes' private bench of :data:`MULTI_NODES` (the main DUT stays alone, as Set ID needs)."""
    if config.getoption("lane") == "realtime":
        return RealtimeEmulatorLane(nodes=MULTI_NODES, timing_error=timing_error, esc_options=emulator_options(config))
    lane = SimLane(nodes=MULTI_NODES, faults=emulator_faults(config), seed=config.getoption("emulator_seed"),
                   esc_config={"boot_time": 0.25, **emulator_options(config)})
    lane.timing_error = timing_error  # the profile's stated error, as on the DUT's lane
    return lane


def echo_info(lane: Lane) -> dict[str, Any]:
    """What the reports say about the host's own frames: whether the bench echoes them, and so which
    clock times them (results.json and JUnit carry these keys; summary.txt and report.html say them)."""
    return {"echo": lane.echo, "echo_note": lane.echo_note, "own_frames_clock": lane.own_clock,
            "own_frames_error_s": round(lane.own_error, 9)}


def cycles_power(items: list[pytest.Item]) -> bool:
    """Whether a test of ``items`` may cycle the DUT's power (marker ``power_cycle`` or ``may_power_cycle``)."""
    return any(it.get_closest_marker("power_cycle") or it.get_closest_marker("may_power_cycle") for it in items)


def prove_bench(config: pytest.Config, items: list[pytest.Item]) -> list[str]:
    """--dut bus: the bench proven before any test (:mod:`..bench.proof`): who answers GET_ESC_ID, the node id given
    among them, and where a selected test may cycle power and a switch is given (not manual: an operator is the
    proof), the switch itself. A failure is a :class:`PreflightError`; returns what was proven, for the run to say."""
    if config.getoption("dut") != "bus":
        return []
    st = state(config)
    profile = st.profile
    assert profile is not None  # loaded by the preflight
    lane = make_lane(config, profile)
    try:
        where = preflight.bus_where(lane.bus_kwargs)
        link = proof.discover(lane, profile, config.getoption("node_id"), where)
        said = [f"bench: {', '.join(f'node {n}' for n in link.nodes)} answered GET_ESC_ID on the bus ({where}); the DUT "
                f"is node {link.node_id}"]
        kind = config.getoption("power") or "none"
        if lane.power.available and kind != "manual" and cycles_power(items):
            named = ({"off": f"--power-off-cmd {config.getoption('power_off_cmd')!r}",
                      "on": f"--power-on-cmd {config.getoption('power_on_cmd')!r}"} if kind == "command"
                     else {"off": f"power off ({lane.power.name})", "on": f"power on ({lane.power.name})"})
            said.append(f"bench: power switch ({kind}) {proof.prove_power(link, named)}")
        return said
    finally:
        lane.close()
