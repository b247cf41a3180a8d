"""labgrid power (``--power labgrid``) and shared places (``--labgrid-place``).

The DUT's supply is switched by labgrid's own PowerProtocol drivers, taken from a labgrid environment
file and target (``labgrid.Environment(FILE).get_target(NAME)``): any PDU, relay or USB hub labgrid
supports works with no code of ours. A power cycle is still proven by the DUT's power-up counter
(:meth:`.dut.Dut.power_cycle`); labgrid only switches.

A bench may be a labgrid *place* on a coordinator (a rig on another machine, shared by many people):
the run acquires (locks) it before it touches the bench, and releases it on every way out (the end,
a failure, an abort, Ctrl-C, SIGTERM: the plugin registers :meth:`LabgridPower.close` as a pytest
cleanup). The place is the one ``--labgrid-place`` names, or the one the target's ``RemotePlace``
resource names; a place someone else holds is refused at once with who holds it.

The lock goes through labgrid's Python client (:mod:`labgrid.remote.client`: ``start_session``, the
session's ``acquire`` / ``release``, which ``labgrid-client -p NAME acquire`` runs too), not a
``labgrid-client`` subprocess: one session serves the lock and the RemotePlace resources (as
``labgrid-client`` itself shares it, through ``RemotePlaceManager``), errors come back as exceptions
whose text names the holder, and the release needs no program on PATH on the way out.

labgrid is imported only here and only when ``--power labgrid`` is used: it is the optional extra
``rig`` (``pip install ".[rig]"``).
"""

from __future__ import annotations

import argparse
import atexit
import contextlib
import io
import os
import signal
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

from .errors import PreflightError
from .power_control import Option, PowerControl

#: what installs labgrid (the set-up error names it)
INSTALL_HINT = 'pip install ".[rig]"'
#: labgrid-client's default coordinator (its ``--coordinator`` help)
DEFAULT_COORDINATOR = "127.0.0.1:20408"


def _import_labgrid():
    try:
        import labgrid  # noqa: F401
        import labgrid.remote.client  # noqa: F401 - grpc and the generated protocol come with it
    except ImportError as exc:
        raise PreflightError(f"--power labgrid needs labgrid, which is not installed here ({exc.name or exc}): "
                             f"{INSTALL_HINT} (in a checkout: pip install -e \".[rig]\")") from None
    return labgrid


def one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


class PlaceLock:
    """A labgrid place acquired through its coordinator for this run, and released again (once)."""

    def __init__(self, name: str, address: str) -> None:
        self.name, self.address = name, address
        self.session: Any = None
        self.acquired = False
        self._old_sigterm: Any = None

    def _run(self, coro) -> None:
        with contextlib.redirect_stdout(io.StringIO()):  # labgrid-client's "acquired place ..." lines
            self.session.loop.run_until_complete(coro)

    def acquire(self) -> None:
        from labgrid.remote.client import Error, start_session

        args = argparse.Namespace(place=self.name, allow_unmatched=False, kick=False)
        try:
            self.session = start_session(self.address, extra={"args": args})
        except Exception as exc:  # noqa: BLE001 - grpc and labgrid raise many kinds; all mean "no coordinator"
            raise PreflightError(f"--labgrid-place {self.name}: cannot reach the labgrid coordinator at {self.address}: "
                                 f"{one_line(exc)} (give --labgrid-coordinator HOST:PORT or LG_COORDINATOR)") from None
        try:
            place = self.session.places.get(self.name)
            if place is None:
                known = ", ".join(sorted(self.session.places)) or "none"
                raise PreflightError(f"--labgrid-place {self.name}: no such place on the coordinator {self.address} "
                                     f"(places: {known}; create it with `labgrid-client -p {self.name} create`)")
            if place.acquired:
                raise PreflightError(self.held_by(place.acquired))
            self._guard_sigterm()
            # pytest's cleanup (the plugin registers it) releases it, even when the session's teardown breaks; this
            # is the backstop for a process that ends some other way before that cleanup is registered
            atexit.register(self.release)
            self.acquired = True  # from here on (an interruption may come before the answer) release() looks
            try:
                self._run(self.session.acquire())
            except Error as exc:
                holder = self.session.places.get(self.name)
                if holder is not None and holder.acquired and holder.acquired != self.me:
                    raise PreflightError(self.held_by(holder.acquired)) from None
                raise PreflightError(f"--labgrid-place {self.name}: the coordinator {self.address} refused to lock "
                                     f"it: {one_line(exc)}") from None
        except BaseException:
            self.release()
            raise

    @property
    def me(self) -> str:
        return f"{self.session.gethostname()}/{self.session.getuser()}"

    def held_by(self, holder: str) -> str:
        if holder == self.me:
            return (f"labgrid place {self.name} is already acquired by you ({holder}): another run, or a "
                    f"`labgrid-client acquire` left over; release it with `labgrid-client -p {self.name} release`")
        return (f"labgrid place {self.name} is locked by {holder} (coordinator {self.address}); it is theirs until "
                f"they release it (`labgrid-client -p {self.name} release`), or take another place")

    def _guard_sigterm(self) -> None:
        """Until the plugin's own guard is in place (its lane fixture), SIGTERM would end the process without
        a release: make it a KeyboardInterrupt, which pytest turns into its teardown (and our cleanup)."""
        if signal.getsignal(signal.SIGTERM) in (signal.SIG_DFL, None):
            def stop(signum, frame):  # noqa: ARG001
                raise KeyboardInterrupt
            try:
                self._old_sigterm = signal.signal(signal.SIGTERM, stop)
            except ValueError:  # not the main thread
                pass

    def release(self) -> None:
        """Release the place (if this run acquired it) and close the session; a release that fails is said on
        stderr with the way out, never raised over the run's own result."""
        session = self.session
        if session is None:
            return
        try:
            if self.acquired:  # this run asked for it: release it if the coordinator says it is ours
                self.acquired = False
                self._run(session.sync_with_coordinator())
                place = session.places.get(self.name)
                if place is not None and place.acquired == self.me:
                    self._run(session.release())
        except Exception as exc:  # noqa: BLE001 - the coordinator may be gone by now
            print(f"ckesc: could not release labgrid place {self.name} ({self.address}): {one_line(exc)}; release it "
                  f"with `labgrid-client -p {self.name} release`", file=sys.stderr)
        finally:
            self.session = None
            atexit.unregister(self.release)
            with contextlib.suppress(Exception):
                session.loop.run_until_complete(session.stop())
                session.loop.run_until_complete(session.close())
            from labgrid.resource.remote import RemotePlaceManager

            manager = RemotePlaceManager.get()
            if manager.session is session:
                manager.session = None
            if self._old_sigterm is not None:
                with contextlib.suppress(ValueError):
                    signal.signal(signal.SIGTERM, self._old_sigterm)


