"""One way to build a bench from its options, below any command: the pytest plugin (its preflight,
``ckesc/session/preflight.py``, from ``config.getoption``), ``ckesc explore`` and ``ckesc profile`` (from their
argparse namespace, ``ckesc/explore/runner.py``) and ``ckesc soak`` (``ckesc/soak/runner.py``) all call :func:`build`.

:class:`BenchOptions` is plain data: one field per bench option (the device under test, its lane, bus, power and
profile), made from the rows :data:`BENCH_ROWS`, which ``ckesc/session/options.py`` lists among the run's other
options (pytest's flags, ``ckesc run``'s and a rig file's keys are made from the same rows: an option is declared
once). :func:`build` checks them (:func:`.checks.check`: one :class:`.errors.PreflightError` line per mistake),
opens the power control (labgrid's place acquired before its bus is touched) and, on a real bus, opens the bus once
within its bound (:func:`.checks.open_bus`), and returns a :class:`Station`: the DUT profile (with the defaults a
real bus takes, and what an emulated ESC's variant declares), the DUT's lane, the ``multi_dut`` bench, the bench
proof (:mod:`.proof`) and :meth:`Station.close`.

Why *station*: "bench" already names the benchmarks folder, this package, the emulator's simulated bench, a rig
file's benches and two fixtures; a test station is the place set up to test one device, its bus, power and
profile, and the word means nothing else here (``Rig`` is a rig file's; a ``TestBench`` pytest would try to
collect as a test class).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

from ..emulator import variants
from . import checks, firmware, labgrid_flash, labgrid_relay, proof
from .errors import PreflightError
from .lanes import BusLane, Lane
from .link import DutError, DutUnreachable, Link, echo_probe
from .options import BENCH_ROWS, BUS_OPEN_TIMEOUT_S, DUT, SAME, BenchOptions, Option  # noqa: F401 - imported from here
from .power import PowerControl, Prompt, open_power
from .profile import DEFAULT_BUS_ERROR_S, DutProfile
from .realtime_lane import RealtimeEmulatorLane
from .sim_lane import SimLane
from .traffic_player import PlayerStats, TrafficPlayer

#: The private bench of the ``multi_dut`` fixture in the emulator lanes: node ids chosen so that
#: node_id % 32 covers 1, 2 and wraps (33 -> slot 1).
MULTI_NODES = (1, 2, 33)



def console_prompt(text: str) -> None:
    """Asks the operator (``--power manual``) at the console."""
    input(f"\n>>> {text} ")


def build(options: BenchOptions, *, prompt: Prompt = console_prompt,
          before_opening: Callable[[], None] | None = None) -> Station:
    """The bench ``options`` describe: checked (:func:`.checks.check`), then, on a real bus, its power control
    opened (labgrid's place acquired first: a shared place is locked before its bus is opened) and the bus opened
    once within ``--bus-open-timeout`` and closed again. ``before_opening``: the caller's own checks, run after the
    bench's and before anything is opened (the session's reports directory). A mistake is a
    :class:`.errors.PreflightError`; nothing is left open by one."""
    profile = checks.check(options)
    image = firmware_image(options)
    if before_opening is not None:
        before_opening()
    power: PowerControl | None = None
    kwargs: dict[str, Any] | None = None
    relay: labgrid_relay.LabgridRelay | None = None
    if options.dut == "bus":
        power = open_power(options.power or "none", options.get, prompt)
        try:
            kwargs = checks.bus_kwargs(options)
            checks.open_bus(kwargs, options.bus_open_timeout or BUS_OPEN_TIMEOUT_S)
            if options.bus_fault_cmd == labgrid_relay.LABGRID:  # opened now: a relay left closed is opened first
                relay = labgrid_relay.open_relay(options.labgrid_env, options.labgrid_target)
        except BaseException:
            _close_power(power)
            raise
    station = Station(options, profile, power, kwargs, image)
    station.bus_fault = relay
    return station


def firmware_image(options: BenchOptions) -> firmware.Image | None:
    """``--firmware``, ``--flash-cmd`` and ``--expect-firmware`` checked (:mod:`.firmware`): the image under test,
    or None when none is given; a mistake is a :class:`.errors.PreflightError`."""
    if not options.firmware:
        for given, flag in ((options.flash_cmd, "--flash-cmd"), (options.expect_firmware, "--expect-firmware")):
            if given:
                raise PreflightError(f"{flag} needs --firmware IMAGE (the image it flashes or proves)")
        return None
    image = firmware.load(options.firmware, options.expect_firmware)
    if options.dut == "bus" and not options.flash_cmd:
        raise PreflightError("--firmware on a real bus needs --flash-cmd \"CMD {image}\" (the command that writes the "
                             "image into the ESC)")
    if options.dut == "emulator" and not image.emulated:
        raise PreflightError(f"--firmware {options.firmware}: --dut emulator runs an emulator image (a TOML file with an "
                             "[esc_information] table: docs/firmware.md), not a binary")
    if options.flash_cmd == labgrid_flash.LABGRID:
        labgrid_flash.check(options.labgrid_env)
    elif options.flash_cmd and options.flash_cmd != firmware.BUILTIN:
        checks.command(firmware.command_line(options.flash_cmd, image), "--flash-cmd")
    checks.fault_names(",".join(image.faults), f"{image.path.name}: faults")
    checks.emulator_options(image.options)
    return image


def _close_power(power: PowerControl | None) -> None:
    close = getattr(power, "close", None)  # labgrid's: its drivers deactivated, its place released
    if close is not None:
        close()


class Station:
    """A bench built from its options (:func:`build`): what every command that drives a DUT needs of it.

    ``profile``: the DUT profile (a real bus's defaults taken; on the emulator, the timing its variant declares);
    ``power``: the power control of a real bus (None for the emulator, whose lanes switch their own);
    :meth:`open_lane` the DUT's lane, :meth:`multi_lane` the ``multi_dut`` fixture's private bench, :meth:`prove`
    the bench proof; :meth:`close` closes the lane and releases the power control (idempotent)."""

    def __init__(self, options: BenchOptions, profile: DutProfile, power: PowerControl | None,
                 bus_kwargs: dict[str, Any] | None, image: firmware.Image | None = None) -> None:
        self.options = options
        self.emulated = options.dut == "emulator"
        #: the firmware image under test (``--firmware``) and, once flashed and proven, what the reports say of it
        self.image = image
        self.firmware: dict[str, Any] | None = None
        own = image.options if image is not None and self.emulated else ()
        #: the conforming variant the emulated ESCs play ({EscConfig field: value}; checked by :func:`build`): an
        #: emulator image's options, then the command line's
        self.played: dict[str, Any] = (checks.emulator_options([*own, *options.emulator_option], options.emulator_variants)
                                       if self.emulated else {})
        for key, value in variants.declared(self.played).items():  # what the emulated ESC's vendor would state
            if value > getattr(profile, key):
                profile = dataclasses.replace(profile, **{key: value})
        self.profile = profile
        self.power = power
        self.bus_kwargs = bus_kwargs
        self.lane: Lane | None = None
        #: the foreign traffic playing on the DUT's lane (``--foreign-traffic``): what it is and what it reached
        self.foreign: ForeignPlay | None = None
        #: the bench's own bus-fault control, given to the DUT's lane (``--bus-fault-cmd labgrid``'s relay); closed
        #: (the relay opened) with the station
        self.bus_fault: labgrid_relay.LabgridRelay | None = None

    # ------------------------------------------------------------------ lanes
    def open_lane(self, on_open: Callable[[Lane], None] | None = None) -> Lane:
        """The DUT's lane, opened once and kept (:attr:`lane`) until :meth:`close_lane`: ``on_open(lane)`` first (the
        caller's listeners: its trace and live rules read every frame from the first), then on a real bus whether the
        host's own frames come back (:meth:`.lanes.BusLane.find_echo`), and only then the foreign traffic
        (``--foreign-traffic``), so that without an echo every frame it plays is handed out from its first."""
        if self.image is not None and not self.emulated and self.firmware is None:
            raise PreflightError("--firmware on a real bus is flashed and proven by ckesc run's bench proof: this "
                                 "command does not flash (run ckesc run --firmware first, then this without it)")
        if self.lane is None:
            self.lane = self._new_lane()
            self.lane.dut_boot_s = self.profile.boot_s  # (a send waits that long for an ESC that reset: Lane.dut_boot_s)
            if self.bus_fault is not None:
                self.bus_fault.lane = self.lane
                self.lane.bus_fault = self.bus_fault  # (bus_fault.bus_fault_control finds it there)
            try:
                if on_open is not None:
                    on_open(self.lane)
                if isinstance(self.lane, BusLane):
                    self.lane.find_echo(echo_probe(nibble_order=self.profile.nibble_order))
                if self.options.foreign_traffic:
                    self.foreign = ForeignPlay(self.options.foreign_traffic, self.lane)
            except BaseException:
                self.close_lane()
                raise
        return self.lane

    def _new_lane(self) -> Lane:
        o, profile = self.options, self.profile
        if self.emulated:
            faults = self._faults()
            nodes = checks.node_list(o.nodes or "1")
            if o.lane == "realtime":
                return RealtimeEmulatorLane(nodes=nodes, faults=faults, temp_flash=True, esc_options=self.played,
                                            seed=o.emulator_seed, timing_error=max(profile.error_s, DEFAULT_BUS_ERROR_S),
                                            firmware=str(self.image.path) if self.image else None)
            # in one process the emulated ESCs keep their flash contents across power cycles: no file needed
            lane = SimLane(nodes=nodes, faults=faults, seed=o.emulator_seed, esc_config=self._esc_config())
            # exact timestamps; a profile may still state a bench's error (0 for the emulator's own): margins below it
            # are then INCONCLUSIVE as on that bench, e.g. to see what a 2 ms bench can tell
            lane.timing_error = profile.error_s
            return lane
        assert self.power is not None and self.bus_kwargs is not None  # opened by build()
        return BusLane(self.bus_kwargs, self.power, timing_error=profile.error_s, bitrate_cmd=o.can_bitrate_cmd,
                       host_send_error=o.host_send_error / 1000, stamp=profile.stamp)

    def multi_lane(self, timing_error: float) -> Lane:
        """The emulator lanes' private bench of :data:`MULTI_NODES` (the main DUT stays alone, as Set ID needs); the
        caller closes it."""
        o = self.options
        if o.lane == "realtime":
            return RealtimeEmulatorLane(nodes=MULTI_NODES, timing_error=timing_error, esc_options=self.played,
                                        firmware=str(self.image.path) if self.image else None)
        lane = SimLane(nodes=MULTI_NODES, faults=self._faults(), seed=o.emulator_seed, esc_config=self._esc_config())
        lane.timing_error = timing_error  # the profile's stated error, as on the DUT's lane
        lane.dut_boot_s = self.profile.boot_s
        return lane

    def _faults(self) -> list[str]:
        """The emulated ESCs' faults: an emulator image's, then ``--emulator-faults``."""
        own = self.image.faults if self.image is not None else ()
        return checks.fault_names(",".join([*own, self.options.emulator_faults]))

    def _esc_config(self) -> dict[str, Any]:
        """The simulated lane's EscConfig fields: its short boot, an emulator image's 240 answer, the variant played."""
        return {"boot_time": 0.25, **(self.image.esc_config if self.image is not None else {}), **self.played}

    def close_lane(self) -> None:
        lane, self.lane = self.lane, None
        try:
            if self.foreign is not None:
                self.foreign.stop()  # its figures stay (``foreign.report()``) for the run's reports
        finally:
            if lane is not None:
                lane.close()

    def close(self) -> None:
        """The DUT's lane closed, then the power control released (labgrid's place); idempotent."""
        try:
            self.close_lane()
        finally:
            try:
                if self.bus_fault is not None:
                    self.bus_fault.close()  # the relay opened on every way out
            finally:
                power, self.power = self.power, None
                _close_power(power)

    # ------------------------------------------------------------------ the proof
    def prove(self, *, cycles_power: bool) -> list[str]:
        """--dut bus: the bench proven before the DUT is judged (:mod:`.proof`), on a lane of its own: who answers
        GET_ESC_ID, the node id given among them, and where the run may cycle power (``cycles_power``) and a switch
        is given (not manual: an operator is the proof), the switch itself. A failure is a
        :class:`.errors.PreflightError`; returns what was proven, for the run to say."""
        o = self.options
        cmd = (labgrid_flash.command_line(o.labgrid_env, o.labgrid_target) if o.flash_cmd == labgrid_flash.LABGRID
               else o.flash_cmd or firmware.BUILTIN)
        output = firmware.flash(self.image, cmd, o.flash_timeout) if self.image else ""
        if self.emulated:
            return self._prove_image(output) if self.image else []
        lane = self._new_lane()
        assert isinstance(lane, BusLane)
        try:
            where = checks.bus_where(lane.bus_kwargs)
            link = proof.discover(lane, self.profile, o.node_id, where)
            said = [f"bench: {', '.join(f'node {n}' for n in link.nodes)} answered GET_ESC_ID on the bus ({where}); the "
                    f"DUT is node {link.node_id}"]
            kind = o.power or "none"
            # a flash tool that does not reset the ESC: the proven power cycle starts the image
            if lane.power.available and kind != "manual" and (cycles_power or self.image is not None):
                named = ({"off": f"--power-off-cmd {o.power_off_cmd!r}", "on": f"--power-on-cmd {o.power_on_cmd!r}"}
                         if kind == "command" else
                         {"off": f"power off ({lane.power.name})", "on": f"power on ({lane.power.name})"})
                said.append(f"bench: power switch ({kind}) {proof.prove_power(link, named)}")
            if self.image is not None:
                said.append(self._image_answers(link, output))
            return said
        finally:
            lane.close()

    def _prove_image(self, output: str) -> list[str]:
        """An emulator image proven as a real one is: the emulated ESC asked 240 on a lane of its own."""
        lane = self._new_lane()
        try:
            nodes = checks.node_list(self.options.nodes or "1")
            link = Link(lane, self.profile, node_id=self.options.node_id or nodes[0])
            try:
                link.discover()  # booted: it answers GET_ESC_ID
            except DutUnreachable:
                pass  # 240 gets no answer either: said so
            return [self._image_answers(link, output)]
        finally:
            lane.close()

    def _image_answers(self, link: Link, output: str) -> str:
        """240 asked and judged against the image's expectation (:func:`.firmware.prove`); what the reports say of
        the image kept in :attr:`firmware`."""
        assert self.image is not None
        try:
            ex = link.request("esc_information", {"option": 0})
            fields = ex.response.physical() if ex.response is not None else None
        except DutError:
            fields = None
        self.firmware = firmware.report(self.image, self.options.flash_cmd, output, fields)
        return firmware.prove(self.image, fields)


class ForeignPlay:
    """Foreign traffic (:mod:`.foreign`) played on a lane for as long as the lane is open: in the simulated lane a
    source of its bus (:meth:`~ckesc.emulator.sim_bus.SimWorld.add_source`, its frames contending by arbitration),
    on a real bus or the real-time emulator a :class:`.traffic_player.TrafficPlayer` sending on the host's own
    handle (:meth:`.lanes.BusLane.play`): every reader of the lane hears what was played, by its echo or the lane's
    copy, on an adapter whose handles do not hear each other too. :meth:`report` is what the run's reports say:
    what was played and the load and lateness reached."""

    def __init__(self, name: str, lane: Lane) -> None:
        from . import foreign  # imports dronecan (about a second): only when foreign traffic is asked for

        self.name = name
        # the other nodes talk at the run's bit rate, their configuration: while a test moves the ESC and the host
        # to another (Set Baud), nothing of theirs gets through (foreign.AtBitrate)
        self.traffic = foreign.profile(name)
        self.source = foreign.AtBitrate(self.traffic, lane.bitrate, lambda: lane.bitrate)
        self.lane = lane
        self.player: TrafficPlayer | None = None
        self.stats: PlayerStats | None = None
        self._t0 = lane.now()
        self._elapsed: float | None = None
        lane.foreign_traffic = self  # the tests that judge it find it there
        if isinstance(lane, SimLane):
            lane.sim.world.add_source(self.source)
        else:
            assert isinstance(lane, BusLane)
            self.player = TrafficPlayer(lane.play, [self.source], bitrate=lane.bitrate).start()

    def stop(self) -> None:
        if self._elapsed is not None:
            return
        self._elapsed = self.lane.now() - self._t0
        if self.player is not None:
            self.stats = self.player.stop()
        elif isinstance(self.lane, SimLane):
            self.lane.sim.world.remove_source(self.source)

    def report(self) -> dict[str, Any]:
        """What was played (its streams, nodes and rates) and what it reached: frames sent, the share of the bus's
        capacity they took, and (real time) how late the player sent them."""
        out: dict[str, Any] = {"profile": self.name, "streams": self.traffic.describe(), "bitrate": self.source.bitrate,
                               "dropped_at_other_bitrate": self.source.dropped}
        if self.player is not None:
            st = self.stats or self.player.stats
            out.update(frames=st.frames, load=round(st.load, 6), late_mean_ms=round(st.late_mean_s * 1000, 3),
                       late_max_ms=round(st.late_max_s * 1000, 3), send_errors=st.send_errors, seconds=round(st.elapsed_s, 3))
        elif isinstance(self.lane, SimLane):
            sim = self.lane.sim.world.source_stats.get(self.traffic.name, {"frames": 0, "busy_s": 0.0})
            seconds = self._elapsed if self._elapsed is not None else self.lane.now() - self._t0
            out.update(frames=int(sim["frames"]), load=round(sim["busy_s"] / seconds, 6) if seconds > 0 else 0.0,
                       late_mean_ms=0.0, late_max_ms=0.0, send_errors=0, seconds=round(seconds, 3))
        return out