class LabgridPower(PowerControl):
    """The DUT's power through a labgrid PowerProtocol driver (and the place it lives on, if any)."""

    name = "labgrid"

    def __init__(self, driver: Any, *, where: str, lock: PlaceLock | None = None, env: Any = None) -> None:
        self.driver, self.where, self.lock, self.env = driver, where, lock, env

    def _switch(self, how: str) -> None:
        try:
            getattr(self.driver, how)()
        except Exception as exc:  # noqa: BLE001 - a driver may raise anything (HTTP, SNMP, a USB hub ...)
            raise RuntimeError(f"labgrid power {how} failed ({self.where}): {one_line(exc)}") from exc

    def off(self) -> None:
        self._switch("off")

    def on(self) -> None:
        self._switch("on")

    def close(self) -> None:
        """Deactivate the drivers and release the place (idempotent: pytest's cleanup runs it on every way out)."""
        try:
            if self.env is not None:
                env, self.env = self.env, None
                with contextlib.suppress(Exception):
                    env.cleanup()
        finally:
            if self.lock is not None:
                self.lock.release()


def coordinator_address(given: str | None, env: Any = None) -> str:
    """labgrid-client's order: the option, the environment file's ``coordinator_address``, LG_COORDINATOR, its default."""
    if given:
        return given
    if env is not None:
        from_file = env.config.get_option("coordinator_address", "")
        if from_file:
            return str(from_file)
    return os.environ.get("LG_COORDINATOR") or DEFAULT_COORDINATOR


def _remote_places(config: dict) -> list[str]:
    from labgrid.factory import target_factory

    resources, _ = target_factory.normalize_config(config)
    return [name for name in resources.get("RemotePlace", {}) if name]


def environment(env_file: str, name: str | None) -> tuple[Any, str]:
    """labgrid's ``Environment`` of ``env_file`` (labgrid importable: the caller checked) and the name of its target
    ``name`` (default: the file's only one), as ``--power``, ``--bus-fault-cmd labgrid`` take them: a file labgrid
    cannot read, several targets and none named, or a target it does not have is a one-line :class:`PreflightError`."""
    from labgrid import Environment

    try:
        env = Environment(str(env_file))
        targets = env.config.get_targets() or {}
    except Exception as exc:  # noqa: BLE001 - YAML, templating, imports of the file: all "cannot read it"
        raise PreflightError(f"--labgrid-env {env_file}: not a labgrid environment file: {one_line(exc)}") from None
    if not name:
        if len(targets) != 1:
            raise PreflightError(f"--labgrid-env {env_file} has targets {', '.join(targets) or '(none)'}: name one "
                                 "with --labgrid-target")
        name = next(iter(targets))
    if name not in targets:
        raise PreflightError(f"--labgrid-env {env_file}: no target {name!r} (targets: {', '.join(targets) or 'none'})")
    return env, name


def open_driver(env: Any, name: str, protocol: str, where: str, *, missing: str, unusable: str) -> Any:
    """Target ``name``'s driver for ``protocol`` (a labgrid protocol or driver class), found without activating it,
    then activated; every problem a one-line :class:`PreflightError`: ``missing`` is the whole error where the target
    has no such driver, ``unusable`` names what the driver is for where it cannot be activated ("``unusable`` of
    ``where`` cannot be used: why"), and labgrid's own configuration and binding errors name the file and ``where``."""
    from labgrid.exceptions import NoDriverFoundError

    try:
        target = env.get_target(name)
        driver = target.get_driver(protocol, activate=False)
    except NoDriverFoundError:
        raise PreflightError(missing) from None
    except Exception as exc:  # noqa: BLE001 - labgrid's config and binding errors
        raise PreflightError(f"--labgrid-env {env.config_file}: {where}: {one_line(exc)}") from None
    try:
        target.activate(driver)
    except Exception as exc:  # noqa: BLE001 - an unavailable resource, a driver that cannot start
        raise PreflightError(f"{unusable} of {where} cannot be used: {one_line(exc)}") from None
    return driver


#: the labgrid options: those of the env file and its target (which --flash-cmd labgrid uses too), then the power's own
LABGRID_TARGET_OPTIONS = ("labgrid_env", "labgrid_target")
LABGRID_OPTIONS = (*LABGRID_TARGET_OPTIONS, "labgrid_place", "labgrid_coordinator")


def labgrid_options(get: Callable[[str], Any]) -> None:
    """--power labgrid's options: given together, the environment file there (labgrid itself is not needed yet)."""
    if get("power") != "labgrid":
        # --flash-cmd labgrid flashes and --bus-fault-cmd labgrid shorts the bus through the target of the same file
        # (:mod:`.labgrid_flash`, :mod:`.labgrid_relay` check it)
        flashes = get("flash_cmd") == "labgrid" or get("bus_fault_cmd") == "labgrid"
        for opt in LABGRID_OPTIONS[len(LABGRID_TARGET_OPTIONS):] if flashes else LABGRID_OPTIONS:
            if get(opt):
                also = ", --flash-cmd labgrid or --bus-fault-cmd labgrid" if opt in LABGRID_TARGET_OPTIONS else ""
                raise PreflightError(f"--{opt.replace('_', '-')} is for --power labgrid{also}")
        return
    env_file = get("labgrid_env")
    if not env_file:
        raise PreflightError("--power labgrid needs --labgrid-env FILE (a labgrid environment file whose target has a "
                             "power driver) and --labgrid-target NAME")
    if not Path(env_file).is_file():
        raise PreflightError(f"--labgrid-env {env_file}: no such file")


def open_power(get: Option) -> LabgridPower:
    """--power labgrid: the target's power driver, activated, on its place (acquired) if it has one.
    Every set-up problem is a :class:`PreflightError` naming the file, the target or the place; a place
    acquired here is released again when a later step fails."""
    labgrid_options(get)
    _import_labgrid()
    from labgrid.resource.remote import RemotePlaceManager

    env_file = get("labgrid_env")
    env, name = environment(env_file, get("labgrid_target"))
    where = f"target {name} of {env_file}"
    try:
        in_file = _remote_places(env.config.get_targets()[name])
    except Exception as exc:  # noqa: BLE001
        raise PreflightError(f"--labgrid-env {env_file}: {where}: {one_line(exc)}") from None
    place = get("labgrid_place")
    if place and in_file and in_file != [place]:
        raise PreflightError(f"--labgrid-place {place}, but {where} is on place {', '.join(in_file)} (RemotePlace)")
    if not place and len(in_file) > 1:
        raise PreflightError(f"{where} names several places ({', '.join(in_file)}): the suite drives one bench")
    place = place or (in_file[0] if in_file else None)
    lock = None
    if place:
        lock = PlaceLock(place, coordinator_address(get("labgrid_coordinator"), env))
        lock.acquire()
        # the RemotePlace resources come through this same session, as labgrid-client shares its own
        manager = RemotePlaceManager.get()
        manager.session, manager.loop = lock.session, lock.session.loop
        where += f" on place {place} ({lock.address})"
    power = LabgridPower(None, where=where, lock=lock, env=env)
    try:
        driver = open_driver(env, name, "PowerProtocol", where, unusable="labgrid power",
                             missing=f"--labgrid-env {env_file}: {where} has no power driver (PowerProtocol: e.g. "
                                     "NetworkPowerDriver on a NetworkPowerPort)")
    except BaseException:
        power.close()
        raise
    power.driver = driver
    power.where = f"{type(driver).__name__} of {where}"
    return power
